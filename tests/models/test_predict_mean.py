"""predict_mean: the posterior mean without the variance, on every engine, against the NumPy reference of eq. (12)
and against ``predict(x)[0]``; its per-factor weights follow appends; evaluate_grid(variance=False)."""

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from tests import reference as ref
from torch_gpioius.geometry.surfaces import evaluate_grid

KT = torch.tensor([[0.05, 0.04], [0.04, 0.06]], dtype=torch.float64)


def _queries(n=200, seed=3):
    return torch.tensor(np.random.default_rng(seed).uniform(-0.35, 0.35, (n, 2)))


def _reference_mean(model, xq, task):
    x, t = model.train_inputs[0].numpy(), model.train_inputs[1].squeeze(-1).numpy()
    kt = model.task_covariance.detach().numpy()
    mean, _ = ref.posterior(x, model.train_targets.numpy(), t, kt, model.theta, model.noise, xq.numpy(), task)
    return mean


@pytest.mark.parametrize("inference", ["dense", "structured", "batched"])
def test_mean_equals_the_reference_and_predict_also_after_appends(two_shape_data, inference):
    m = tg.GPIOIS(*two_shape_data, task_covariance=KT, inference=inference)
    xq = _queries()
    for step in range(3):
        for task in (0, 1):
            mean = m.predict_mean(xq, task).detach()
            np.testing.assert_allclose(mean.numpy(), _reference_mean(m, xq, task), rtol=0, atol=1e-10)
            np.testing.assert_allclose(mean, m.predict(xq, task)[0].detach(), rtol=0, atol=1e-12)
        # a contact and its free space: the cached outer weights must follow (batched borders them in place)
        angle = 0.4 + 0.3 * step
        c = 0.15 * np.array([np.cos(angle), np.sin(angle)])
        m.add_observations(torch.tensor(np.stack([c, 1.4 * c])), torch.tensor([0.0, 1.0]), 0)
    assert m.train_targets.numel() == two_shape_data[1].numel() + 6


def test_truncated_basis_mean_equals_its_predict_and_follows_appends(two_shape_data):
    x, y, t = two_shape_data
    a = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], 1)            # a dense camera: 600 outer points, numerically low rank
    xo = torch.tensor(np.concatenate([0.2 * ring, 0.3 * ring]))
    yo = torch.cat([torch.zeros(300), torch.ones(300)]).double()
    m = tg.GPIOIS(torch.cat([x[t == 0], xo]), torch.cat([y[t == 0], yo]),
                  torch.cat([t[t == 0], torch.ones(600, dtype=t.dtype)]), task_covariance=KT, outer_tol=1e-6)
    xq = _queries()
    assert m._inference().rank < 600                     # the basis is truncated
    for step in range(2):
        e = m._inference()
        f = e.factor(m._task_matrix())
        # the rotated part U alpha_rot and the raw part g / s nearly cancel (each ~1e3 times alpha_o here), so the
        # two orders of summation differ by rounding of the parts: eps times |k_o| . (|U alpha_rot| + |g / s|)
        parts = (e.u @ e._alpha_rot(f)).abs() + e._alpha_raw(f).abs()
        rounding = torch.finfo(torch.float64).eps * float((e.kernel.value(xq, e.xo) @ parts).max())
        for task in (0, 1):
            mean, _ = m.predict(xq, task)
            np.testing.assert_allclose(m.predict_mean(xq, task).detach(), mean.detach(), rtol=0,
                                       atol=10 * rounding)
        m.add_observations(torch.tensor([[0.0, -0.15 - 0.01 * step]]), torch.tensor([0.0]), 0)


def test_gpis_mean_equals_the_reference(two_shape_data):
    x, y, t = two_shape_data
    m = tg.GPIS(x[t == 0], y[t == 0])
    xq = _queries()
    want, _ = ref.posterior(x[t == 0].numpy(), y[t == 0].numpy(), np.zeros(int((t == 0).sum()), dtype=int),
                            np.ones((1, 1)), m.theta, m.noise, xq.numpy(), 0)
    np.testing.assert_allclose(m.predict_mean(xq).detach().numpy(), want, rtol=0, atol=1e-10)


@pytest.mark.parametrize("inference", ["dense", "structured"])
def test_local_model_mean_equals_its_predict(two_shape_data, inference):
    m = tg.LocalGPIOIS(*two_shape_data, regions=3, inference=inference)
    m.set_params(torch.tensor([0.05, 0.3, 0.8, -0.2, 1.1], dtype=torch.float64))
    xq = _queries()
    for task in (0, 1):
        np.testing.assert_allclose(m.predict_mean(xq, task).detach(), m.predict(xq, task)[0].detach(),
                                   rtol=0, atol=1e-12)


def test_mean_is_differentiable_like_predict(two_shape_data):
    m = tg.GPIOIS(*two_shape_data, task_covariance=KT)
    x1 = _queries(20).requires_grad_(True)
    x2 = x1.detach().clone().requires_grad_(True)
    (g1,) = torch.autograd.grad(m.predict_mean(x1, 0).sum(), x1)
    (g2,) = torch.autograd.grad(m.predict(x2, 0)[0].sum(), x2)
    np.testing.assert_allclose(g1, g2, rtol=0, atol=1e-10)


def test_grid_without_variance_has_the_same_mean(two_shape_data):
    m = tg.GPIOIS(*two_shape_data, task_covariance=KT)
    box = np.array([[-0.3, -0.3], [0.3, 0.3]])
    full = evaluate_grid(m, box, 0.02, 0)
    mean_only = evaluate_grid(m, box, 0.02, 0, variance=False)
    assert mean_only.var is None and full.var is not None
    np.testing.assert_allclose(mean_only.mean, full.mean, rtol=0, atol=1e-12)

"""Matérn-5/2: the second kernel, through the contract, in closed form, and through GPIOIS with both exact engines."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.testing import KernelContract
from torch_gpioius.kernels import Matern52


class TestContract(KernelContract):
    def make(self):
        return Matern52(lengthscale=0.15, outputscale=2.0)


class TestContract2D(KernelContract):
    dim = 2

    def make(self):
        return Matern52(lengthscale=0.08)


def test_values_in_closed_form():
    k = Matern52(lengthscale=0.1, outputscale=3.0)
    r = np.array([0.0, 0.01, 0.1, 0.37])
    a = torch.tensor(np.c_[r, np.zeros(4), np.zeros(4)])
    got = k.value(a, torch.zeros(1, 3, dtype=torch.float64))[:, 0].numpy()
    s = math.sqrt(5) * r / 0.1
    np.testing.assert_allclose(got, 3.0 * (1 + s + s * s / 3) * np.exp(-s), rtol=1e-14)
    with pytest.raises(ValueError, match="lengthscale"):
        Matern52(lengthscale=0.0)
    with pytest.raises(ValueError, match="outputscale"):
        Matern52(outputscale=float("nan"))


def test_values_without_a_graph_are_the_graph_values_to_the_bit():
    """Outside autograd the values are computed in place on row blocks (for grids against many observations);
    they are the differentiable expression's values exactly, over more rows than one block."""
    k = Matern52(lengthscale=0.07, outputscale=1.3)
    g = torch.Generator().manual_seed(0)
    a = torch.rand(3 * Matern52._BLOCK + 17, 3, generator=g, dtype=torch.float64)
    b = torch.rand(300, 3, generator=g, dtype=torch.float64)
    with torch.no_grad():
        fast = k.value(a, b)
    graph = k.value(a.clone().requires_grad_(True), b)
    assert graph.requires_grad and not fast.requires_grad
    assert torch.equal(fast, graph.detach())
    s = math.sqrt(5) * torch.cdist(a, b).numpy() / 0.07
    np.testing.assert_allclose(fast.numpy(), 1.3 * (1 + s + s * s / 3) * np.exp(-s), rtol=1e-12, atol=1e-15)


def test_gpiois_with_matern_is_exact_on_both_engines(two_shape_data):
    """The structured engine stays exact for a kernel that is not the inverse multiquadric: the same marginal
    likelihood, gradient, Hessian, posterior and closed-form gradients as one dense Cholesky, after appends too."""
    x, y, t = two_shape_data
    kt = torch.tensor([[0.8, 0.5], [0.5, 0.9]], dtype=torch.float64)
    dense = tg.GPIOIS(x, y, t, kernel=Matern52(0.12), noise=0.006, inference="dense", task_covariance=kt)
    fast = tg.GPIOIS(x, y, t, kernel=Matern52(0.12), noise=0.006, inference="structured", task_covariance=kt)
    assert type(fast._inference()).__name__ == "StructuredExactInference"
    extra = torch.tensor([[0.14, 0.05], [0.0, 0.16], [0.2, 0.2]], dtype=torch.float64)
    for m in (dense, fast):
        m.add_observations(extra, [0.0, 0.0, 1.0], 0)
    md, gd, hd = dense._inference().mll_derivatives(kt)
    mf, gf, hf = fast._inference().mll_derivatives(kt)
    assert abs(md - mf) <= 1e-10 * abs(md)
    torch.testing.assert_close(gf, gd, rtol=1e-8, atol=1e-9)
    torch.testing.assert_close(hf, hd, rtol=1e-7, atol=1e-8)
    q = torch.tensor([[0.1, 0.1], [0.0, -0.15], [0.3, 0.0]], dtype=torch.float64)
    for task in (0, 1):
        (mu_d, v_d), (mu_f, v_f) = dense.predict(q, task), fast.predict(q, task)
        torch.testing.assert_close(mu_f, mu_d, rtol=1e-11, atol=1e-12)
        torch.testing.assert_close(v_f, v_d, rtol=1e-9, atol=1e-12)
    mean, var, g_mean, g_var = fast._predict_with_gradients(q, 0)
    qq = q.clone().requires_grad_(True)
    mu, v = dense.predict(qq, 0)
    (gm,) = torch.autograd.grad(mu.sum(), qq)
    qq = q.clone().requires_grad_(True)
    (gv,) = torch.autograd.grad(dense.predict(qq, 0)[1].sum(), qq)
    torch.testing.assert_close(g_mean, gm, rtol=1e-9, atol=1e-10)
    torch.testing.assert_close(g_var, gv, rtol=1e-7, atol=1e-9)
    dense.fit()
    fast.fit()
    torch.testing.assert_close(fast.task_covariance, dense.task_covariance, rtol=1e-6, atol=1e-9)
    assert tg.metrics.prior_variance(fast, 0) == pytest.approx(float(fast.task_covariance[0, 0]) * 1.0)
    assert fast.theta == fast.lengthscale == fast.kernel.length and fast.kernel.describe()["kernel"] == "Matern52"

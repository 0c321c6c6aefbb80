import numpy as np
import pytest
import torch

import torch_gpioius as tg
from tests import reference as ref


def test_gpis_matches_reference():
    rng = np.random.default_rng(3)
    x = rng.uniform(-0.3, 0.3, (40, 3))
    y = (rng.uniform(size=40) > 0.5).astype(float)
    m = tg.GPIS(torch.tensor(x), torch.tensor(y), kernel=tg.kernels.InverseMultiquadricKernel(0.15), noise=0.08)
    xq = rng.uniform(-0.3, 0.3, (12, 3))
    mean, var = m.predict(torch.tensor(xq))
    one = np.ones((1, 1))
    t = np.zeros(40, dtype=int)
    rm, rv = ref.posterior(x, y, t, one, 0.15, 0.08, xq, 0)
    np.testing.assert_allclose(mean.numpy(), rm, atol=1e-8, rtol=0)
    np.testing.assert_allclose(var.numpy(), rv, atol=1e-8, rtol=0)
    assert abs(float(m.log_marginal_likelihood()) - ref.mll(x, y, t, one, 0.15, 0.08)) < 1e-8
    post = m.eval()(torch.tensor(xq))
    np.testing.assert_allclose(post.mean.detach().numpy(), rm, atol=1e-8, rtol=0)
    np.testing.assert_allclose(post.variance.detach().numpy(), rv, atol=1e-8, rtol=0)


def test_gpiois_with_identity_task_covariance_equals_gpis_on_inner_data(two_shape_data):
    x, y, t = two_shape_data
    joint = tg.GPIOIS(x, y, t, task_covariance=torch.eye(2))
    alone = tg.GPIS(x[t == 0], y[t == 0])
    xq = torch.rand(10, 2, dtype=torch.float64) - 0.5
    torch.testing.assert_close(joint.predict(xq, 0)[0], alone.predict(xq)[0], atol=1e-10, rtol=0)
    torch.testing.assert_close(joint.predict(xq, 0)[1], alone.predict(xq)[1], atol=1e-10, rtol=0)


def test_gpis_add_observations_and_bad_input():
    m = tg.GPIS(torch.zeros(1, 2), torch.zeros(1))
    m.add_observations(torch.tensor([[0.1, 0.0]]), torch.tensor([1.0]))
    assert m.train_inputs[0].shape == (2, 2)
    with pytest.raises(ValueError, match="labels"):
        m.add_observations(torch.tensor([[0.2, 0.0]]), torch.tensor([0.3]))
    assert m.train_inputs[0].shape == (2, 2)


def test_learn_theta_in_the_gpytorch_idiom():
    """theta is fixed by default; with learn_theta it trains through ExactMarginalLogLikelihood."""
    rng = np.random.default_rng(4)
    a = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    x = np.concatenate([0.2 * np.stack([np.cos(a), np.sin(a)], -1), 0.35 * np.stack([np.cos(a), np.sin(a)], -1)])
    y = np.concatenate([np.zeros(30), np.ones(30)])
    m = tg.GPIS(torch.tensor(x), torch.tensor(y),
                kernel=tg.kernels.InverseMultiquadricKernel(0.02, learn_lengthscale=True))
    from gpytorch.mlls import ExactMarginalLogLikelihood
    mll = ExactMarginalLogLikelihood(m.likelihood, m)
    params = [p for p in m.parameters() if p.requires_grad]
    assert len(params) == 1
    start = float(m.log_marginal_likelihood())
    opt = torch.optim.Adam(params, lr=0.1)
    m.train()
    for _ in range(30):
        opt.zero_grad()
        with tg.exact_arithmetic():   # backward inside too: linear_operator reads the settings there
            loss = -mll(m(m.train_inputs[0]), m.train_targets)
            loss.backward()
        opt.step()
    assert m.theta != pytest.approx(0.02)
    assert float(m.log_marginal_likelihood()) > start
    del rng


def test_gpytorch_gradients_exact_only_inside_context():
    """Above GPyTorch's max_cholesky_size (800), gradients of model(x) are exact only if backward runs inside
    tg.exact_arithmetic(); model.predict is exact wherever it is differentiated (finite differences as reference)."""
    rng = np.random.default_rng(7)
    n = 820
    x = rng.uniform(-0.5, 0.5, (n, 3))
    y = (rng.uniform(size=n) > 0.5).astype(float)
    m = tg.GPIS(torch.tensor(x), torch.tensor(y), kernel=tg.kernels.InverseMultiquadricKernel(0.15), noise=0.08).eval()
    q = torch.tensor([[0.05, -0.1, 0.2]], dtype=torch.float64)
    fd, err = ref.richardson_derivative(lambda p: float(m.predict(torch.tensor(p))[1]), q.numpy(), 1e-3)
    xq = q.clone().requires_grad_(True)
    grad_predict, = torch.autograd.grad(m.predict(xq)[1].sum(), xq)
    ref.assert_close_to_reference(grad_predict[0].numpy(), fd, err, what="d var / dx of model.predict")
    xq = q.clone().requires_grad_(True)
    with tg.exact_arithmetic():
        var = m(xq).variance
        grad_inside, = torch.autograd.grad(var.sum(), xq)
    ref.assert_close_to_reference(grad_inside[0].numpy(), fd, err, what="d var / dx of model(x) in the context")


@pytest.mark.parametrize(
    "args, match",
    [
        ((None, [0.0]), "train_x: missing"),
        (([[0.0, 0.0]], None), "train_y: missing"),
        (([[0.0, 0.0]], "0"), "train_y"),
        ((torch.zeros(1, 2, dtype=torch.complex128), [0.0]), "real"),
    ],
)
def test_missing_or_malformed_data_are_named(args, match):
    with pytest.raises(ValueError, match=match):
        tg.GPIS(*args)

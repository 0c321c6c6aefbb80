"""The kernel's length, the noise and K_t learned together (inference.hyperparameters, GPIOIS/GPIS
.learn_hyperparameters): the likelihood against GPyTorch's and the exact engines', its gradient against differences,
the optimum against the bounds, and the model's keep-or-restore rule."""

import math

import gpytorch
import numpy as np
import pytest
import torch

import torch_gpioius as tg
from tests.reference import richardson_derivative
from torch_gpioius.inference.hyperparameters import exact_mll, exact_mll_fast, maximize_hyperparameters
from torch_gpioius.kernels import InverseMultiquadricKernel, Matern52

KT = torch.tensor([[0.8, 0.5], [0.5, 0.9]], dtype=torch.float64)


def _sphere_data(n_in=30, n_out=80, seed=0):
    """Touches on one cap of a sphere of 10 cm with free space 3 cm out and 2 cm inside (label -0.4), and a camera's
    view of a cover 8 mm out, all round, with its free space."""
    rng = np.random.default_rng(seed)

    def on_sphere(n, cap):
        v = rng.standard_normal((n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        if cap:
            v[:, 2] = np.abs(v[:, 2]) + 0.5
            v /= np.linalg.norm(v, axis=1, keepdims=True)
        return v

    u_in, u_out = on_sphere(n_in, True), on_sphere(n_out, False)
    x = np.concatenate([0.10 * u_in, 0.13 * u_in[: n_in // 3], 0.08 * u_in[: n_in // 3],
                        0.108 * u_out, 0.158 * u_out[: n_out // 2]])
    y = np.concatenate([np.zeros(n_in), np.ones(n_in // 3), np.full(n_in // 3, -0.4),
                        np.zeros(n_out), np.ones(n_out // 2)])
    t = np.concatenate([np.zeros(n_in + 2 * (n_in // 3)), np.ones(n_out + n_out // 2)]).astype(np.int64)
    x = x + 1e-3 * rng.standard_normal(x.shape)
    return torch.tensor(x), torch.tensor(y), torch.tensor(t)


@pytest.mark.parametrize("kernel", [Matern52(0.07), InverseMultiquadricKernel(0.12)], ids=["matern", "imq"])
def test_exact_mll_is_gpytorch_and_the_engines(kernel):
    """Three independent computations of one number: the autograd likelihood here, GPyTorch's
    ExactMarginalLogLikelihood (times n: it divides by n) through the model's forward, and the structured engine."""
    x, y, t = _sphere_data()
    model = tg.GPIOIS(x, y, t, kernel=kernel, noise=0.01, task_covariance=KT)
    ours = float(exact_mll(model.kernel, x, y, t, torch.tensor(model.kernel.length, dtype=torch.float64),
                           torch.tensor(model.noise, dtype=torch.float64), KT))
    model.train()
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(model.likelihood, model)
    with tg.exact_arithmetic():
        theirs = float(mll(model(x, t), y).detach()) * len(y)
    model.eval()
    engine = float(model.log_marginal_likelihood())
    assert abs(ours - theirs) <= 1e-9 * abs(ours)
    assert abs(ours - engine) <= 1e-9 * abs(ours)


def test_the_gradient_matches_differences():
    x, y, t = _sphere_data()
    kernel = Matern52(0.07)
    point = np.array([0.07, 0.01, 0.8, 0.5, 0.6])           # length, noise, L00, L10, L11

    def f(p):
        p = torch.as_tensor(p, dtype=torch.float64)
        chol = torch.stack([torch.stack([p[2], torch.zeros((), dtype=torch.float64)]), p[3:5]])
        return exact_mll(kernel, x, y, t, p[0], p[1], chol @ chol.T)

    p = torch.tensor(point, requires_grad=True)
    (grad,) = torch.autograd.grad(f(p), p)
    steps = np.array([1e-3, 1e-4, 1e-2, 1e-2, 1e-2])
    for i in range(5):
        e = np.zeros(5)
        e[i] = 1.0
        est, err = richardson_derivative(lambda v: float(f(v)), point, steps[i], directions=[e])
        assert abs(float(grad[i]) - float(est[0])) <= 10 * float(err[0]) + 1e-7 * abs(float(grad[i])), i


@pytest.mark.parametrize("kernel", [Matern52(0.07), InverseMultiquadricKernel(0.12)], ids=["matern", "imq"])
def test_the_closed_form_gradient_is_autograds(kernel):
    """The optimiser's likelihood (the trace form ``tr(W dG) / 2``) has autograd-through-Cholesky's value and
    gradient, in every parameter, to rounding."""
    x, y, t = _sphere_data()
    grads = []
    for f in (exact_mll, exact_mll_fast):
        length = torch.tensor(0.07, dtype=torch.float64, requires_grad=True)
        noise = torch.tensor(0.02, dtype=torch.float64, requires_grad=True)
        kt = torch.tensor([[0.8, 0.5], [0.5, 0.9]], dtype=torch.float64, requires_grad=True)
        value = f(kernel, x, y, t, length, noise, kt)
        value.backward()
        grads.append((float(value.detach()), float(length.grad), float(noise.grad), kt.grad.clone()))
    (v0, l0, n0, k0), (v1, l1, n1, k1) = grads
    assert abs(v1 - v0) <= 1e-12 * abs(v0)
    assert abs(l1 - l0) <= 1e-9 * abs(l0) and abs(n1 - n0) <= 1e-9 * abs(n0)
    torch.testing.assert_close(k1, k0, rtol=1e-9, atol=1e-9 * float(k0.abs().max()))


def _log_gradient(kernel, x, y, t, result):
    """The likelihood and its gradient in (log length, log noise, L00, L10, L11) at a result."""
    chol = torch.linalg.cholesky(result.task_covariance)
    p = torch.tensor([math.log(result.length), math.log(result.noise), float(chol[0, 0]), float(chol[1, 0]),
                      float(chol[1, 1])], dtype=torch.float64, requires_grad=True)
    c = torch.stack([torch.stack([p[2], torch.zeros((), dtype=torch.float64)]), p[3:5]])
    value = exact_mll(kernel, x, y, t, p[0].exp(), p[1].exp(), c @ c.T)
    (g,) = torch.autograd.grad(value, p)
    return float(value.detach()), g


def test_the_optimum_is_stationary_where_free_and_pushes_out_at_a_bound():
    """The first-order conditions of a bounded maximum (KKT): zero gradient in the free parameters; at a bound, a
    gradient pointing out of the range. On a sphere the likelihood wants a long length (a smooth body); within
    (0.03, 0.06) m it ends at the upper bound, and says so."""
    x, y, t = _sphere_data()
    kernel = Matern52(0.1)
    for bounds in ((0.02, 0.5), (0.03, 0.06)):
        result = maximize_hyperparameters(kernel, x, y, t, 0.08, torch.eye(2, dtype=torch.float64),
                                          length_bounds=bounds)
        assert result.mll >= result.mll_start and result.evaluations >= 2
        assert bounds[0] <= result.length <= bounds[1] and 1e-4 <= result.noise <= 0.5
        value, g = _log_gradient(kernel, x, y, t, result)
        assert abs(value - result.mll) <= 1e-9 * abs(result.mll)
        scale = max(1.0, abs(value))
        assert float(g[1:].abs().max()) < 1e-3 * scale                    # noise and K_t free
        if "length" in result.at_bound:
            assert result.length == pytest.approx(bounds[1], rel=2e-2) and float(g[0]) > 0
        else:
            assert abs(float(g[0])) < 1e-3 * scale
    assert "length" in result.at_bound                           # the narrow range binds
    assert kernel.length == 0.1                                  # the kernel itself is not changed


def test_the_model_keeps_values_that_raise_the_full_likelihood():
    x, y, t = _sphere_data()
    model = tg.GPIOIS(x, y, t, kernel=Matern52(0.1), noise=0.08).fit()
    before = float(model.log_marginal_likelihood())
    model.learn_hyperparameters()
    r = model.hyper_result
    assert r.kept and r.points == len(y)
    assert model.kernel.length == pytest.approx(r.length, rel=1e-12) and model.noise == pytest.approx(r.noise, rel=1e-9)
    after = float(model.log_marginal_likelihood())
    assert after >= before and r.mll_full == pytest.approx(after, rel=1e-12) and r.mll_full_before == before
    # exact at the new values: the structured engine's likelihood and posterior are a dense Cholesky's
    dense = tg.GPIOIS(x, y, t, kernel=Matern52(model.kernel.length), noise=model.noise, inference="dense",
                      task_covariance=model.task_covariance)
    assert abs(float(dense.log_marginal_likelihood()) - after) <= 1e-9 * abs(after)
    q = torch.tensor([[0.0, 0.0, 0.1], [0.05, 0.02, 0.12]], dtype=torch.float64)
    torch.testing.assert_close(model.predict(q, 0)[0], dense.predict(q, 0)[0], rtol=1e-9, atol=1e-10)
    # the parameters live in the model (GPyTorch's): its state_dict carries them, and a checkpoint restores them
    state = model.state_dict()
    fresh = tg.GPIOIS(x, y, t, kernel=Matern52(0.1), noise=0.08)
    fresh.load_state_dict(state)
    assert fresh.kernel.length == model.kernel.length and fresh.noise == model.noise


@pytest.mark.parametrize("kernel", [Matern52(0.06), InverseMultiquadricKernel(0.06)], ids=["matern", "imq"])
def test_values_that_lower_the_full_likelihood_are_put_back(kernel):
    """Learned on a thinned copy within bounds that exclude the full data's optimum, the values can lower the full
    likelihood: the model is then left exactly as it was, raw parameters (the inverse multiquadric's softplus does
    not round-trip a float) and engine included."""
    x, y, t = _sphere_data()
    model = tg.GPIOIS(x, y, t, kernel=kernel, noise=0.01).fit()
    kt, mll, raw = model.task_covariance, float(model.log_marginal_likelihood()), model.hyperparameter_state()
    engine = model._inference()
    model.learn_hyperparameters(size=4, outer_size=4, length_bounds=(0.3, 0.5), noise_bounds=(0.3, 0.5))
    r = model.hyper_result
    assert not r.kept and r.points == 8 and r.length >= 0.3
    assert model.hyperparameter_state() == raw and model.noise == pytest.approx(0.01, rel=1e-15)
    assert torch.equal(model.task_covariance, kt) and model._inference() is engine
    assert float(model.log_marginal_likelihood()) == mll


def test_bad_settings_are_refused_and_change_nothing():
    x, y, t = _sphere_data()
    model = tg.GPIOIS(x, y, t, kernel=Matern52(0.1), noise=0.08).fit()
    kt = model.task_covariance
    for kw, match in ((dict(size=1), "size"), (dict(outer_size=0), "outer_size"),
                      (dict(length_bounds=(0.3, 0.1)), "length_bounds"),
                      (dict(noise_bounds=(0.0, 1.0)), "noise_bounds"),
                      (dict(length_bounds="wide"), "length_bounds"), (dict(max_iter=0), "max_iter")):
        with pytest.raises(ValueError, match=match):
            model.learn_hyperparameters(**kw)
    assert model.kernel.length == 0.1 and torch.equal(model.task_covariance, kt) and model.hyper_result is None

    class Fixed(tg.kernels.ExactKernel):          # the contract's optional part left out: usable, not learnable
        def value(self, a, b):
            return torch.exp(-torch.cdist(a, b) / 0.1)

        def gradient(self, a, b, value=None):
            raise NotImplementedError

        def prior_variance(self, scale=1.0):
            return scale

        def second_derivative_at_zero(self):
            return math.nan

        def describe(self):
            return {"kernel": "Fixed"}

    with pytest.raises(TypeError, match="no learnable length"):
        tg.GPIOIS(x, y, t, kernel=Fixed(), noise=0.08, inference="dense").learn_hyperparameters()


def test_the_hyperparameter_state_is_checked_before_it_is_loaded():
    x, y, t = _sphere_data()
    model = tg.GPIOIS(x, y, t, kernel=Matern52(0.1), noise=0.08)
    state = model.hyperparameter_state()
    assert set(state) == {"covar_module.raw_lengthscale", "likelihood.noise_covar.raw_noise"}
    for bad, match in (({"covar_module.raw_theta": [[0.1]]}, "not a parameter"),
                       ({"covar_module.raw_lengthscale": [0.1, 0.2]}, "shape"),
                       ({"covar_module.raw_lengthscale": [[-0.1]]}, "lengthscale|theta|range|length")):
        with pytest.raises(ValueError, match=match):
            model.load_hyperparameter_state(bad)
        assert model.hyperparameter_state() == state
    model.load_hyperparameter_state({"covar_module.raw_lengthscale": [[0.07]]})
    assert model.kernel.length == 0.07


def test_gpis_learns_its_length_and_noise():
    x, y, t = _sphere_data()
    inner = t == 0
    model = tg.GPIS(x[inner], y[inner], kernel=Matern52(0.1), noise=0.08)
    before = float(model.log_marginal_likelihood())
    model.learn_hyperparameters()
    r = model.hyper_result
    assert r.kept and r.task_covariance is None and model.kernel.length != 0.1
    assert float(model.log_marginal_likelihood()) >= before
    ref = maximize_hyperparameters(Matern52(0.1), x[inner], y[inner], torch.zeros(int(inner.sum()), dtype=torch.long),
                                   0.08, None)
    assert ref.mll == pytest.approx(float(model.log_marginal_likelihood()), rel=1e-9)

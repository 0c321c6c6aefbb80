import numpy as np
import pytest
import torch
from gpytorch.mlls import ExactMarginalLogLikelihood
from scipy.optimize import minimize

import torch_gpioius as tg
from tests import reference as ref

KT = np.array([[0.8, 0.5], [0.5, 1.3]])


def _model(data, kt=KT, **kw):
    x, y, t = data
    return tg.GPIOIS(x, y, t, theta=0.1, noise=0.006, task_covariance=torch.tensor(kt), **kw)


@pytest.mark.parametrize("inference", ["dense", "structured"])
@pytest.mark.parametrize("task", [0, 1])
def test_predict_matches_dense_reference(random_data, task, inference):
    x, y, t = random_data
    m = _model(random_data, inference=inference)
    xq = np.random.default_rng(5).uniform(-0.4, 0.4, (25, 2))
    mean, var = m.predict(torch.tensor(xq), task=task)
    rm, rv = ref.posterior(x.numpy(), y.numpy(), t.numpy(), KT, 0.1, 0.006, xq, task)
    np.testing.assert_allclose(mean.numpy(), rm, atol=1e-8, rtol=0)
    np.testing.assert_allclose(var.numpy(), rv, atol=1e-8, rtol=0)


@pytest.mark.parametrize("task", [0, 1])
def test_gpytorch_posterior_matches_reference(random_data, task):
    """The GPyTorch idiom model(x, task) gives the same exact posterior."""
    x, y, t = random_data
    m = _model(random_data).eval()
    xq = np.random.default_rng(6).uniform(-0.4, 0.4, (20, 2))
    post = m(torch.tensor(xq), task)
    rm, rv = ref.posterior(x.numpy(), y.numpy(), t.numpy(), KT, 0.1, 0.006, xq, task)
    np.testing.assert_allclose(post.mean.detach().numpy(), rm, atol=1e-8, rtol=0)
    np.testing.assert_allclose(post.variance.detach().numpy(), rv, atol=1e-8, rtol=0)


@pytest.mark.parametrize("inference", ["dense", "structured"])
def test_mll_matches_reference_and_gpytorch(random_data, inference):
    x, y, t = random_data
    m = _model(random_data, inference=inference)
    expected = ref.mll(x.numpy(), y.numpy(), t.numpy(), KT, 0.1, 0.006)
    assert abs(float(m.log_marginal_likelihood()) - expected) < 1e-8
    m.train()
    with tg.exact_arithmetic():
        gp = ExactMarginalLogLikelihood(m.likelihood, m)(m(*m.train_inputs), m.train_targets) * len(y)
    assert abs(float(gp) - expected) < 1e-8


def test_exact_above_gpytorch_cholesky_threshold():
    """N = 900 > GPyTorch's max_cholesky_size (800): our calls must stay exact (CG would be off by ~1e-3)."""
    rng = np.random.default_rng(2)
    n = 900
    x = rng.uniform(-1, 1, (n, 2))
    y = (rng.uniform(size=n) > 0.5).astype(float)
    t = (rng.uniform(size=n) > 0.5).astype(np.int64)
    m = tg.GPIOIS(torch.tensor(x), torch.tensor(y), torch.tensor(t), task_covariance=torch.tensor(KT)).eval()
    xq = rng.uniform(-1, 1, (10, 2))
    rm, rv = ref.posterior(x, y, t, KT, 0.1, 0.006, xq, 0)
    post = m(torch.tensor(xq), 0)
    np.testing.assert_allclose(post.mean.detach().numpy(), rm, atol=1e-8, rtol=0)
    np.testing.assert_allclose(post.variance.detach().numpy(), rv, atol=1e-8, rtol=0)
    assert abs(float(m.log_marginal_likelihood()) - ref.mll(x, y, t, KT, 0.1, 0.006)) < 1e-7


def test_mll_derivatives_match_finite_differences(random_data):
    x, y, t = (d.numpy() for d in random_data)
    engine = tg.DenseExactInference(*random_data, theta=0.1, noise=0.006)
    f, g, h = engine.mll_derivatives(torch.tensor(KT))
    assert abs(f - ref.mll(x, y, t, KT, 0.1, 0.006)) < 1e-8
    eps = 1e-5
    basis = [np.array([[1, 0], [0, 0.0]]), np.array([[0, 1], [1, 0.0]]), np.array([[0, 0], [0, 1.0]])]
    fd = np.array([(ref.mll(x, y, t, KT + eps * e, 0.1, 0.006) - ref.mll(x, y, t, KT - eps * e, 0.1, 0.006))
                   / (2 * eps) for e in basis])
    np.testing.assert_allclose(g.numpy(), fd, rtol=1e-6, atol=1e-6)
    for j, e in enumerate(basis):
        gp = engine.mll_derivatives(torch.tensor(KT + eps * e))[1].numpy()
        gm = engine.mll_derivatives(torch.tensor(KT - eps * e))[1].numpy()
        np.testing.assert_allclose(h.numpy()[:, j], (gp - gm) / (2 * eps), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("inference", ["dense", "structured"])
def test_fit_reaches_stationary_psd_optimum_at_least_as_good_as_multistart(two_shape_data, inference):
    x, y, t = (d.numpy() for d in two_shape_data)
    m = tg.GPIOIS(*two_shape_data, theta=0.1, noise=0.006, inference=inference).fit()
    kt = m.task_covariance.numpy()
    assert np.linalg.eigvalsh(kt).min() >= 0
    assert m.fit_result.converged
    best = m.fit_result.mll
    assert abs(best - ref.mll(x, y, t, kt, 0.1, 0.006)) < 1e-8

    # Gradient of the independent reference MLL w.r.t. the Cholesky parameters at the optimum: ~0.
    lo = np.linalg.cholesky(kt)
    phi = np.array([np.log(lo[0, 0]), lo[1, 0], np.log(lo[1, 1])])
    eps = 1e-6
    grad = np.array([(ref.mll(x, y, t, ref.kt_from_chol(phi + eps * e), 0.1, 0.006)
                      - ref.mll(x, y, t, ref.kt_from_chol(phi - eps * e), 0.1, 0.006)) / (2 * eps)
                     for e in np.eye(3)])
    assert np.abs(grad).max() < 1e-4, grad

    # Multi-start reference optimiser (Nelder-Mead on the reference MLL, random starts).
    rng = np.random.default_rng(0)
    ref_best = -np.inf
    for _ in range(6):
        p0 = rng.normal(0, 1.5, 3)
        res = minimize(lambda p: -ref.mll(x, y, t, ref.kt_from_chol(p), 0.1, 0.006), p0, method="Nelder-Mead",
                       options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 20000, "maxfev": 20000})
        ref_best = max(ref_best, -res.fun)
    assert best >= ref_best - 1e-6


def test_fit_is_deterministic_and_learns_only_task_covariance(two_shape_data):
    a = tg.GPIOIS(*two_shape_data).fit()
    b = tg.GPIOIS(*two_shape_data).fit()
    assert torch.equal(a.task_covariance, b.task_covariance)
    assert a.theta == pytest.approx(0.1, abs=1e-12) and a.noise == pytest.approx(0.006, abs=1e-12)
    assert a.prior_mean == 1.0


def test_similarity_definition():
    m = tg.GPIOIS(torch.zeros(1, 2), torch.zeros(1), torch.zeros(1, dtype=torch.long),
                  task_covariance=torch.tensor([[0.5, 0.6], [0.6, 2.0]]))
    assert m.similarity == pytest.approx(1.2)   # ratio, may exceed 1
    assert m.correlation == pytest.approx(0.6)
    torch.testing.assert_close(m.task_covariance, torch.tensor([[0.5, 0.6], [0.6, 2.0]], dtype=torch.float64))


@pytest.mark.parametrize("inference", ["dense", "structured"])
def test_add_observations_equals_fresh_model(random_data, inference):
    x, y, t = random_data
    m = _model((x[:40], y[:40], t[:40]), inference=inference)
    xq = torch.rand(7, 2, dtype=torch.float64)
    m.predict(xq)  # build the engine, so the append path is exercised
    m.add_observations(x[40:], y[40:], t[40:])   # includes outer points: the structured engine rebuilds
    fresh = _model(random_data, inference="dense")
    for task in (0, 1):
        a, b = m.predict(xq, task), fresh.predict(xq, task)
        torch.testing.assert_close(a[0], b[0], atol=1e-10, rtol=0)
        torch.testing.assert_close(a[1], b[1], atol=1e-10, rtol=0)
    assert abs(float(m.log_marginal_likelihood() - fresh.log_marginal_likelihood())) < 1e-9


def test_state_dict_round_trip(two_shape_data):
    xq = torch.rand(9, 2, dtype=torch.float64) - 0.5
    # dense engine: bit-identical
    m = tg.GPIOIS(*two_shape_data, inference="dense").fit()
    other = tg.GPIOIS(*two_shape_data, inference="dense")
    other.load_state_dict(m.state_dict())
    for task in (0, 1):
        assert torch.equal(m.predict(xq, task)[0], other.predict(xq, task)[0])
        assert torch.equal(m.predict(xq, task)[1], other.predict(xq, task)[1])
    # structured engine: its head/tail split depends on the c it was built at, so equal to rounding
    m = tg.GPIOIS(*two_shape_data, inference="structured").fit()
    other = tg.GPIOIS(*two_shape_data, inference="structured")
    other.load_state_dict(m.state_dict())
    assert torch.equal(m.task_covariance, other.task_covariance)
    for task in (0, 1):
        torch.testing.assert_close(m.predict(xq, task)[0], other.predict(xq, task)[0], rtol=1e-12, atol=1e-13)
        torch.testing.assert_close(m.predict(xq, task)[1], other.predict(xq, task)[1], rtol=1e-12, atol=1e-13)


def test_duplicate_points_tiny_noise_escalating_jitter_no_nan():
    x = torch.tensor([[0.0, 0.0], [0.0, 0.0], [0.1, 0.0], [0.1, 0.0]], dtype=torch.float64)
    m = tg.GPIOIS(x, torch.zeros(4), torch.tensor([0, 0, 1, 1]), noise=1e-20,
                  task_covariance=torch.tensor([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.warns(tg.JitterWarning, match="jitter"):
        mean, var = m.predict(torch.tensor([[0.05, 0.0]], dtype=torch.float64))
    assert torch.isfinite(mean).all() and torch.isfinite(var).all()
    assert torch.isfinite(m.log_marginal_likelihood())


def _snapshot(m):
    return (m.train_inputs[0].clone(), m.train_inputs[1].clone(), m.train_targets.clone(),
            m.predict(torch.zeros(1, 2, dtype=torch.float64))[0].clone())


@pytest.mark.parametrize("bad, match", [
    (dict(x=[[float("nan"), 0.0]], y=[0], task=[0]), "NaN"),
    (dict(x=[[float("inf"), 0.0]], y=[0], task=[0]), "NaN or inf"),
    (dict(x=[[0.0, 0.0]], y=[0, 1], task=[0]), "length"),
    (dict(x=[[0.0, 0.0]], y=[0], task=[0, 1]), "length"),
    (dict(x=[[0.0, 0.0]], y=[2], task=[0]), "labels"),
    (dict(x=[[0.0, 0.0]], y=[0], task=[3]), "task ids"),
    (dict(x=[[0.0, 0.0]], y=[0], task=[-1]), "task ids"),
    (dict(x=np.zeros((0, 2)), y=[], task=[]), "empty"),
    (dict(x=[[0.0, 0.0, 0.0]], y=[0], task=[0]), "dimension"),
    (dict(x=[0.0, 0.0], y=[0], task=[0]), "2-D"),
])
def test_bad_input_raises_and_leaves_model_unchanged(random_data, bad, match):
    m = _model(random_data)
    before = _snapshot(m)
    with pytest.raises(ValueError, match=match):
        m.add_observations(np.asarray(bad["x"], dtype=float), np.asarray(bad["y"], dtype=float),
                           np.asarray(bad["task"]))
    after = _snapshot(m)
    for a, b in zip(before, after):
        assert torch.equal(a, b)


def test_bad_constructor_and_query_input():
    with pytest.raises(ValueError, match="empty"):
        tg.GPIOIS(torch.zeros(0, 2), torch.zeros(0), torch.zeros(0, dtype=torch.long))
    with pytest.raises(ValueError, match="labels"):
        tg.GPIOIS(torch.zeros(2, 2), torch.tensor([0.0, 0.5]), torch.zeros(2, dtype=torch.long))
    m = tg.GPIOIS(torch.zeros(2, 2), torch.zeros(2), torch.tensor([0, 1]))
    with pytest.raises(ValueError, match="dimension"):
        m.predict(torch.zeros(3, 3))
    with pytest.raises(ValueError, match="NaN"):
        m.predict(torch.tensor([[float("nan"), 0.0]]))
    with pytest.raises(ValueError, match="task"):
        m.predict(torch.zeros(1, 2), task=2)
    with pytest.raises(ValueError, match="semi-definite"):
        m.task_covariance = torch.tensor([[1.0, 2.0], [2.0, 1.0]])


def test_remove_observations_equals_model_on_remaining_data(random_data):
    x, y, t = random_data
    m = _model(random_data)
    m.predict(torch.zeros(1, 2, dtype=torch.float64))
    drop = torch.zeros(len(y), dtype=torch.bool)
    drop[[3, 10, 11, 40]] = True
    m.remove_observations(drop)
    fresh = _model((x[~drop], y[~drop], t[~drop]))
    xq = torch.rand(6, 2, dtype=torch.float64)
    for task in (0, 1):
        torch.testing.assert_close(m.predict(xq, task)[0], fresh.predict(xq, task)[0], atol=1e-12, rtol=0)
        torch.testing.assert_close(m.predict(xq, task)[1], fresh.predict(xq, task)[1], atol=1e-12, rtol=0)
    m.remove_observations([0, 1])
    assert m.train_targets.shape[0] == len(y) - 6
    with pytest.raises(ValueError, match="out of range"):
        m.remove_observations([1000])
    with pytest.raises(ValueError, match="every observation"):
        m.remove_observations(torch.ones(len(y) - 6, dtype=torch.bool))
    assert m.train_targets.shape[0] == len(y) - 6

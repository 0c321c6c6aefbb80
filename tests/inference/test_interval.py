"""Profile-likelihood intervals of the similarity, against a brute-force profile of the independent NumPy MLL."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize

import torch_gpioius as tg
from tests import reference as ref
from torch_gpioius.inference.interval import chi2_quantile


def brute_profile(x, y, t, rho, theta=0.1, noise=0.006):
    """max over (a, c) of the reference MLL at correlation rho, by Nelder-Mead from several starts."""
    best = -np.inf
    for u0, w0 in ((-1.0, -1.0), (0.0, 0.0), (-2.0, -0.5), (-0.5, -2.0)):
        def neg(p):
            a, c = math.exp(2 * p[0]), math.exp(2 * p[1])
            kt = np.array([[a, rho * math.sqrt(a * c)], [rho * math.sqrt(a * c), c]])
            try:
                return -ref.mll(x, y, t, kt, theta, noise)
            except AssertionError:
                return np.inf
        res = minimize(neg, [u0, w0], method="Nelder-Mead", options=dict(xatol=1e-7, fatol=1e-10, maxiter=4000))
        best = max(best, -res.fun)
    return best


def test_correlation_interval_matches_a_brute_force_profile(two_shape_data):
    x, y, t = (d.numpy() for d in two_shape_data)
    m = tg.GPIOIS(*two_shape_data, inference="dense").fit()
    lo, hi = m.similarity_interval(0.95)
    grid = np.linspace(-0.2, 1.0, 61)
    prof = np.array([brute_profile(x, y, t, r) for r in grid])
    l_hat = prof.max()
    inside = 2 * (l_hat - prof) <= chi2_quantile(0.95)
    step = grid[1] - grid[0]
    # the brute-force set is an interval whose ends bracket ours to the grid step
    assert grid[inside].min() - step <= lo <= grid[inside].min() + 1e-9
    assert grid[inside].max() - 1e-9 <= hi <= grid[inside].max() + step
    assert lo < m.correlation < hi
    # the structured engine gives the same interval
    lo2, hi2 = tg.GPIOIS(*two_shape_data, inference="structured").fit().similarity_interval()
    assert abs(lo2 - lo) < 2e-3 and abs(hi2 - hi) < 2e-3


def test_an_interval_at_the_boundary_uses_the_mixture_quantile():
    """Inner contacts on the outer shape, no free space: the fit sits on rho = 1 and the interval reaches 1."""
    a = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], -1)
    x = np.concatenate([0.2 * ring[:10], 0.2 * ring])
    y = np.zeros(40)
    t = np.r_[np.zeros(10), np.ones(30)]
    m = tg.GPIOIS(x, y, t).fit()
    lo, hi = m.similarity_interval()
    assert hi == 1.0 and m.correlation > 0.999 and lo < 1.0
    assert chi2_quantile(0.95, boundary=True) == pytest.approx(2.7055, abs=1e-3)


def test_unidentified_similarity_spans_everything(two_shape_data):
    x, y, t = two_shape_data
    m = tg.GPIOIS(x[t == 1], y[t == 1], t[t == 1])
    assert m.similarity_interval() == (-1.0, 1.0)
    assert m.similarity_interval(kind="ratio") == (-math.inf, math.inf)
    with pytest.raises(ValueError, match="kind"):
        m.similarity_interval(kind="slope")


def test_ratio_interval_contains_the_estimate_and_matches_a_grid(two_shape_data):
    x, y, t = (d.numpy() for d in two_shape_data)
    m = tg.GPIOIS(*two_shape_data, inference="dense").fit()
    lo, hi = m.similarity_interval(kind="ratio")
    assert lo < m.similarity < hi

    def brute_ratio(s):
        best = -np.inf
        for u0, w0 in ((-1.0, -1.0), (0.0, -2.0), (-2.0, 0.0)):
            def neg(p):
                a, l2 = math.exp(2 * p[0]), math.exp(2 * p[1])
                kt = np.array([[a, s * a], [s * a, s * s * a + l2]])
                return -ref.mll(x, y, t, kt, 0.1, 0.006)
            res = minimize(neg, [u0, w0], method="Nelder-Mead", options=dict(xatol=1e-7, fatol=1e-10, maxiter=4000))
            best = max(best, -res.fun)
        return best
    l_hat = brute_ratio(m.similarity)
    q = chi2_quantile(0.95)
    assert 2 * (l_hat - brute_ratio(lo)) == pytest.approx(q, abs=0.05)
    assert 2 * (l_hat - brute_ratio(hi)) == pytest.approx(q, abs=0.05)


def test_the_profiles_slope_and_curvature_match_finite_differences(two_shape_data):
    """The search for the endpoints steps with the profile's slope (envelope theorem) and starts from its curvature
    (a Schur complement of the MLL's Hessian): both against central differences of the profile itself."""
    from torch_gpioius.inference.interval import _profile_slope

    m = tg.GPIOIS(*two_shape_data, inference="dense").fit()
    engine = m._inference()
    kt = m.task_covariance
    start = np.array([0.5 * math.log(float(kt[0, 0])), 0.5 * math.log(float(kt[1, 1]))])
    for rho in (0.3, 0.6, 0.85):
        f, x, slope, curv = _profile_slope(engine.mll_derivatives, rho, start)
        h = 1e-4
        fp, fm = (_profile_slope(engine.mll_derivatives, rho + d, x)[0] for d in (h, -h))
        # the profile's values are maximised to ~1e-11 nats, so the differences carry ~1e-7 (slope) and ~1e-3
        # (curvature) of rounding, beside truncations of h^2 f'''/6 and h^2 f''''/12 (~1e-6); measured: 1e-6
        assert slope == pytest.approx((fp - fm) / (2 * h), rel=1e-5, abs=1e-5)
        assert curv == pytest.approx((fp - 2 * f + fm) / h ** 2, rel=1e-3, abs=1e-2)


def test_the_endpoint_search_agrees_with_bisection_on_the_same_profile(two_shape_data):
    """The Newton search on the signed root and a plain bisection of the same profile find the same crossings,
    each to its bracket of 1e-3, and the search needs fewer MLL evaluations."""
    from torch_gpioius.inference import interval as iv

    m = tg.GPIOIS(*two_shape_data, inference="dense").fit()
    engine = m._inference()
    calls = [0]

    def evaluate(kt):
        calls[0] += 1
        return engine.mll_derivatives(kt)

    lo, hi, rho_hat = iv.correlation_interval(evaluate, m.task_covariance)
    n_search = calls[0]
    calls[0] = 0
    kt = m.task_covariance
    x = np.array([0.5 * math.log(float(kt[0, 0])), 0.5 * math.log(float(kt[1, 1]))])
    f_hat, x_hat = iv.profile_correlation(evaluate, rho_hat, x)
    q = chi2_quantile(0.95)
    ends = []
    for edge in (-1.0, 1.0):
        inside, outside, xi = rho_hat, edge, x_hat
        while abs(outside - inside) > 1e-3:
            mid = 0.5 * (inside + outside)
            f_mid, x_mid = iv.profile_correlation(evaluate, mid, xi)
            if 2 * (f_hat - f_mid) <= q:
                inside, xi = mid, x_mid
            else:
                outside = mid
        ends.append(0.5 * (inside + outside))
    assert abs(lo - ends[0]) <= 1e-3 and abs(hi - ends[1]) <= 1e-3
    assert n_search < calls[0]


def test_the_chi2_quantile_without_scipy_is_scipys():
    """chi2_1 quantiles from the standard library's normal quantile (scipy.stats cost 1.9 s to import per run)
    against scipy's own, inside and at the boundary (the 50:50 mixture of chi2_0 and chi2_1)."""
    from scipy.stats import chi2

    for level in (0.6, 0.8, 0.9, 0.95, 0.99, 0.999):
        assert chi2_quantile(level) == pytest.approx(float(chi2.ppf(level, 1)), rel=1e-12)
        assert chi2_quantile(level, boundary=True) == pytest.approx(float(chi2.ppf(2 * level - 1, 1)), rel=1e-12)

"""The fast exact engine (StructuredExactInference) held equal to the dense reference (issue 4)."""

import functools
import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.inference import DenseExactInference
from torch_gpioius.exploration.planning import plan_direction
from torch_gpioius.inference.structured import DirectStructuredInference, StructuredExactInference
from torch_gpioius.core.tolerances import tol
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ

REL = 1e-6  # the tolerance; the engine achieves ~1e-10


def _surface_data(n_outer=600, n_inner=120, seed=0, d=3):
    """Outer points on an ellipsoid and 5 cm outside it; inner contacts on a smaller one plus free space."""
    rng = np.random.default_rng(seed)

    def ellipsoid(n, radii):
        v = rng.normal(size=(n, d))
        return v / np.linalg.norm(v, axis=1, keepdims=True) * np.asarray(radii)

    r_out, r_in = (0.25, 0.18, 0.3)[:d], (0.2, 0.14, 0.25)[:d]
    xo = np.concatenate([ellipsoid(n_outer // 2, r_out), ellipsoid(n_outer - n_outer // 2, np.add(r_out, 0.05))])
    yo = np.r_[np.zeros(n_outer // 2), np.ones(n_outer - n_outer // 2)]
    n_free = n_inner // 5
    xi = np.concatenate([ellipsoid(n_inner - n_free, r_in), ellipsoid(n_free, np.add(r_in, 0.03))])
    yi = np.r_[np.zeros(n_inner - n_free), np.ones(n_free)]
    return (torch.tensor(np.concatenate([xi, xo])), torch.tensor(np.r_[yi, yo]),
            torch.tensor(np.r_[np.zeros(n_inner), np.ones(n_outer)].astype(np.int64)))


def _rel(a, b):
    return float((torch.as_tensor(a) - torch.as_tensor(b)).abs().max() / torch.as_tensor(b).abs().max())


@pytest.mark.parametrize("theta, noise", [(0.15, 0.08), (0.1, 0.006)])
def test_engine_equals_dense_values_and_derivatives(theta, noise):
    x, y, t = _surface_data()
    perm = torch.randperm(len(y), generator=torch.Generator().manual_seed(0))   # task order must not matter
    x, y, t = x[perm], y[perm], t[perm]
    dense = DenseExactInference(x, y, t, IMQ(theta), noise)
    fast = StructuredExactInference(x, y, t, IMQ(theta), noise)
    xq = x[:40] + 0.01
    for kt in ([[0.3, 0.25], [0.25, 0.4]], [[0.05, 0.01], [0.01, 0.6]], [[1.0, -0.5], [-0.5, 0.3]]):
        b = torch.tensor(kt, dtype=torch.float64)
        fd, gd, hd = dense.mll_derivatives(b)
        fs, gs, hs = fast.mll_derivatives(b)
        assert abs(fs - fd) <= REL * abs(fd) * 1e-3
        assert _rel(gs, gd) < 1e-9 and _rel(hs, hd) < 1e-9
        for task in (0, 1):
            md, vd = dense.predict(xq, task, b)
            ms, vs = fast.predict(xq, task, b)
            assert _rel(ms, md) < 1e-9
            assert float(((vs - vd).abs() / vd).max()) < 1e-7
    assert fast.series is not None and len(fast.series.n_j) > 1   # the expansion is really exercised


@pytest.mark.parametrize("outer_tol", [None, 1e-1])
def test_direct_engine_equals_dense_over_spread_task_covariances(outer_tol):
    """DirectStructuredInference (T(c) by direct products, no Chebyshev store) equals the dense reference, and the
    store engine, at K_t[1, 1] spread over five decades (one store window spans a factor of 2), also appended to and
    with a truncated outer basis; it never builds a store."""
    x, y, t = _surface_data(n_outer=500, n_inner=90, seed=7)
    first = int((t == 0).nonzero()[60])                 # inner rows after this one are appended later
    keep = torch.ones(len(t), dtype=torch.bool)
    later = (t == 0) & (torch.arange(len(t)) > first)
    keep[later] = False
    direct = DirectStructuredInference(x[keep], y[keep], t[keep], kernel=IMQ(0.15), noise=0.08, outer_tol=outer_tol)
    direct.append(x[later], y[later], t[later])
    store = StructuredExactInference(x, y, t, kernel=IMQ(0.15), noise=0.08, outer_tol=outer_tol)
    xi = torch.cat([x[keep][t[keep] == 0], x[later]])   # the direct engine's inner order: kept, then appended
    yi = torch.cat([y[keep][t[keep] == 0], y[later]])
    xs, ys = torch.cat([xi, x[t == 1]]), torch.cat([yi, y[t == 1]])
    ts = torch.cat([torch.zeros(len(xi), dtype=torch.long), torch.ones(int((t == 1).sum()), dtype=torch.long)])
    xq = x[:30] + 0.01
    for kt in ([[0.3, 0.25], [0.25, 0.4]], [[0.02, 0.03], [0.03, 0.05]], [[2.0, -3.0], [-3.0, 40.0]],
               [[0.5, 0.01], [0.01, 4e-4]]):
        b = torch.tensor(kt, dtype=torch.float64)
        fd, gd, hd = direct.mll_derivatives(b)
        fs, gs, hs = store.mll_derivatives(b)
        assert abs(fd - fs) <= 1e-10 * len(y)
        assert _rel(gd, gs) < 1e-8 and _rel(hd, hs) < 1e-8
        assert abs(float(direct.mll(b)) - fd) <= 1e-12 * len(y)
        if outer_tol is None:                            # the dense reference, exact K_oo
            ref = DenseExactInference(xs, ys, ts, IMQ(0.15), 0.08)
            fr, gr, hr = ref.mll_derivatives(b)
            assert abs(fd - fr) <= 1e-10 * len(y)
            assert _rel(gd, gr) < 1e-9 and _rel(hd, hr) < 1e-9
            predict = functools.partial(ref.predict, b=b)
        else:                                            # dense with the truncated basis' K' in place of K_oo
            fr, _, predict = _dense_with_kernel(direct, xs, ys, ts, b)
            assert abs(fd - float(fr)) <= 1e-10 * len(y)
        for task in (0, 1):
            md, vd = direct.predict(xq, task, b)
            mr, vr = predict(xq, task)
            # truncated: the complement's terms are differences of numbers ~1e3 c times the result (at c = 40 the
            # store engine is 9e-8 off the reference, the direct one 3.5e-8)
            assert _rel(md, mr) < (1e-9 if outer_tol is None else 1e-8 * max(1.0, kt[1][1]))
            assert float(((vd - vr).abs() / vr).max()) < 1e-7
    assert direct.series is None                         # no store was ever built
    assert store.series is not None


def test_restarts_scout_copy_uses_the_direct_engine():
    """GPIOIS.fit(scout=...)'s thinned copy evaluates with DirectStructuredInference (for the structured, batched
    and outer_tol engines), and its likelihood equals one built by hand on the same thinned data."""
    x, y, t = _surface_data(n_outer=300, n_inner=120, seed=8)
    b = torch.tensor([[0.3, 0.25], [0.25, 0.4]], dtype=torch.float64)
    for kwargs in ({"inference": "batched"}, {"inference": "structured"}, {"outer_tol": 1e-1}):
        m = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, task_covariance=b, **kwargs)
        built = []
        original = DirectStructuredInference.__init__

        def spy(self, *args, **kw):
            built.append(self)
            original(self, *args, **kw)

        DirectStructuredInference.__init__ = spy
        try:
            evaluate = m._task_fitter().likelihood(m._scout_engine(40))           # (evaluate, level)
        finally:
            DirectStructuredInference.__init__ = original
        assert len(built) == 1 and built[0].n_inner == 40
        assert built[0].outer_tol == kwargs.get("outer_tol")
        keep = m._thinned(40)
        ref = DenseExactInference(x[keep], y[keep], t[keep], IMQ(0.15), 0.08)
        evaluate, level = evaluate
        f, g, _ = evaluate(b)
        assert level(b) == f
        if "outer_tol" not in kwargs:
            fr, gr, _ = ref.mll_derivatives(b)
            assert abs(f - fr) <= 1e-10 * int(keep.sum()) and _rel(g, gr) < 1e-9
        assert built[0].series is None


def test_no_drift_after_200_incremental_additions():
    x, y, t = _surface_data(n_outer=600, n_inner=260, seed=1)
    inner, outer = t == 0, t == 1
    xi, yi = x[inner], y[inner]
    start = torch.cat([x[inner][:60], x[outer]]), torch.cat([yi[:60], y[outer]]), torch.cat(
        [torch.zeros(60, dtype=torch.long), torch.ones(int(outer.sum()), dtype=torch.long)])
    fast = StructuredExactInference(*start, kernel=IMQ(0.15), noise=0.08)
    b = torch.tensor([[0.3, 0.2], [0.2, 0.5]], dtype=torch.float64)
    fast.mll_derivatives(b)                       # builds the split, then grows it
    for k in range(60, 260):
        fast.append(xi[k:k + 1], yi[k:k + 1], torch.zeros(1, dtype=torch.long))
        if k % 50 == 0:
            b = b * 1.1                           # K_t moves as it does between steps
            fast.mll_derivatives(b)
            # the invariant behind exactness: the truncation of the current store stays within the tolerance
            assert fast.series.bound() * float(b[0, 1]) ** 2 <= tol.structured_series * fast.noise
    dense = DenseExactInference(torch.cat([xi, x[outer]]), torch.cat([yi, y[outer]]),
                                torch.cat([torch.zeros(260, dtype=torch.long), torch.ones(int(outer.sum()),
                                                                                          dtype=torch.long)]),
                                IMQ(0.15), 0.08)    # a fresh dense solve
    fd, gd, hd = dense.mll_derivatives(b)
    fs, gs, hs = fast.mll_derivatives(b)
    assert abs(fs - fd) <= 1e-9 * abs(fd) and _rel(gs, gd) < 1e-8 and _rel(hs, hd) < 1e-8
    xq = xi[:30] + 0.02
    md, vd = dense.predict(xq, 0, b)
    ms, vs = fast.predict(xq, 0, b)
    assert _rel(ms, md) < 1e-9 and float(((vs - vd).abs() / vd).max()) < 1e-7


def test_models_fit_and_plan_agree():
    """K_t, MLL, mu, V and the planned direction: structured vs dense models, within the issue's tolerances."""
    x, y, t = _surface_data(n_outer=500, n_inner=100, seed=2)
    dense = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, inference="dense").fit()
    fast = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, inference="structured").fit()
    assert _rel(fast.task_covariance, dense.task_covariance) < REL
    assert abs(float(fast.log_marginal_likelihood() - dense.log_marginal_likelihood())) < REL * abs(
        float(dense.log_marginal_likelihood()))
    contact = x[0]
    pd = plan_direction(dense, contact, step=0.01)
    pf = plan_direction(fast, contact, step=0.01)
    cos = float(pd.direction @ pf.direction) / 1e-4
    assert math.acos(min(1.0, cos)) < 1e-6
    xq = x[:20] + 0.01
    torch.testing.assert_close(fast.predict(xq)[0], dense.predict(xq)[0], rtol=REL, atol=0)
    torch.testing.assert_close(fast.predict(xq)[1], dense.predict(xq)[1], rtol=REL, atol=0)


def test_exploration_data_structured_equals_dense():
    """A short 2-D exploration run on the structured engine, then its data refitted densely."""
    scene = tg.sim.paper_objects_2d()["A"]
    trace = tg.explore(scene, mode="visual-tactile", max_steps=15)
    m = trace.model
    assert isinstance(m._inference(), StructuredExactInference)
    dense = tg.GPIOIS(m.train_inputs[0], m.train_targets, m.train_task, kernel=IMQ(0.1), noise=0.006,
                      task_covariance=m.task_covariance, inference="dense")
    xq = torch.as_tensor(scene.sample_boundary("inner", 0.05))
    torch.testing.assert_close(m.predict(xq)[0], dense.predict(xq)[0], rtol=1e-9, atol=1e-12)
    torch.testing.assert_close(m.predict(xq)[1], dense.predict(xq)[1], rtol=1e-7, atol=1e-12)
    refit_dense = dense.fit(multi_start=False)
    refit_fast = tg.GPIOIS(m.train_inputs[0], m.train_targets, m.train_task, kernel=IMQ(0.1), noise=0.006,
                           task_covariance=m.task_covariance, inference="structured").fit(multi_start=False)
    assert _rel(refit_fast.task_covariance, refit_dense.task_covariance) < REL


def test_structured_needs_outer_points():
    with pytest.raises(ValueError, match="outer"):
        tg.GPIOIS(torch.zeros(2, 2), torch.zeros(2), torch.zeros(2, dtype=torch.long),
                  inference="structured").predict(torch.zeros(1, 2))
    with pytest.raises(ValueError, match="inference"):
        tg.GPIOIS(torch.zeros(2, 2), torch.zeros(2), torch.zeros(2, dtype=torch.long), inference="fast")


# ---------------------------------------------------------------------------------------------------------------
# The Chebyshev expansion of T(c) (structured._ChebyshevStore) against independent references.

from torch_gpioius.inference import structured as st_mod  # noqa: E402


def _chebyshev_sum(coef, x, order):
    """sum_j coef_j T_j(x) and its first two x-derivatives (NumPy's Chebyshev class: an independent route)."""
    series = np.polynomial.chebyshev.Chebyshev(coef[:order + 1])
    return series(x), series.deriv(1)(x), series.deriv(2)(x)


@pytest.mark.parametrize("lam", [0.0, 1e-6, 3e-3, 0.08, 1.0, 40.0, 5e3])
def test_truncation_bounds_hold_for_every_order(lam):
    """err[k, J] bounds |e|, |c e_c| and |c^2 e_cc| of f(c) = 1/(c lam + s) truncated after order J, on the window."""
    s, c0 = 0.08, 0.3
    u0, h = math.log(c0), math.log(st_mod.WINDOW)
    lam_t = torch.tensor([lam], dtype=torch.float64)
    err = st_mod._unit_error_bounds(lam_t, s, u0, h)[0].numpy()
    coef = st_mod._chebyshev_coefficients(lam_t, s, u0, h)[0].numpy()
    x = np.linspace(-1, 1, 801)
    c = np.exp(u0 + h * x)
    f = 1 / (c * lam + s)
    c_fc = -c * lam / (c * lam + s) ** 2                       # c df/dc
    c2_fcc = 2 * (c * lam) ** 2 / (c * lam + s) ** 3           # c^2 d^2f/dc^2
    # rounding of each computed coefficient (a 129-term cosine sum), amplified by the derivatives of T_j
    delta = 4 * (st_mod.N_NODES + 2) * np.finfo(float).eps * f.max()
    j = np.arange(st_mod.J_MAX + 1)
    r0 = np.cumsum(np.full(len(j), delta))
    r1 = np.cumsum(delta * j**2 / h)
    r2 = np.cumsum(delta * (j**4 / (3 * h**2) + j**2 / h))
    informative = 0
    for order in range(st_mod.J_MAX + 1):
        p, px, pxx = _chebyshev_sum(coef, x, order)
        # c d/dc = (1/h) d/dx; c^2 d^2/dc^2 = (1/h^2) d^2/dx^2 - (1/h) d/dx
        e0 = np.abs(p - f).max()
        e1 = np.abs(px / h - c_fc).max()
        e2 = np.abs(pxx / h**2 - px / h - c2_fcc).max()
        assert e0 <= err[order] + r0[order] and e1 <= err[order] + r1[order] and e2 <= err[order] + r2[order], \
            (order, e0, e1, e2, err[order])
        informative += err[order] > r2[order]                  # orders where truncation, not rounding, is tested
    assert informative >= (3 if lam >= 1e-3 else 0)
    assert err[-1] < 1e-14 * (1 / s)                           # and it is not vacuous


def _store_case(seed=3, n_outer=300, n_inner=40):
    x, y, t = _surface_data(n_outer=n_outer, n_inner=n_inner, seed=seed)
    eng = StructuredExactInference(x, y, t, kernel=IMQ(0.15), noise=0.08)
    return eng


def test_store_equals_direct_sum_within_its_bound():
    eng = _store_case()
    c0, beta2 = 0.3, 0.05
    store = st_mod._ChebyshevStore(eng.lam, eng.p, eng.noise, c0, beta2)
    assert store.bound() * beta2 <= tol.structured_series * eng.noise
    for c in (c0 / 2, c0 / 1.3, c0, 1.7 * c0, 2 * c0):
        t0, t1, t2 = store.t_matrices(c)
        d = 1 / (c * eng.lam + eng.noise)
        ref0 = (eng.p * d) @ eng.p.T
        ref1 = (eng.p * (-eng.lam * d * d)) @ eng.p.T
        ref2 = (eng.p * (2 * eng.lam**2 * d**3)) @ eng.p.T
        scale = float(torch.linalg.matrix_norm(ref0, ord=2))
        # truncation within the rigorous bound, plus rounding: the coefficients' (~1e-16 relative) amplified by
        # the derivatives of the Chebyshev polynomials (~J^2 for T', ~J^4 for T'')
        assert float(torch.linalg.matrix_norm(t0 - ref0, ord=2)) <= store.bound() + 1e-13 * scale
        assert c * float(torch.linalg.matrix_norm(t1 - ref1, ord=2)) <= store.bound() + 1e-11 * scale
        assert c * c * float(torch.linalg.matrix_norm(t2 - ref2, ord=2)) <= store.bound() + 1e-9 * scale
        assert torch.equal(t0, t0.T)                       # unpacked exactly symmetric
    t_only = store.t_matrices(c0, derivatives=False)
    assert t_only[1] is None and torch.equal(t_only[0], store.t_matrices(c0)[0])


def _direct_t(eng, c):
    d = 1 / (c * eng.lam + eng.noise)
    return [(eng.p * wk) @ eng.p.T for wk in (d, -eng.lam * d * d, 2 * eng.lam**2 * d**3)]


def test_store_grown_by_appends_equals_direct_sum():
    """Rows appended in place (several batches) give the same T, T', T'' as the direct sum over all rows."""
    eng = _store_case(n_inner=60)
    grown = st_mod._ChebyshevStore(eng.lam, eng.p[:20], eng.noise, 0.3, 0.05)
    orders = list(grown.n_j)
    for lo in range(20, 60, 7):
        grown.append(eng.p[lo:lo + 7])
    assert grown.size == 60 and grown.n_j == orders          # orders are kept until the bound asks otherwise
    assert grown.bound() > st_mod._ChebyshevStore(eng.lam, eng.p[:20], eng.noise, 0.3, 0.05).bound()
    c = 0.4
    ref = _direct_t(eng, c)
    scale = float(torch.linalg.matrix_norm(ref[0], ord=2))
    for k, (got, want, rnd) in enumerate(zip(grown.t_matrices(c), ref, (1e-13, 1e-11, 1e-9))):
        err = c**k * float(torch.linalg.matrix_norm(got - want, ord=2))
        assert err <= grown.bound() + rnd * scale, (k, err)


def test_window_moves_with_c_and_results_stay_exact():
    x, y, t = _surface_data(n_outer=400, n_inner=60, seed=4)
    dense = DenseExactInference(x, y, t, IMQ(0.15), 0.08)
    fast = StructuredExactInference(x, y, t, IMQ(0.15), 0.08)
    centres = []
    for c in (0.05, 0.09, 0.5, 4.0, 0.02):                  # leaves the window [c0/2, 2 c0] several times
        b = torch.tensor([[0.3, 0.05], [0.05, c]], dtype=torch.float64)
        fd, gd, hd = dense.mll_derivatives(b)
        fs, gs, hs = fast.mll_derivatives(b)
        centres.append(fast.series.u0)
        assert abs(fs - fd) <= 1e-10 * abs(fd) and _rel(gs, gd) < 1e-8 and _rel(hs, hd) < 1e-7
        assert abs(math.log(c) - fast.series.u0) <= fast.series.h
    assert len(set(centres)) >= 4


def test_closed_form_gradients_equal_autograd():
    x, y, t = _surface_data(n_outer=300, n_inner=50, seed=5)
    fast = StructuredExactInference(x, y, t, IMQ(0.15), 0.08)
    new = x[t == 0][:3] + 0.004
    fast.append(new, torch.tensor([0.0, 1.0, 1.0], dtype=torch.float64), torch.zeros(3, dtype=torch.long))
    b = torch.tensor([[0.3, 0.2], [0.2, 0.4]], dtype=torch.float64)
    rng = torch.Generator().manual_seed(0)
    queries = [new[:1], new, x[:25] + 0.01 * torch.randn(25, 3, generator=rng, dtype=torch.float64)]
    for xq in queries:                                      # cached rotated rows (just added) and fresh ones
        for task in (0, 1):
            mean, var, g_mean, g_var = fast.predict_with_gradients(xq, task, b, chunk=8)
            xg = xq.clone().requires_grad_(True)
            m_ref, v_ref = fast.predict(xg, task, b)
            gm_ref, = torch.autograd.grad(m_ref.sum(), xg, retain_graph=True)
            gv_ref, = torch.autograd.grad(v_ref.sum(), xg)
            torch.testing.assert_close(mean, m_ref.detach(), rtol=1e-12, atol=1e-12)
            torch.testing.assert_close(var, v_ref.detach(), rtol=1e-9, atol=1e-12)
            torch.testing.assert_close(g_mean, gm_ref, rtol=1e-9, atol=1e-10)
            torch.testing.assert_close(g_var, gv_ref, rtol=1e-7, atol=1e-9)


def test_planner_geometry_closed_form_equals_autograd():
    x, y, t = _surface_data(n_outer=300, n_inner=50, seed=6)
    fast = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, inference="structured").fit()
    dense = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, inference="dense",
                      task_covariance=fast.task_covariance)
    xq = x[:10] + 0.01
    a = tg.geometry.surface_geometry(fast, xq)            # closed form
    b = tg.geometry.surface_geometry(dense, xq)           # autograd through the dense engine
    torch.testing.assert_close(a.grad_mean, b.grad_mean, rtol=1e-8, atol=1e-9)
    torch.testing.assert_close(a.grad_var, b.grad_var, rtol=1e-6, atol=1e-9)
    torch.testing.assert_close(a.normal, b.normal, rtol=1e-8, atol=1e-10)
    with pytest.raises(ValueError, match="task"):
        fast._predict_with_gradients(xq, 2)


def test_removing_inner_points_keeps_the_eigendecomposition():
    x, y, t = _surface_data(n_outer=300, n_inner=60, seed=7)
    m = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, inference="structured").fit()
    engine = m._inference()
    u = engine.u
    inner = torch.nonzero(t == 0).flatten()
    drop = torch.zeros(len(y), dtype=torch.bool)
    drop[inner[[2, 7, 30]]] = True
    series = engine.series
    assert series is not None and series.size == 60
    m.remove_observations(drop)
    assert m._inference() is engine and engine.u is u and engine.n_inner == 57
    # the Chebyshev store drops the rows in place (no rebuild), and its T(c) is still P D P^T of the kept rows
    assert engine.series is series and series.size == 57
    # at the store's window (the fit's last step may have left it: its trials beyond the window take T directly, and
    # the store moves at the next factorisation there)
    c = math.exp(series.u0)
    t_store = series.t_matrices(c, derivatives=False)[0]
    t_exact = (engine.p / (c * engine.lam + engine.noise)) @ engine.p.T
    assert float((t_store - t_exact).abs().max()) <= 1e-9 * float(t_exact.abs().max())
    fresh = tg.GPIOIS(x[~drop], y[~drop], t[~drop], kernel=IMQ(0.15), noise=0.08, inference="dense",
                      task_covariance=m.task_covariance)
    xq = x[:15] + 0.01
    for task in (0, 1):
        torch.testing.assert_close(m.predict(xq, task)[0], fresh.predict(xq, task)[0], rtol=1e-10, atol=1e-12)
        torch.testing.assert_close(m.predict(xq, task)[1], fresh.predict(xq, task)[1], rtol=1e-8, atol=1e-12)
    assert abs(float(m.log_marginal_likelihood() - fresh.log_marginal_likelihood())) < 1e-9 * abs(
        float(fresh.log_marginal_likelihood()))
    m.covar_module.theta = 0.2                               # a stale engine is never reused
    m.remove_observations([int(torch.nonzero(m.train_task == 0)[0])])
    assert m._inference() is not engine and m._inference().kernel.describe()["lengthscale"] == pytest.approx(
        0.2, rel=1e-12
    )
    engine = m._inference()
    outer_first = int(torch.nonzero(m.train_task == 1)[0])
    m.remove_observations([outer_first])                   # an outer point: the engine is rebuilt
    assert m._inference() is not engine and m._inference().n == len(y) - 5


# ---------------------------------------------------------------------------------------------------------------
# The truncated outer basis (outer_tol): an approximation beside the exact engine (issue 26).
def _dense_with_kernel(eng, x, y, t, kt):
    """Dense reference with ``K' = U diag(lam) U^T`` in place of K_oo, differentiable in K_t (autograd)."""
    inner, outer = t == 0, t == 1
    order = torch.cat([torch.nonzero(inner).flatten(), torch.nonzero(outer).flatten()])
    xs, ys = x[order], y[order]
    n_i = int(inner.sum())
    k = eng.kernel.value(xs, xs)
    kp = (eng.u * eng.lam) @ eng.u.T
    a, b, c = kt[0, 0], kt[0, 1], kt[1, 1]
    g = torch.cat([torch.cat([a * k[:n_i, :n_i], b * k[:n_i, n_i:]], 1), torch.cat([b * k[n_i:, :n_i], c * kp], 1)])
    g = g + eng.noise * torch.eye(len(ys), dtype=torch.float64)
    chol = torch.linalg.cholesky(g)
    r = ys - eng.mean
    alpha = torch.cholesky_solve(r.unsqueeze(-1), chol).squeeze(-1)
    mll = -0.5 * (2 * chol.diagonal().log().sum() + r @ alpha) - 0.5 * len(ys) * math.log(2 * math.pi)

    def predict(xq, task):
        scale = torch.cat([kt[task, 0].expand(n_i), kt[task, 1].expand(len(ys) - n_i)])
        kq = eng.kernel.value(xq, xs) * scale
        v = torch.linalg.solve_triangular(chol, kq.T, upper=False)
        return eng.mean + kq @ alpha, kt[task, task] * eng.kernel.prior_variance(1.0) - (v * v).sum(0)

    return mll, alpha, predict


def test_truncated_engine_is_exact_for_its_kernel():
    """With K' in place of K_oo the engine's arithmetic is exact: MLL, its gradient and Hessian, mean, variance and
    their x-gradients equal a dense solve with K' (and autograd through it)."""
    x, y, t = _surface_data(n_outer=1200, n_inner=100, seed=4)
    eng = StructuredExactInference(x, y, t, kernel=IMQ(0.15), noise=0.08, outer_tol=1e-1)
    assert eng.truncated and eng.rank < 1200 and 0 < eng.dropped_trace <= 1e-1 * 0.08
    xq = x[:25] + 0.01
    for kt in ([[0.3, 0.25], [0.25, 0.4]], [[1.0, -0.5], [-0.5, 0.3]]):
        p = torch.tensor([kt[0][0], kt[0][1], kt[1][1]], dtype=torch.float64, requires_grad=True)
        b = torch.stack([torch.stack([p[0], p[1]]), torch.stack([p[1], p[2]])])
        mll_ref, _, predict = _dense_with_kernel(eng, x, y, t, b)
        g_ref = torch.autograd.grad(mll_ref, p, create_graph=True)[0]
        h_ref = torch.stack([torch.autograd.grad(g_ref[j], p, retain_graph=True)[0] for j in range(3)])
        fs, gs, hs = eng.mll_derivatives(b.detach())
        # the MLL is a small difference of terms of size ~N (here ~20 from ~1e3): rounding scales with N
        assert abs(fs - float(mll_ref)) <= 1e-10 * len(y)
        assert _rel(gs, g_ref.detach()) < 1e-8 and _rel(hs, h_ref.detach()) < 1e-8
        for task in (0, 1):
            mr, vr = predict(xq, task)
            ms, vs = eng.predict(xq, task, b.detach())
            # 1e-8: the complement's terms (k . g / s, |k|^2 / s) are differences of numbers ~1e3 times the result
            assert _rel(ms, mr.detach()) < 1e-8 and float(((vs - vr.detach()).abs() / vr.detach()).max()) < 1e-7
            m2, v2, gm, gv = eng.predict_with_gradients(xq, task, b.detach())
            xg = xq.clone().requires_grad_(True)
            ma, va = eng.predict(xg, task, b.detach())
            gma, = torch.autograd.grad(ma.sum(), xg, retain_graph=True)
            gva, = torch.autograd.grad(va.sum(), xg)
            assert _rel(m2, ms) < 1e-8 and _rel(v2, vs) < 1e-8
            assert _rel(gm, gma) < 1e-9 and _rel(gv, gva) < 1e-7


def test_truncated_engine_is_within_its_bound_of_the_exact_one():
    """|MLL' - MLL| <= (delta + c tr(E) |alpha'|^2 (1 + delta)) / 2 with delta = c tr(E) / s (the Gram matrices
    differ by c E >= 0 in the outer block); a tighter tolerance moves everything towards the exact engine."""
    x, y, t = _surface_data(n_outer=1200, n_inner=100, seed=5)
    exact = StructuredExactInference(x, y, t, kernel=IMQ(0.15), noise=0.08)
    b = torch.tensor([[0.3, 0.25], [0.25, 0.4]], dtype=torch.float64)
    xq = x[:25] + 0.01
    errors = []
    for outer_tol in (10.0, 1e-1, 1e-3):
        eng = StructuredExactInference(x, y, t, kernel=IMQ(0.15), noise=0.08, outer_tol=outer_tol)
        delta = eng.truncation(0.4)
        assert delta == pytest.approx(0.4 * eng.dropped_trace / 0.08, rel=1e-12) and delta <= 0.4 * outer_tol
        _, alpha, _ = _dense_with_kernel(eng, x, y, t, b)
        bound = 0.5 * (delta + 0.4 * eng.dropped_trace * float(alpha @ alpha) * (1 + delta))
        err = abs(float(eng.mll(b)) - float(exact.mll(b)))
        assert eng.truncated and err <= bound + 1e-10 * abs(float(exact.mll(b)))      # + rounding
        errors.append((err, _rel(eng.predict(xq, 0, b)[0], exact.predict(xq, 0, b)[0])))
    assert errors[0][0] > errors[1][0] > errors[2][0] and errors[0][1] > errors[2][1] and errors[2][1] < 1e-6


def test_truncated_engine_grows_and_shrinks_like_a_fresh_one():
    """Appends (with the planner's cached rows) and removals keep the basis and equal a fresh truncated engine;
    outer points rebuild it with the same tolerance."""
    x, y, t = _surface_data(n_outer=1200, n_inner=80, seed=6)
    inner = torch.nonzero(t == 0).flatten()
    first = torch.ones(len(y), dtype=torch.bool)
    first[inner[40:]] = False
    eng = StructuredExactInference(x[first], y[first], t[first], kernel=IMQ(0.15), noise=0.08, outer_tol=1e-2)
    u = eng.u
    b = torch.tensor([[0.3, 0.2], [0.2, 0.5]], dtype=torch.float64)
    eng.mll_derivatives(b)
    for k in range(40, 80, 5):
        eng.append(x[inner[k:k + 5]], y[inner[k:k + 5]], torch.zeros(5, dtype=torch.long))
    assert eng.u is u
    fresh = StructuredExactInference(x, y, t, kernel=IMQ(0.15), noise=0.08, outer_tol=1e-2)
    torch.testing.assert_close(fresh.lam, eng.lam, rtol=0, atol=0)       # the same outer points, the same basis
    f1, g1, h1 = eng.mll_derivatives(b)
    f2, g2, h2 = fresh.mll_derivatives(b)
    assert abs(f1 - f2) <= 1e-10 * abs(f2) and _rel(g1, g2) < 1e-9 and _rel(h1, h2) < 1e-9
    contact = x[inner[75]].unsqueeze(0)                                   # served from the cached rotated rows
    for a_, b_ in zip(eng.predict_with_gradients(contact, 0, b), fresh.predict_with_gradients(contact, 0, b)):
        torch.testing.assert_close(a_, b_, rtol=1e-9, atol=1e-12)
    drop = torch.zeros(eng.n, dtype=torch.bool)
    drop[[3, 50, 70]] = True                                              # inner rows (inner first in data order)
    tasks = torch.cat([torch.zeros(eng.n_inner, dtype=torch.long), torch.ones(1200, dtype=torch.long)])
    assert eng.remove(drop, tasks)
    keep = torch.ones(len(y), dtype=torch.bool)
    keep[inner[[3, 50, 70]]] = False
    fresh = StructuredExactInference(x[keep], y[keep], t[keep], kernel=IMQ(0.15), noise=0.08, outer_tol=1e-2)
    xq = x[:10] + 0.01
    torch.testing.assert_close(eng.predict(xq, 0, b)[1], fresh.predict(xq, 0, b)[1], rtol=1e-9, atol=1e-12)
    assert abs(float(eng.mll(b) - fresh.mll(b))) <= 1e-10 * abs(float(fresh.mll(b)))
    eng.append(torch.tensor([[0.4, 0.0, 0.0]], dtype=torch.float64), torch.ones(1, dtype=torch.float64),
               torch.ones(1, dtype=torch.long))
    assert eng.outer_tol == 1e-2 and eng.truncated and len(eng.xo) == 1201


def test_model_outer_tol_fits_near_the_exact_model_and_reports_its_bound():
    x, y, t = _surface_data(n_outer=1200, n_inner=100, seed=8)
    exact = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08).fit()
    approx = tg.GPIOIS(x, y, t, kernel=IMQ(0.15), noise=0.08, outer_tol=1e-2).fit()
    assert exact.truncation == 0.0 and approx._inference().truncated
    assert 0 < approx.truncation <= 1e-2 * float(approx.task_covariance[1, 1])
    assert _rel(approx.task_covariance, exact.task_covariance) < 1e-4
    for bad in (0.0, -1e-3, float("nan"), "1e-3", True):
        with pytest.raises(ValueError, match="outer_tol"):
            tg.GPIOIS(x, y, t, outer_tol=bad)
    with pytest.raises(ValueError, match="outer_tol"):
        tg.GPIOIS(x, y, t, inference="dense", outer_tol=1e-3)
    with pytest.raises(ValueError, match="outer_tol"):
        tg.GPIOIS(x[t == 0], y[t == 0], t[t == 0], outer_tol=1e-3).fit()

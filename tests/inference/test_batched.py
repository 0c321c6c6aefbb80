"""The batched engine (rank-k bordering at a held K_t) held equal to a dense solve, and the re-learning rule."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.inference import BatchedExactInference, DenseExactInference
from torch_gpioius.inference.batched import SOLVE_BLOCK, _LowerFactor
from torch_gpioius.inference.structured import DirectStructuredInference, StructuredExactInference
from torch_gpioius.inference.optim import predicted_gain
from torch_gpioius.exploration.planning import plan_direction
from torch_gpioius.kernels import InverseMultiquadricKernel as IMQ

THETA, NOISE = 0.15, 0.08
KT = torch.tensor([[0.9, 0.7], [0.7, 1.1]], dtype=torch.float64)


def _ellipsoid(rng, n, radii):
    v = rng.normal(size=(n, 3))
    return torch.tensor(v / np.linalg.norm(v, axis=1, keepdims=True) * np.asarray(radii))


def _start(rng, n_outer=300, n_inner=30):
    xo = torch.cat([_ellipsoid(rng, n_outer // 2, (0.25, 0.18, 0.3)), _ellipsoid(rng, n_outer // 2, (0.3, 0.23, 0.35))])
    yo = torch.cat([torch.zeros(n_outer // 2), torch.ones(n_outer // 2)]).double()
    xi = _ellipsoid(rng, n_inner, (0.2, 0.14, 0.25))
    x = torch.cat([xi, xo])
    y = torch.cat([torch.zeros(n_inner, dtype=torch.float64), yo])
    t = torch.cat([torch.zeros(n_inner, dtype=torch.long), torch.ones(n_outer, dtype=torch.long)])
    return x, y, t


def _patch(rng, k):
    """k inner points near one surface point: a contact, surface points, free space (y = 1) in front."""
    c = _ellipsoid(rng, 1, (0.2, 0.14, 0.25))
    pts = c + 0.01 * torch.tensor(rng.normal(size=(k, 3)))
    y = torch.tensor((rng.random(k) < 0.25).astype(np.float64))
    pts = torch.where(y.bool().unsqueeze(1), pts * 1.08, pts)
    return pts, y


def _dense(engine):
    x = torch.cat([engine.xi, engine.xo])
    y = torch.cat([engine.yi, engine.yo])
    t = torch.cat([torch.zeros(engine.n_inner, dtype=torch.long), torch.ones(len(engine.xo), dtype=torch.long)])
    return DenseExactInference(x, y, t, IMQ(THETA), NOISE)


def _assert_exact(engine, rng, kt=KT):
    """Posterior (mean; variance over the prior variance), MLL and gradient within 1e-9 of a dense solve."""
    dense = _dense(engine)
    q = _ellipsoid(rng, 50, (0.2, 0.14, 0.25)) * torch.tensor(rng.uniform(0.9, 1.1, (50, 1)))
    for task in (0, 1):
        m1, v1 = engine.predict(q, task, kt)
        m2, v2 = dense.predict(q, task, kt)
        assert float((m1 - m2).abs().max()) < 1e-9
        assert float((v1 - v2).abs().max()) < 1e-9 * float(kt[task, task])
    mll1, g1 = engine.mll_gradient(kt)
    mll2, g2, _ = dense.mll_derivatives(kt)
    assert abs(mll1 - mll2) < 1e-9 * abs(mll2)
    # each gradient entry is a sum of terms of size ~N: hold it to 1e-9 of that scale
    assert float((g1 - g2).abs().max()) < 1e-9 * engine.n


def test_hundreds_of_batched_appends_stay_exact():
    rng = np.random.default_rng(0)
    engine = BatchedExactInference(*_start(rng), kernel=IMQ(THETA), noise=NOISE)
    engine.factor(KT)                                   # builds the held factorisation
    for step in range(240):
        x, y = _patch(rng, int(rng.integers(1, 9)))
        engine.append(x, y, torch.zeros(len(y), dtype=torch.long))
        if step in (0, 120):
            _assert_exact(engine, rng)
    assert engine.bordered_batches == 240              # never refactorised
    assert engine._held["chol"].sq.buf.shape[0] > 30 + 64   # the buffers grew past their first capacity
    _assert_exact(engine, rng)
    # the bordered inverse did not drift from the inverse of a fresh factorisation
    fresh = BatchedExactInference(torch.cat([engine.xi, engine.xo]), torch.cat([engine.yi, engine.yo]),
                                  torch.cat([torch.zeros(engine.n_inner, dtype=torch.long),
                                             torch.ones(len(engine.xo), dtype=torch.long)]), kernel=IMQ(THETA),
                                  noise=NOISE)
    fresh.factor(KT)
    w1, w2 = engine._held["w"].view, fresh._held["w"].view
    assert float((w1 - w2).abs().max() / w2.abs().max()) < 1e-9


def test_a_new_task_covariance_or_outer_points_or_removal_rebuild_and_stay_exact():
    rng = np.random.default_rng(1)
    engine = BatchedExactInference(*_start(rng), kernel=IMQ(THETA), noise=NOISE)
    engine.factor(KT)
    for _ in range(5):
        x, y = _patch(rng, 6)
        engine.append(x, y, torch.zeros(6, dtype=torch.long))
    other = torch.tensor([[0.3, 0.1], [0.1, 0.5]], dtype=torch.float64)
    _assert_exact(engine, rng, other)                   # a held state at another K_t is built afresh
    assert engine.bordered_batches == 0
    xo = _ellipsoid(rng, 4, (0.3, 0.23, 0.35))
    engine.append(xo, torch.ones(4, dtype=torch.float64), torch.ones(4, dtype=torch.long))
    assert engine._held is None and len(engine.xo) == 304
    _assert_exact(engine, rng)
    engine.append(*_patch(rng, 5), torch.zeros(5, dtype=torch.long))
    drop = torch.zeros(engine.n, dtype=torch.bool)
    task = torch.cat([torch.zeros(engine.n_inner, dtype=torch.long), torch.ones(len(engine.xo), dtype=torch.long)])
    drop[[0, 3, engine.n_inner - 1]] = True
    assert engine.remove(drop, task)
    assert engine._held is None
    _assert_exact(engine, rng)


def test_a_hold_behind_the_store_sums_t_directly_and_equals_the_store_and_a_dense_solve():
    """After a re-learning (the Chebyshev store current) and batches bordered in (the store behind), a new held K_t
    sums T and T' directly; held at the same K_t through the store instead, every held quantity agrees to rounding,
    and both equal a dense solve. A second new K_t refills the first's buffers in place."""
    rng = np.random.default_rng(11)
    engine = BatchedExactInference(*_start(rng), kernel=IMQ(THETA), noise=NOISE)
    engine.mll_derivatives(KT)                            # a Newton evaluation: the store holds every row
    assert engine.series is not None and not engine._store_behind(KT)
    for _ in range(6):
        engine.append(*_patch(rng, 8), torch.zeros(8, dtype=torch.long))
    other = torch.tensor([[0.8, 0.6], [0.6, 1.3]], dtype=torch.float64)
    assert engine._store_behind(other)
    direct = engine._direct_factor(other)
    store = super(BatchedExactInference, engine).factor(other, derivatives=True)
    for key in ("t0", "t1", "pd", "chol", "alpha_i"):
        scale = float(store[key].abs().max())
        assert float((direct[key] - store[key]).abs().max()) < 1e-10 * scale, key
    assert abs(float(direct["logdet_s"] - store["logdet_s"])) < 1e-10 * abs(float(store["logdet_s"]))
    engine._held = None
    _assert_exact(engine, rng, other)                     # held through the direct sum
    buffers = [engine._held[k].buf for k in ("w", "t0", "t1")]
    third = torch.tensor([[0.5, 0.2], [0.2, 0.9]], dtype=torch.float64)
    _assert_exact(engine, rng, third)
    assert all(engine._held[k].buf is b for k, b in zip(("w", "t0", "t1"), buffers))   # refilled, not reallocated


def test_the_gradient_at_a_k_t_a_newton_run_last_evaluated_uses_that_k_t():
    """A fit called again without new data asks for the gradient at the K_t its Newton run evaluated last: the
    engine's cache answers the factorisation, and the traces must use that K_t's S^-1, not an older held one."""
    rng = np.random.default_rng(12)
    engine = BatchedExactInference(*_start(rng), kernel=IMQ(THETA), noise=NOISE)
    engine.mll_gradient(KT)                               # held at KT
    other = torch.tensor([[0.4, 0.2], [0.2, 0.7]], dtype=torch.float64)
    engine.mll_derivatives(other)                         # a Newton evaluation at another K_t
    mll, g = engine.mll_gradient(other)
    mll_d, g_d, _ = _dense(engine).mll_derivatives(other)
    assert mll == pytest.approx(mll_d, rel=1e-10) and float((g - g_d).abs().max()) < 1e-9 * engine.n


def test_the_value_alone_then_the_derivatives_at_the_same_k_t_equal_a_fresh_evaluation():
    """``mll_value`` (a Newton trial judged by its value) equals the MLL that ``mll_derivatives`` reports there, and
    the derivatives asked next at the same K_t (the trial accepted) reuse that factorisation and equal a fresh
    engine's and a dense solve's; on the batched engine the value alone builds no held state (the held K_t and its
    buffers stay), and after it the held state still answers at the held K_t."""
    rng = np.random.default_rng(13)
    data = _start(rng, n_inner=40)
    for cls in (StructuredExactInference, DirectStructuredInference, BatchedExactInference):
        engine = cls(*data, kernel=IMQ(THETA), noise=NOISE)
        fresh = cls(*data, kernel=IMQ(THETA), noise=NOISE)
        if cls is BatchedExactInference:
            engine.mll_gradient(KT)                       # held at KT
            held = engine._held
        for i, kt in enumerate(([[0.4, 0.2], [0.2, 0.7]], [[0.05, 0.07], [0.07, 0.1]])):
            b = torch.tensor(kt, dtype=torch.float64)
            store = engine.series
            value = engine.mll_value(b)
            assert engine._cache.get("t1") is None        # the value alone: no derivative matrices yet
            f, g, h = engine.mll_derivatives(b)
            f_ref, g_ref, h_ref = fresh.mll_derivatives(b)
            f_d, g_d, h_d = _dense(engine).mll_derivatives(b)
            assert value == f                             # the same factorisation
            if i and cls is not DirectStructuredInference:
                # K_t[1, 1] 0.1 lies beyond the store's window (0.35-1.4) built at the first: T and its derivatives
                # came from direct products, the store not rebuilt for a trial
                assert engine.series is store and not store.covers(0.1, 0.07 ** 2)
            assert f == pytest.approx(f_ref, rel=1e-12) and f == pytest.approx(f_d, rel=1e-10)
            # the fresh engine may take T from its store where this one, beyond its store's window, took T directly
            # (both exact to the store's 1e-13 of s): the Hessian to the dense reference's tolerance
            assert (
                float((g - g_ref).abs().max()) < 1e-10 * engine.n and float((h - h_ref).abs().max()) < 1e-9 * engine.n
            )
            assert float((g - g_d).abs().max()) < 1e-9 * engine.n and float((h - h_d).abs().max()) < 1e-9 * engine.n
        if cls is BatchedExactInference:
            assert engine._held is held and held["key"] == tuple(KT.flatten().tolist())
            mll, grad = engine.mll_gradient(KT)
            assert engine._held is held
            f_d, g_d, _ = _dense(engine).mll_derivatives(KT)
            assert mll == pytest.approx(f_d, rel=1e-10) and float((grad - g_d).abs().max()) < 1e-9 * engine.n


def test_blocked_triangular_solves_equal_lapack():
    n = 2 * SOLVE_BLOCK + 37
    rng = np.random.default_rng(2)
    a = torch.tensor(rng.normal(size=(n, n)))
    low = torch.linalg.cholesky(a @ a.T / n + torch.eye(n, dtype=torch.float64))
    factor = _LowerFactor(low[:n - 40, :n - 40], n + 50)
    factor.solve(torch.ones(n - 40, 1, dtype=torch.float64))      # caches the diagonal blocks, one of them partial
    factor.border(low[n - 40:, :n - 40], low[n - 40:, n - 40:])  # grows the partial block: its cache must go
    assert torch.equal(factor.sq.view, low)
    rhs = torch.tensor(rng.normal(size=(n, 3)))
    for transpose in (False, True):
        ref = torch.linalg.solve_triangular(low.T if transpose else low, rhs, upper=transpose)
        got = factor.solve(rhs, transpose=transpose)
        assert float((got - ref).abs().max() / ref.abs().max()) < 1e-12


def test_predicted_gain_is_the_newton_decrement_of_a_quadratic():
    a = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    g = np.array([0.4, -0.2, 0.1])          # f(x) = g.x - x.A x / 2 gains g.A^-1 g / 2 at its maximum
    assert predicted_gain(g, -a, np.ones(3, bool)) == pytest.approx(0.5 * g @ np.linalg.solve(a, g), rel=1e-14)
    free = np.array([True, False, True])
    sub = np.ix_(free, free)
    assert predicted_gain(g, -a, free) == pytest.approx(0.5 * g[free] @ np.linalg.solve(a[sub], g[free]), rel=1e-14)
    assert predicted_gain(g, a, np.ones(3, bool)) == math.inf     # not a maximum: re-learn
    assert predicted_gain(g, -a, np.zeros(3, bool)) == 0.0


def test_a_held_newton_step_reaches_a_quadratics_maximum_within_its_caps_and_bounds():
    from torch_gpioius.inference.optim import cholesky_bounds, held_newton_step

    a = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    phi = np.array([-1.0, 0.2, -1.5])
    target = np.array([-0.8, 0.1, -1.2])            # f = -(p - target).A (p - target) / 2
    step = held_newton_step(phi, a @ (target - phi), -a)
    assert np.allclose(step, target, rtol=0, atol=1e-14)
    # a step longer than the trust radius is shortened along its direction; the bounds clamp it
    far = np.array([-1.0, 0.2, 9.0])
    capped = held_newton_step(phi, a @ (far - phi), -a)
    assert np.allclose((capped - phi) / np.linalg.norm(capped - phi), (far - phi) / np.linalg.norm(far - phi))
    assert abs(capped[2] - phi[2]) <= 2.0 + 1e-12
    lower, upper = cholesky_bounds()
    low = held_newton_step(np.array([lower[0], 0.2, -1.5]), np.array([-1.0, 0.0, 0.0]), -a)
    assert low[0] == lower[0]                        # at the bound, pushed past it: held there
    assert held_newton_step(phi, np.ones(3), a) is None          # no maximum's Hessian: no step


def _model(rng, inference="batched"):
    x, y, t = _start(rng, 300, 40)
    return tg.GPIOIS(x, y, t, kernel=IMQ(THETA), noise=NOISE, inference=inference).fit()


def test_fit_holds_task_covariance_while_the_gradient_predicts_little_and_relearns_otherwise():
    rng = np.random.default_rng(3)
    model = _model(rng)
    assert model.fit_result.relearned and model.fit_result.hessian is not None
    kt = model.task_covariance.clone()
    kinds = []
    for _ in range(4):
        x, y = _patch(rng, 16)
        model.add_observations(x, y, 0)
        model.fit(min_gain=math.inf, max_hold=3)
        kinds.append(model.fit_result.relearned)
        plan_direction(model, x[0], step=0.01)
    assert kinds == [False, False, False, True]         # held three times, then re-learned (max_hold)
    x, y = _patch(rng, 16)
    model.add_observations(x, y, 0)
    kt_held = model.task_covariance.clone()
    model.fit(min_gain=math.inf)
    held = model.fit_result
    assert not held.relearned and torch.equal(model.task_covariance, kt_held) and held.predicted_gain > 0
    # the held fit's MLL and gradient are those of a dense solve at the held K_t
    dense = _dense(model._inference())
    mll_d, g_d, _ = dense.mll_derivatives(model._task_matrix())
    assert held.mll == pytest.approx(mll_d, rel=1e-12)
    # min_gain = 0 re-learns every time; the result equals a full fit from the same start
    twin = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, kernel=IMQ(THETA), noise=NOISE,
                     task_covariance=kt_held, inference="structured").fit(multi_start=False)
    model.fit(min_gain=0.0)
    assert model.fit_result.relearned
    assert float((model.task_covariance - twin.task_covariance).abs().max()) < 1e-9
    assert not torch.equal(kt, model.task_covariance)


def test_held_gain_prediction_tracks_the_real_gain():
    """The Newton decrement with an old Hessian is a prediction: it must be of the size of the real gain. At an
    optimum inside K_t's bounds, where a quadratic describes the likelihood (on the ridge of a correlation of 1 it
    does not: there the re-learning steps along ``w`` to where the likelihood turns, nats off, which the decrement
    under-predicts by up to 2.6x on ``_model``'s data)."""
    rng = np.random.default_rng(4)
    model = _interior_model(rng)
    ratios = []
    for _ in range(6):
        x, y = _interior_patch(rng, 24)
        model.add_observations(x, y, 0)
        model.fit(min_gain=math.inf, max_hold=100)
        predicted = model.fit_result.predicted_gain
        held_mll = model.fit_result.mll
        best = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, kernel=IMQ(THETA), noise=NOISE,
                         task_covariance=model.task_covariance, inference="structured").fit(multi_start=False)
        ratios.append(predicted / (best.fit_result.mll - held_mll))
    assert all(0.5 < r < 2.0 for r in ratios), ratios


def _interior_model(rng):
    """An inner shape unlike the outer one (another ellipsoid's axes): K_t's optimum has a correlation near 0.5, inside
    its bounds (the concentric data of ``_model`` put it at 1)."""
    x, y, t = _start(rng, 300, 0)
    xi = _ellipsoid(rng, 40, INTERIOR_RADII)
    return tg.GPIOIS(torch.cat([xi, x]), torch.cat([torch.zeros(40, dtype=torch.float64), y]),
                     torch.cat([torch.zeros(40, dtype=torch.long), t]), kernel=IMQ(THETA), noise=NOISE,
                     inference="batched").fit()


INTERIOR_RADII = (0.12, 0.2, 0.15)


def _interior_patch(rng, k, radii=INTERIOR_RADII):
    c = _ellipsoid(rng, 1, radii)
    pts = c + 0.01 * torch.tensor(rng.normal(size=(k, 3)))
    y = torch.tensor((rng.random(k) < 0.25).astype(np.float64))
    return torch.where(y.bool().unsqueeze(1), pts * 1.08, pts), y


def test_a_tracking_step_raises_the_exact_mll_and_leaves_what_it_predicts():
    """track=True: one Newton step with the held Hessian; the MLL at the new K_t is a dense solve's, it rises, and the
    gain still to be had (a full re-learning from there, recomputed) is of the size the record reports."""
    rng = np.random.default_rng(7)
    model = _interior_model(rng)
    assert 0.2 < model.correlation < 0.8
    hessian = model.fit_result.hessian
    for _ in range(5):
        model.add_observations(*_interior_patch(rng, 24), 0)
        kt_before = model.task_covariance.clone()
        before = float(_dense(model._inference()).mll(kt_before.clone()))
        model.fit(min_gain=0.0, track=True, max_hold=100)
        r = model.fit_result
        assert r.tracked and not r.relearned and r.iterations == 1
        assert np.array_equal(r.hessian, hessian)                    # the held Hessian, not a new one
        dense_mll = float(_dense(model._inference()).mll(model._task_matrix()))
        assert r.mll == pytest.approx(dense_mll, rel=1e-12) and dense_mll > before
        best = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, kernel=IMQ(THETA), noise=NOISE,
                         task_covariance=model.task_covariance, inference="structured").fit(multi_start=False)
        remaining = best.fit_result.mll - r.mll
        assert 0.4 * r.predicted_gain < remaining < 2.0 * r.predicted_gain       # measured ratios 0.5-1.3
    # a held Hessian that is no maximum's cannot give a step: the fit re-learns in full
    model.fit_result.hessian = -model.fit_result.hessian
    model.add_observations(*_interior_patch(rng, 24), 0)
    model.fit(min_gain=0.0, track=True, max_hold=100)
    assert model.fit_result.relearned and not model.fit_result.tracked


def test_on_the_ridge_of_a_correlation_of_1_w_is_held_and_its_gain_bounded():
    """Concentric shapes: K_t at a correlation of 1, on the flat ridge where ``w = log L[1,1]`` sits near its bound.
    Where the gradient pushes w further down, the rule holds w and counts ``|g_w| / 2`` for it: the gain that taking w
    all the way to its bound really brings (recomputed by a dense solve) stays below that; tracking steps there leave
    w where it is. Where the gradient points back off the ridge the rule has no bound and never holds (a re-learning
    there leaves the ridge for the optimum that multi-start finds); where w sits at
    its very bound and the gradient points back inside, no tracking step is taken (a Hessian taken at a bound says
    nothing of the interior)."""
    from torch_gpioius.inference.optim import cholesky_bounds, chol_params_to_task_covariance
    from torch_gpioius.inference.task_fit import on_ridge as _on_ridge, ridge as _ridge
    from torch_gpioius.inference.optim import task_covariance_to_chol_params

    rng = np.random.default_rng(7)
    model = _model(rng)
    lower, upper = cholesky_bounds()
    seen = set()
    for _ in range(5):
        model.add_observations(*_patch(rng, 24), 0)
        kt = model._task_matrix()
        phi = task_covariance_to_chol_params(model.task_covariance)
        mll, grad, free = model._task_fitter().chol_gradient(kt)
        held, bound = _ridge(model.task_covariance, grad, free)
        if bound == math.inf:                   # the gradient points off the ridge: no bound, the rule re-learns
            seen.add("off")
            assert _on_ridge(model.task_covariance) and held[2] and grad[2] > 0
        elif bound > 0:
            seen.add("ridge")
            assert _on_ridge(model.task_covariance) and not held[2]
            down = phi.copy()
            down[2] = lower[2]
            gain = float(_dense(model._inference()).mll(chol_params_to_task_covariance(down))) - mll
            assert -1e-9 <= gain <= bound * (1 + 1e-3) + 1e-12
        at_bound_and_free = bool((((phi <= lower) | (phi >= upper)) & free).any())
        model.fit(min_gain=0.0, track=True, max_hold=100)
        if bound == math.inf:                   # never held there: re-learned, or tracked where the MLL rose
            assert model.fit_result.relearned or model.fit_result.tracked
            if model.fit_result.relearned:      # and the re-learning reaches the optimum off the ridge
                seen.add("left")
                best = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, kernel=IMQ(THETA),
                                 noise=NOISE, inference="structured").fit(multi_start=True)
                assert model.correlation < 0.99
                assert model.fit_result.mll == pytest.approx(best.fit_result.mll, abs=1e-6)
        if model.fit_result.tracked:
            seen.add("tracked")
            assert not at_bound_and_free
            if 0 < bound < math.inf:  # w held: the step moved u and v only (w read back from K_t loses ~1e-7)
                assert task_covariance_to_chol_params(model.task_covariance)[2] == pytest.approx(phi[2], abs=1e-4)
    assert seen == {"ridge", "tracked", "off", "left"}, seen


def test_tracking_counts_towards_max_hold():
    rng = np.random.default_rng(8)
    model = _interior_model(rng)
    kinds = []
    for _ in range(4):
        model.add_observations(*_interior_patch(rng, 16), 0)
        model.fit(min_gain=0.0, track=True, max_hold=3)
        kinds.append((model.fit_result.tracked, model.fit_result.relearned))
    assert kinds == [(True, False)] * 3 + [(False, True)]


@pytest.mark.filterwarnings("ignore:GPIOIS.fit. K_t's fit stopped")     # the reference's stall at the bound
def test_scouted_restarts_find_the_other_basin_and_cost_one_full_relearning_per_basin():
    """The fixed starts on a thinned copy (10 of the 15 touches) of a dataset whose warm start sticks at a correlation
    of 1 (tests/models/test_gpiois.py): the copy's other basin is re-learned on all the data, which finds the same
    optimum as the fixed starts on all the data. Where the copy finds no other basin, the full data see only the warm
    start's Newton run."""
    from tests.models.test_gpiois import _sticky_model, _stuck_start

    full, scouted = _sticky_model(), _sticky_model()
    for model in (full, scouted):                       # a first fit from the stuck start stays at a correlation of 1
        model.task_covariance = _stuck_start()
        model.fit(multi_start=False)
        assert model.correlation > 0.999
    full.fit(multi_start=True)
    scouted.fit(multi_start=True, scout=10)
    assert scouted.fit_result.starts == 4 and scouted.fit_result.scout == 10 and full.fit_result.scout == 0
    assert scouted.correlation < 0.5
    assert float((scouted.task_covariance - full.task_covariance).abs().max()) < 1e-6
    # a scout as large as the data is no scout: the fixed starts run on all of it
    whole = _sticky_model()
    whole.task_covariance = _stuck_start()
    whole.fit(multi_start=False)
    assert whole.fit(multi_start=True, scout=15).fit_result.scout == 0
    # one basin: the full engine evaluates only the warm start's run
    rng = np.random.default_rng(9)
    model = _model(rng)
    for _ in range(3):
        model.add_observations(*_patch(rng, 16), 0)
    engine = model._inference()
    calls = []
    original = engine.mll_derivatives
    engine.mll_derivatives = lambda kt: calls.append(1) or original(kt)
    model.fit(multi_start=True, scout=30)
    # one Newton run: an evaluation per iteration, and one more unless the Newton-decrement stop ended it, plus at most
    # one step per coordinate along which the likelihood looked convex and did not rise (newton_maximize)
    assert model.fit_result.scout == 30
    assert model.fit_result.iterations <= len(calls) <= model.fit_result.iterations + 4
    best = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, kernel=IMQ(THETA), noise=NOISE,
                     inference="structured").fit(multi_start=True)
    assert model.fit_result.mll == pytest.approx(best.fit_result.mll, abs=1e-7)


@pytest.mark.filterwarnings("ignore:GPIOIS.fit. K_t's fit stopped")     # the reference's stall at the bound
def test_a_restart_under_the_min_gain_rule_holds_its_warm_start_and_still_finds_the_other_basin():
    """A restart with ``min_gain`` (a patch run's fits) takes its warm start by the rule: where the exact gradient
    predicts little, no Newton run on all the data (no full evaluation with a Hessian), and the K_t kept is within the
    rule's gain of the best of all starts on all the data (recomputed by the structured engine's own multi-start).
    Where the warm start sticks at a correlation of 1, the copy's fixed starts still find the other basin, which the
    full data then re-learn: the same optimum as the restarts on all the data."""
    from tests.models.test_gpiois import _sticky_model, _stuck_start

    rng = np.random.default_rng(9)
    model = _model(rng)
    for _ in range(3):
        model.add_observations(*_patch(rng, 16), 0)
    model.fit(min_gain=0.0)                                  # a re-learning: the Hessian the rule holds with
    engine = model._inference()
    calls = []
    original = engine.mll_derivatives
    engine.mll_derivatives = lambda kt: calls.append(1) or original(kt)
    model.add_observations(*_patch(rng, 16), 0)
    model.fit(multi_start=True, scout=30, min_gain=0.1, track=True)
    assert model.fit_result.starts == 4 and model.fit_result.scout == 30 and not model.fit_result.relearned
    best = tg.GPIOIS(model.train_inputs[0], model.train_targets, model.train_task, kernel=IMQ(THETA), noise=NOISE,
                     inference="structured").fit(multi_start=True)
    gap = best.fit_result.mll - float(model._inference().mll(model._task_matrix()))
    assert -1e-9 <= gap <= 0.1
    assert len(calls) <= 1                                   # at most a tracking step's one factorisation
    # the sticky dataset: held at its local optimum, yet the scouts find the global one
    full, scouted = _sticky_model(), _sticky_model()
    for m in (full, scouted):
        m.task_covariance = _stuck_start()
        m.fit(multi_start=False)
        assert m.correlation > 0.999
    full.fit(multi_start=True)
    scouted.fit(multi_start=True, scout=10, min_gain=0.1, track=True)
    assert scouted.correlation < 0.5 and scouted.fit_result.relearned
    assert float((scouted.task_covariance - full.task_covariance).abs().max()) < 1e-6


@pytest.mark.filterwarnings("ignore:GPIOIS.fit. K_t's fit stopped")     # Newton's stalls on the flat ridge
def test_a_relearning_off_a_correlation_of_1_walks_on_the_scout_and_polishes_on_all_the_data(monkeypatch):
    """Concentric shapes put K_t's correlation at 1; patches of another shape then move the optimum inside (a
    correlation near 0.3). From the warm K_t the full data's Newton run walks off the ridge in many evaluations; with
    ``scout`` the thinned copy walks and the full data polish in a few, to the same optimum."""
    rng = np.random.default_rng(0)
    base = _model(rng)
    assert base.correlation > 1 - 1e-6
    ridge, ridge_fit, relearned = base.task_covariance.clone(), base.fit_result, []
    for i in range(27):
        base.add_observations(*_interior_patch(rng, 16, (0.1, 0.22, 0.12)), 0)
        base.fit(min_gain=0.0)                               # re-learned every step
        relearned.append(base.correlation)
    # the re-learnings leave the ridge as the optimum does (they once stayed on it, 24 nats below, reported converged)
    assert relearned[-1] < 0.6 and base.fit_result.converged
    base.task_covariance, base.fit_result = ridge, ridge_fit  # the warm K_t, a re-learning at a correlation of 1
    counts, models = [], []
    for scout in (None, 200):
        model = tg.GPIOIS(base.train_inputs[0], base.train_targets, base.train_task, kernel=IMQ(THETA), noise=NOISE,
                          task_covariance=base.task_covariance, inference="batched")
        model.fit_result = base.fit_result                  # a later fit: warm-started, no restarts
        engine = model._inference()
        calls = []
        original = engine.mll_derivatives
        engine.mll_derivatives = lambda kt, original=original, calls=calls: calls.append(1) or original(kt)
        model.fit(min_gain=0.0, scout=scout)
        counts.append(len(calls))
        models.append(model)
    plain, scouted = models
    assert plain.correlation < 0.6 and scouted.correlation == pytest.approx(plain.correlation, abs=1e-6)
    assert scouted.fit_result.mll == pytest.approx(plain.fit_result.mll, abs=1e-6)
    assert counts[1] <= 4 < 8 <= counts[0], counts
    # a restart under the min_gain rule, whose warm start cannot be held there (the gradient points off the ridge, where
    # the held Hessian says nothing), walks on the copy too, and the full data polish in a few evaluations
    restart = tg.GPIOIS(base.train_inputs[0], base.train_targets, base.train_task, kernel=IMQ(THETA), noise=NOISE,
                        task_covariance=base.task_covariance, inference="batched")
    restart.fit_result = base.fit_result
    from torch_gpioius.inference.task_fit import TaskCovarianceFitter

    # no fixed start to find it: the copy's run from the warm K_t must find the other basin
    monkeypatch.setattr(TaskCovarianceFitter, "fixed_starts", lambda self: [])
    engine = restart._inference()
    calls = []
    original = engine.mll_derivatives
    engine.mll_derivatives = lambda kt: calls.append(1) or original(kt)
    restart.fit(multi_start=True, min_gain=1e3, track=True, scout=200)
    assert restart.correlation == pytest.approx(plain.correlation, abs=1e-6)
    assert restart.fit_result.mll == pytest.approx(plain.fit_result.mll, abs=1e-6)
    assert len(calls) <= 4, calls


def test_a_relearning_on_the_ridge_whose_optimum_stays_there_polishes_the_copys_result():
    """Concentric data whose optimum is at a correlation of 1; the warm K_t on the ridge but off the optimum's u and v
    (K_t00 up by a fifth, or K_t01 down), where the gradient along ``w`` points off the ridge. From the warm K_t the
    full data walk up ``w`` and back down to its bound (20 evaluations or more); with ``scout`` the copy makes that walk
    and the full data start from where it ended: a few evaluations, the same optimum."""
    from torch_gpioius.inference.optim import chol_params_to_task_covariance, task_covariance_to_chol_params

    rng = np.random.default_rng(7)
    base = _model(rng)
    for _ in range(3):
        base.add_observations(*_patch(rng, 24), 0)
    base.fit(multi_start=True)
    assert base.correlation > 1 - 1e-6
    for shift in ((0.1, 0.0), (0.0, -0.05)):
        phi = task_covariance_to_chol_params(base.task_covariance)
        phi[:2] += shift
        phi[2] = -11.0
        counts, results = [], []
        for scout in (None, 60):
            model = tg.GPIOIS(base.train_inputs[0], base.train_targets, base.train_task, kernel=IMQ(THETA), noise=NOISE,
                              task_covariance=chol_params_to_task_covariance(phi), inference="batched")
            model.fit_result = base.fit_result
            engine = model._inference()
            assert model._task_fitter().chol_gradient(model._task_matrix())[1][2] > 0     # pointing off the ridge
            calls = []
            original = engine.mll_derivatives
            engine.mll_derivatives = lambda kt, original=original, calls=calls: calls.append(1) or original(kt)
            model.fit(min_gain=0.0, scout=scout)
            counts.append(len(calls))
            results.append(model.fit_result.mll)
        assert results[1] == pytest.approx(results[0], abs=1e-6) == pytest.approx(base.fit_result.mll, abs=1e-6)
        assert counts[1] <= 4 < 20 <= counts[0], counts


@pytest.mark.filterwarnings("ignore:GPIOIS.fit. K_t's fit stopped")
def test_a_fit_judging_trials_by_their_value_reaches_the_same_optimum_with_fewer_hessians():
    """GPIOIS.fit judges a Newton trial by the engine's ``mll_value`` and asks ``mll_derivatives`` only where it is
    accepted: the walk off the ridge of a correlation of 1 (many trials refused) ends at the same K_t as with every
    trial evaluated with its Hessian, with fewer Hessians (the edge steps up ``w`` walk by values alone too)."""
    rng = np.random.default_rng(0)
    base = _model(rng)
    ridge, ridge_fit = base.task_covariance.clone(), base.fit_result
    for _ in range(20):
        base.add_observations(*_interior_patch(rng, 16, (0.1, 0.22, 0.12)), 0)
    runs = []
    for judged in (False, True):
        model = tg.GPIOIS(base.train_inputs[0], base.train_targets, base.train_task, kernel=IMQ(THETA), noise=NOISE,
                          task_covariance=ridge, inference="batched")
        model.fit_result = ridge_fit                          # a later fit, warm-started on the ridge
        engine = model._inference()
        if not judged:                      # as an engine whose value alone costs its derivatives declares
            engine.value_alone = False
        hessians, values = [], []
        derivatives, value = engine.mll_derivatives, engine.mll_value
        engine.mll_derivatives = lambda kt: hessians.append(1) or derivatives(kt)
        engine.mll_value = lambda kt: values.append(1) or value(kt)
        model.fit(min_gain=0.0)
        runs.append((model, len(hessians), len(values)))
    (plain, plain_hessians, plain_values), (judged, judged_hessians, judged_values) = runs
    assert plain_values == 0 and plain.correlation < 0.6
    assert judged.fit_result.converged and plain.fit_result.converged
    assert float((judged.task_covariance - plain.task_covariance).abs().max()) < 1e-6
    assert judged.fit_result.mll == pytest.approx(plain.fit_result.mll, abs=1e-9)
    assert judged_hessians < plain_hessians, (judged_hessians, plain_hessians)


@pytest.mark.parametrize("kwargs", [{"min_gain": -1.0}, {"min_gain": math.nan}, {"min_gain": 0.1, "max_hold": 0},
                                    {"scout": 1}, {"scout": 2.5}, {"scout": True}])
def test_bad_relearning_settings_are_refused_and_leave_the_model_alone(kwargs):
    rng = np.random.default_rng(5)
    model = _model(rng)
    before = (model.task_covariance.clone(), model.fit_result)
    with pytest.raises(ValueError, match="min_gain|max_hold|scout"):
        model.fit(**kwargs)
    assert torch.equal(model.task_covariance, before[0]) and model.fit_result is before[1]


def test_the_structured_engine_takes_the_same_rule_through_its_full_derivatives():
    rng = np.random.default_rng(6)
    model = _model(rng, "structured")
    x, y = _patch(rng, 8)
    model.add_observations(x, y, 0)
    model.fit(min_gain=math.inf)
    assert not model.fit_result.relearned and math.isfinite(model.fit_result.predicted_gain)


def test_batched_inference_needs_outer_points():
    x = torch.rand(5, 3, dtype=torch.float64)
    with pytest.raises(ValueError, match="batched"):
        tg.GPIOIS(x, torch.zeros(5), torch.zeros(5, dtype=torch.long), inference="batched").fit()


@pytest.mark.filterwarnings("ignore:GPIOIS.fit. K_t's fit stopped")
def test_a_first_fit_scouts_its_starts_and_re_learns_each_basin_on_all_the_data():
    """Issue 60, item 9: a user's file of 1,000 contacts spent 177 of its fit's 236 s in four Newton runs on all the
    data (the first fit's starts). With ``scout``, a first fit runs its starts on the thinned copy and re-learns on all
    the data from each basin found there: the same optimum as every start on all the data (also from a start that
    sticks at a correlation of 1), with fewer evaluations on all of it."""
    from tests.models.test_gpiois import _sticky_model, _stuck_start

    for start in (None, _stuck_start()):
        full, scouted = _sticky_model(), _sticky_model()
        counts = {}
        for name, model in (("full", full), ("scouted", scouted)):
            if start is not None:
                model.task_covariance = start
            engine = model._inference()
            original = engine.mll_derivatives
            counts[name] = []
            engine.mll_derivatives = lambda kt, c=counts[name], f=original: c.append(1) or f(kt)
        full.fit()
        scouted.fit(scout=10)
        assert scouted.fit_result.starts == 4 and scouted.fit_result.scout == 10 and full.fit_result.scout == 0
        assert float((scouted.task_covariance - full.task_covariance).abs().max()) < 1e-6
        assert scouted.fit_result.mll == pytest.approx(full.fit_result.mll, abs=1e-7)
        assert len(counts["scouted"]) < len(counts["full"]), counts

"""The fast exact engine (StructuredExactInference) held equal to the dense reference (issue 4)."""

import math

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from torch_gpioius.inference import DenseExactInference
from torch_gpioius.planning import plan_direction
from torch_gpioius.structured import StructuredExactInference

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
    dense = DenseExactInference(x, y, t, theta, noise)
    fast = StructuredExactInference(x, y, t, theta, noise)
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


def test_no_drift_after_200_incremental_additions():
    x, y, t = _surface_data(n_outer=600, n_inner=260, seed=1)
    inner, outer = t == 0, t == 1
    xi, yi = x[inner], y[inner]
    start = torch.cat([x[inner][:60], x[outer]]), torch.cat([yi[:60], y[outer]]), torch.cat(
        [torch.zeros(60, dtype=torch.long), torch.ones(int(outer.sum()), dtype=torch.long)])
    fast = StructuredExactInference(*start, theta=0.15, noise=0.08)
    b = torch.tensor([[0.3, 0.2], [0.2, 0.5]], dtype=torch.float64)
    fast.mll_derivatives(b)                       # builds the split, then grows it
    for k in range(60, 260):
        fast.append(xi[k:k + 1], yi[k:k + 1], torch.zeros(1, dtype=torch.long))
        if k % 50 == 0:
            b = b * 1.1                           # K_t moves as it does between steps
            fast.mll_derivatives(b)
    dense = DenseExactInference(torch.cat([xi, x[outer]]), torch.cat([yi, y[outer]]),
                                torch.cat([torch.zeros(260, dtype=torch.long), torch.ones(int(outer.sum()),
                                                                                          dtype=torch.long)]),
                                0.15, 0.08)         # a fresh dense solve
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
    dense = tg.GPIOIS(x, y, t, theta=0.15, noise=0.08, inference="dense").fit()
    fast = tg.GPIOIS(x, y, t, theta=0.15, noise=0.08, inference="structured").fit()
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
    dense = tg.GPIOIS(m.train_inputs[0], m.train_targets, m.train_task, theta=0.1, noise=0.006,
                      task_covariance=m.task_covariance, inference="dense")
    xq = torch.as_tensor(scene.sample_boundary("inner", 0.05))
    torch.testing.assert_close(m.predict(xq)[0], dense.predict(xq)[0], rtol=1e-9, atol=1e-12)
    torch.testing.assert_close(m.predict(xq)[1], dense.predict(xq)[1], rtol=1e-7, atol=1e-12)
    refit_dense = dense.fit(multi_start=False)
    refit_fast = tg.GPIOIS(m.train_inputs[0], m.train_targets, m.train_task, theta=0.1, noise=0.006,
                           task_covariance=m.task_covariance, inference="structured").fit(multi_start=False)
    assert _rel(refit_fast.task_covariance, refit_dense.task_covariance) < REL


def test_structured_needs_outer_points():
    with pytest.raises(ValueError, match="outer"):
        tg.GPIOIS(torch.zeros(2, 2), torch.zeros(2), torch.zeros(2, dtype=torch.long),
                  inference="structured").predict(torch.zeros(1, 2))
    with pytest.raises(ValueError, match="inference"):
        tg.GPIOIS(torch.zeros(2, 2), torch.zeros(2), torch.zeros(2, dtype=torch.long), inference="fast")

import numpy as np
import pytest
import torch
import trimesh

import torch_gpioius as tg
from torch_gpioius.geometry.metrics import hausdorff_distance, resample_polyline, uncertainty_measure


def circle(r, n=200, c=(0.0, 0.0)):
    a = np.linspace(0, 2 * np.pi, n + 1)
    return np.stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a)], -1)


def square(half, c=(0.0, 0.0)):
    s = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]], dtype=float) * half
    return s + np.asarray(c)


def test_hausdorff_known_answers():
    assert hausdorff_distance([circle(0.2, 2000)], [circle(0.3, 2000)]) == pytest.approx(0.1, abs=1e-4)
    # nested squares: the outer corner is farthest from the inner square: sqrt(2) * 0.05
    assert hausdorff_distance([square(0.10)], [square(0.15)]) == pytest.approx(np.sqrt(2) * 0.05, abs=5e-4)
    # translated square: the translation
    assert hausdorff_distance([square(0.1)], [square(0.1, (0.03, 0.0))]) == pytest.approx(0.03, abs=5e-4)
    # point sets by hand
    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    b = np.array([[0.0, 0.5]])
    assert hausdorff_distance(a, b) == pytest.approx(np.hypot(1.0, 0.5))
    assert hausdorff_distance([square(0.1)], []) == float("inf")


def test_hausdorff_meshes():
    inner = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    outer = trimesh.creation.box(extents=(1.2, 1.2, 1.2))
    assert hausdorff_distance(inner, outer, spacing=0.01) == pytest.approx(np.sqrt(3) * 0.1, abs=1e-6)


def test_resample_polyline_uniform():
    pts, w = resample_polyline(square(0.5), 0.01)
    assert w.sum() == pytest.approx(4.0)
    assert len(pts) == 400


def test_uncertainty_measure_is_length_normalised():
    model = tg.GPIS(torch.tensor([[0.2, 0.0], [0.0, 0.2]], dtype=torch.float64), torch.zeros(2))
    a = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    dense = 0.2 * np.stack([np.cos(a), np.sin(a)], -1)
    expected = model.predict(torch.tensor(dense))[1].mean().item()   # independent: uniform angles
    # a curve given with very uneven vertex density gives the same value (per unit length, not per vertex)
    uneven = np.concatenate([circle(0.2, 2000)[:1000], circle(0.2, 20)[10:]])
    got = uncertainty_measure(model, [uneven], spacing=0.001, relative=False)
    assert got == pytest.approx(expected, rel=2e-3)
    assert uncertainty_measure(model, [circle(0.2, 500)], spacing=0.001, relative=False) == pytest.approx(
        expected, rel=1e-4)
    # relative (default): divided by the GPIS prior variance 1 / theta
    assert uncertainty_measure(model, [uneven], spacing=0.001) == pytest.approx(got * model.theta, rel=1e-12)
    assert np.isnan(uncertainty_measure(model, []))


def test_relative_uncertainty_uses_the_task_prior_variance():
    x = torch.tensor([[0.2, 0.0], [0.0, 0.2], [0.5, 0.5]], dtype=torch.float64)
    m = tg.GPIOIS(
        x,
        torch.zeros(3),
        torch.tensor([0, 0, 1]),
        task_covariance=torch.tensor([[0.04, 0.01], [0.01, 0.09]], dtype=torch.float64),
    )
    raw = uncertainty_measure(m, [circle(0.2, 400)], relative=False)
    rel = uncertainty_measure(m, [circle(0.2, 400)])
    assert rel == pytest.approx(raw / (0.04 / 0.1), rel=1e-12)
    assert 0.0 <= rel <= 1.0


def test_surface_agreement_on_concentric_spheres():
    """An estimate grown by delta everywhere: Chamfer delta, F-score 1 at thresholds >= delta and 0 below, bias
    +delta (the estimate outside), every sample observed; shrunk, the bias is -delta."""
    from torch_gpioius.geometry.metrics import surface_agreement

    delta = 0.004
    d = np.full(500, delta)
    grown = surface_agreement(d, d, truth_signed=+d)
    assert grown["chamfer"] == pytest.approx(delta) and grown["bias"] == pytest.approx(delta)
    assert grown["fscore_1mm"] == 0.0 and grown["fscore_5mm"] == grown["fscore_10mm"] == grown["fscore_20mm"] == 1.0
    assert grown["unseen"] == 0.0 and grown["hausdorff_observed"] == pytest.approx(delta)
    assert surface_agreement(d, d, truth_signed=-d)["bias"] == pytest.approx(-delta)
    # precision and recall apart: half the estimate 3 cm off (a phantom piece), the truth covered
    est = np.r_[np.full(50, 0.001), np.full(50, 0.03)]
    m = surface_agreement(est, np.full(100, 0.001))
    p, r = 0.5, 1.0
    assert m["fscore_5mm"] == pytest.approx(2 * p * r / (p + r)) and m["chamfer"] == pytest.approx(
        0.5 * (0.0155 + 0.001)
    )
    # a part nobody observed: the observed Hausdorff leaves it out, the unseen share counts it
    truth = np.r_[np.full(80, 0.002), np.full(20, 0.05)]
    obs = np.r_[np.ones(80, bool), np.zeros(20, bool)]
    m = surface_agreement(np.full(100, 0.002), truth, observed=obs)
    assert m["unseen"] == pytest.approx(0.2) and m["hausdorff_observed"] == pytest.approx(0.002)
    assert np.isnan(surface_agreement(np.zeros(0), d)["chamfer"])


def test_a_3d_run_records_the_fields_metrics_consistently():
    import torch_gpioius as tg
    from torch_gpioius.geometry.metrics import SHAPE_METRICS
    from torch_gpioius.sim.forcefield import sphere_scene

    trace = tg.explore(sphere_scene(), max_travel=0.03, metrics_every=100)
    last = {k: float(trace.shape[k][-1]) for k in SHAPE_METRICS}
    assert all(np.isfinite(v) for v in last.values())
    assert 0 < last["chamfer"] <= trace.hausdorff[-1] + 1e-9
    assert last["hausdorff_observed"] <= trace.hausdorff[-1] + 1e-9
    f = [last[f"fscore_{t}mm"] for t in (1, 5, 10, 20)]
    assert all(0 <= a <= b <= 1 for a, b in zip(f, f[1:]))             # more lenient, never lower
    assert 0 <= last["unseen"] <= 1 and abs(last["bias"]) <= trace.hausdorff[-1]
    assert trace.records()[-1]["chamfer"] == last["chamfer"]


def test_curve_shape_metrics_on_concentric_circles():
    """The 2-D form: an estimate 4 mm outside a true circle everywhere. Chamfer 4 mm, F-score 0 at 1 mm and 1 from
    5 mm on, bias +4 mm (the estimate outside: the model's mean is negative on the true circle), all observed."""
    from torch_gpioius.geometry.metrics import curve_shape_metrics

    a = np.linspace(0, 2 * np.pi, 721)
    circle = lambda r: np.stack([r * np.cos(a), r * np.sin(a)], -1)        # noqa: E731  (closed: 0 and 2 pi)
    ring = circle(0.104)[:-1:20]
    model = tg.GPIS(torch.as_tensor(np.r_[ring, 1.5 * ring]), torch.as_tensor(np.r_[np.zeros(36), np.ones(36)]),
                    kernel=tg.kernels.InverseMultiquadricKernel(0.1), noise=1e-4)
    m = curve_shape_metrics(model, [circle(0.104)], [circle(0.1)], spacing=1e-3)
    assert m["chamfer"] == pytest.approx(0.004, abs=2e-5) and m["bias"] == pytest.approx(0.004, abs=2e-5)
    assert m["fscore_1mm"] == 0.0 and m["fscore_5mm"] == m["fscore_20mm"] == 1.0
    assert m["unseen"] == 0.0 and m["hausdorff_observed"] == pytest.approx(0.004, abs=2e-5)
    assert np.isnan(curve_shape_metrics(model, [], [circle(0.1)])["chamfer"])


def test_a_2d_run_records_the_fields_metrics():
    trace = tg.explore(tg.sim.paper_objects_2d()["A"], max_steps=6)
    assert np.isfinite(trace.shape["chamfer"]).all() and (trace.shape["chamfer"] <= trace.hausdorff + 1e-9).all()

import numpy as np
import pytest
import torch
import trimesh

import torch_gpioius as tg
from torch_gpioius.metrics import hausdorff_distance, resample_polyline, uncertainty_measure


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
    m = tg.GPIOIS(x, torch.zeros(3), torch.tensor([0, 0, 1]), task_covariance=torch.tensor([[0.04, 0.01],
                                                                                          [0.01, 0.09]], dtype=torch.float64))
    raw = uncertainty_measure(m, [circle(0.2, 400)], relative=False)
    rel = uncertainty_measure(m, [circle(0.2, 400)])
    assert rel == pytest.approx(raw / (0.04 / 0.1), rel=1e-12)
    assert 0.0 <= rel <= 1.0

"""Zero-level set extraction: 2-D curves (scikit-image ``find_contours``), 3-D meshes (``marching_cubes``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from skimage import measure

from .geometry import predict_task

__all__ = ["GridField", "evaluate_grid", "zero_level_curves", "zero_level_mesh", "closed_curves"]


@dataclass
class GridField:
    """Posterior on a regular grid.

    Attributes:
        axes: tuple of d `(n_k,)` coordinate arrays [m].
        mean: `(n_1, ..., n_d)` posterior mean (``indexing='ij'``).
        var: `(n_1, ..., n_d)` posterior variance.
    """

    axes: tuple[np.ndarray, ...]
    mean: np.ndarray
    var: np.ndarray

    @property
    def spacing(self) -> tuple[float, ...]:
        return tuple(float(a[1] - a[0]) for a in self.axes)


def _check_bounds(bounds, dim: int) -> np.ndarray:
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (dim, 2) or not np.isfinite(b).all() or not (b[:, 1] > b[:, 0]).all():
        raise ValueError(f"bounds: expected {dim} finite (min, max) pairs with min < max [m], got {b.tolist()}")
    return b


def evaluate_grid(model, bounds, resolution: float, task: int = 0) -> GridField:
    """Evaluate the posterior mean and variance on a regular grid covering ``bounds``.

    Args:
        model: ``GPIS`` or ``GPIOIS``.
        bounds: `(d, 2)` min/max per axis [m], base frame.
        resolution: grid spacing [m] (the last cell may be slightly smaller to hit the max bound).
        task: 0 (inner) or 1 (outer).

    Returns:
        ``GridField``.
    """
    b = _check_bounds(bounds, model.dim)
    if not resolution > 0:
        raise ValueError(f"resolution: must be positive [m], got {resolution}")
    axes = tuple(np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / resolution)) + 1)) for lo, hi in b)
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    x0 = model.train_inputs[0]
    with torch.no_grad():
        mean, var = predict_task(model, torch.as_tensor(mesh, dtype=x0.dtype, device=x0.device), task)
    shape = tuple(len(a) for a in axes)
    return GridField(axes, mean.cpu().numpy().reshape(shape), var.cpu().numpy().reshape(shape))


def zero_level_curves(model, bounds, resolution: float = 0.005, task: int = 0,
                      field: GridField | None = None) -> list[np.ndarray]:
    """2-D estimated shape {mu = 0} (eq. 4 / 14) as polylines.

    Args:
        model: a 2-D ``GPIS`` or ``GPIOIS``.
        bounds: `(2, 2)` [[x_min, x_max], [y_min, y_max]] [m].
        resolution: grid spacing [m]; curve vertices are linearly interpolated between grid nodes.
        task: 0 (inner) or 1 (outer).
        field: a precomputed ``GridField`` (skips the evaluation).

    Returns:
        List of `(k, 2)` polylines [m]; a closed curve repeats its first vertex at the end. Empty if the
        level set does not cross the grid.
    """
    if model.dim != 2:
        raise ValueError(f"zero_level_curves: needs a 2-D model, got dimension {model.dim}")
    f = field if field is not None else evaluate_grid(model, bounds, resolution, task)
    out = []
    for c in measure.find_contours(f.mean, 0.0):
        pts = np.stack([np.interp(c[:, k], np.arange(len(f.axes[k])), f.axes[k]) for k in range(2)], axis=-1)
        out.append(pts)
    return out


def closed_curves(curves: list[np.ndarray]) -> list[np.ndarray]:
    """The curves among ``curves`` that are closed (first vertex equals last)."""
    return [c for c in curves if len(c) >= 4 and np.allclose(c[0], c[-1])]


def zero_level_mesh(model, bounds, resolution: float = 0.01, task: int = 0,
                    field: GridField | None = None) -> trimesh.Trimesh | None:
    """3-D estimated shape {mu = 0} as a triangle mesh by marching cubes.

    Args:
        model: a 3-D ``GPIS`` or ``GPIOIS``.
        bounds: `(3, 2)` min/max per axis [m].
        resolution: grid spacing [m].
        task: 0 (inner) or 1 (outer).
        field: a precomputed ``GridField``.

    Returns:
        ``trimesh.Trimesh`` in the base frame [m] with normals pointing outward (towards mu > 0), or None if
        mu does not change sign on the grid.
    """
    if model.dim != 3:
        raise ValueError(f"zero_level_mesh: needs a 3-D model, got dimension {model.dim}")
    f = field if field is not None else evaluate_grid(model, bounds, resolution, task)
    if not (f.mean.min() < 0 < f.mean.max()):
        return None
    verts, faces, _, _ = measure.marching_cubes(f.mean, level=0.0, spacing=f.spacing, gradient_direction="descent")  # mu < 0 inside
    verts = verts + np.array([a[0] for a in f.axes])
    return trimesh.Trimesh(vertices=verts, faces=faces, process=True)

"""Zero-level set extraction: 2-D curves (scikit-image ``find_contours``), 3-D meshes (``marching_cubes``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from skimage import measure

from ._validation import as_bounds
from .geometry import predict_mean_task, predict_task
from .polylines import distance_to_segments, segments

__all__ = ["data_bounds", "grid_resolution", "GridField", "evaluate_grid", "zero_level_curves", "zero_level_mesh",
           "closed_curves", "touched_pieces", "surface_samples", "clip_mesh"]


def data_bounds(x: np.ndarray, pad: float = 0.05) -> np.ndarray:
    """`(2, d)` box [min corner; max corner] of `(n, d)` points, padded by ``pad`` [m]."""
    return np.stack([x.min(0) - pad, x.max(0) + pad])


def grid_resolution(resolution, dim: int, default_2d: float = 0.005, default_3d: float = 0.01) -> float:
    """The grid spacing [m] of an estimate: ``resolution`` checked (1 mm to 50 cm), or the default when None.

    Raises:
        ValueError: zero, negative, NaN or out of range (0 used to mean the default silently).
    """
    from ._validation import as_float

    if resolution is None:
        return default_2d if dim == 2 else default_3d
    return as_float(resolution, "resolution", lo=1e-3, hi=0.5, positive=True, unit="m")


@dataclass
class GridField:
    """Posterior on a regular grid.

    Attributes:
        axes: tuple of d `(n_k,)` coordinate arrays [m].
        mean: `(n_1, ..., n_d)` posterior mean (``indexing='ij'``).
        var: `(n_1, ..., n_d)` posterior variance, or None when it was not evaluated (``variance=False``).
    """

    axes: tuple[np.ndarray, ...]
    mean: np.ndarray
    var: np.ndarray | None = None

    @property
    def spacing(self) -> tuple[float, ...]:
        return tuple(float(a[1] - a[0]) for a in self.axes)


#: Largest grid :func:`evaluate_grid` builds (4 million nodes, ~100 MB of results): a finer request is a mistake
#: (explore(metrics_resolution=1e-5) asked for 25 GiB).
MAX_GRID_POINTS = 4_000_000


def evaluate_grid(model, bounds, resolution: float, task: int = 0, variance: bool = True) -> GridField:
    """Evaluate the posterior mean and variance on a regular grid covering ``bounds``.

    Args:
        model: ``GPIS`` or ``GPIOIS``.
        bounds: `(2, d)` box `[min corner; max corner]` [m], base frame (trimesh's ``mesh.bounds`` layout).
        resolution: grid spacing [m] (the last cell may be slightly smaller to hit the max bound).
        task: 0 (inner) or 1 (outer).
        variance: also evaluate the variance. Meshing the estimate needs only the mean, and with thousands of
            outer points the variance costs thousands of times more per node (``model.predict_mean``).

    Returns:
        ``GridField``.

    Raises:
        ValueError: a bad box, a non-positive resolution, or a grid of more than ``MAX_GRID_POINTS`` nodes.
    """
    from ._validation import as_float
    b = as_bounds(bounds, model.dim)
    resolution = as_float(resolution, "resolution", positive=True, unit="m")
    counts = [max(2, int(np.ceil((hi - lo) / resolution)) + 1) for lo, hi in b.T]
    if float(np.prod(np.asarray(counts, dtype=np.float64))) > MAX_GRID_POINTS:
        raise ValueError(f"resolution: {resolution:g} m over a {np.ptp(b, axis=0).round(3).tolist()} m box needs "
                         f"{'x'.join(map(str, counts))} grid nodes (more than {MAX_GRID_POINTS}); use a coarser one")
    axes = tuple(np.linspace(lo, hi, n) for (lo, hi), n in zip(b.T, counts))
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    x0 = model.train_inputs[0]
    xq = torch.as_tensor(mesh, dtype=x0.dtype, device=x0.device)
    shape = tuple(len(a) for a in axes)
    with torch.no_grad():
        if not variance:
            return GridField(axes, predict_mean_task(model, xq, task).cpu().numpy().reshape(shape))
        mean, var = predict_task(model, xq, task)
    return GridField(axes, mean.cpu().numpy().reshape(shape), var.cpu().numpy().reshape(shape))


def zero_level_curves(model, bounds, resolution: float = 0.005, task: int = 0,
                      field: GridField | None = None) -> list[np.ndarray]:
    """2-D estimated shape {mu = 0} (eq. 4 / 14) as polylines.

    Args:
        model: a 2-D ``GPIS`` or ``GPIOIS``.
        bounds: `(2, 2)` box `[[x_min, y_min], [x_max, y_max]]` [m].
        resolution: grid spacing [m]; curve vertices are linearly interpolated between grid nodes.
        task: 0 (inner) or 1 (outer).
        field: a precomputed ``GridField`` (skips the evaluation).

    Returns:
        List of `(k, 2)` polylines [m]; a closed curve repeats its first vertex at the end. Empty if the
        level set does not cross the grid.
    """
    if model.dim != 2:
        raise ValueError(f"zero_level_curves: needs a 2-D model, got dimension {model.dim}")
    f = field if field is not None else evaluate_grid(model, bounds, resolution, task, variance=False)
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
        bounds: `(2, 3)` box `[min corner; max corner]` [m].
        resolution: grid spacing [m].
        task: 0 (inner) or 1 (outer).
        field: a precomputed ``GridField``.

    Returns:
        ``trimesh.Trimesh`` in the base frame [m] with normals pointing outward (towards mu > 0), or None if
        mu does not change sign on the grid.
    """
    if model.dim != 3:
        raise ValueError(f"zero_level_mesh: needs a 3-D model, got dimension {model.dim}")
    f = field if field is not None else evaluate_grid(model, bounds, resolution, task, variance=False)
    if not (f.mean.min() < 0 < f.mean.max()):
        return None
    verts, faces, _, _ = measure.marching_cubes(
        f.mean, level=0.0, spacing=f.spacing, gradient_direction="descent"
    )  # mu < 0 inside
    verts = verts + np.array([a[0] for a in f.axes])
    return trimesh.Trimesh(vertices=verts, faces=faces, process=True)


def _distances_to_piece(points: np.ndarray, piece) -> np.ndarray:
    """Exact distance from `(n, d)` points to one piece: a `(k, d)` polyline or a ``trimesh.Trimesh``."""
    if isinstance(piece, trimesh.Trimesh):
        return np.abs(trimesh.proximity.ProximityQuery(piece).on_surface(points)[1])
    return distance_to_segments(points, segments([piece]))


def touched_pieces(surface, contacts, radius: float = 0.01, min_fraction: float = 0.05):
    """The pieces of an estimated zero set that the fingertip slid along: the estimate a user means.

    A GPIS mean can dip below zero in unobserved space (beside a corner, under a loose cover) and create
    pieces of {mu = 0} that no contact supports. Distance to the nearest contact does not separate them (such a
    blob can lie within 2 cm of a corner contact); how many contacts a piece passes through does: the object's
    piece passes within a few millimetres of nearly all of them, a blob of none.

    A piece (a connected polyline in 2-D, a connected component of the mesh in 3-D) is kept when at least
    ``max(1, ceil(min_fraction * n))`` of the ``n`` contacts lie within ``radius`` of it.

    Args:
        surface: list of `(k, 2)` polylines (:func:`zero_level_curves`), or a ``trimesh.Trimesh``
            (:func:`zero_level_mesh`), or None.
        contacts: `(n, d)` contact positions [m].
        radius: how close a contact must be to count as on the piece [m].
        min_fraction: the fraction of all contacts a piece must pass through.

    Returns:
        The kept polylines (a list), or one ``trimesh.Trimesh`` of the kept components (None if none is kept).
    """
    contacts = np.asarray(contacts, dtype=np.float64)
    need = max(1, int(np.ceil(min_fraction * len(contacts))))
    if surface is None or len(contacts) == 0:
        return None if isinstance(surface, trimesh.Trimesh) or surface is None else []
    if isinstance(surface, trimesh.Trimesh):
        parts = surface.split(only_watertight=False)
        kept = [p for p in parts if int((_distances_to_piece(contacts, p) <= radius).sum()) >= need]
        return trimesh.util.concatenate(kept) if kept else None
    return [c for c in surface if len(c) >= 2 and int((_distances_to_piece(contacts, c) <= radius).sum()) >= need]


def surface_samples(mesh: trimesh.Trimesh | None, spacing: float, seed: int = 0) -> np.ndarray:
    """`(n, 3)` points on a mesh: its vertices plus area-uniform samples, about one per ``spacing``^2 [m]."""
    if mesh is None or len(mesh.faces) == 0:
        return np.zeros((0, 3))
    count = int(min(max(mesh.area / spacing**2, 100), 400_000))
    pts, _ = trimesh.sample.sample_surface(mesh, count, seed=seed)
    return np.concatenate([np.asarray(mesh.vertices), pts])


def clip_mesh(mesh: trimesh.Trimesh | None, lower, upper) -> trimesh.Trimesh | None:
    """The faces of ``mesh`` whose centres lie in the box ``lower <= c <= upper`` [m]; None if none do."""
    if mesh is None:
        return None
    c = mesh.triangles_center
    keep = ((c >= np.asarray(lower)) & (c <= np.asarray(upper))).all(axis=1)
    if not keep.any():
        return None
    return mesh.submesh([np.flatnonzero(keep)], append=True)

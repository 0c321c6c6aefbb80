"""Zero-level set extraction: 2-D curves (scikit-image ``find_contours``), 3-D meshes (``marching_cubes``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from skimage import measure

from ..core.validation import as_bounds
from .differential import predict_mean_task, predict_task
from .polylines import distance_to_segments, segments

__all__ = ["data_bounds", "grid_resolution", "GridField", "evaluate_grid", "zero_level_curves", "zero_level_mesh",
           "closed_curves", "touched_pieces", "surface_samples", "clip_mesh", "project_to_level", "newton_onto_level",
           "converged_level_mesh", "converged_level_curves", "RULER", "REFINED_EDGE"]


def data_bounds(x: np.ndarray, pad: float = 0.05) -> np.ndarray:
    """`(2, d)` box [min corner; max corner] of `(n, d)` points, padded by ``pad`` [m]."""
    return np.stack([x.min(0) - pad, x.max(0) + pad])


def grid_resolution(resolution, dim: int, default_2d: float = 0.005, default_3d: float = 0.01) -> float:
    """The grid spacing [m] of an estimate: ``resolution`` checked (1 mm to 50 cm), or the default when None.

    Raises:
        ValueError: zero, negative, NaN or out of range (0 used to mean the default silently).
    """
    from ..core.validation import as_float

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
    from ..core.validation import as_float
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


#: The longest edge of a converged estimate's mesh or curve, as a fraction of its marching grid: a flat facet of edge
#: e over a surface of curvature radius R lies e^2 / (8 R) off it (0.03 mm at 2.5 mm over a 3 cm radius).
REFINED_EDGE = 0.25
#: The name of the ruler that measures estimates (records and run files carry it; files of another are measured again).
RULER = "projected"


def project_to_level(model, points, task: int = 0, *, max_step: float, iterations: int = 8,
                     tol: float = 1e-6, chunk: int = 4096, gradients: bool = False):
    """Move points onto the estimate ``{mu_task = 0}`` along the mean's gradient (Newton's method on mu):
    ``x <- x - mu(x) g / |g|^2`` with ``g = grad mu(x)`` by autograd (the model's own normals, eq. 20-21), each step at
    most ``max_step`` long, until ``|mu| / |g|`` (the distance to the level set to first order) is below ``tol``.

    Args:
        model: a ``GPIS`` or ``GPIOIS``.
        points: `(n, d)` points near the estimate [m], base frame (a marching-cubes mesh's vertices).
        task: 0 (inner) or 1 (outer).
        max_step: the longest step [m] (half a grid cell: a point never jumps to another sheet of the level set).
        iterations: Newton steps at most.
        tol: the first-order distance [m] below which a point has arrived.
        chunk: points per batch (bounds the kernel rows held at once).
        gradients: also return the mean's gradient at each point's last evaluation.

    Returns:
        ``(projected (n, d), residual (n,))``: the points moved, and each one's ``|mu| / |g|`` there [m] (inf where
        the gradient vanishes: such a point is left where it was); with ``gradients``, also ``g`` `(n, d)` [1/m].
    """
    from .differential import predict_mean_task

    pts = np.array(points, dtype=np.float64, copy=True)
    residual = np.full(len(pts), np.inf)
    grads = np.zeros_like(pts)
    x0 = model.train_inputs[0]
    for a in range(0, len(pts), chunk):
        x = torch.as_tensor(pts[a:a + chunk], dtype=x0.dtype, device=x0.device)
        active = torch.ones(len(x), dtype=torch.bool, device=x.device)
        for it in range(iterations + 1):
            xa = x[active].detach().requires_grad_(True)
            with torch.enable_grad():
                mu = predict_mean_task(model, xa, task)
                (g,) = torch.autograd.grad(mu.sum(), xa)
            mu, g = mu.detach(), g.detach()
            norm2 = (g * g).sum(dim=-1)
            dist = mu.abs() / norm2.sqrt().clamp_min(1e-300)
            idx = torch.nonzero(active).squeeze(-1)
            residual[a + idx.cpu().numpy()] = torch.where(norm2 > 0, dist, torch.full_like(dist, np.inf)).cpu().numpy()
            grads[a + idx.cpu().numpy()] = g.cpu().numpy()
            moving = (dist > tol) & (norm2 > 0)
            if not bool(moving.any()) or it == iterations:
                break
            step = -(mu / norm2.clamp_min(1e-300)).unsqueeze(-1) * g
            length = step.norm(dim=-1, keepdim=True)
            step = step * torch.clamp(max_step / length.clamp_min(1e-300), max=1.0)
            x[idx[moving]] = (xa.detach() + step)[moving]
            active[idx[~moving]] = False
        pts[a:a + chunk] = x.cpu().numpy()
    return (pts, residual, grads) if gradients else (pts, residual)


def _grid_gradient(field: GridField, points: np.ndarray) -> np.ndarray:
    """`(n, d)` the gradient of a grid's mean at ``points`` [1/m]: central differences on the grid, interpolated
    linearly."""
    from scipy.interpolate import RegularGridInterpolator

    parts = np.gradient(field.mean, *field.axes, edge_order=2)
    return np.stack([RegularGridInterpolator(field.axes, g, bounds_error=False, fill_value=None)(points)
                     for g in parts], axis=-1)


def newton_onto_level(points: np.ndarray, grads: np.ndarray, mu: np.ndarray,
                      max_step: float) -> tuple[np.ndarray, np.ndarray]:
    """One Newton step of ``points`` `(n, d)` [m] onto the zero level of a field whose values there are ``mu`` `(n,)`,
    along ``grads`` `(n, d)` [1/m] (the field's gradient there, or one interpolated near it): ``x - mu g / |g|^2``,
    each step at most ``max_step`` [m] long.

    Returns:
        ``(points (n, d), residual (n,))``: the points moved, and ``|mu| / |g|`` [m] before the step (the distance
        they were moved by, to first order)."""
    norm2 = np.maximum((grads * grads).sum(axis=1), 1e-300)
    step = -(mu / norm2)[:, None] * grads
    length = np.linalg.norm(step, axis=1, keepdims=True)
    return points + step * np.minimum(1.0, max_step / np.maximum(length, 1e-300)), np.abs(mu) / np.sqrt(norm2)


#: A midpoint moved farther than this share of the grid's spacing by :func:`_settle` is projected by Newton's method
#: with its exact gradient (its ends' gradients did not describe the surface between them).
_SETTLE_FAR = 0.1


def _settle(model, points: np.ndarray, grads: np.ndarray, task: int, max_step: float,
            chunk: int = 8192) -> tuple[np.ndarray, np.ndarray]:
    """One Newton step onto ``{mu_task = 0}`` for points already within a facet's sagitta of it (midpoints of
    projected vertices), along the gradients ``grads`` `(n, d)` interpolated from their ends: one evaluation of the
    mean, no derivative. Where the interpolated gradient is off by an angle t from the true one, what remains of the
    sagitta is about t^2 / 2 of it (t ~ 0.2 rad for a 1 cm edge on a 5 cm radius: 2 %, a few micrometres).

    Returns:
        ``(points (n, d), residual (n,))``: the points moved, and ``|mu| / |g|`` [m] before the step (the distance
        they were moved by, to first order)."""
    from .differential import predict_mean_task

    x0 = model.train_inputs[0]
    out = np.array(points, dtype=np.float64, copy=True)
    moved = np.zeros(len(out))
    with torch.no_grad():
        for a in range(0, len(out), chunk):
            x = torch.as_tensor(out[a:a + chunk], dtype=x0.dtype, device=x0.device)
            mu = predict_mean_task(model, x, task).cpu().numpy()
            out[a:a + chunk], moved[a:a + chunk] = newton_onto_level(out[a:a + chunk], grads[a:a + chunk], mu,
                                                                     max_step)
    return out, moved


def converged_level_mesh(model, bounds, resolution: float = 0.01, task: int = 0, field: GridField | None = None,
                         edge: float | None = None, keep=None) -> trimesh.Trimesh | None:
    """The estimate ``{mu_task = 0}`` as a mesh that lies on it: marching cubes on a grid of ``resolution``
    (:func:`zero_level_mesh`), every edge then split to at most ``edge`` and every vertex moved onto ``mu = 0`` by
    :func:`project_to_level`. Its error against the exact level set is the facets' sagitta, ``edge^2 / (8 R)`` for a
    curvature radius R, instead of marching cubes' interpolation error on the grid (a 2 cm grid moved a run's Chamfer
    distance by -15 % to +89 %); the shape metrics of docs/results-benchmark.md come from it.

    Args:
        model: a 3-D ``GPIS`` or ``GPIOIS``.
        bounds: `(2, 3)` box [m] (ignored with ``field``).
        resolution: the marching grid [m]; a piece of the estimate thinner than a cell may be missed by it.
        task: 0 (inner) or 1 (outer).
        field: a precomputed ``GridField`` of the mean.
        edge: the longest edge [m] (default: :data:`REFINED_EDGE` of the grid's spacing).
        keep: `(2, 3)` a box [m]: only the grid's facets with a vertex within a cell of it are refined and returned
            (a measurement's range: nothing outside it is moved onto the level set); None: every facet.

    Returns:
        ``trimesh.Trimesh`` [m] with outward normals, or None where mu does not change sign on the grid. Its
        ``metadata["ruler"]`` holds the grid, the edge, ``last_step``: the largest ``|mu| / |grad mu|`` [m] of a grid
        vertex before its last Newton step (after it, that step's quadratic remainder) and ``settled``: the farthest
        a midpoint moved;
        ``metadata["grid_mesh"]`` the marching-cubes facets with their vertices on the level set, before the split;
        ``metadata["coarser_mesh"]`` the facets before the last split (edges twice as long: for averages of smooth
        fields over the surface, such as the uncertainty of eq. 23, at a quarter of the facets);
        ``metadata["gradients"]`` `(V, 3)` the mean's gradient at each vertex (exact at the grid's, interpolated from
        a split's ends elsewhere), with which a point on a facet is moved onto the surface
        (:func:`torch_gpioius.sim.forcefield.score_surface`).
    """
    coarse = zero_level_mesh(model, bounds, resolution, task, field=field)
    if coarse is None:
        return None
    h = float(max(field.spacing)) if field is not None else float(resolution)
    edge = REFINED_EDGE * h if edge is None else float(edge)
    if keep is not None:
        box = np.asarray(keep, dtype=np.float64) + np.array([[-h], [h]])
        near = ((coarse.vertices >= box[0]) & (coarse.vertices <= box[1])).all(axis=1)
        faces = np.flatnonzero(near[np.asarray(coarse.faces)].any(axis=1))
        if not len(faces):
            return None
        coarse = coarse.submesh([faces], append=True)
    # the grid's vertices by Newton steps along the gradient of the grid's own field (central differences, linearly
    # interpolated: no derivative of the model is taken), those that stay far by Newton's method with the exact
    # gradient; then each level of midpoints, which lie within a sagitta of the surface, by one step along the
    # gradient interpolated from their ends (_settle)
    verts = np.asarray(coarse.vertices, dtype=np.float64)
    if field is not None:
        grads = _grid_gradient(field, verts)
        verts, moved = _settle(model, verts, grads, task, 0.5 * h)
        verts, residual = _settle(model, verts, grads, task, 0.5 * h)
        far = np.flatnonzero(residual > _SETTLE_FAR * h * 1e-2)
        if len(far):
            verts[far], residual[far], grads[far] = project_to_level(model, verts[far], task, max_step=0.5 * h,
                                                                     gradients=True)
    else:
        verts, residual, grads = project_to_level(model, verts, task, max_step=0.5 * h, gradients=True)
    faces = np.asarray(coarse.faces)
    grid_mesh = trimesh.Trimesh(vertices=verts.copy(), faces=faces, process=False)
    settled = 0.0
    # the levels of splitting from the grid's facets (each halves every edge), counted before any vertex moves: a
    # midpoint that settles far from its ends must not keep its edges long and the splitting going
    longest = float(np.linalg.norm(verts[faces[:, [1, 2, 0]]] - verts[faces], axis=-1).max(initial=0.0))
    levels = max(0, int(np.ceil(np.log2(longest / edge)))) if longest > edge else 0
    coarser = grid_mesh
    for level in range(levels):
        if level == levels - 1:            # the last level's parents: facets twice the edge, on the level set
            coarser = trimesh.Trimesh(vertices=verts.copy(), faces=faces, process=False)
        n_old = len(verts)
        verts, faces, attributes = trimesh.remesh.subdivide(verts, faces, vertex_attributes={"g": grads})
        grads = attributes["g"]
        verts[n_old:], moved = _settle(model, verts[n_old:], grads[n_old:], task, 0.25 * h)
        far = np.flatnonzero(moved > _SETTLE_FAR * h)
        if len(far):        # a midpoint the interpolated gradient sent astray (a sharp fold): Newton's method instead
            fixed, _, fixed_g = project_to_level(model, verts[n_old + far], task, max_step=0.25 * h, gradients=True)
            verts[n_old + far], grads[n_old + far] = fixed, fixed_g
        settled = max(settled, float(moved.max(initial=0.0)))
    out = trimesh.Trimesh(vertices=verts, faces=faces, process=False)
    # how far the grid's vertices were from the level set before their last step [m] (after it, the step's quadratic
    # remainder), and the farthest a midpoint was moved
    out.metadata["ruler"] = {"name": RULER, "grid": h, "edge": edge,
                             "last_step": float(np.max(residual[np.isfinite(residual)], initial=0.0)),
                             "settled": settled}
    out.metadata["grid_mesh"] = grid_mesh       # the grid's facets, their vertices on the level set
    out.metadata["coarser_mesh"] = coarser      # the facets before the last split (averages of smooth fields)
    out.metadata["gradients"] = grads           # (V, d): the mean's gradient at each vertex (interpolated at splits)
    return out


def converged_level_curves(model, bounds, resolution: float = 0.005, task: int = 0,
                           field: GridField | None = None, edge: float | None = None) -> list[np.ndarray]:
    """:func:`zero_level_curves` made to lie on ``{mu_task = 0}``: each polyline's segments split to at most ``edge``
    (default :data:`REFINED_EDGE` of the grid) and every vertex moved onto the level set (:func:`project_to_level`).
    A closed curve stays closed (its last vertex is its first)."""
    curves = zero_level_curves(model, bounds, resolution, task, field=field)
    if not curves:
        return curves
    h = float(max(field.spacing)) if field is not None else float(resolution)
    edge = REFINED_EDGE * h if edge is None else float(edge)
    out = []
    for c in curves:
        closed = len(c) >= 4 and np.allclose(c[0], c[-1])
        seg = np.linalg.norm(np.diff(c, axis=0), axis=1)
        pieces = [c[:1]]
        for a, b, length in zip(c[:-1], c[1:], seg):
            k = max(1, int(np.ceil(length / edge)))
            pieces.append(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
        dense = np.concatenate(pieces)
        moved, _ = project_to_level(model, dense[:-1] if closed else dense, task, max_step=0.5 * h)
        out.append(np.vstack([moved, moved[:1]]) if closed else moved)
    return out


def _distances_to_piece(points: np.ndarray, piece) -> np.ndarray:
    """Exact distance from `(n, d)` points to one piece: a `(k, d)` polyline or a ``trimesh.Trimesh`` (libigl's AABB
    tree: trimesh's proximity query built an r-tree of every facet, 0.5 s for a measurement's refined estimate)."""
    if isinstance(piece, trimesh.Trimesh):
        import igl

        tree = igl.AABB()
        v = np.ascontiguousarray(piece.vertices, dtype=np.float64)
        f = np.ascontiguousarray(piece.faces, dtype=np.int64)
        tree.init(v, f)
        d2 = tree.squared_distance(v, f, np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3))[0]
        return np.sqrt(np.maximum(d2, 0.0))
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

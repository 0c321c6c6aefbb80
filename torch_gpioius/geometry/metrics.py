"""Evaluation metrics of Sec. V-A-3: uncertainty measure (eq. 23) and Hausdorff distance (eq. 24)."""

from __future__ import annotations

from typing import Sequence, Union

import numpy as np
import torch
import trimesh

from .differential import predict_task
from .polylines import distance_to_segments, resample_polyline, segments

__all__ = ["resample_polyline", "uncertainty_measure", "prior_variance", "hausdorff_distance", "directed_hausdorff",
           "Shape", "surface_agreement", "curve_shape_metrics", "observed_samples", "FSCORE_THRESHOLDS",
           "OBSERVED_WITHIN", "SHAPE_METRICS", "mesh_quadrature", "vertex_quadrature", "cell_quadrature"]

#: A shape for the metrics: an `(n, d)` point set, a list of `(k, d)` polylines, or a triangle mesh.
Shape = Union[np.ndarray, Sequence[np.ndarray], trimesh.Trimesh]


def uncertainty_measure(model, surface: Shape, task: int = 0, spacing: float = 0.0025,
                        relative: bool = True) -> float:
    r"""Uncertainty measure, eq. (23): mean posterior variance over the estimated surface, normalised.

    Two normalisations make it comparable across objects of different size and across models (Sec. V-A-3):

    * per unit of surface, not per extracted vertex: curves are resampled uniformly by arc length (``spacing``)
      and meshes are weighted by triangle area, giving :math:`\frac{1}{|\hat S|}\int_{\hat S} V\,ds`,
      independent of the object's size and of how finely the surface was extracted;
    * with ``relative=True`` (default), V is divided by the prior variance of the task,
      ``k(x, x) K_t[task, task] = K_t[task, task] / theta`` (``1 / theta`` for GPIS): the fraction of the prior
      uncertainty left, in [0, 1]. Without it, a GPIOIS whose learned ``K_t[0, 0]`` is 0.03 would look 30 times
      "more certain" than a GPIS (amplitude 1) with the same data.

    Args:
        model: ``GPIS`` or ``GPIOIS``.
        surface: the estimated surface: list of `(k, d)` polylines (2-D), a ``trimesh.Trimesh`` (3-D, its facets'
            centroids weighted by area), a quadrature ``(points (n, d), weights (n,))`` (:func:`vertex_quadrature`),
            or an `(n, d)` point set (plain mean).
        task: task whose variance is averaged (0: inner).
        spacing: resampling step for polylines [m].
        relative: divide by the prior variance (dimensionless result) instead of returning units of V.

    Returns:
        The uncertainty measure (NaN if the surface is empty).
    """
    pts, w = _weighted_points(surface, spacing)
    if len(pts) == 0 or w.sum() <= 0:
        return float("nan")
    x0 = model.train_inputs[0]
    with torch.no_grad():
        _, var = predict_task(model, torch.as_tensor(pts, dtype=x0.dtype, device=x0.device), task)
    value = float((var.cpu().numpy() * w).sum() / w.sum())
    return value / prior_variance(model, task) if relative else value


def prior_variance(model, task: int = 0) -> float:
    """Prior variance of F_task at any point: ``k(x, x) K_t[task, task]`` (``k(x, x)`` for GPIS; ``1 / theta`` for the
    inverse multiquadric)."""
    scale = 1.0 if getattr(model, "num_tasks", 1) == 1 else float(model.task_covariance[task, task])
    return model.covar_module.prior_variance(scale)


def _weighted_points(surface: Shape, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(surface, tuple):                          # a quadrature: (points (n, d), weights (n,))
        return np.asarray(surface[0], dtype=np.float64), np.asarray(surface[1], dtype=np.float64)
    if isinstance(surface, trimesh.Trimesh):
        return np.array(surface.triangles_center), np.array(surface.area_faces)
    if isinstance(surface, np.ndarray):
        if surface.ndim != 2:
            raise ValueError(f"surface: expected an (n, d) point set, got shape {surface.shape}")
        return surface, np.ones(len(surface))
    parts = [resample_polyline(c, spacing) for c in surface if len(c) >= 2]
    if not parts:
        return np.zeros((0, 2)), np.zeros(0)
    return np.concatenate([p for p, _ in parts]), np.concatenate([w for _, w in parts])


def _sample(shape: Shape, spacing: float) -> np.ndarray:
    if isinstance(shape, trimesh.Trimesh):
        count = int(min(max(shape.area / spacing**2, 2000), 200_000))
        pts, _ = trimesh.sample.sample_surface(shape, count, seed=0)
        return np.concatenate([np.asarray(shape.vertices), pts])
    if isinstance(shape, np.ndarray):
        return shape
    parts = [resample_polyline(c, spacing)[0] for c in shape if len(c) >= 2]
    verts = [np.asarray(c, dtype=np.float64) for c in shape]
    return np.concatenate(parts + verts) if parts else np.concatenate(verts)


def _distance_to(points: np.ndarray, shape: Shape) -> np.ndarray:
    if isinstance(shape, trimesh.Trimesh):
        # in chunks: trimesh's closest_point holds candidate triangles for all points at once (GBs for 10^4)
        query = trimesh.proximity.ProximityQuery(shape)
        return np.concatenate([query.on_surface(points[i:i + 1000])[1] for i in range(0, len(points), 1000)])
    if isinstance(shape, np.ndarray):
        from scipy.spatial import cKDTree
        return cKDTree(shape).query(points, workers=-1)[0]
    return distance_to_segments(points, segments(shape))


def _is_empty(shape: Shape) -> bool:
    if isinstance(shape, trimesh.Trimesh):
        return len(shape.faces) == 0
    if isinstance(shape, np.ndarray):
        return len(shape) == 0
    return all(len(c) == 0 for c in shape)


def directed_hausdorff(a: Shape, b: Shape, spacing: float = 5e-4) -> float:
    """max over x in A of d(x, B) [m]: A is sampled at ``spacing``; distances to B are exact."""
    if _is_empty(a) or _is_empty(b):
        return float("inf")
    pa = _sample(a, spacing)
    return float(_distance_to(pa, b).max())


def hausdorff_distance(a: Shape, b: Shape, spacing: float = 5e-4) -> float:
    r"""Hausdorff distance between two shapes, eq. (24) [m].

    :math:`d_H(A, B) = \max[\max_{x\in A} d(x, B), \max_{x\in B} d(x, A)]`.

    Shapes: an `(n, d)` numpy array is a finite point set; a list of `(k, d)` arrays is a set of polylines
    (close a polygon by repeating its first vertex); a ``trimesh.Trimesh`` is a surface. Distances *to* a
    polyline or mesh are exact (point-to-segment / point-to-triangle); the shape measured *from* is sampled at
    ``spacing`` (plus its vertices), so for curves the result is within ``spacing / 2`` of the exact value.

    Returns:
        The distance [m]; ``inf`` if one shape is empty.
    """
    return max(directed_hausdorff(a, b, spacing), directed_hausdorff(b, a, spacing))


#: Distances [m] at which :func:`surface_agreement` reports the F-score (the visuo-tactile literature's 1-20 mm).
FSCORE_THRESHOLDS = (0.001, 0.005, 0.010, 0.020)
#: How far [m] a true-surface point may lie from every observation and still count as observed.
OBSERVED_WITHIN = 0.02
#: The names :func:`surface_agreement` returns, in the order records, logs and tables carry them.
SHAPE_METRICS = ("chamfer", "fscore_1mm", "fscore_5mm", "fscore_10mm", "fscore_20mm", "bias", "hausdorff_observed",
                 "unseen")


def surface_agreement(est_to_truth: np.ndarray, truth_to_est: np.ndarray, truth_signed: np.ndarray | None = None,
                      observed: np.ndarray | None = None, est_near_observed: np.ndarray | None = None,
                      est_weights: np.ndarray | None = None, truth_weights: np.ndarray | None = None) -> dict:
    """The field's shape metrics from the two directed distances between an estimated and a true surface.

    Args:
        est_to_truth: `(n,)` distance [m] of samples of the estimated surface from the true surface.
        truth_to_est: `(m,)` distance [m] of samples of the true surface from the estimated surface.
        truth_signed: `(m,)` the same, signed: negative where the true surface lies *outside* the estimate (the
            estimate is shrunk there), positive where inside; None: no bias.
        observed: `(m,)` bool, the true-surface samples within :data:`OBSERVED_WITHIN` of an observation; None: every
            sample counts as observed.
        est_near_observed: `(n,)` bool, the estimate's samples near the observed true surface (they enter the
            observed Hausdorff distance); None: all.
        est_weights: `(n,)` the area each estimate sample stands for [m^2] (a quadrature of the surface: facets'
            centroids weighted by their areas); None: equal weights (uniform samples). Means, shares and the median
            are then integrals over the surfaces, whatever their facets' sizes.
        truth_weights: `(m,)` the same for the true surface's samples.

    Returns:
        ``{"chamfer", "fscore_1mm", "fscore_5mm", "fscore_10mm", "fscore_20mm", "bias", "hausdorff_observed",
        "unseen"}``: the Chamfer distance (mean of the two mean distances) [m]; the F-score at each threshold
        (harmonic mean of precision, the share of estimate samples within it of the truth, and recall, the share of
        truth samples within it of the estimate); the median signed distance [m] (``bias``: negative = the estimate
        lies inside the true surface); the Hausdorff distance over the observed true surface [m]; the share of the
        true surface further than :data:`OBSERVED_WITHIN` from every observation. NaN where a set is empty.
    """
    a, b = np.asarray(est_to_truth, dtype=float), np.asarray(truth_to_est, dtype=float)
    nan = float("nan")
    if not len(a) or not len(b):
        return {"chamfer": nan, **{f"fscore_{round(t * 1e3)}mm": nan for t in FSCORE_THRESHOLDS}, "bias": nan,
                "hausdorff_observed": nan, "unseen": nan}
    wa = np.ones(len(a)) if est_weights is None else np.asarray(est_weights, dtype=float)
    wb = np.ones(len(b)) if truth_weights is None else np.asarray(truth_weights, dtype=float)
    out = {"chamfer": 0.5 * (_mean(a, wa) + _mean(b, wb))}
    for t in FSCORE_THRESHOLDS:
        p, r = _mean(a <= t, wa), _mean(b <= t, wb)
        out[f"fscore_{round(t * 1e3)}mm"] = 0.0 if p + r == 0 else 2 * p * r / (p + r)
    if truth_signed is None:
        out["bias"] = nan
    else:
        out["bias"] = float(np.median(truth_signed)) if truth_weights is None else _median(truth_signed, wb)
    obs = np.ones(len(b), dtype=bool) if observed is None else np.asarray(observed, dtype=bool)
    near = np.ones(len(a), dtype=bool) if est_near_observed is None else np.asarray(est_near_observed, dtype=bool)
    out["unseen"] = float(max(0.0, 1.0 - _mean(obs, wb)))
    out["hausdorff_observed"] = (max(float(b[obs].max()), float(a[near].max()) if near.any() else 0.0)
                                 if obs.any() else nan)
    return out


def _mean(values, weights: np.ndarray) -> float:
    return float(np.dot(np.asarray(values, dtype=float), weights) / weights.sum())


def _median(values, weights: np.ndarray) -> float:
    """The weighted median: the value at which half the weight lies at or below (the midpoint between two values
    where the half falls exactly between them, as ``np.median`` of equal weights)."""
    v = np.asarray(values, dtype=float)
    order = np.argsort(v, kind="stable")
    cum = np.cumsum(weights[order])
    half = 0.5 * cum[-1]
    i = int(np.searchsorted(cum, half))
    if np.isclose(cum[i], half, rtol=1e-12, atol=0.0) and i + 1 < len(v):
        return float(0.5 * (v[order[i]] + v[order[i + 1]]))
    return float(v[order[i]])


def vertex_quadrature(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """A quadrature on a mesh's vertices: ``(vertices (n, 3), weights (n,))``, each vertex weighted by a third of its
    facets' areas [m^2]. For a mesh whose vertices lie on a curved surface (:func:`~torch_gpioius.geometry.surfaces.
    converged_level_mesh`), the points are on it, where facets' centroids lie a sagitta off it."""
    weights = np.zeros(len(mesh.vertices))
    np.add.at(weights, np.asarray(mesh.faces).ravel(), np.repeat(np.asarray(mesh.area_faces) / 3.0, 3))
    return np.asarray(mesh.vertices, dtype=np.float64), weights


def cell_quadrature(points: np.ndarray, weights: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """A coarser quadrature of the same surface for a field smooth on the scale of ``cell`` [m]: the points gathered
    in cubic cells of that edge, each cell standing for its total weight at its point nearest the cell's weighted
    mean (a point of the surface, as all of ``points`` are).

    Returns:
        ``(points (k, d), weights (k,))``, k at most the count of occupied cells.
    """
    points, weights = np.asarray(points, dtype=np.float64), np.asarray(weights, dtype=np.float64)
    if not len(points):
        return points, weights
    _, cell_of = np.unique(np.floor(points / cell).astype(np.int64), axis=0, return_inverse=True)
    cell_of = cell_of.reshape(-1)
    k = int(cell_of.max()) + 1
    total = np.bincount(cell_of, weights, minlength=k)
    centre = np.stack([np.bincount(cell_of, weights * points[:, j], minlength=k) for j in range(points.shape[1])],
                      axis=1) / np.maximum(total, 1e-300)[:, None]
    d2 = ((points - centre[cell_of]) ** 2).sum(axis=1)
    order = np.lexsort((d2, cell_of))                       # by cell, the nearest to its mean first
    first = order[np.r_[True, cell_of[order][1:] != cell_of[order][:-1]]]
    return points[first], total[cell_of[first]]


def mesh_quadrature(mesh: trimesh.Trimesh, edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A quadrature of a surface for the shape metrics: its facets split until no edge exceeds ``edge`` [m], then
    each facet's centroid and area.

    Returns:
        ``(centroids (k, 3), areas (k,), vertices (v, 3))``: the refined facets' centroids [m] and areas [m^2], and
        the refined mesh's vertices (what a Hausdorff distance also takes: the extremes of the surface).
    """
    verts, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    if len(faces) and float(np.linalg.norm(verts[faces[:, [1, 2, 0]]] - verts[faces], axis=-1).max()) > edge:
        verts, faces = trimesh.remesh.subdivide_to_size(verts, faces, max_edge=edge, max_iter=20)
    tri = verts[faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return tri.mean(axis=1), areas, verts


def curve_shape_metrics(model, curves: Sequence[np.ndarray], truth: Sequence[np.ndarray], spacing: float = 5e-3,
                        task: int = 0) -> dict:
    """:func:`surface_agreement` of a 2-D estimate: closed ``curves`` `[(k, 2)]` against the ``truth`` curves, both
    sampled by arc length at ``spacing`` [m] with exact point-to-segment distances the other way; a true-curve
    sample lies outside the estimate where it is enclosed by none of the closed curves (by parity: a hole's curve
    inside another undoes it), which is where the mean is positive; "observed": within :data:`OBSERVED_WITHIN` of a
    surface observation (y = 0) of either task of ``model``. ``task`` is kept for the signature's symmetry."""
    from matplotlib.path import Path as Polygon

    if _is_empty(curves) or _is_empty(truth):
        return surface_agreement(np.zeros(0), np.zeros(0))
    est, tru = _sample(list(curves), spacing), _sample(list(truth), spacing)
    a, b = _distance_to(est, list(truth)), _distance_to(tru, list(curves))
    # a point-in-polygon parity test instead of the model's mean at every sample (5 ms of each 2-D step)
    inside = np.zeros(len(tru), dtype=bool)
    for c in curves:
        if len(c) >= 3:
            inside ^= Polygon(np.asarray(c, dtype=np.float64)[:, :2]).contains_points(tru[:, :2])
    observed, near = observed_samples(model, tru, est)
    return surface_agreement(a, b, np.where(inside, b, -b), observed, near)


def observed_samples(model, truth: np.ndarray, est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(observed (m,), near (n,))`` for :func:`surface_agreement`: the true-surface samples `(m, d)` within
    :data:`OBSERVED_WITHIN` of a surface observation (y = 0, either task) of ``model``, and the estimate's samples
    `(n, d)` within it of an observed one."""
    from scipy.spatial import cKDTree

    x = model.train_inputs[0].detach().cpu().numpy()
    obs = x[model.train_targets.detach().cpu().numpy() == 0]
    observed = cKDTree(obs).query(truth)[0] <= OBSERVED_WITHIN if len(obs) else np.zeros(len(truth), dtype=bool)
    near = cKDTree(truth[observed]).query(est)[0] <= OBSERVED_WITHIN if observed.any() else \
        np.zeros(len(est), dtype=bool)
    return observed, near

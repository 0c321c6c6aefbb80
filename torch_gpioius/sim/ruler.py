"""The converged ruler of the 3-D worlds: an estimate's metrics against the true body (:func:`estimate_metrics_3d`,
:func:`score_surface`), the level set found on a grid, every vertex moved onto it and the facets split fine, the
truth sampled as finely, each in the exploration range (docs/results-benchmark.md, "The ruler").
"""

from __future__ import annotations

import numpy as np
import torch
import trimesh

from ..exploration.world import Measurement

__all__ = ["METRICS_GRID", "METRICS_EDGE", "U_CELL", "SUP_FACETS", "estimate_metrics_3d", "score_surface"]

#: The grid of the estimate's marching cubes for the metrics [m]. Every vertex is then moved onto the level set and
#: the facets split to :data:`METRICS_EDGE` (:func:`torch_gpioius.geometry.surfaces.converged_level_mesh`), so the
#: grid sets only which pieces of the estimate are found: a 2 cm grid missed a bunny estimate's thin ridge (its
#: Hausdorff distance 8 % off, against 2 % on this grid). Halving it moves no figure by more than 2 %
#: (docs/results-benchmark.md).
METRICS_GRID = 0.01
#: The longest facet edge of the estimate and of the truth for the metrics [m]. A facet's chord lies e^2 / (8 R) off a
#: surface of curvature radius R (0.4 mm at 1 cm over 3 cm); :func:`score_surface` moves its quadrature points and each
#: true point's closest point onto the level set, which leaves the figures within 0.7 % of 2.5 mm facets' on the runs
#: measured (docs/results-benchmark.md, "The ruler").
METRICS_EDGE = 0.01


#: The cells [m] in which the uncertainty's quadrature gathers the estimate's vertices (the variance is smooth on the
#: kernel's length, 4-10 cm).
U_CELL = 0.015


def estimate_metrics_3d(model, scene, resolution: float = METRICS_GRID, spacing: float = METRICS_EDGE,
                        contacts=None) -> Measurement:
    """Uncertainty (eq. 23), Hausdorff distance (eq. 24) and the field's shape metrics of the estimated inner surface,
    in the range, measured with the converged ruler.

    The estimate ``{mu_in = 0}`` is meshed by marching cubes on a grid of ``resolution`` over the exploration range
    grown by a cell, every vertex moved onto the level set and every facet split to edges of at most ``spacing``
    (:func:`~torch_gpioius.geometry.surfaces.converged_level_mesh`), then scored by :func:`score_surface` (inside:
    mu < 0).
    Halving ``resolution`` moves every figure by under 2 % (tests/sim/test_forcefield.py; docs/results-benchmark.md,
    "The ruler"). With ``contacts``, also the Hausdorff distance of the touched pieces only
    (:func:`torch_gpioius.geometry.surfaces.touched_pieces`). The uncertainty averages the variance over the vertices,
    gathered in cells of :data:`U_CELL` (:func:`torch_gpioius.geometry.metrics.cell_quadrature`).

    Returns:
        :class:`Measurement` (``surface``: the estimated mesh in the range, or None); NaN metrics when the estimate
        has no surface in the range.
    """
    from ..geometry.metrics import cell_quadrature, uncertainty_measure, vertex_quadrature
    from ..geometry.surfaces import clip_mesh, converged_level_mesh, evaluate_grid, touched_pieces

    # the grid over the range and a cell around it: the estimate is judged in the range alone
    field = evaluate_grid(model, scene.bounds(resolution), resolution, 0, variance=False)
    whole = converged_level_mesh(model, None, field=field, edge=spacing, keep=scene.range)
    if whole is None:
        return Measurement(estimate=False)

    def mean(points: np.ndarray) -> np.ndarray:
        from ..geometry.differential import predict_mean_task

        with torch.no_grad():
            return predict_mean_task(model, torch.as_tensor(points, dtype=torch.float64), 0).detach().cpu().numpy()

    scored = score_surface(scene, whole, None, model.train_inputs[0].detach().cpu().numpy()[
        model.train_targets.detach().cpu().numpy() == 0], spacing, mean=mean)
    if scored is None:
        return Measurement(estimate=False)
    _, h, shape = scored
    mesh = clip_mesh(whole, scene.range[0], scene.range[1])         # the estimate in the range (the run's surface)
    if mesh is None:
        return Measurement(estimate=False)
    mesh.metadata["ruler"] = whole.metadata["ruler"]
    ht = float("nan")
    if contacts is not None and len(contacts):
        touched = touched_pieces(mesh, contacts)
        if touched is not None:
            from .meshes import MeshDistance

            t = np.concatenate([touched.vertices, touched.triangles_center])
            t = t[scene.in_range(t)]
            if len(t):
                ht = max(float(np.max(scene._inner_unsigned(t))),
                         float(np.max(MeshDistance(touched, signed=False)(_truth_points(scene, spacing)))))
    # the uncertainty, an average of the variance (smooth on the kernel's length, every query O(N_o r)), on the
    # vertices (on the surface) gathered in cells of 1.5 cm: within 0.7 % of every vertex on the runs measured, at a
    # tenth of the queries
    return Measurement(h, ht, uncertainty_measure(model, cell_quadrature(*vertex_quadrature(mesh), U_CELL), 0), None,
                       mesh, estimate=True, shape=shape)


def _truth_points(scene, spacing: float) -> np.ndarray:
    """The true surface's quadrature points and vertices in the range (a Hausdorff distance's samples)."""
    c, _, v = scene.inner_quadrature(spacing)
    return np.concatenate([v, c])


def score_surface(scene, surface: trimesh.Trimesh | None, inside, observations: np.ndarray,
                  spacing: float = METRICS_EDGE, mean=None) -> tuple[trimesh.Trimesh, float, dict] | None:
    """Score an estimated inner surface against a ranged world's true body: the converged ruler's metrics for any
    surface (the method's estimate, or a baseline's: :mod:`torch_gpioius.baselines`).

    The surface and the true inner mesh, each split to facets of edges at most ``spacing``
    (:func:`~torch_gpioius.geometry.metrics.mesh_quadrature`,
    :meth:`~torch_gpioius.sim.ranged.RangedScene.inner_quadrature`), are restricted to the exploration range (the
    robot can neither touch nor be judged on what lies outside it, e.g. under the arm). Means, shares and the median
    are integrals over the surfaces (each facet's centroid weighted by its area), with exact point-to-triangle
    distances both ways, so they do not depend on how the facets happen to be sized; the Hausdorff distance is the
    largest exact distance of either surface's facet vertices and centroids from the other surface (within a
    facet's size of the exact supremum).

    Args:
        scene: a :class:`~torch_gpioius.sim.ranged.RangedScene`.
        surface: the estimate (a mesh on it, e.g. :func:`~torch_gpioius.geometry.surfaces.converged_level_mesh`), or
            None.
        inside: ``inside(points (m, 3)) -> (m,) bool``, whether points lie inside the estimate (the bias' sign); None:
            the side of the closest facet of ``surface``, whose normals point out.
        observations: `(k, 3)` the surface observations [m] ("unseen": true surface more than 2 cm from all).
        spacing: the facets' longest edge [m].
        mean: ``mean(points (m, 3)) -> (m,)``, the field whose zero level ``surface`` lies on (its vertices'
            gradients in ``surface.metadata["gradients"]``,
            :func:`~torch_gpioius.geometry.surfaces.converged_level_mesh`);
            with it the facets' chords are corrected to second order: each centroid is moved onto the level set, and
            each true point's distance is taken to the level set near its closest facet point (one Newton step
            along the gradient interpolated there), so that facets twice as long measure as finely. None: the facets
            as they are.

    Returns:
        ``(the surface in the range, Hausdorff distance [m], shape metrics)``
        (:func:`~torch_gpioius.geometry.metrics.surface_agreement`), or None when the surface has nothing in the range.
    """
    from ..geometry.metrics import OBSERVED_WITHIN, mesh_quadrature, surface_agreement
    from ..geometry.surfaces import clip_mesh
    from .meshes import MeshDistance

    grads = None if surface is None or mean is None else surface.metadata.get("gradients")
    if grads is not None:               # the refined mesh as it is (its vertices aligned with their gradients)
        mesh = surface
        tri = np.asarray(mesh.vertices)[mesh.faces]
        est_c = tri.mean(axis=1)
        est_w = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        est_c = _onto_level(est_c, np.asarray(grads)[mesh.faces].mean(axis=1), mean, spacing)
        est_v = np.asarray(mesh.vertices)
    else:
        mesh = clip_mesh(surface, scene.range[0], scene.range[1])
        if mesh is None:
            return None
        est_c, est_w, est_v = mesh_quadrature(mesh, spacing)
    keep = scene.in_range(est_c)
    est_c, est_w = est_c[keep], est_w[keep]
    if not len(est_c):
        return None
    truth_c, truth_w, truth_v = scene.inner_quadrature(spacing)
    # exact point-to-triangle distances by libigl's AABB trees (the true body's built once per scene), of the facets'
    # centroids (the integrals) and vertices (with them, the Hausdorff distance's extremes)
    inner = getattr(scene, "_inner_unsigned", None)
    if inner is None:
        inner = scene._inner_unsigned = MeshDistance(scene.inner, signed=False)
    est_v = est_v[scene.in_range(est_v)]
    est_all = np.asarray(inner(np.concatenate([est_c, est_v])), dtype=float)
    est_to_truth = est_all[:len(est_c)]
    distance, closest, face = MeshDistance(mesh, signed=False).closest(np.concatenate([truth_c, truth_v]))
    if grads is not None:
        # from the closest facet point onto the level set there (one Newton step along the interpolated gradient)
        bary = trimesh.triangles.points_to_barycentric(np.asarray(mesh.vertices)[mesh.faces[face]], closest)
        g = np.einsum("ij,ijk->ik", bary, np.asarray(grads)[mesh.faces[face]])
        closest = _onto_level(closest, g, mean, spacing)
        distance = np.linalg.norm(np.concatenate([truth_c, truth_v]) - closest, axis=1)
    truth_to_est, closest, face = distance[:len(truth_c)], closest[:len(truth_c)], face[:len(truth_c)]
    h = max(float(est_all.max()), float(distance.max()))
    if inside is None:
        # the side of the estimate's closest facet (its normals point out): the model's mean need not be evaluated
        within = np.einsum("ij,ij->i", truth_c - closest, np.asarray(mesh.face_normals)[face]) < 0
    else:
        within = np.asarray(inside(truth_c), dtype=bool)
    signed = np.where(within, truth_to_est, -truth_to_est)
    from scipy.spatial import cKDTree

    obs = np.asarray(observations, dtype=float).reshape(-1, 3)
    observed = cKDTree(obs).query(truth_c)[0] <= OBSERVED_WITHIN if len(obs) else np.zeros(len(truth_c), bool)
    observed_tree = cKDTree(truth_c[observed]) if observed.any() else None

    def near_observed(points: np.ndarray, within: float = OBSERVED_WITHIN) -> np.ndarray:
        if observed_tree is None:
            return np.zeros(len(points), bool)
        return observed_tree.query(points)[0] <= within

    near = near_observed(est_c)
    weights = est_w
    if grads is not None:
        # the suprema over the estimate (the Hausdorff distances) at facets as fine as where they are attained: the
        # facets at or near the largest distances, over the whole estimate and near the observed body, split twice
        # and their points moved onto the level set, weightless (the integrals keep their quadrature)
        # (near the observed body: also the facets a facet's size beyond it, where its supremum may lie on a border)
        extra = _sup_points(mesh, grads, mean, spacing, keep, est_to_truth,
                            near_observed(est_c, OBSERVED_WITHIN + spacing))
        if len(extra):
            extra = extra[scene.in_range(extra)]
            d = np.asarray(inner(extra), dtype=float)
            h = max(h, float(d.max(initial=0.0)))
            est_to_truth = np.r_[est_to_truth, d]
            near = np.r_[near, near_observed(extra)]
            weights = np.r_[est_w, np.zeros(len(d))]
    return mesh, h, surface_agreement(est_to_truth, truth_to_est, signed, observed, near, est_weights=weights,
                                      truth_weights=truth_w)


#: How many facets :func:`score_surface` splits near each supremum of the estimate's distance from the body.
SUP_FACETS = 64


def _sup_points(mesh: trimesh.Trimesh, grads, mean, spacing: float, keep: np.ndarray, values: np.ndarray,
                near: np.ndarray) -> np.ndarray:
    """Points of the facets where the estimate's distance from the body is largest (over all of it, and over the part
    near the observed body), each facet split twice and the new points moved onto the level set: `(k, 3)`."""
    kept = np.flatnonzero(keep)
    chosen: set[int] = set()
    for mask in (np.ones(len(values), bool), near):
        if not mask.any():
            continue
        v = np.where(mask, values, -np.inf)
        top = np.argsort(v)[::-1][:SUP_FACETS]
        chosen |= {int(kept[i]) for i in top if np.isfinite(v[i]) and v[i] >= v[top[0]] - spacing}
    if not chosen:
        return np.zeros((0, 3))
    faces = np.asarray(mesh.faces)[sorted(chosen)]
    verts, g = np.asarray(mesh.vertices), np.asarray(grads)
    n0 = len(verts)
    for _ in range(2):
        verts, faces, attributes = trimesh.remesh.subdivide(verts, faces, vertex_attributes={"g": g})
        g = attributes["g"]
    fresh = verts[n0:]
    centroids = verts[faces].mean(axis=1)
    points = np.concatenate([fresh, centroids])
    return _onto_level(points, np.concatenate([g[n0:], g[faces].mean(axis=1)]), mean, spacing)


def _onto_level(points: np.ndarray, grads: np.ndarray, mean, limit: float) -> np.ndarray:
    """Points on or near facets moved onto the level set of ``mean`` by one Newton step along ``grads`` `(n, 3)`,
    each step at most ``limit`` [m] long (a facet's sagitta is far shorter)."""
    from ..geometry.surfaces import newton_onto_level

    return newton_onto_level(points, grads, np.asarray(mean(points), dtype=float), limit)[0]

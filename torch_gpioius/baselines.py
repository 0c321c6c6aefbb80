"""Simple baselines scored beside the method, from the very observations of a visual-tactile run.

Is the fusion better than the simple thing an engineer would do instead? Each baseline builds an estimate of the
inner surface from the run's own data, and the same converged ruler scores it (:func:`score_baselines`):

* ``vision``: a GPIS on the camera's observations alone (as captured, before any retraction of its inside points),
  with the run's kernel and sigma^2, its surface taken for the inner one;
* ``vision-shrunk-5``: that surface moved inward along its normals by the gap the first five contacts measure (the
  median depth of a contact under it);
* ``vision-shrunk-all``: the same with the gap of every contact of the run;
* ``vision-shrunk-5-plain``, ``vision-shrunk-all-plain``: the two shrunk surfaces from the capture labelled as the
  paper labels it, each point in the voxel it was measured in, where the run's settings smooth the depths along the
  rays first (``ObservationPolicy.ray_smoothing``, the default): the smoothing is the method's choice, and under 4 cm
  covers the shrunk surface measured better without it (0.71 -> 0.46 cm on 20 primitives; docs/results-benchmark.md).
  Where the run does not smooth they are the two above.

Touch alone, the fourth, is the study's own ``tactile`` mode run on the same object and seed (paired in the tables).

A baseline is an entry of :data:`BASELINES`: a function ``baseline(data: BaselineData) -> BaselineEstimate | None``
registered with :func:`register_baseline`; a user's own is one function and one registration, and every study run
scores it (``gpioius study`` imports plugins first; docs/architecture.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch
import trimesh

from .core.registry import Entry, Registry

__all__ = ["BaselineData", "BaselineEstimate", "BASELINES", "register_baseline", "score_baselines",
           "vision_surface", "contact_depths", "shrunk", "BASELINE_METRICS", "BASELINE_EDGE"]

#: The metrics a baseline's score carries (records, runs.csv's ``baseline_<name>_<metric>`` columns).
BASELINE_METRICS = ("chamfer", "fscore_5mm", "fscore_10mm", "bias", "hausdorff", "gap")
#: The facets' longest edge of a baseline's surface [m]: 5 mm, scored as they are (within 0.5 % of 2.5 mm facets on
#: the runs measured; a shrunk surface has no field whose level set would correct its chords).
BASELINE_EDGE = 0.005


@dataclass
class BaselineData:
    """The observations of one run that a baseline may use.

    Attributes:
        outer_x: `(n, 3)` the camera's observations as captured [m], base frame.
        outer_y: `(n,)` their labels (0 on the seen surface, 1 in free space, < 0 inside).
        contacts: `(k, 3)` the run's contacts in the order they were made [m].
        kernel: the run's kernel (an :class:`~torch_gpioius.kernels.ExactKernel`; copied before use).
        noise: the run's sigma^2.
        bounds: `(2, 3)` the box to mesh estimates in [m].
        resolution: the marching grid [m] (the converged ruler's).
        edge: the facets' longest edge [m].
        keep: `(2, 3)` the box the estimates are judged in [m] (facets beyond it by more than a cell are not
            refined); None: all of ``bounds``.
        plain: ``(x (m, 3), y (m,))`` the same capture labelled without the ray smoothing, or None where the run did
            not smooth (then :meth:`plain_data` is these data).
    """

    outer_x: np.ndarray
    outer_y: np.ndarray
    contacts: np.ndarray
    kernel: object
    noise: float
    bounds: np.ndarray
    resolution: float = 0.01
    edge: float = BASELINE_EDGE
    keep: np.ndarray | None = None
    plain: tuple | None = None
    _cache: dict = field(default_factory=dict, repr=False)

    def plain_data(self) -> "BaselineData":
        """These data with the camera's observations labelled without the ray smoothing (:attr:`plain`; themselves
        where there is none), cached, so that a baseline of each form builds its vision surface once."""
        if self.plain is None:
            return self
        if "plain" not in self._cache:
            x, y = self.plain
            self._cache["plain"] = BaselineData(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64),
                                                self.contacts, self.kernel, self.noise, self.bounds, self.resolution,
                                                self.edge, self.keep)
        return self._cache["plain"]


@dataclass
class BaselineEstimate:
    """A baseline's estimate of the inner surface.

    Attributes:
        surface: a mesh on it [m] (closed where the estimate closes in the box), its facets' normals outward.
        inside: ``inside(points (m, 3)) -> (m,) bool``: whether points lie inside the estimate; None: the side of the
            closest facet of ``surface``.
        gap: the gap it was shrunk by [m] (NaN where none).
    """

    surface: trimesh.Trimesh
    inside: Callable[[np.ndarray], np.ndarray] | None = None
    gap: float = math.nan


@dataclass
class BaselineEntry(Entry):
    """A registered baseline (its ``obj``: ``baseline(data) -> BaselineEstimate | None``)."""


#: The baselines every visual-tactile study run is scored beside, by name.
BASELINES: Registry = Registry("baseline", entry_type=BaselineEntry)


def register_baseline(name: str, function: Callable, *, description: str = "") -> Callable:
    """Score ``function`` (``function(data: BaselineData) -> BaselineEstimate | None``) beside every visual-tactile
    study run under ``name`` (an identifier; hyphens allowed).

    Raises:
        ValueError: the name is taken by another baseline.
    """
    BASELINES.register(name, function, description=description)
    return function


def vision_surface(data: BaselineData) -> tuple[object, trimesh.Trimesh] | None:
    """The GPIS of the camera's observations alone and its converged surface (cached on ``data``), or None where the
    camera saw nothing or its estimate does not cross the box."""
    if "vision" in data._cache:
        return data._cache["vision"]
    import copy

    from .models.gpis import GPIS
    from .geometry.surfaces import converged_level_mesh, evaluate_grid

    out = None
    if len(data.outer_y) and (data.outer_y == 0).any():
        x = torch.as_tensor(data.outer_x, dtype=torch.float64)
        y = torch.as_tensor(data.outer_y, dtype=torch.float64)
        model = GPIS(x, y, kernel=copy.deepcopy(data.kernel), noise=data.noise)
        field = evaluate_grid(model, data.bounds, data.resolution, 0, variance=False)
        mesh = converged_level_mesh(model, None, field=field, edge=data.edge, keep=data.keep)
        out = None if mesh is None else (model, mesh)
    data._cache["vision"] = out
    return out


def _mean(model, points: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return model.predict_mean(torch.as_tensor(np.asarray(points, dtype=np.float64))).detach().cpu().numpy()


def contact_depths(model, mesh: trimesh.Trimesh, contacts: np.ndarray) -> np.ndarray:
    """`(k,)` how deep each contact lies under the vision surface [m]: its distance from ``mesh``, positive where the
    vision GPIS ``model`` has it inside (mu < 0), negative outside."""
    from .sim.meshes import MeshDistance

    if not len(contacts):
        return np.zeros(0)
    d = np.asarray(MeshDistance(mesh, signed=False)(contacts), dtype=float)
    return np.where(_mean(model, contacts) < 0, d, -d)


def shrunk(model, mesh: trimesh.Trimesh, gap: float) -> BaselineEstimate:
    """The vision surface ``mesh`` (:func:`vision_surface`) moved inward along its normals (the GPIS's gradient at each
    vertex, outward: ``mesh.metadata["gradients"]``) by ``gap`` [m]; its facets keep their outward orientation."""
    g = np.asarray(mesh.metadata["gradients"], dtype=np.float64)
    normals = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    moved = trimesh.Trimesh(vertices=np.asarray(mesh.vertices) - gap * normals, faces=np.asarray(mesh.faces),
                            process=False)
    return BaselineEstimate(moved, None, float(gap))


def _vision(data: BaselineData) -> BaselineEstimate | None:
    found = vision_surface(data)
    if found is None:
        return None
    return BaselineEstimate(found[1], None)


def _plain(baseline):
    """``baseline`` on the capture labelled without the ray smoothing (:meth:`BaselineData.plain_data`)."""
    def on_plain(data: BaselineData) -> BaselineEstimate | None:
        return baseline(data.plain_data())
    return on_plain


def _shrunk_by(first: int | None):
    def baseline(data: BaselineData) -> BaselineEstimate | None:
        found = vision_surface(data)
        contacts = data.contacts if first is None else data.contacts[:first]
        if found is None or not len(contacts):
            return None
        model, mesh = found
        return shrunk(model, mesh, float(np.median(contact_depths(model, mesh, contacts))))
    return baseline


register_baseline("vision", _vision, description="a GPIS of the camera's observations alone, taken for the inner "
                                                 "surface")
register_baseline("vision-shrunk-5", _shrunk_by(5), description="the vision surface moved inward by the median depth "
                                                                "of the first five contacts under it")
register_baseline("vision-shrunk-all", _shrunk_by(None), description="the vision surface moved inward by the median "
                                                                     "depth of every contact under it")
register_baseline("vision-shrunk-5-plain", _plain(_shrunk_by(5)),
                  description="vision-shrunk-5 from the capture labelled without the ray smoothing")
register_baseline("vision-shrunk-all-plain", _plain(_shrunk_by(None)),
                  description="vision-shrunk-all from the capture labelled without the ray smoothing")


def score_baselines(scene, data: BaselineData, observations: np.ndarray, names=None) -> dict[str, dict]:
    """Each baseline's estimate scored by the converged ruler against ``scene``'s true body
    (:func:`torch_gpioius.sim.forcefield.score_surface`).

    Args:
        scene: a ranged 3-D world with a known truth.
        data: the run's observations.
        observations: `(k, 3)` the run's surface observations [m] (the "unseen" share, as the method's).
        names: the baselines to score (default: every registered one).

    Returns:
        ``{name: {"chamfer", "fscore_5mm", "fscore_10mm", "bias", "hausdorff", "gap"}}``; NaN metrics (F-scores 0)
        where a baseline gives no estimate in the range.
    """
    from .sim.ruler import score_surface

    out = {}
    for name in names if names is not None else BASELINES.names():
        estimate = BASELINES[name](data)
        scored = None if estimate is None else score_surface(scene, estimate.surface, estimate.inside, observations,
                                                            data.edge)
        if scored is None:
            out[name] = {"chamfer": math.inf, "fscore_5mm": 0.0, "fscore_10mm": 0.0, "bias": math.nan,
                         "hausdorff": math.inf, "gap": math.nan if estimate is None else estimate.gap}
            continue
        _, h, shape = scored
        out[name] = {"chamfer": shape["chamfer"], "fscore_5mm": shape["fscore_5mm"],
                     "fscore_10mm": shape["fscore_10mm"], "bias": shape["bias"], "hausdorff": h, "gap": estimate.gap}
    return out

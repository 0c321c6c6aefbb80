"""Reaching for surface no sensor has seen (beyond the paper): lift off, move in free space, touch again there.

The paper's sliding follows the gradient of the inner variance V from where the fingertip is (eq. 19). It is a
local rule: a body part the camera does not see and the path never passes near (the back of a teddy's head, the
far side of a bunny below its ears) stays an extrapolation of the outer shape until the end of the run, and the
Hausdorff distance, a maximum, stays there with it (docs/results-real.md: at the end of the tight teddy's runs 17 %
of its true surface was more than 2 cm from every observation).

A *reach* takes the global view every ``min_steps`` steps:

1. **where**: the estimated inner surface ``{mu_in = 0}`` is meshed on a coarse grid over the exploration range
   (marching cubes, :func:`torch_gpioius.geometry.surfaces.zero_level_mesh`) and sampled about every ``resolution``;
   each sample's posterior variance ``V`` and outward normal come from the model (:func:`torch_gpioius.geometry.
   surface_geometry`). A target must lie at least ``min_distance`` from the contact (nearer surface the sliding
   reaches by itself), in the range, and have ``V`` at least ``min_ratio`` times the largest variance within
   ``min_distance`` of the contact and ``min_variance`` times the prior variance: otherwise nothing is left that a
   reach would learn more about than the sliding nearby, and the policy does nothing.
2. **how**: through free space the model is sure of. The fingertip lifts along the measured contact normal by the
   smallest clearance of ``clearances`` from which that free space is reachable, follows the shortest route through
   it to a point a clearance out along the target's normal, and approaches along the inward normal. "Sure" is
   ``mu_in >= clear_level`` (and, with a camera, ``mu_out >= clear_level``: outside the cover it saw, so a cloth is
   not dragged), on a 2 cm grid over the range grown by 12 cm (never below the range's floor, where the body stands
   on its support); the route is Dijkstra's on that grid, cut down to the corners it needs, each leg checked every
   centimetre. The targets are tried in decreasing ``V``; the first whose path (lift, route, stand-off) is no
   longer than ``max_transit`` and the travel budget left wins.
3. **moving**: the lift (:meth:`ContactController.lift`) and the legs (guarded :meth:`ContactController.approach`
   moves, which stop at any contact on the way: the estimate may be wrong, and such a contact is a touch like any
   other) go through the toucher, so every joint, speed, force and workspace limit of the robot applies.

What a reach records: the free space along its path (y = 1, inner task) and the contact where it ends (y = 0); the
planner then starts afresh from there. Its travel counts in the travel budget and it counts as a step of the step
budget (as a tap does, ``state.taps``). When the target's approach finds nothing (the estimate was too far out) the
fingertip is left in free space and the next step's lost-contact recovery re-approaches
(:func:`torch_gpioius.exploration.loop.recover`).

Use: ``explore(world, evidence="reach")``, ``evidence=ReachPolicy(min_steps=10)``, ``gpioius study --modes
visual-tactile+reach``. 3-D worlds only (it meshes the estimate).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch

from .evidence import Evidence
from .protocols import EvidencePolicyBase

__all__ = ["ReachPolicy", "ReachPlan"]


@dataclass(frozen=True)
class ReachPlan:
    """Where a reach goes and how (the output of :meth:`ReachPolicy.plan`; base frame, metres).

    Attributes:
        target: `(3,)` the point of the estimated inner surface to touch.
        normal: `(3,)` the estimate's outward normal there (the approach is along ``-normal``).
        waypoints: `(k, 3)` the path's corners: the contact, the lifted point, the corners of the route through free
            space, and last the point ``clearance`` out along ``normal`` from the target.
        lift: how far the fingertip lifts off the contact along the measured normal before the route [m] (one of
            the policy's ``clearances``).
        clearance: the target's stand-off [m].
        variance: the inner posterior variance at the target.
        near_variance: the largest inner posterior variance at the contact and the surface samples within
            ``min_distance`` of it (what the sliding reaches by itself).
        length: the path's length to the target [m] (lift, route, stand-off).
        candidates: surface samples that passed the variance and distance tests.
    """

    target: np.ndarray
    normal: np.ndarray
    waypoints: np.ndarray
    lift: float
    clearance: float
    variance: float
    near_variance: float
    length: float
    candidates: int


@dataclass(frozen=True)
class ReachPolicy(EvidencePolicyBase):
    """When and where to reach for unseen surface (see the module docstring).

    Attributes:
        min_steps: planning steps between two reaches (and before the first).
        min_ratio: the target's inner variance must be at least this multiple of the largest within ``min_distance``
            of the contact (surface the sliding reaches by itself).
        min_variance: ... and at least this share of the inner prior variance.
        min_distance: targets nearer the contact than this [m] are left to the sliding.
        resolution: grid spacing of the estimate's mesh and spacing of its samples [m].
        clearances: lifts and stand-offs tried, smallest first [m] (each at most 0.1 m: ``ContactController.lift``'s
            ``extra``).
        clear_level: the least posterior mean (inner, and outer with a camera) along the path.
        max_transit: the longest path to a target [m].
        max_checks: targets whose paths are checked, in decreasing variance.
        bounds: `(2, 3)` the exploration range `[min corner; max corner]` [m]; None: set by the exploration from its
            range penalty (eq. 25), else the model's data box.
        budget: the run's travel budget [m] (set by the exploration), or None.
    """

    min_steps: int = 15
    min_ratio: float = 2.0
    min_variance: float = 0.01
    min_distance: float = 0.05
    resolution: float = 0.015
    clearances: tuple = (0.04, 0.07, 0.10)
    clear_level: float = 0.3
    max_transit: float = 0.35
    max_checks: int = 24
    bounds: tuple | None = None
    budget: float | None = None
    name: str = "reach"
    #: unlike a tap, a reach is useful without a camera (touch alone explores the same way)
    needs_vision = False

    def __post_init__(self) -> None:
        from ..core.validation import as_float, as_int

        as_int(self.min_steps, "ReachPolicy.min_steps", 1, 1_000_000)
        as_int(self.max_checks, "ReachPolicy.max_checks", 1, 10_000)
        as_float(self.min_ratio, "ReachPolicy.min_ratio", lo=1.0, hi=1e6)
        as_float(self.min_variance, "ReachPolicy.min_variance", lo=0.0, hi=1.0)
        for name in ("min_distance", "resolution", "max_transit"):
            as_float(getattr(self, name), f"ReachPolicy.{name}", lo=1e-3, hi=2.0, unit="m")
        as_float(self.clear_level, "ReachPolicy.clear_level", lo=0.0, hi=1.0)
        c = self.clearances
        if (not isinstance(c, (tuple, list)) or not c
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and 0.005 <= v <= 0.1 for v in c)
                or list(c) != sorted(c)):
            raise ValueError(f"ReachPolicy.clearances: must be increasing distances in [0.005, 0.1] m, got {c!r}")
        object.__setattr__(self, "clearances", tuple(float(v) for v in c))
        if self.bounds is not None:
            from ..core.validation import as_bounds

            object.__setattr__(self, "bounds", tuple(map(tuple, as_bounds(self.bounds, 3).tolist())))
        if self.budget is not None:
            as_float(self.budget, "ReachPolicy.budget", positive=True, unit="m")

    def for_run(self, *, dim: int, bounds=None, budget: float | None = None) -> "ReachPolicy":
        """This policy with the exploration's range and travel budget filled in where it has none.

        Raises:
            ValueError: a world that is not 3-D.
        """
        if dim != 3:
            raise ValueError(f"evidence='reach': a reach meshes the estimate, which needs a 3-D world (got {dim}-D)")
        return replace(self, bounds=self.bounds if self.bounds is not None or bounds is None else bounds,
                       budget=self.budget if self.budget is not None else budget)

    def due(self, state) -> bool:
        """Whether to look for a reach after the current step: ``min_steps`` since the last evidence action and
        some travel budget left; reads the state, changes nothing."""
        if state.steps - state.last_evidence < self.min_steps:
            return False
        return self._left(state) > self.min_distance

    def _left(self, state) -> float:
        return min(self.max_transit, math.inf if self.budget is None else self.budget - state.travel)

    def plan(self, state) -> ReachPlan | None:
        """The target and the path of a reach from the current contact, or None when no surface qualifies or none
        can be reached within the travel left (see the module docstring). Reads the model, moves nothing."""
        from ..geometry.differential import surface_geometry
        from ..geometry.metrics import prior_variance
        from ..geometry.surfaces import data_bounds, surface_samples, zero_level_mesh

        model = state.model
        x0 = model.train_inputs[0]
        if x0.shape[-1] != 3 or state.normal is None:
            return None
        bounds = (np.asarray(self.bounds) if self.bounds is not None
                  else data_bounds(x0.detach().cpu().numpy()))
        pts = surface_samples(zero_level_mesh(model, bounds, self.resolution, task=0), self.resolution)
        lo, hi = bounds[0] + 0.5 * self.resolution, bounds[1] - 0.5 * self.resolution
        contact = np.asarray(state.contact, dtype=np.float64)
        if len(pts):
            pts = pts[((pts >= lo) & (pts <= hi)).all(axis=1)]
        if not len(pts):
            return None
        geo = surface_geometry(model, torch.as_tensor(np.concatenate([contact[None], pts])), 0)
        var = geo.var.cpu().numpy()
        near = np.linalg.norm(pts - contact, axis=1) < self.min_distance
        v_near = float(max(var[0], var[1:][near].max(initial=0.0)))      # what the sliding will find by itself
        var, normal_defined = var[1:], geo.normal_defined.cpu().numpy()[1:]
        floor = max(self.min_ratio * v_near, self.min_variance * prior_variance(model, 0))
        ok = (var >= floor) & normal_defined & ~near
        if not ok.any():
            return None
        order = np.flatnonzero(ok)[np.argsort(-var[ok], kind="stable")][: self.max_checks]
        normals = geo.normal.cpu().numpy()[1:]
        n0 = state.normal.detach().cpu().numpy().astype(np.float64)
        n0 = n0 / max(float(np.linalg.norm(n0)), 1e-12)
        left = self._left(state)
        roads = _FreeSpace(self, model, bounds)
        for h in self.clearances:               # the smallest lift from which the free space is reachable
            a = contact + h * n0
            if roads.clear([a]) and roads.start(a):
                break
        else:
            return None
        for i in order:
            for g in self.clearances:
                b = pts[i] + g * normals[i]
                if not roads.clear([b]):
                    continue
                route = roads.route(b)
                if route is None:
                    break                           # not connected to the lift: a larger stand-off is no nearer
                length = h + _length(route) + g
                if length > left:
                    break
                return ReachPlan(pts[i], normals[i], np.concatenate([contact[None], route]), h, g,
                                 float(var[i]), v_near, length, int(ok.sum()))
        return None

    def gather(self, state, toucher) -> Evidence | None:
        """Plan a reach and make it: lift, a guarded leg to each corner of the route, the approach along the target's
        inward normal.

        Returns:
            the :class:`Evidence` (an evidence action like a tap: counted in ``state.taps``, logged as a ``tap``
            record; ``contact`` None when the fingertip ended in free space), or None when no target qualified or the
            robot refused or faulted on the lift.
        """
        plan = self.plan(state)
        if plan is None:
            return None
        up = torch.as_tensor(plan.waypoints[1] - plan.waypoints[0])
        try:                                  # the clearance itself: |h n| can round above the lift's 0.1 m bound
            lift = toucher.lift(up / up.norm(), step=0.005, until_force_below=0.1, extra=plan.lift,
                                max_distance=plan.lift + 0.05)
        except RuntimeError:                  # refused, or a fault (the controller stopped or retreated): no reach; if
            return None                       # contact is lost, the next step's recovery re-approaches
        touches = [lift]

        def leg(direction: np.ndarray, distance: float):
            r = toucher.approach(torch.as_tensor(direction / np.linalg.norm(direction)), max_travel=distance)
            touches.append(r)
            return r

        try:
            here = lift.path[-1].numpy()
            for corner in plan.waypoints[2:]:
                to = corner - here
                if float(np.linalg.norm(to)) <= 1e-6:
                    continue
                r = leg(to, float(np.linalg.norm(to)))
                if r.in_contact:              # something where the estimate saw free space: a touch all the same
                    return Evidence(touches, r.contact.numpy(), r.force_normal)
                here = r.path[-1].numpy()
            r = leg(-plan.normal, max(float(np.dot(here - plan.target, plan.normal)), 0.0) + 0.05)
        except RuntimeError:                  # a leg refused: the next step's lost-contact recovery takes over
            return Evidence(touches, None, None)
        if not r.in_contact:
            return Evidence(touches, None, None)
        return Evidence(touches, r.contact.numpy(), r.force_normal)

    def describe(self) -> dict:
        out = asdict(self)
        out["bounds"] = None if self.bounds is None else [list(b) for b in self.bounds]
        out["clearances"] = list(self.clearances)
        return out


def _densify(corners, spacing: float) -> np.ndarray:
    """`(m, 3)` points every ``spacing`` [m] or closer along the polyline through ``corners``, ends included."""
    corners = [np.asarray(c, dtype=np.float64) for c in corners]
    out = [corners[0][None]]
    for p, q in zip(corners[:-1], corners[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(q - p) / spacing)))
        out.append(p + np.linspace(0.0, 1.0, n + 1)[1:, None] * (q - p))
    return np.concatenate(out)


def _length(corners: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(corners, axis=0), axis=1).sum())


def _least_mean(model, xs: np.ndarray) -> np.ndarray:
    """`(m,)` the smaller posterior mean of the inner task and (GPIOIS) the outer one at points `(m, 3)`."""
    from ..geometry.differential import predict_mean_task

    x0 = model.train_inputs[0]
    q = torch.as_tensor(xs, dtype=x0.dtype, device=x0.device)
    with torch.no_grad():
        means = [predict_mean_task(model, q, t) for t in range(getattr(model, "num_tasks", 1))]
    return torch.stack(means).min(dim=0).values.cpu().numpy()


def _sure_free(model, xs: np.ndarray, level: float) -> bool:
    """Whether the posterior mean is at least ``level`` at every point `(m, 3)`, inner task and (GPIOIS) outer."""
    return float(_least_mean(model, xs).min()) >= level


class _FreeSpace:
    """Shortest routes through the free space the model is sure of: a grid (``GRID`` [m]) over the exploration range
    grown by the largest clearance and 2 cm on every side but the floor (a route never passes below the range, where
    the body stands on its support), its nodes with ``mu >= clear_level`` (inner and outer), 26-neighbour edges
    between them, and Dijkstra from the node nearest the lifted point (scipy's, on the grid's sparse graph); a route
    is then shortened by keeping only the corners it needs, each leg checked every centimetre."""

    GRID = 0.02

    def __init__(self, policy: ReachPolicy, model, bounds: np.ndarray):
        self.model, self.level = model, policy.clear_level
        grow = policy.clearances[-1] + 0.02
        lo, hi = bounds[0] - grow, bounds[1] + grow
        lo[2] = bounds[0][2]
        axes = [np.arange(lo[k], hi[k] + 0.5 * self.GRID, self.GRID) for k in range(3)]
        self.shape = tuple(len(a) for a in axes)
        self.nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        self.free = _least_mean(model, self.nodes) >= self.level
        self.source = None
        self.dist = self.pred = None

    def clear(self, corners) -> bool:
        return _sure_free(self.model, _densify(corners, 0.01), self.level)

    def _nearest_free(self, p: np.ndarray) -> int | None:
        """The nearest free node to ``p`` that a straight, clear leg joins to it (within two grid cells)."""
        d = np.linalg.norm(self.nodes - p, axis=1)
        near = np.flatnonzero(self.free & (d <= 2.0 * self.GRID))
        for i in near[np.argsort(d[near], kind="stable")][:6]:
            if self.clear([p, self.nodes[i]]):
                return int(i)
        return None

    def start(self, a: np.ndarray) -> bool:
        """Route from the lifted point ``a``; False if no free node is reachable from it."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra

        src = self._nearest_free(a)
        if src is None:
            return False
        idx = np.arange(len(self.nodes)).reshape(self.shape)
        rows, cols, w = [], [], []
        for off in [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) > (0, 0, 0)]:
            sl_a = tuple(slice(max(0, -o), n - max(0, o)) for o, n in zip(off, self.shape))
            sl_b = tuple(slice(max(0, o), n - max(0, -o)) for o, n in zip(off, self.shape))
            ia, ib = idx[sl_a].ravel(), idx[sl_b].ravel()
            keep = self.free[ia] & self.free[ib]
            rows.append(ia[keep])
            cols.append(ib[keep])
            w.append(np.full(int(keep.sum()), self.GRID * math.sqrt(sum(o * o for o in off))))
        n = len(self.nodes)
        graph = coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
        self.dist, self.pred = dijkstra(graph, directed=False, indices=src, return_predecessors=True)
        self.source, self.a = src, np.asarray(a, dtype=np.float64)
        return True

    def route(self, b: np.ndarray) -> np.ndarray | None:
        """`(k, 3)` corners from the lifted point to ``b`` through sure free space, or None if it is not reachable."""
        dst = self._nearest_free(b)
        if dst is None or not np.isfinite(self.dist[dst]):
            return None
        chain = [dst]
        while chain[-1] != self.source:
            chain.append(int(self.pred[chain[-1]]))
        pts = np.concatenate([self.a[None], self.nodes[chain[::-1]], np.asarray(b, dtype=np.float64)[None]])
        corners, i = [pts[0]], 0                          # keep only the corners the route needs
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self.clear([pts[i], pts[j]]):
                j -= 1
            corners.append(pts[j])
            i = j
        return np.stack(corners)

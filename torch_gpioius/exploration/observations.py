"""What the exploration records from what the sensors report: the observation model.

The paper fixes the GP model and the planner, not which observations a toucher and a camera produce; these choices
decide whether the similarity means anything (docs/method-notes.md). The same rules serve every world:

* vision, once before exploring: the seen outer surface (y = 0, task 1) and free space in front of it (y = 1,
  task 1), optionally cropped to the region of interest and averaged in voxels (paper: 5 cm);
* touch, every step: the contact (y = 0, task 0) and the free space the fingertip crossed with ``|F|`` below the
  contact threshold (y = 1, task 0), thinned to a spacing and kept a margin away from every contact; free space
  recorded earlier is retracted when a later contact lands within that margin.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch

from ..core.validation import INSIDE_DEPTH_MAX, as_int, label_problem
from ..models.gpiois import INNER, OUTER
from ..models.labels import MAX_VOXEL, ObservationPolicy, check_voxel
from ..geometry.voxels import voxel_average

__all__ = ["Observations", "ObservationPolicy", "check_voxel", "MAX_VOXEL", "thin_points", "thin_indices",
           "free_space_along", "retract_free_space", "vision_observations", "drop_contradicted_inside",
           "inside_checked_by_step", "uncontradicted", "uncontradicted_by_step", "INSIDE_CLEARANCE",
           "retract_vision_inside", "offset_outer_mean",
           "renew_deep_vision_inside", "deepen_vision_inside", "carried_mean", "CARRY_MIN_RATIO",
           "cover_gap", "CoverGap", "GAP_MIN_CONTACTS", "INNER", "OUTER"]

@dataclass
class Observations:
    """A batch of observations: the one unit that flows from a sensor through the model to the log, resume, exports
    and the viewer.

    A point touch gives one surface point (``y = 0``) and the free space the fingertip crossed (``y = 1``); a tactile
    patch gives many surface points with normals and the free space in front of the pad; one camera capture gives
    the seen surface and free space in front of it (task 1).

    Attributes:
        x: `(n, d)` positions [m] in the world's frame (the robot base frame on a robot).
        y: `(n,)` labels: 0 on a surface, 1 in free space, negative inside a body (``inside_label``).
        task: `(n,)` 0 inner (touch), 1 outer (vision).
        normal: `(n, d)` outward unit normals where a sensor measured one (NaN rows where it did not), or None.
        step: the exploration step the batch arrived at (0: before exploring).
        source: what produced it ("vision", "touch", "evidence", "patch", ...).

    Raises:
        ValueError: wrong shapes, NaN or inf positions, labels or task ids outside {0, 1}, normals that are not unit
            vectors (names the field).
    """

    x: np.ndarray
    y: np.ndarray
    task: np.ndarray
    normal: np.ndarray | None = None
    step: int = 0
    source: str = ""

    def __post_init__(self) -> None:
        x = np.asarray(self.x, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] not in (2, 3):
            raise ValueError(f"Observations.x: expected (n, 2) or (n, 3) positions [m], got shape {x.shape}")
        n = len(x)
        y = np.asarray(self.y, dtype=np.float64).reshape(-1)
        task = np.asarray(self.task).reshape(-1)
        if task.size == 1 and n != 1:
            task = np.full(n, task.item())
        if y.shape != (n,) or task.shape != (n,):
            raise ValueError(f"Observations: y and task must have shape ({n},), got {y.shape} and {task.shape}")
        if not np.isfinite(x).all():
            raise ValueError("Observations.x: contains NaN or inf")
        if (problem := label_problem(y)) is not None:
            raise ValueError(f"Observations.y: {problem}")
        if not np.isin(task, (0, 1)).all():
            raise ValueError("Observations.task: ids must be 0 (inner) or 1 (outer)")
        self.x, self.y, self.task = x, y, task.astype(np.int64)
        if self.normal is not None:
            nrm = np.asarray(self.normal, dtype=np.float64)
            if nrm.shape != x.shape:
                raise ValueError(f"Observations.normal: expected shape {x.shape}, got {nrm.shape}")
            known = np.isfinite(nrm).all(axis=1)
            if not np.allclose(np.linalg.norm(nrm[known], axis=1), 1.0, atol=1e-6):
                raise ValueError("Observations.normal: normals must be unit vectors (NaN rows where unknown)")
            self.normal = nrm
        if isinstance(self.step, bool) or not isinstance(self.step, (int, np.integer)) or self.step < 0:
            raise ValueError(f"Observations.step: must be a non-negative integer, got {self.step!r}")
        self.step = int(self.step)

    def __len__(self) -> int:
        return len(self.x)

    @property
    def dim(self) -> int:
        return self.x.shape[1]

    def subset(self, keep: np.ndarray) -> "Observations":
        """The observations ``keep`` (a `(n,)` bool mask or indices) selects, in order."""
        keep = np.asarray(keep)
        return Observations(self.x[keep], self.y[keep], self.task[keep],
                            None if self.normal is None else self.normal[keep], self.step, self.source)

    @classmethod
    def empty(cls, dim: int, step: int = 0, source: str = "") -> "Observations":
        """No observation (a touch that added nothing)."""
        return cls(np.zeros((0, dim)), np.zeros(0), np.zeros(0, np.int64), step=step, source=source)

    @classmethod
    def concat(cls, batches: list["Observations"], source: str | None = None) -> "Observations":
        """The batches one after another (normals kept where any batch has them; the first batch's step)."""
        batches = [b for b in batches if b is not None]
        if not batches:
            raise ValueError("Observations.concat: no batch")
        normals = None
        if any(b.normal is not None for b in batches):
            normals = np.concatenate([b.normal if b.normal is not None else np.full(b.x.shape, np.nan)
                                      for b in batches])
        return cls(np.concatenate([b.x for b in batches]), np.concatenate([b.y for b in batches]),
                   np.concatenate([b.task for b in batches]), normals, batches[0].step,
                   batches[0].source if source is None else source)


def thin_indices(points: np.ndarray, spacing: float, avoid: np.ndarray, margin: float) -> np.ndarray:
    """Indices of the greedy subset of ``points`` `(n, d)` that :func:`thin_points` keeps, in order: `(k,)` int64."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.size == 0:
        return np.empty(0, dtype=np.int64)
    candidates = np.arange(len(pts))
    avoid = np.asarray(avoid, dtype=np.float64).reshape(-1, pts.shape[1])
    if len(avoid):
        candidates = candidates[np.linalg.norm(pts[:, None] - avoid[None], axis=-1).min(axis=1) >= margin]
    kept = np.empty((len(candidates), pts.shape[1]))
    out: list[int] = []
    limit = spacing * (1.0 - 1e-9)
    for i in candidates:
        p = pts[i]
        if not out or bool((np.sqrt(((kept[:len(out)] - p) ** 2).sum(axis=1)) >= limit).all()):
            kept[len(out)] = p
            out.append(int(i))
    return np.asarray(out, dtype=np.int64)


def thin_points(points: np.ndarray, spacing: float, avoid: np.ndarray, margin: float) -> np.ndarray:
    """Greedy subset of ``points`` `(n, d)` with neighbours at least ``spacing`` apart (to rounding) and every point
    at least ``margin`` from each of ``avoid`` `(k, d)` [m]; the order of ``points`` is kept.

    Free space is kept away from contacts (docs/method-notes.md, section 2). Points exactly ``spacing`` apart are
    kept: the comparison allows a relative 1e-9 for rounding.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.size == 0:
        return pts.reshape(0, pts.shape[-1] if pts.ndim == 2 else 0)
    return pts[thin_indices(pts, spacing, avoid, margin)]


def free_space_along(a: np.ndarray, b: np.ndarray, spacing: float, include_end: bool = True) -> np.ndarray:
    """Samples every ``spacing`` [m] on the segment a -> b (and b itself if ``include_end``): `(k, d)`."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    length = float(np.linalg.norm(b - a))
    if length == 0:
        return a[None].copy()
    n = int(math.floor(length / spacing))
    s = np.arange(0, n + 1) * spacing
    if include_end and (len(s) == 0 or s[-1] < length - 1e-12):
        s = np.append(s, length)
    return a + np.outer(s / length, b - a)


#: An inside point is dropped when a surface observation lies closer than this fraction of its depth: its own contact
#: or seen point lies at the full depth, neighbours on a flat or convex surface further; closer ones mean a part
#: thinner than the depth (a mug's wall, a bunny's ear) or an inside corner.
INSIDE_CLEARANCE = 0.9


def drop_contradicted_inside(obs: Observations, policy: ObservationPolicy, x_known: np.ndarray | None = None,
                             y_known: np.ndarray | None = None) -> Observations:
    """``obs`` without the inside points (y < 0) that other observations contradict: a free-space observation
    (y = 1) closer than the point's depth (:meth:`ObservationPolicy.inside_depth`), or a surface observation
    (y = 0) closer than :data:`INSIDE_CLEARANCE` of it (the far side of a thin part), among ``obs`` itself and the
    known observations ``x_known`` `(m, d)`, ``y_known`` `(m,)` of either task.

    An inside point says the body is thicker than its depth there; a robot cannot measure that, so each is checked
    against what was seen and felt around it. With ``policy.inside_halvings``, a contradicted point whose own
    surface point is in ``obs`` (a contact, or a seen point, exactly its depth from it) is tried again at half the
    depth on the same line, up to that many times, as :func:`vision_observations` does; the first depth nothing
    contradicts replaces it (same row, its label that depth's)."""
    obs, keep = _checked(obs, policy, x_known, y_known)
    return obs if keep.all() else obs.subset(keep)


def _checked(obs: Observations, policy: ObservationPolicy, x_known, y_known) -> tuple[Observations, np.ndarray]:
    """``obs`` with its contradicted inside points moved halfway to their own surface point and relabelled where
    that depth is uncontradicted (up to ``policy.inside_halvings`` times), and `(n,)` bool which rows stand
    (:func:`drop_contradicted_inside`, :func:`inside_checked_by_step`)."""
    from scipy.spatial import cKDTree

    keep = uncontradicted(obs.x, obs.y, policy, x_known, y_known)
    if keep.all() or not policy.inside_halvings:
        return obs, keep
    x, y = obs.x.copy(), obs.y.copy()
    surface = np.flatnonzero(y == 0)
    todo = np.flatnonzero(~keep & (y < 0))
    if not len(surface) or not len(todo):
        return obs, keep
    depth = policy.inside_depth(y[todo])
    dist, j = cKDTree(x[surface]).query(x[todo])
    own = np.abs(dist - depth) <= 1e-6 * depth          # its own surface point, exactly its depth away
    todo, depth, origin = todo[own], depth[own], x[surface[j[own]]]
    others = np.ones(len(y), dtype=bool)
    others[todo] = False                                  # judged against the batch without the points being moved
    xk = x[others] if x_known is None else np.concatenate([x[others], np.asarray(x_known, dtype=np.float64)])
    yk = y[others] if y_known is None else np.concatenate([y[others], np.asarray(y_known, dtype=np.float64)])
    for _ in range(policy.inside_halvings):
        if not len(todo):
            break
        depth = depth / 2
        x[todo] = origin + (x[todo] - origin) / 2
        y[todo] = [policy.inside_label(d) for d in depth]
        ok = uncontradicted(x[todo], y[todo], policy, xk, yk)
        keep[todo[ok]] = True
        todo, depth, origin = todo[~ok], depth[~ok], origin[~ok]
    return dataclasses.replace(obs, x=x, y=y), keep


def uncontradicted(x: np.ndarray, y: np.ndarray, policy: ObservationPolicy, x_known: np.ndarray | None = None,
                   y_known: np.ndarray | None = None) -> np.ndarray:
    """`(n,)` bool: which of the observations `x` `(n, d)` [m], `y` `(n,)` :func:`drop_contradicted_inside` keeps
    (every one that is not an inside point, and each inside point no other observation contradicts)."""
    from scipy.spatial import cKDTree

    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    inside = y < 0
    keep = ~inside
    if not inside.any():
        return keep
    xs, ys = [x[~inside]], [y[~inside]]
    if x_known is not None and len(x_known):
        xs.append(np.asarray(x_known, dtype=np.float64))
        ys.append(np.asarray(y_known, dtype=np.float64))
    xa, ya = np.concatenate(xs), np.concatenate(ys)
    pts, depth = x[inside], policy.inside_depth(y[inside])
    ok = np.ones(len(pts), dtype=bool)
    for sel, limit in ((ya == 0, INSIDE_CLEARANCE * depth), (ya == 1, depth)):
        if sel.any():
            ok &= cKDTree(xa[sel]).query(pts)[0] >= limit * (1.0 - 1e-9)
    keep[np.flatnonzero(inside)[ok]] = True
    return keep


def uncontradicted_by_step(x: np.ndarray, y: np.ndarray, steps: np.ndarray, policy: ObservationPolicy,
                           x_other: np.ndarray, y_other: np.ndarray) -> np.ndarray:
    """`(n,)` bool: the inner observations `x` `(n, d)`, `y` `(n,)` kept once the inside points that other
    observations contradict are dropped, each judged as an exploration judged it when it was placed: against the
    observations `x_other` `(m, d)`, `y_other` `(m,)` known throughout (the camera's) and the inner ones of its
    ``steps`` `(n,)` and before. Logged files (a contacts CSV with steps, a bag) are labelled here; with
    ``policy.inside_halvings`` the points tried again at half the depth are :func:`inside_checked_by_step`'s."""
    return inside_checked_by_step(x, y, steps, policy, x_other, y_other)[2]


def inside_checked_by_step(x: np.ndarray, y: np.ndarray, steps: np.ndarray, policy: ObservationPolicy,
                           x_other: np.ndarray, y_other: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x, y, keep)``: the inner observations `x` `(n, d)`, `y` `(n,)` with each inside point judged as
    :func:`drop_contradicted_inside` judged it in the step it was placed (``steps`` `(n,)`: against that step's
    observations, the inner ones before it and the camera's `x_other` `(m, d)`, `y_other` `(m,)`), the points
    tried again at half the depth (``policy.inside_halvings``) moved and relabelled, and `(n,)` bool which rows are
    kept (:func:`uncontradicted_by_step`)."""
    x, y, steps = np.array(x, dtype=np.float64), np.array(y, dtype=np.float64), np.asarray(steps)
    keep = np.ones(len(y), dtype=bool)
    inside = y < 0
    for step in np.unique(steps[inside]):
        batch = np.flatnonzero(steps == step)
        earlier = ~inside & (steps < step)
        mine, keep[batch] = _checked(Observations(x[batch], y[batch], np.zeros(len(batch), np.int64)), policy,
                                     np.concatenate([x[earlier], x_other]), np.concatenate([y[earlier], y_other]))
        x[batch], y[batch] = mine.x, mine.y
    return x, y, keep


def retract_free_space(model, contact: np.ndarray, margin: float) -> np.ndarray:
    """Remove the inner free-space observations closer than ``margin`` [m] to a new ``contact``.

    Keeps the free-space margin at all times: free space recorded earlier (e.g. pressed along an edge not yet
    touched) is retracted once a contact lands within the margin of it.

    Returns:
        `(k,)` indices (into the observations before the call) that were removed.
    """
    free_in = model.train_targets.cpu().numpy() == 1
    if getattr(model, "num_tasks", 1) > 1:
        free_in &= (model.train_inputs[1].squeeze(-1) == 0).cpu().numpy()
    x = model.train_inputs[0].cpu().numpy()
    too_close = free_in & (np.linalg.norm(x - contact, axis=1) < margin)
    if too_close.any():
        model.remove_observations(torch.as_tensor(too_close))
    return np.flatnonzero(too_close)


#: The fewest contacts before the cover's gap is judged (:func:`retract_vision_inside`): the first touches can land
#: on a fold or where the camera saw nothing.
GAP_MIN_CONTACTS = 5


def cover_gap(contacts: np.ndarray, seen: np.ndarray, reach: float = 0.02, neighbours: int = 6) -> float:
    """How far the cover stands off the body, as the touches show it: the median over the contacts `(k, d)` of
    their distance to the seen cover `(m, d)` (both base frame [m]), along the normal of a plane through the
    ``neighbours`` nearest seen points; NaN with fewer than :data:`GAP_MIN_CONTACTS` contacts that count.

    A contact counts where it lies within ``reach`` [m] of that plane's patch along it (its foot point is no further
    than ``reach`` from the patch's mean): where the camera saw the cover above it. The plane, not the nearest point,
    because the camera's points are voxel-averaged (2-5 cm apart): the nearest one lies up to a voxel along the
    surface, which alone reads as 2-3 cm of gap on a tight cover (measured on the real shapes: 3 cm median on a
    bunny under 8 mm, against 0.8-1.6 cm along the plane, and 3.9-5.3 cm under a cover 4 cm off).

    An exploration asks this at every step with one contact more: :class:`CoverGap` gives the same value and
    computes each contact's plane once."""
    return CoverGap(neighbours)(contacts, seen, reach)


class CoverGap:
    """:func:`cover_gap` for a run's contacts, which only grow, against seen cover that changes only when the camera's
    data do: each contact's plane distance is computed once while the seen points stay the same (at 150 contacts
    and 1,500 seen points the whole computation took 2 ms a step, half of it the planes' SVDs; the same points
    again and again). The value equals :func:`cover_gap`'s exactly: each contact's distance depends on that contact
    and the seen points alone, and any change of the seen points, or contacts that are not the earlier ones plus
    new ones, starts over.

    Args:
        neighbours: the seen points each contact's plane goes through.
    """

    def __init__(self, neighbours: int = 6):
        self.neighbours = as_int(neighbours, "neighbours", 3)
        self._seen = self._tree = None
        self._contacts = self._gap = self._along = self._feet = None

    def __call__(self, contacts: np.ndarray, seen: np.ndarray, reach: float = 0.02) -> float:
        """The gap [m] (:func:`cover_gap`) of contacts `(k, d)` under seen cover `(m, d)`, base frame [m]."""
        _, counted = self.measured(contacts, seen, reach)
        return float(np.median(counted)) if len(counted) >= GAP_MIN_CONTACTS else math.nan

    def measured(self, contacts: np.ndarray, seen: np.ndarray, reach: float = 0.02) -> tuple[np.ndarray,
                                                                                              np.ndarray]:
        """Each counted contact's gap, where it was measured: `(j, d)` the contacts' feet on the seen cover's local
        planes [m] and `(j,)` their distances from those planes [m] (the contacts that count, as :func:`cover_gap`
        says; none with fewer than :data:`GAP_MIN_CONTACTS` contacts or 3 seen points)."""
        contacts, seen = np.asarray(contacts, dtype=np.float64), np.asarray(seen, dtype=np.float64)
        k = min(self.neighbours, len(seen))
        d = contacts.shape[-1] if contacts.ndim == 2 else seen.shape[-1]
        if len(contacts) < GAP_MIN_CONTACTS or k < 3:
            return np.zeros((0, d)), np.zeros(0)
        if self._seen is None or not np.array_equal(self._seen, seen):
            from scipy.spatial import cKDTree

            self._seen, self._tree, self._contacts = seen.copy(), cKDTree(seen), None
        done = 0 if self._contacts is None else len(self._contacts)
        if self._contacts is None or done > len(contacts) or not np.array_equal(self._contacts, contacts[:done]):
            done, self._contacts, self._gap, self._along = 0, contacts[:0].copy(), np.zeros(0), np.zeros(0)
            self._feet = contacts[:0].copy()
        new = contacts[done:]
        if len(new):
            _, idx = self._tree.query(new, k=k)
            patch = seen[idx]                                                   # (n, k, d)
            centre = patch.mean(axis=1)
            normal = np.linalg.svd(patch - centre[:, None])[2][:, -1]          # the plane's normal, (n, d)
            offset = new - centre
            height = (offset * normal).sum(axis=1)
            gap = np.abs(height)
            along = np.sqrt(np.maximum((offset ** 2).sum(axis=1) - gap ** 2, 0.0))
            self._contacts = np.concatenate([self._contacts, new])
            self._gap, self._along = np.concatenate([self._gap, gap]), np.concatenate([self._along, along])
            self._feet = np.concatenate([self._feet, new - height[:, None] * normal])
        counted = self._along <= reach
        return self._feet[counted], self._gap[counted]


def retract_vision_inside(model, contacts: np.ndarray, policy: ObservationPolicy,
                          gap: CoverGap | None = None) -> np.ndarray:
    """Remove the camera's inside points (outer task, y < 0) once the touches show a cover that stands off the body
    by more than ``policy.vision_inside_gap`` (:func:`cover_gap` of ``contacts`` `(k, d)` [m] and the model's seen
    points, outer task y = 0, with a reach of the camera's voxel or 2 cm; at least :data:`GAP_MIN_CONTACTS`
    contacts under seen cover). Once removed they are not added back.

    The camera's inside points are right about the cover (they lie inside it) but the model's transfer carries them
    onto the body: with a correlation near 1 the inner estimate copies the outer field, so behind a cover 4 cm off
    the body the estimate sits where the camera's points say "inside", in the gap (docs/results-real.md, the wide
    cover). Decided from the model's data and the contacts alone, so that a resumed run decides alike. ``gap``: the
    run's :class:`CoverGap`, which keeps each contact's distance from one step to the next (None: computed afresh).
    With ``policy.cover_offset`` the outer task's prior mean stands for the gap from then on as well
    (:func:`offset_outer_mean`); with ``vision_inside_deep`` too they are kept (and continued,
    :func:`deepen_vision_inside`), and with ``cover_even`` retracted, the continued ones with them, once the
    contacts' gaps spread wider than that share of their median (:func:`gap_spread`), unless ``cover_uneven_field``
    turns the one gap into a field of the gaps (:func:`_takes_field`), which keeps them.

    Returns:
        `(k,)` indices (into the observations before the call) that were removed; empty when kept.
    """
    none = np.zeros(0, dtype=np.int64)
    if policy.vision_inside_gap is None or getattr(model, "num_tasks", 1) < 2 or len(contacts) < GAP_MIN_CONTACTS:
        return none
    one_gap = policy.cover_offset and policy.vision_inside_deep
    if one_gap and not _judges_evenness(policy):              # kept, and deepened (deepen_vision_inside)
        return none
    y = model.train_targets.cpu().numpy()
    outer = (model.train_inputs[1].squeeze(-1) == OUTER).cpu().numpy()
    inside = outer & (y < 0)
    if not inside.any():
        return none
    if one_gap:                                               # kept while the gap is even; retracted once it is not
        if getattr(model, "outer_field", None) is not None:   # cover_uneven_field: a gap per place, kept
            return none
        gaps = _seen_gaps(model, y, outer, contacts, policy, gap)
        if _takes_field(model, y, outer, contacts, gaps, policy, gap) is not None:
            return none                                       # kept: offset_outer_mean takes the field
        if _field_pending(model, gaps, policy) or not _uneven(gaps, policy, offset_set=model.outer_mean != 1.0):
            return none
    else:
        seen_gap = _seen_gap(model, y, outer, contacts, policy, gap)
        if not seen_gap > policy.vision_inside_gap:         # NaN (too few contacts under seen cover) keeps them
            return none
    model.remove_observations(torch.as_tensor(inside))
    return np.flatnonzero(inside)


def _seen_gaps(model, y: np.ndarray, outer: np.ndarray, contacts: np.ndarray, policy: ObservationPolicy,
               gap: CoverGap | None) -> np.ndarray:
    """`(j,)` each counted contact's gap [m] under the model's seen points (outer task, ``y == 0``; ``y`` and
    ``outer`` the model's labels and outer-task mask), with a reach of the camera's voxel or 2 cm
    (:meth:`CoverGap.measured`; none with fewer than :data:`GAP_MIN_CONTACTS` contacts). ``gap``: the run's
    :class:`CoverGap`."""
    measure = gap if gap is not None else CoverGap()
    seen = model.train_inputs[0].cpu().numpy()[outer & (y == 0)]
    return measure.measured(contacts, seen, reach=max(0.02, policy.voxel or 0.0))[1]


def _seen_gap(model, y: np.ndarray, outer: np.ndarray, contacts: np.ndarray, policy: ObservationPolicy,
              gap: CoverGap | None) -> float:
    """The cover's gap [m] the ``contacts`` show under the model's seen points: the median of :func:`_seen_gaps`,
    NaN with fewer than :data:`GAP_MIN_CONTACTS` counted; what :func:`retract_vision_inside` and
    :func:`offset_outer_mean` decide by."""
    return _median_gap(_seen_gaps(model, y, outer, contacts, policy, gap))


def _median_gap(gaps: np.ndarray) -> float:
    """The median of the counted contacts' ``gaps`` `(j,)` [m], NaN with fewer than :data:`GAP_MIN_CONTACTS`."""
    return float(np.median(gaps)) if len(gaps) >= GAP_MIN_CONTACTS else math.nan


def gap_spread(gaps: np.ndarray) -> float:
    """How unevenly a cover stands off the body, as the contacts' gaps `(j,)` [m] show it: their interquartile range
    over their median (0: one gap everywhere; NaN with fewer than :data:`GAP_MIN_CONTACTS` gaps or a median of 0).

    Why this measure: a cover grown evenly off a body reads the same gap under every contact, up to the seen cover's
    local planes' error (on the benchmark's 4 cm covers 0.00-0.06 of the median on primitives, up to 0.5 on blobs,
    whose overhangs the planes measure worst); a cover that hangs, sags or drapes reads the gap of each place, and
    the quartiles, unlike the extremes, are not moved by one contact beside a seen edge (docs/method-notes.md
    section 27)."""
    gaps = np.asarray(gaps, dtype=np.float64)
    if len(gaps) < GAP_MIN_CONTACTS:
        return math.nan
    p25, med, p75 = np.percentile(gaps, [25, 50, 75])
    return float((p75 - p25) / med) if med > 0 else math.nan


def _judges_evenness(policy: ObservationPolicy) -> bool:
    """Whether the one gap is taken only while the contacts' gaps agree (``policy.cover_even``, one gap)."""
    return policy.cover_even is not None and policy.cover_offset and policy.vision_inside_deep \
        and not policy.cover_gap_field


def _uneven(gaps: np.ndarray, policy: ObservationPolicy, offset_set: bool) -> bool:
    """With ``policy.cover_even``: the contacts' ``gaps`` `(j,)` [m] show a cover standing off beyond
    ``policy.vision_inside_gap`` (or the outer mean stands for it already, ``offset_set``) and spread wider than
    ``cover_even`` of their median (:func:`gap_spread`); False with too few to judge."""
    if len(gaps) < GAP_MIN_CONTACTS:
        return False
    beyond = offset_set or float(np.median(gaps)) > policy.vision_inside_gap
    return beyond and gap_spread(gaps) > policy.cover_even


def _retracted(model, y: np.ndarray, outer: np.ndarray, policy: ObservationPolicy) -> bool:
    """Whether the camera's inside points were retracted (the policy places them and none is left): with
    ``cover_even``, the record that the contacts found the cover uneven, decided from the model's data alone."""
    return policy.vision_inside is not None and not (outer & (y < 0)).any()


#: The outer task's prior mean follows the touches' gap (:func:`offset_outer_mean`) once that moved by more than this
#: [m] since it was set: each change rebuilds the outer factorisation, and the gap, a median over the contacts, moves
#: by millimetres from step to step.
OFFSET_STEP = 0.005


def offset_outer_mean(model, contacts: np.ndarray, policy: ObservationPolicy, gap: CoverGap | None = None) -> bool:
    """With ``policy.cover_offset``, set the outer task's prior mean to ``1 - g / ramp`` once the touches show the
    cover standing off the body by ``g`` more than ``policy.vision_inside_gap`` (:func:`cover_gap` of ``contacts``
    `(k, d)` [m] and the model's seen points, as :func:`retract_vision_inside` measures it), and follow ``g`` when it
    moves by more than :data:`OFFSET_STEP` afterwards; with ``policy.cover_carry`` the mean followed is
    :func:`carried_mean` of ``1 - g / ramp`` under the last fit's K_t, from the step after it was first set.

    A cover ``g`` off the body everywhere is the body's field ``g / ramp`` label units higher (the labels rise from 0
    on a surface by one per ramp, :attr:`ObservationPolicy.ramp`); with the one prior mean of the paper, the learned
    task covariance carries that offset onto the inner estimate as well, which then sits in the gap (a correlation of
    1 copies the cover). The touches measure the gap; the outer mean takes it out of the transfer, and K_t relates
    the shapes. The camera's inside points are retracted at the same step (:func:`retract_vision_inside`): kept,
    they pin the outer field's ramp inside a cover that does not everywhere stand as far off as the median says,
    and on the real shapes' wide covers the estimate at a quarter of the travel was worse by 0.1-1.0 cm of Chamfer
    distance on 11 of 15 runs (docs/method-notes.md section 15). Decided from the model's data and the contacts
    alone, so that a resumed run decides alike.

    With ``policy.cover_even`` (and ``vision_inside_deep``, one gap) the mean is set only while the contacts' gaps
    spread no wider than that share of their median (:func:`gap_spread`), and goes back to 1 for the rest of the run
    once they do (:func:`retract_vision_inside` retracts the camera's inside points at the same step; a run whose
    camera inside points were retracted does not set it again); with ``policy.cover_uneven_field`` too, a gap set
    that way becomes the field of the contacts' gaps instead, where it passes the limit over a region, and is renewed
    as :func:`_offset_outer_field` renews it for the rest of the run (:func:`_takes_field`).

    Returns:
        Whether the mean changed (the caller re-learns K_t as every step does).
    """
    if (not policy.cover_offset or policy.vision_inside_gap is None or not hasattr(model, "set_outer_mean")
            or len(contacts) < GAP_MIN_CONTACTS):
        return False
    y = model.train_targets.cpu().numpy()
    outer = (model.train_inputs[1].squeeze(-1) == OUTER).cpu().numpy()
    if policy.cover_gap_field or getattr(model, "outer_field", None) is not None:   # (cover_uneven_field's)
        return _offset_outer_field(model, y, outer, contacts, policy, gap)
    gaps = _seen_gaps(model, y, outer, contacts, policy, gap)
    seen_gap = _median_gap(gaps)
    held = model.outer_mean != 1.0          # the mean stands for a gap (carried through K_t with cover_carry)
    if _judges_evenness(policy):
        if not held and _retracted(model, y, outer, policy):    # found uneven before: not set again
            return False
        field = _takes_field(model, y, outer, contacts, gaps, policy, gap)
        if field is not None:                                   # cover_uneven_field: for the rest of the run
            model.set_outer_mean(field)
            return True
        if _uneven(gaps, policy, offset_set=held):              # not one gap
            if not held or _field_pending(model, gaps, policy):        # (the field not yet judged: nothing changes)
                return False
            model.set_outer_mean(1.0)                           # the paper's one mean, for good
            return True
    if not math.isfinite(seen_gap) or (not held and not seen_gap > policy.vision_inside_gap):
        return False
    want = 1.0 - seen_gap / policy.ramp
    if policy.cover_carry and held:   # set before: K_t was learned at a gap's mean (first: at 1, whose r carries
        want = carried_mean(want, model.task_covariance)                  # the gap itself)
    if abs(want - model.outer_mean) * policy.ramp <= OFFSET_STEP:    # without the carry: the gap moved that far
        return False
    model.set_outer_mean(want)
    return True


#: The smallest transfer ``r = K_t[0,1] / K_t[1,1]`` :func:`carried_mean` divides by: a correction of at most one
#: label unit (the whole ramp). Below it the learned tasks hardly share a shape, and a mean moved further would stand
#: for a gap the touches did not measure.
CARRY_MIN_RATIO = 0.5


def carried_mean(base: float, task_covariance) -> float:
    """The outer task's prior mean that puts the inner estimate's zero level where ``base`` (``1 - g / ramp``, a
    cover ``g`` off the body) means it to lie, under the transfer the learned ``task_covariance`` `(2, 2)` makes.

    Where the touches are far, the inner posterior mean is ``1 + r (mu_out(x) - m_out)`` with ``r = K_t[0,1] /
    K_t[1,1]`` (exactly so without inner observations: the inner task's prediction is the outer residual carried
    across by the task covariance). At the body, ``g`` below the cover, the outer field reads ``-g / ramp``; the inner
    estimate is 0 there when ``m_out = 1 / r - g / ramp = base + (1 / r - 1)``. With ``r = 1`` that is ``base``; the
    marginal likelihood rarely gives 1 (0.5-0.95 under the benchmark's 4 cm covers), and with ``base`` alone the
    estimate sinks into the body away from the touches (docs/method-notes.md section 31).

    Args:
        base: the mean that stands for the gap, ``1 - g / ramp`` [label units].
        task_covariance: K_t, the last fit's.

    Returns:
        ``base + 1 / max(r, CARRY_MIN_RATIO) - 1``; ``base`` itself where ``r`` is not a positive number (a K_t not
        yet learned, or tasks that disagree in sign).
    """
    kt = np.asarray(task_covariance, dtype=np.float64)
    r = kt[0, 1] / kt[1, 1] if kt[1, 1] > 0 else math.nan
    if not (math.isfinite(r) and r > 0):
        return float(base)
    return float(base) + 1.0 / max(float(r), CARRY_MIN_RATIO) - 1.0


#: The gap field becomes the outer mean (:func:`offset_outer_mean` with ``cover_gap_field``) once it exceeds the
#: cover-gap limit at this share of the places the contacts measured it, and at least :data:`FIELD_PLACES` of them:
#: a region, not a contact or two beside a seen edge, where the local plane reads centimetres under a tight cover.
#: Chosen on objects 100-119 (the default runs' contacts, replayed): under tight covers the field's largest value
#: passed 3 cm on 10 of 38 runs, a quarter of the places on 4; under uneven covers on 33 and 30 of 38
#: (docs/method-notes.md section 18).
FIELD_SHARE = 0.25
#: ... the fewest places measured before the share is judged.
FIELD_PLACES = 8


def _offset_outer_field(model, y: np.ndarray, outer: np.ndarray, contacts: np.ndarray, policy: ObservationPolicy,
                        gap: CoverGap | None) -> bool:
    """:func:`offset_outer_mean` with ``policy.cover_gap_field``: the outer mean from a :class:`GapField` of the
    contacts' gaps, set once the field exceeds ``policy.vision_inside_gap`` at a share :data:`FIELD_SHARE` of the
    places the contacts measured it (at least :data:`FIELD_PLACES` of them), and renewed when it moves by more than
    :data:`OFFSET_STEP` at any seen point."""
    field, feet, seen = _gap_field(model, y, outer, contacts, policy, gap)
    if field is None:
        return False
    current = model.outer_field
    if current is None:
        if not _fires(field, feet, policy):
            return False
    else:
        if policy.cover_carry:      # set before: carried through the last fit's K_t (first: without, as one gap)
            field = field.carried(carried_mean(0.0, model.task_covariance))
        moved = float((field.gap(seen) - current.gap(seen)).abs().max())
        if max(moved, abs(field.carry - current.carry) * policy.ramp) <= OFFSET_STEP:
            return False
    model.set_outer_mean(field)
    return True


def _gap_field(model, y: np.ndarray, outer: np.ndarray, contacts: np.ndarray, policy: ObservationPolicy,
               gap: CoverGap | None):
    """The :class:`GapField` of the counted contacts' gaps (clipped to [0, ``INSIDE_DEPTH_MAX``]), their feet on
    the model's seen cover `(j, d)` and the seen points `(m, d)`; the field None with fewer than
    :data:`GAP_MIN_CONTACTS` gaps."""
    from ..models.gapfield import GapField

    measure = gap if gap is not None else CoverGap()
    seen = model.train_inputs[0].cpu().numpy()[outer & (y == 0)]
    feet, gaps = measure.measured(contacts, seen, reach=max(0.02, policy.voxel or 0.0))
    if len(gaps) < GAP_MIN_CONTACTS:
        return None, feet, seen
    return GapField.fit(feet, np.clip(gaps, 0.0, INSIDE_DEPTH_MAX), ramp=policy.ramp), feet, seen


def _fires(field, feet: np.ndarray, policy: ObservationPolicy) -> bool:
    """Whether ``field`` exceeds ``policy.vision_inside_gap`` at :data:`FIELD_SHARE` of the places ``feet`` `(j, d)`
    the contacts measured it, at least :data:`FIELD_PLACES` of them."""
    beyond = field.gap(feet).numpy() > policy.vision_inside_gap
    return len(beyond) >= FIELD_PLACES and bool(beyond.mean() >= FIELD_SHARE)


def _fields_a_cover(model, policy: ObservationPolicy) -> bool:
    """Whether ``policy.cover_uneven_field`` can act on ``model`` (one whose outer mean can be set). Its callers are
    reached only where a gap the touches stop agreeing on is given up (:func:`_judges_evenness`): with ``cover_even``
    off no gap ever is, and ``cover_gap_field`` takes its field whatever the spread, so there the setting does
    nothing."""
    return policy.cover_uneven_field and hasattr(model, "set_outer_mean")


def _field_pending(model, gaps: np.ndarray, policy: ObservationPolicy) -> bool:
    """With ``policy.cover_uneven_field`` and the one gap taken, whether the contacts' ``gaps`` `(j,)` are too few for
    the field to be judged (:data:`FIELD_PLACES`): the one gap the touches stop agreeing on is then kept until they
    are, not given up (it is taken from the fifth contact on)."""
    return (_fields_a_cover(model, policy) and getattr(model, "outer_mean", 1.0) != 1.0
            and len(gaps) < FIELD_PLACES)


def _takes_field(model, y: np.ndarray, outer: np.ndarray, contacts: np.ndarray, gaps: np.ndarray,
                 policy: ObservationPolicy, gap: CoverGap | None):
    """With ``policy.cover_uneven_field``, the gap field a cover takes in place of its one gap once the touches stop
    agreeing on it (None when it takes none): where the one gap was taken (the outer mean stands for it) and the
    contacts' ``gaps`` `(j,)` [m] now spread wider than ``cover_even`` (:func:`_uneven`), and their field
    (:func:`_gap_field`) exceeds the limit at a region of the places they measured it (:func:`_fires`, as
    ``cover_gap_field`` sets it first).

    Not where the touches disagree from their first judgement: there (a tight cover bridging a concavity, whose
    touches under the bridge read 2-4 cm; a sleeve sagging 1.5-4 cm off) a field carries the bridge's or the sag's gap
    over the parts around it, and in the loop 7 of 8 such tight blobs and 5 of 5 sleeve seeds came out worse, where
    the covers whose touches first agreed came out closer on 33 runs and worse on 16 (docs/method-notes.md section
    32)."""
    held = getattr(model, "outer_mean", 1.0) != 1.0
    if (not _fields_a_cover(model, policy) or not held or len(gaps) < FIELD_PLACES    # (too few: _fires refuses)
            or not _uneven(gaps, policy, offset_set=True)):
        return None
    field, feet, _ = _gap_field(model, y, outer, contacts, policy, gap)
    return field if field is not None and _fires(field, feet, policy) else None


def renew_deep_vision_inside(model, policy: ObservationPolicy) -> np.ndarray:
    """With ``policy.cover_gap_field``, or a model whose outer mean is a gap field (``cover_uneven_field``), remove
    the camera's inside points continued below the first
    (:func:`deepen_vision_inside` places them again from the renewed field at the same step): call it when
    :func:`offset_outer_mean` changed the field.

    Returns:
        `(k,)` indices (into the observations before the call) that were removed; empty when none.
    """
    none = np.zeros(0, dtype=np.int64)
    if (not (policy.cover_gap_field or getattr(model, "outer_field", None) is not None)
            or policy.vision_inside is None or getattr(model, "num_tasks", 1) < 2):
        return none
    y = model.train_targets.cpu().numpy()
    outer = (model.train_inputs[1].squeeze(-1) == OUTER).cpu().numpy()
    deep = outer & (y < policy.inside_label(policy.vision_inside) - 1e-9)
    if not deep.any():
        return none
    model.remove_observations(torch.as_tensor(deep))
    return np.flatnonzero(deep)


def deepen_vision_inside(model, contacts: np.ndarray, policy: ObservationPolicy,
                         gap: CoverGap | None = None) -> Observations | None:
    """With ``policy.vision_inside_deep`` (and ``cover_offset``), the camera's inside points continued down to the
    cover's gap, once the touches show it beyond ``policy.vision_inside_gap`` (as :func:`offset_outer_mean` measures
    it): behind each inside point, along the line from its nearest seen point, more every ``vision_inside`` down to
    ``g + vision_inside``, each labelled by its depth (:meth:`ObservationPolicy.inside_label`). A point is dropped
    where the camera's own observations contradict it (a seen point closer than :data:`INSIDE_CLEARANCE` of its
    depth, free space closer than its depth: :func:`uncontradicted`); the touches do not, since the outer task's
    inside reaches through the gap to the body. Added once (a model that holds a deeper camera point has them);
    decided from the model's data and the contacts alone, so that a resumed run decides alike.

    Why: the paper's labels give the outer field values only at and in front of the seen surface, so the level the
    offset mean reads a gap below the cover is the field's reversion to its prior, not the offset surface; with
    points down to the gap it is a signed distance there. Offline, on the final data of 40 runs under wide and uneven
    covers, this with the offset mean brought 33 closer (docs/method-notes.md section 16).

    Returns:
        The new outer observations (task 1, source "camera-deep"), or None when none is due.
    """
    if (not (policy.vision_inside_deep and policy.cover_offset) or policy.vision_inside is None
            or policy.vision_inside_gap is None or getattr(model, "num_tasks", 1) < 2
            or len(contacts) < GAP_MIN_CONTACTS):
        return None
    y = model.train_targets.cpu().numpy()
    outer = (model.train_inputs[1].squeeze(-1) == OUTER).cpu().numpy()
    first = policy.inside_label(policy.vision_inside)
    behind = outer & (y < 0)
    if not behind.any() or (y[behind] < first - 1e-9).any():      # none to continue, or continued already
        return None
    field = getattr(model, "outer_field", None)
    if policy.cover_gap_field or field is not None:                # (the latter: cover_uneven_field, taken)
        if field is None:                                          # not yet set (_offset_outer_field)
            return None
    else:
        field, seen_gap = None, _seen_gap(model, y, outer, contacts, policy, gap)
        if not seen_gap > policy.vision_inside_gap:
            return None
    from scipy.spatial import cKDTree

    x = model.train_inputs[0].cpu().numpy()
    seen = x[outer & (y == 0)]
    _, j = cKDTree(seen).query(x[behind])
    step = x[behind] - seen[j]            # the inward line (voxel averaging leaves it near, not at, vision_inside)
    length = np.linalg.norm(step, axis=1, keepdims=True)
    inward = step / np.maximum(length, 1e-12)
    vi = policy.vision_inside
    g = (field.gap(seen[j]).numpy() if field is not None else np.full(len(j), seen_gap))  # each point's gap [m]
    count = ((g + vi) // vi + 1e-9).astype(np.int64)               # depths vi * 2 .. vi * count
    depths = vi * np.arange(2, max(int(count.max()), 1) + 1)
    if not len(depths):
        return None
    reach = np.concatenate([count >= k for k in range(2, len(depths) + 2)])    # (len(depths) * n,)
    points = np.concatenate([seen[j] + inward * d for d in depths])[reach]
    labels = np.repeat([policy.inside_label(d) for d in depths], len(step))[reach]
    if not len(points):
        return None
    known = outer & (y >= 0)
    keep = uncontradicted(points, labels, policy, x[known], y[known])
    if not keep.any():
        return None
    return Observations(points[keep], labels[keep], np.ones(int(keep.sum()), np.int64), source="camera-deep")


def vision_observations(cloud, policy: ObservationPolicy, crop: np.ndarray | None = None) -> tuple[np.ndarray,
                                                                                                    np.ndarray]:
    """Outer-task observations from one capture: the seen surface (y = 0), free space in front of it (y = 1) and,
    with ``policy.vision_inside``, points behind it along the rays (y < 0, :meth:`ObservationPolicy.inside_label`).

    Args:
        cloud: a :class:`torch_gpioius.sensors.PointCloud` (its ``free_space(offset)`` knows the geometry of the
            view: along the rays to the camera, or outward in a 2-D view).
        policy: voxel size and free-space offset.
        crop: `(2, d)` box [min; max] to crop the cloud to, or None.

    Returns:
        ``x (n, d)`` [m] and ``y (n,)``.

    Raises:
        ValueError: nothing of the object is seen (inside the crop box).
    """
    if crop is not None:
        cloud = cloud.cropped(crop[0], crop[1])
    if len(cloud) == 0:
        raise ValueError("vision: the camera sees nothing of the object near the exploration range")
    smooth = cloud.smoothed_along_rays(policy.ray_smoothing) if policy.ray_smoothing else cloud
    if policy.voxel:          # each point averaged in the voxel its smoothed depth lies in (ray_smoothing's doc)
        seen = cloud.voxel_averaged(policy.voxel, at=smooth.points).points
    else:
        seen = smooth.points
    xs, ys = [seen], [np.zeros(len(seen))]
    if policy.vision_free_offset is not None and cloud.sees_free_space:
        free = cloud.free_space(policy.vision_free_offset)
        if policy.vision_free_far is not None:
            free = np.concatenate([free, cloud.free_space(policy.vision_free_far)])
        if policy.voxel and len(free):
            free = voxel_average(free, policy.voxel)
        if len(free):
            xs.append(free)
            ys.append(np.ones(len(free)))
    if policy.vision_inside is not None and cloud.sees_free_space:
        xs, ys = _with_inside(cloud, policy, np.concatenate(xs), np.concatenate(ys))
    return np.concatenate(xs), np.concatenate(ys)


def _with_inside(cloud, policy: ObservationPolicy, x: np.ndarray, y: np.ndarray) -> tuple[list, list]:
    """``[x, inside...]``, ``[y, labels...]``: the observations `x` `(n, d)`, `y` `(n,)` of one capture and its
    inside points ``policy.vision_inside`` behind the seen voxels that ``x`` does not contradict; where one is, again
    at half the depth behind the same voxel, up to ``policy.inside_halvings`` times, if it is a thin part
    (:func:`_thin_parts`). The lines behind the voxels are computed once
    (:meth:`~torch_gpioius.sensors.PointCloud.with_normals`); a view without them (None: the 2-D world's, which
    knows its outline and is sampled afresh at each depth) is :func:`_with_inside_resampled`."""
    lines = cloud.with_normals(policy.voxel)
    if lines is None:
        return _with_inside_resampled(cloud, policy, x, y)
    xs, ys = [x], [y]
    pts, nrm = lines
    todo = np.ones(len(pts), dtype=bool)
    depth = policy.vision_inside
    for k in range(policy.inside_halvings + 1):
        if k == 1:                                   # contradicted by a thin part, not a stray voxel
            todo &= _thin_parts(pts, nrm, policy.vision_inside)
        points = pts[todo] - depth * nrm[todo]
        labels = np.full(len(points), policy.inside_label(depth))
        keep = uncontradicted(points, labels, policy, x, y)
        xs.append(points[keep])
        ys.append(labels[keep])
        todo[np.flatnonzero(todo)[keep]] = False
        if not todo.any():
            break
        depth /= 2
    return xs, ys


def _with_inside_resampled(view, policy: ObservationPolicy, x: np.ndarray, y: np.ndarray) -> tuple[list, list]:
    """:func:`_with_inside` for a view whose ``behind`` samples each depth afresh (the 2-D world's): at each half
    depth, the points farther than the depth before from every point kept deeper."""
    from scipy.spatial import cKDTree

    xs, ys = [x], [y]
    depth = policy.vision_inside
    for k in range(policy.inside_halvings + 1):
        points = view.behind(depth, policy.voxel)
        kept = np.concatenate(xs[1:]) if k else np.zeros((0, x.shape[1]))
        if len(kept) and len(points):
            points = points[cKDTree(kept).query(points)[0] > 2 * depth]
        labels = np.full(len(points), policy.inside_label(depth))
        keep = uncontradicted(points, labels, policy, x, y)
        xs.append(points[keep])
        ys.append(labels[keep])
        depth /= 2
    return xs, ys


def _thin_parts(points: np.ndarray, normals: np.ndarray, depth: float) -> np.ndarray:
    """`(n,)` bool: which seen voxels' inside points ``depth`` deep (behind `points` `(n, d)` along their outward
    `normals` `(n, d)`) lie within :data:`INSIDE_CLEARANCE` of that depth of another voxel facing the other way
    (normals more than 120 degrees apart, :data:`THIN_FACING`): the far side of a part thinner than the depth, where
    half the depth can still lie inside. A voxel whose point is near only surfaces facing its own way is a stray (a
    voxel mean that depth noise at a grazing ray carried a centimetre out in front of the surface it belongs to,
    which then lies behind it): no shallower point would lie inside."""
    from scipy.spatial import cKDTree

    if not len(points):
        return np.zeros(0, dtype=bool)
    near = cKDTree(points).query_ball_point(points - depth * normals, INSIDE_CLEARANCE * depth)
    return np.array([bool(len(j)) and bool((normals[j] @ normals[i] < THIN_FACING).any())
                     for i, j in enumerate(near)])


#: The cosine between two voxels' normals below which they face opposite ways (:func:`_thin_parts`): 120 degrees, so
#: that a stray voxel beside a rounded edge (its plane fit sideways, the face's down) is not taken for a thin part.
THIN_FACING = -0.5

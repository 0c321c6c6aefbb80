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

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..voxels import voxel_average

__all__ = ["ObservationPolicy", "thin_points", "thin_indices", "free_space_along", "retract_free_space", "vision_observations"]


@dataclass(frozen=True)
class ObservationPolicy:
    """Which observations the exploration records (see docs/method-notes.md for the evidence).

    Attributes:
        vision_free_offset: distance in front of each seen outer point (along the camera ray, or outward in the 2-D
            view) of the camera's free-space point (y = 1, task outer) [m]; ``None`` disables them.
        voxel: edge of the voxels the camera's points are averaged in [m] (paper: 0.05); ``None`` keeps them all.
        crop_margin: the cloud is cropped to the exploration range grown by this [m] (what a real camera sees
            beyond, tables and walls, is not the object); ``None`` keeps everything.
        free_space_spacing: spacing of the free-space samples along the path the fingertip occupied with
            ``|F|`` below the contact threshold (y = 1, task inner) [m].
        free_space_margin: free-space samples closer than this to any contact are not recorded, and recorded ones
            are retracted when a later contact lands closer [m]; keeps the inner Gram block well conditioned.
    """

    vision_free_offset: float | None = 0.05
    voxel: float | None = None
    crop_margin: float | None = None
    free_space_spacing: float = 0.02
    free_space_margin: float = 0.02

    def __post_init__(self) -> None:
        for name in ("vision_free_offset", "voxel", "crop_margin"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not
                                  (math.isfinite(v) and v > 0)):
                raise ValueError(f"ObservationPolicy.{name}: must be a positive number [m] or None, got {v!r}")
        for name in ("free_space_spacing", "free_space_margin"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= 1.0):
                raise ValueError(f"ObservationPolicy.{name}: must be in (0, 1] m, got {v!r}")


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


def vision_observations(cloud, policy: ObservationPolicy, crop: np.ndarray | None = None) -> tuple[np.ndarray,
                                                                                                    np.ndarray]:
    """Outer-task observations from one capture: the seen surface (y = 0) and free space in front of it (y = 1).

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
    seen = cloud.voxel_averaged(policy.voxel).points if policy.voxel else cloud.points
    xs, ys = [seen], [np.zeros(len(seen))]
    if policy.vision_free_offset is not None and cloud.sees_free_space:
        free = cloud.free_space(policy.vision_free_offset)
        if policy.voxel and len(free):
            free = voxel_average(free, policy.voxel)
        if len(free):
            xs.append(free)
            ys.append(np.ones(len(free)))
    return np.concatenate(xs), np.concatenate(ys)

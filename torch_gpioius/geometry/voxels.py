"""Averaging points in cubic voxels (the paper's 5 cm Kinect averaging, Sec. VI-A), at once or cloud by cloud.

:func:`voxel_average` averages one set of points; :class:`VoxelAccumulator` gives the same averages over many clouds
while holding only one sum and one count per occupied voxel, so a recording of many camera frames is averaged
without keeping the frames (``import_bag`` reads a bag's clouds this way).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["voxel_average", "VoxelAccumulator", "VOXEL_RANGE"]

#: Accepted voxel edge lengths [m] (a finer or coarser grid is a unit mistake: 1e-300 overflowed the voxel indices
#: and collapsed every point into one; inf did the same).
VOXEL_RANGE = (1e-4, 10.0)


def _check_voxel(voxel) -> float:
    if isinstance(voxel, bool) or not isinstance(voxel, (int, float, np.floating)) or not (
            math.isfinite(voxel) and VOXEL_RANGE[0] <= voxel <= VOXEL_RANGE[1]):
        raise ValueError(f"voxel size must be a number in [{VOXEL_RANGE[0]:g}, {VOXEL_RANGE[1]:g}] m, got {voxel!r}")
    return float(voxel)


def _keys(points: np.ndarray, voxel: float) -> np.ndarray:
    scaled = np.floor(points / voxel)
    if np.abs(scaled).max() >= 2.0**62:
        raise ValueError(f"voxel size {voxel:g} m: voxel indices overflow for points up to {np.abs(points).max():g} m")
    return scaled.astype(np.int64)


def _placed(points: np.ndarray, at, where: str) -> np.ndarray:
    """The `(n, d)` positions that choose the voxels of ``points`` `(n, d)`: ``at`` where given (as float64), else
    the points themselves. Raises a ValueError naming ``where`` when ``at`` has another shape."""
    if at is None:
        return points
    at = np.asarray(at, dtype=np.float64)
    if at.shape != points.shape:
        raise ValueError(f"{where}: at must have the points' shape {points.shape}, got {at.shape}")
    return at


def _grouped(keys: np.ndarray, values: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique voxel keys (lexicographic), the summed values and counts of each."""
    uniq, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    sums = np.zeros((len(uniq), values.shape[1]))
    np.add.at(sums, inv, values)
    return uniq, sums, np.bincount(inv, weights=counts, minlength=len(uniq))


def voxel_average(points: np.ndarray, voxel: float, values: np.ndarray | None = None, at: np.ndarray | None = None):
    """Average the points in each occupied cubic voxel (the paper's 5 cm Kinect averaging).

    Args:
        points: `(n, d)` [m].
        voxel: edge length [m], in :data:`VOXEL_RANGE`; voxels are aligned to the origin of the frame.
        values: optional `(n, c)` values carried by the points (normals, say), averaged over the same voxels.
        at: optional `(n, d)` positions [m] that choose each point's voxel in its place (a noisy point's smoothed
            position, say); the means are still of ``points``.

    Returns:
        `(k, d)` one mean point per occupied voxel, in lexicographic voxel order; with ``values``, also their
        `(k, c)` means, as a pair.

    Raises:
        ValueError: a voxel size outside the range, or voxel indices that do not fit in int64.
    """
    voxel = _check_voxel(voxel)
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        return points if values is None else (points, np.asarray(values, dtype=np.float64).reshape(0, -1))
    at = _placed(points, at, "voxel_average")
    if values is None:
        _, sums, counts = _grouped(_keys(at, voxel), points, np.ones(len(points)))
        return sums / counts[:, None]
    values = np.asarray(values, dtype=np.float64).reshape(len(points), -1)
    _, sums, counts = _grouped(_keys(at, voxel), np.concatenate([points, values], axis=1), np.ones(len(points)))
    means = sums / counts[:, None]
    return means[:, :points.shape[1]], means[:, points.shape[1]:]


class VoxelAccumulator:
    """Voxel averages over points that arrive in batches (e.g. one camera frame at a time).

    After any sequence of :meth:`add`, :meth:`mean` equals :func:`voxel_average` of all the points added (to the
    rounding of a different summation order), while memory holds one key, sum and count per occupied voxel.

    Args:
        voxel: edge length [m], in :data:`VOXEL_RANGE`.
        dim: point dimension.
    """

    def __init__(self, voxel: float, dim: int = 3) -> None:
        self.voxel = _check_voxel(voxel)
        self._keys = np.zeros((0, dim), np.int64)
        self._sums = np.zeros((0, dim))
        self._counts = np.zeros(0)
        self.points_added = 0

    def add(self, points: np.ndarray, at: np.ndarray | None = None) -> None:
        """Add `(n, d)` points [m]; ``at`` `(n, d)` [m], where given, chooses each point's voxel in its place (as
        :func:`voxel_average`'s)."""
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != self._keys.shape[1]:
            raise ValueError(f"points: expected (n, {self._keys.shape[1]}), got shape {p.shape}")
        at = _placed(p, at, "VoxelAccumulator.add")
        if len(p) == 0:
            return
        k, s, c = _grouped(_keys(at, self.voxel), p, np.ones(len(p)))
        self._keys, self._sums, self._counts = _grouped(np.concatenate([self._keys, k]),
                                                        np.concatenate([self._sums, s]),
                                                        np.concatenate([self._counts, c]))
        self.points_added += len(p)

    def __len__(self) -> int:
        return len(self._keys)

    def mean(self) -> np.ndarray:
        """`(k, d)` one mean point per occupied voxel, in lexicographic voxel order."""
        return self._sums / self._counts[:, None] if len(self._counts) else self._sums.copy()

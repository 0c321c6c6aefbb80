"""Polylines: resampling by arc length, their segments, and exact point-to-segment distances (plain NumPy; the
metrics and the touched pieces of an estimate use them)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["resample_polyline", "segments", "distance_to_segments"]


def resample_polyline(curve: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points spaced uniformly by arc length along a polyline, with the length each point stands for.

    Args:
        curve: `(k, d)` polyline [m] (closed if its last vertex repeats the first).
        spacing: target spacing [m].

    Returns:
        `(p, d)` points and `(p,)` weights [m] (arc length per point; they sum to the curve length).
    """
    curve = np.asarray(curve, dtype=np.float64)
    seg = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    length = seg.sum()
    if len(curve) < 2 or length == 0:
        return curve[:1], np.zeros(1)
    n = max(1, int(np.ceil(length / spacing)))
    s = (np.arange(n) + 0.5) * (length / n)  # midpoints of n equal pieces
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    pts = np.stack([np.interp(s, cum, curve[:, k]) for k in range(curve.shape[1])], axis=-1)
    return pts, np.full(n, length / n)


def segments(polylines: Sequence[np.ndarray]) -> np.ndarray:
    """`(S, 2, d)` the segments of `(k, d)` polylines [m] (those of fewer than two vertices have none)."""
    segs = [np.stack([c[:-1], c[1:]], axis=1) for c in (np.asarray(c, dtype=np.float64) for c in polylines)
            if len(c) >= 2]
    return np.concatenate(segs) if segs else np.zeros((0, 2, 2))


def distance_to_segments(p: np.ndarray, segs: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """Exact Euclidean distance from each point `(P, d)` to the nearest segment `(S, 2, d)`."""
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    denom = np.maximum((ab * ab).sum(-1), 1e-300)
    out = np.empty(len(p))
    for i in range(0, len(p), chunk):
        q = p[i:i + chunk, None, :]
        t = np.clip(((q - a) * ab).sum(-1) / denom, 0.0, 1.0)
        d = np.linalg.norm(q - (a + t[..., None] * ab), axis=-1)
        out[i:i + chunk] = d.min(axis=1)
    return out

"""Boxes as the ecosystem writes them: ``(2, d)`` = [min corner; max corner], as trimesh's ``mesh.bounds``."""

from __future__ import annotations

import numpy as np

__all__ = ["as_bounds"]


def as_bounds(bounds, dim: int, name: str = "bounds") -> np.ndarray:
    """Validate a box given as `(2, d)` `[min corner; max corner]` [m] and return it as a float64 array.

    Raises:
        ValueError: wrong shape (a `(d, 2)` box of [min, max] rows is named as such), NaN/inf, or min >= max.
    """
    try:
        b = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a (2, {dim}) array [min corner; max corner] [m], got {bounds!r}") from None
    if b.shape != (2, dim):
        hint = (" (that is the [min, max]-per-axis layout: pass its transpose, e.g. mesh.bounds or "
                "np.asarray(b).T)") if b.shape == (dim, 2) else ""
        raise ValueError(f"{name}: expected shape (2, {dim}) = [min corner; max corner] like trimesh's mesh.bounds, "
                         f"got {b.shape}{hint}")
    if not np.isfinite(b).all():
        raise ValueError(f"{name}: contains NaN or inf")
    if not (b[1] > b[0]).all():
        hint = " (an [[min, max] per axis] box? transpose it)" if dim == 2 else ""
        raise ValueError(f"{name}: the max corner must exceed the min corner on every axis, got {b.tolist()}{hint}")
    return b

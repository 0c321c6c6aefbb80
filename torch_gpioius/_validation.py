"""Input checks shared by the models: every public entry point validates before it mutates state."""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = ["as_points", "as_labels", "as_tasks"]


def as_points(x, name: str = "x", dim: int | None = None, dtype: torch.dtype = torch.float64,
              device: torch.device | None = None, allow_empty: bool = False) -> Tensor:
    """Return ``x`` as an ``(n, d)`` floating tensor or raise ``ValueError`` naming the problem."""
    try:
        t = torch.as_tensor(x)
    except Exception as exc:  # pragma: no cover - exotic input types
        raise ValueError(f"{name}: cannot be converted to a tensor ({exc})") from None
    if t.dim() != 2:
        raise ValueError(f"{name}: expected a 2-D tensor of shape (n, d), got shape {tuple(t.shape)}")
    if t.shape[0] == 0 and not allow_empty:
        raise ValueError(f"{name}: empty data (0 points)")
    if t.shape[1] == 0:
        raise ValueError(f"{name}: points have dimension 0")
    if dim is not None and t.shape[1] != dim:
        raise ValueError(f"{name}: expected points of dimension {dim}, got dimension {t.shape[1]}")
    if t.is_complex() or t.dtype == torch.bool:
        raise ValueError(f"{name}: expected real coordinates, got dtype {t.dtype}")
    t = t.to(dtype=dtype, device=device)
    if not torch.isfinite(t).all():
        bad = (~torch.isfinite(t)).any(-1).nonzero().flatten()[:5].tolist()
        raise ValueError(f"{name}: contains NaN or inf coordinates (first bad rows: {bad})")
    return t


def as_labels(y, n: int, name: str = "y", dtype: torch.dtype = torch.float64,
              device: torch.device | None = None) -> Tensor:
    """Return surface labels as an ``(n,)`` float tensor with values in {0, 1}."""
    t = torch.as_tensor(y)
    if t.dim() != 1:
        raise ValueError(f"{name}: expected a 1-D tensor of labels, got shape {tuple(t.shape)}")
    if t.shape[0] != n:
        raise ValueError(f"{name}: length {t.shape[0]} does not match the {n} points")
    t = t.to(dtype=dtype, device=device)
    if not torch.isfinite(t).all():
        raise ValueError(f"{name}: contains NaN or inf labels")
    if not ((t == 0) | (t == 1)).all():
        bad = sorted(set(t[(t != 0) & (t != 1)].tolist()))[:5]
        raise ValueError(f"{name}: labels must be 0 (surface) or 1 (free space), got {bad}")
    return t


def as_tasks(task, n: int, name: str = "task", device: torch.device | None = None) -> Tensor:
    """Return task ids as an ``(n,)`` long tensor with values in {0 (inner), 1 (outer)}."""
    if isinstance(task, int):
        task = torch.full((n,), task)
    t = torch.as_tensor(task)
    if t.dim() != 1:
        raise ValueError(f"{name}: expected a 1-D tensor of task ids, got shape {tuple(t.shape)}")
    if t.shape[0] != n:
        raise ValueError(f"{name}: length {t.shape[0]} does not match the {n} points")
    if t.is_floating_point():
        if not torch.isfinite(t).all() or not (t == t.round()).all():
            raise ValueError(f"{name}: task ids must be integers 0 (inner) or 1 (outer)")
    if not ((t == 0) | (t == 1)).all():
        bad = sorted(set(t[(t != 0) & (t != 1)].tolist()))[:5]
        raise ValueError(f"{name}: task ids must be 0 (inner) or 1 (outer), got {bad}")
    return t.to(dtype=torch.long, device=device)

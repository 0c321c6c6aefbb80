r"""A tactile patch as observations: surface points with normals where the gel was pressed, free space where not.

The conversion (documented in docs/method-notes.md, "Tactile patches"), for a :class:`~torch_gpioius.sensors.
tactile.TactileReading` whose frames and sign conventions its module states:

* **surface points** (y = 0, task 0): the touched surface ``p_ij = (x_j, y_i, -depth_ij)`` of every pixel pressed at
  least ``contact_depth``, taken deepest first and thinned greedily to ``spacing``;
* **normals**: the object's outward normal from the depth map's gradient, ``n ∝ (-d depth/dx, -d depth/dy, -1)``
  in the pad frame (the object faces the sensor, -z), by central differences over contact pixels (one-sided at
  the contact's edge; NaN rows where a pixel has no contact neighbour along an axis);
* **free space** (y = 1, task 0): the undeformed gel surface (z = 0) at pixels pressed less than ``contact_depth``
  or not at all: the object did not reach it (to within ``contact_depth``). A gel senses only what presses it, so
  this is the only free space a pad can vouch for. Thinned to ``free_spacing`` and kept ``free_margin`` (2 cm) from
  every surface point (opposite labels closer than the kernel can bend between make the likelihood buy the jump
  with a huge signal variance; on a 2 x 2 cm pad this keeps free space only where the contact is off to one side).

All points are in the base frame (the reading's pose).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.moved import renamed
from .observations import Observations, thin_indices

__all__ = ["PatchThinning", "patch_observations", "DEPTH_RESOLUTION"]


__getattr__ = renamed(__name__, {"PatchSettings": (__name__, "PatchThinning", "settings are the estimator's")})

DEPTH_RESOLUTION = 1e-9
"""Depths closer than this [m] count as equal when ordering a patch's points (far below any gel's noise)."""


@dataclass(frozen=True)
class PatchThinning:
    """How densely a patch is recorded.

    Attributes:
        spacing: spacing of the kept surface points [m] (2 mm: ~100 points on a 2 x 2 cm pad).
        free_spacing: spacing of the kept free-space points [m].
        free_margin: free-space points closer than this to a surface point of the patch are dropped [m]. 2 cm, as the
            point touch's margin (docs/method-notes.md, sections 2 and 11): the gel vouches for free space right
            beside the contact, but labels 0 and 1 a few mm apart make the likelihood buy the jump with a huge
            K_t[0,0] (3 mm took K_t[0,0] to 1.7e6 and the correlation to 0.13 within 0.3 m on object E).

    Raises:
        ValueError: a value that is not a positive number of metres up to 0.1.
    """

    spacing: float = 0.002
    free_spacing: float = 0.004
    free_margin: float = 0.02

    def __post_init__(self) -> None:
        for name in ("spacing", "free_spacing", "free_margin"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= 0.1):
                raise ValueError(f"PatchThinning.{name}: must be in (0, 0.1] m, got {v!r}")


def _normals(depth: np.ndarray, contact: np.ndarray, pitch: float) -> np.ndarray:
    """`(H, W, 3)` pad-frame outward normals of the touched surface (NaN where undefined)."""
    z = np.where(contact, -depth, np.nan)

    def slope(axis: int) -> np.ndarray:
        fwd = np.full_like(z, np.nan)
        bwd = np.full_like(z, np.nan)
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        diff = (z[tuple(hi)] - z[tuple(lo)]) / pitch
        fwd[tuple(lo)] = diff                    # forward difference at i: z[i+1] - z[i]
        bwd[tuple(hi)] = diff                    # backward difference at i: z[i] - z[i-1]
        central = 0.5 * (fwd + bwd)
        return np.where(np.isfinite(central), central, np.where(np.isfinite(fwd), fwd, bwd))

    gx, gy = slope(1), slope(0)
    n = np.stack([gx, gy, -np.ones_like(gx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def patch_observations(reading, settings: PatchThinning | None = None, step: int = 0) -> Observations:
    """The observations of one tactile reading (see the module docstring).

    Args:
        reading: a :class:`~torch_gpioius.sensors.tactile.TactileReading` (checked on construction).
        settings: thinning (default :class:`PatchThinning`).
        step: the exploration step it arrives at.

    Returns:
        ``Observations`` with ``source="patch"``: surface points first (deepest first), then free space; normals
        for the surface points (NaN rows for free space and where undefined).

    Raises:
        ValueError: an all-NaN depth map (the gel reports no reading at all: a sensor fault or an unreadable frame,
            since the exploration reads the pad at a contact).
    """
    settings = settings or PatchThinning()
    depth = reading.depth
    if not np.isfinite(depth).any():
        raise ValueError("tactile reading: the depth map is all NaN (the gel reports nothing at all; at a contact "
                         "this is a sensor fault or an unreadable frame)")
    contact = reading.contact_mask
    pitch = reading.calibration.pitch
    pts = reading.pixel_points()
    normals = _normals(depth, contact, pitch)
    # The greedy thinning is a Python loop over candidates: a DIGIT frame has 76,800 pixels, so candidates are
    # first taken on a pixel grid of half the spacing (the greedy pass then enforces the spacing itself).
    grid = np.zeros_like(contact)
    stride = max(1, int(settings.spacing / (2 * pitch)))
    grid[::stride, ::stride] = True
    cand = contact & grid
    # Deepest first, with depths compared to DEPTH_RESOLUTION and ties in pixel order: a symmetric contact (a
    # sphere, a flat face) has many pixels of equal depth up to rounding, and ordering them by 1e-16 m would let
    # the greedy thinning keep different points for the same contact on two CPUs or after a resume.
    key = np.where(cand, np.rint(depth / DEPTH_RESOLUTION), -np.inf)
    order = np.argsort(-key, axis=None, kind="stable")[:int(cand.sum())]
    surf = pts.reshape(-1, 3)[order]
    surf_n = normals.reshape(-1, 3)[order]
    keep = thin_indices(surf, settings.spacing, np.zeros((0, 3)), 0.0)
    surf, surf_n = surf[keep], surf_n[keep]
    grid[:] = False
    stride = max(1, int(settings.free_spacing / (2 * pitch)))
    grid[::stride, ::stride] = True
    free_px = pts[~contact & grid].copy()
    free_px[:, 2] = 0.0                                    # the undeformed gel surface
    free = free_px[thin_indices(free_px, settings.free_spacing, surf, settings.free_margin)]
    x = reading.to_base(np.concatenate([surf, free]))
    nrm = np.concatenate([reading.to_base(surf_n, directions=True), np.full((len(free), 3), np.nan)])
    y = np.r_[np.zeros(len(surf)), np.ones(len(free))]
    return Observations(x, y, np.zeros(len(x), np.int64), normal=nrm, step=step, source="patch")

r"""A simulated gel pad (DIGIT-like) for the 3-D worlds: depth maps by ray casting against the body, with the cloth.

Where the fingertip rests in contact, the pad faces the measured contact normal (its outward axis along minus the
normal: a compliant wrist or the planner's orientation would hold it so; orientation control is not simulated).
For each pixel a ray runs along the pad's axis from behind the gel, and the body's first crossing ``s`` (relative
to the pad plane) is found by sphere tracing on the body's exact signed distance. Then:

* **the gel is pressed** where the body comes within the cloth's thickness ``t`` of the pad: the cloth is pinched
  between gel and body, so the pixel reads the body **plus the cloth** (indentation ``t - s``). A gel cannot see
  through fabric: the surface it reports there is ``t`` proud of the body;
* **elsewhere** nothing presses the gel (NaN): the cover beyond the contact is not pressed by the pad (in the
  force-field world the fingertip has passed through the cover's field; cloth lying lightly on the gel is below
  the contact depth);
* **how deep**: the pad is placed so that its deepest pixel is pressed by ``|F| / gel_stiffness`` (clamped to
  [2 x contact depth, 80 % of the gel]): the gel takes the contact force, the fingertip's position and the force
  stay what the force sensor and the safety gate see.

**With a simulated cover** (the MuJoCo world: ``cover`` gives the first crossing of the cloth along each ray, from
the cloth's current state), the cloth is where the simulation put it instead of everywhere:

* where the body, at the pixel where it comes nearest the pad, is bare or lies within ``pinch`` behind the cover's
  face (the simulated cloth's pinched layer, as the world's own contact check counts it), the pad presses the cloth onto
  the body: a pixel reads the body plus the cloth where the cloth is between pad and body along its ray, and the bare
  body where the cloth has slid away (a flat pad flattens the fabric it presses; the simulated fingertip is a small
  sphere, so the cloth's shape around it is not what a pad would leave);
* otherwise the cover alone carries the force (a cloth stretched like a trampoline, a fold, foam thicker than the
  gel): the pad reads the cover's surface, which is what a gel would report; the exploration then learns the cover
  as the inner surface there, as a real pad would make it.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..tactile import TactileCalibration, TactileReading

__all__ = ["SimulatedGelPad", "SIM_PAD_CALIBRATION", "pad_pose"]

#: A DIGIT-like pad at simulation resolution: 40 x 40 px of 0.5 mm (2 x 2 cm), 3 mm of gel, contact at 0.1 mm.
SIM_PAD_CALIBRATION = TactileCalibration(pitch=5e-4, gel_thickness=3e-3, contact_depth=1e-4)


def pad_pose(origin: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """`(4, 4)` pad-to-base transform with its origin at ``origin`` and its z axis along ``axis`` (unit)."""
    z = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    pose[:3, 3] = origin
    return pose


class SimulatedGelPad:
    """A gel pad in a simulated world (see the module docstring).

    Args:
        body_distance: ``(n, 3) -> (n,)`` exact signed distance to the body [m] (negative inside).
        position: ``() -> (3,)`` the fingertip's position [m], base frame.
        force: ``() -> (3,)`` the contact force on the fingertip [N], base frame (points out of the object).
        calibration: the pad's calibration.
        shape: pixels `(H, W)`.
        cloth_thickness: thickness of the cover's fabric pinched under the pad [m] (0: no cover).
        gel_stiffness: force per metre of the deepest indentation [N/m].
        clock: ``() -> float`` the world's time [s].
        cover: ``(origins (n, 3), axis (3,), far) -> (n,)`` distance along ``axis`` from each origin to the cover's
            outer face [m] (inf where the ray meets no cover within ``far``), or None: the cloth is everywhere
            between pad and body (the force-field world, whose cover is a field, not a sheet).
        pinch: with ``cover``: how far in front of the body the cover's face may lie and still be pressed onto it
            [m] (default ``cloth_thickness`` + 1 mm; a simulated cloth's pinched layer is its collision thickness).
    """

    def __init__(self, body_distance: Callable, position: Callable, force: Callable,
                 calibration: TactileCalibration = SIM_PAD_CALIBRATION, shape: tuple[int, int] = (40, 40),
                 cloth_thickness: float = 5e-4, gel_stiffness: float = 2000.0, clock: Callable = lambda: 0.0,
                 cover: Callable | None = None, pinch: float | None = None):
        if not 0 <= cloth_thickness < calibration.gel_thickness:
            raise ValueError(f"cloth_thickness: must be in [0, gel thickness {calibration.gel_thickness:g}) m, got "
                             f"{cloth_thickness!r}")
        if not gel_stiffness > 0:
            raise ValueError(f"gel_stiffness: must be > 0 N/m, got {gel_stiffness!r}")
        self.body_distance, self.position, self.force = body_distance, position, force
        self.calibration, self.shape = calibration, tuple(int(v) for v in shape)
        self.cloth_thickness, self.gel_stiffness, self.clock = float(cloth_thickness), float(gel_stiffness), clock
        self.cover = cover
        self.pinch = self.cloth_thickness + 1e-3 if pinch is None else float(pinch)
        if not self.pinch >= 0:
            raise ValueError(f"pinch: must be >= 0 m, got {pinch!r}")

    def _origins(self, pose: np.ndarray, reach: float) -> np.ndarray:
        """`(H W, 3)` ray origins: the pixels ``reach`` behind the pad plane, base frame."""
        h, w = self.shape
        pitch = self.calibration.pitch
        jj, ii = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        plane = np.stack([(jj - (w - 1) / 2) * pitch, (ii - (h - 1) / 2) * pitch, np.full_like(jj, -reach)], -1)
        return plane.reshape(-1, 3) @ pose[:3, :3].T + pose[:3, 3]

    def _crossings(self, pose: np.ndarray, reach: float, far: float) -> np.ndarray:
        """`(H, W)` signed position ``s`` along the pad's axis where each pixel's ray enters the body (inf where it
        does not before ``far``); rays start ``reach`` behind the pad plane."""
        h, w = self.shape
        origin = self._origins(pose, 0.0)
        axis = pose[:3, 2]
        s = np.full(len(origin), -reach)
        done = np.zeros(len(origin), bool)
        for _ in range(64):                                  # sphere tracing: never steps past the surface
            live = ~done
            if not live.any():
                break
            d = np.asarray(self.body_distance(origin[live] + s[live, None] * axis), dtype=np.float64)
            hit = d < 1e-7
            idx = np.flatnonzero(live)
            done[idx[hit]] = True
            s[idx[~hit]] += d[~hit]
            gone = s > far
            s[gone & ~done] = np.inf
            done |= gone
        s[~done] = np.inf
        return s.reshape(h, w)

    def read(self) -> TactileReading:
        """The pad's depth map where the fingertip is now.

        Raises:
            RuntimeError: no contact force to face (below 0.5 N): the pad is read only in contact.
        """
        cal, t = self.calibration, self.cloth_thickness
        c = np.asarray(self.position(), dtype=np.float64).reshape(3)
        f = np.asarray(self.force(), dtype=np.float64).reshape(3)
        mag = float(np.linalg.norm(f))
        if not mag >= 0.5:
            raise RuntimeError(f"tactile pad: read out of contact (|F| = {mag:.2f} N)")
        axis = -f / mag                                      # into the object
        reach = cal.gel_thickness
        pose0 = pad_pose(c, axis)
        s = self._crossings(pose0, 4 * reach, 4 * reach)
        press = float(np.clip(mag / self.gel_stiffness, 2 * cal.contact_depth, 0.8 * reach))
        if self.cover is None:
            surface = s - t                                  # the body plus the cloth, everywhere
        else:
            rays = np.asarray(self.cover(self._origins(pose0, 4 * reach), axis, 8 * reach), dtype=np.float64)
            cloth = rays.reshape(s.shape) - 4 * reach        # the cover's face, on the same axis as s
            at = np.unravel_index(np.argmin(s), s.shape)     # where the body comes nearest the pad
            on_body = bool(np.isfinite(s[at])) and (cloth[at] > s[at] or s[at] - cloth[at] <= self.pinch)
            surface = np.where(cloth <= s, s - t, s) if on_body else cloth
        deepest = float(np.min(surface))
        if not np.isfinite(deepest):
            raise RuntimeError("tactile pad: nothing lies under the pad at the contact")
        # move the pad along its axis so that the deepest pixel is pressed by ``press``
        shift = deepest + press
        pose = pad_pose(c + shift * axis, axis)
        depth = np.where(surface < shift, shift - surface, np.nan)
        depth = np.minimum(depth, reach)                     # the gel bottoms out
        return TactileReading(depth, pose, cal, float(self.clock()))

"""A simulated fingertip force sensor for the simulated worlds.

Contact is a force field (a spring law, the penalty method of contact mechanics): pressing ``delta`` metres into the
inner (rigid-ish) object pushes back with ``k_inner · delta`` along its outward normal; the soft cover adds ``k_cover ·
depth`` along the cover's outward normal, small enough that the cover alone stays below the 1 N contact threshold over
centimetres.
"""

from __future__ import annotations

from typing import Callable, Mapping, Protocol

import numpy as np
import torch

from ..base import ChecksumStorm, ForceReading, ForceSensor, SensorDisconnected, SensorTimeout

__all__ = ["SignedDistance", "SphereSDF", "ForceFieldContact", "SimulatedForceSensor", "FAULTS"]

#: Fault names :class:`SimulatedForceSensor` can inject at chosen reads.
FAULTS = ("stale", "timeout", "overload", "spike", "checksum", "disconnect")


class SignedDistance(Protocol):
    """``sdf(points (m, 3)) -> (distance (m,), outward unit normal (m, 3))``; distance < 0 inside [m]."""

    def __call__(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]: ...


class SphereSDF:
    """Analytic sphere: ``|p - c| - r`` with normal ``(p - c)/|p - c|``."""

    def __init__(self, center: torch.Tensor, radius: float) -> None:
        self.center = torch.as_tensor(center, dtype=torch.float64)
        self.radius = float(radius)

    def __call__(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        v = torch.as_tensor(points, dtype=torch.float64) - self.center
        r = v.norm(dim=-1).clamp_min(1e-12)
        return r - self.radius, v / r[..., None]


class ForceFieldContact:
    """Force on a point fingertip from an inner object under a soft cover.

    Args:
        inner: signed distance of the inner object.
        outer: signed distance of the cover's outer surface (None: no cover).
        k_inner: stiffness of the inner object [N/m] (1000 N/m: 1 N at 1 mm, 5 N at 5 mm).
        k_cover: stiffness of the cover [N/m] (10 N/m: 0.1 N per cm of cover).
        inner_bounds: optional `(2, 3)` axis-aligned box [m] holding the inner surface: a fingertip outside it is
            outside that surface, so its spring pushes with exactly zero force and its signed distance is not
            evaluated (a mesh's distance is a tree search; most of an approach is in free space).
        outer_bounds: the same for the cover's outer surface.
    """

    def __init__(self, inner: SignedDistance, outer: SignedDistance | None = None, *, k_inner: float = 1000.0,
                 k_cover: float = 10.0, inner_bounds=None, outer_bounds=None) -> None:
        self.inner, self.outer = inner, outer
        self.k_inner, self.k_cover = float(k_inner), float(k_cover)
        self._boxes = [_box(inner_bounds, "inner_bounds"), _box(outer_bounds, "outer_bounds")]

    def _spring(self, sdf: SignedDistance, box: np.ndarray | None, k: float, p: torch.Tensor) -> torch.Tensor | None:
        if box is not None:
            x = p[0].detach().cpu().numpy()
            if (x < box[0]).any() or (x > box[1]).any():
                return None
        d, n = sdf(p)
        return k * torch.clamp(-d[0], min=0.0) * n[0]

    def __call__(self, p: torch.Tensor) -> torch.Tensor:
        """`(3,)` force on the fingertip at `(3,)` position ``p``, base frame [N]."""
        p = torch.as_tensor(p, dtype=torch.float64).reshape(1, 3)
        f = torch.zeros(3, dtype=torch.float64)
        for sdf, box, k in ((self.inner, self._boxes[0], self.k_inner), (self.outer, self._boxes[1], self.k_cover)):
            if sdf is not None:
                push = self._spring(sdf, box, k, p)
                if push is not None:
                    f = f + push
        return f


def _box(bounds, name: str) -> np.ndarray | None:
    if bounds is None:
        return None
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (2, 3) or not np.isfinite(b).all() or (b[0] > b[1]).any():
        raise ValueError(f"{name}: expected a finite (2, 3) box [lower; upper] [m], got {bounds!r}")
    return b


class SimulatedForceSensor(ForceSensor):
    """A simulated 3-axis sensor at the fingertip, reading the contact model at the robot's pose.

    Args:
        contact: maps the fingertip position `(3,)` [m, base] to the force `(3,)` [N, base].
        pose: returns the current ``T_base_tool`` `(4, 4)`; the sensor frame is the tool frame.
        clock: returns the current time [s] (e.g. the simulated robot's clock); default: 1 ms per read.
        noise_std: white noise per axis [N].
        drift: `(3,)` offset growth [N/s] until :meth:`tare`.
        dropout: probability that a read returns the previous sample unchanged (a stale reading).
        faults: read index (0-based) -> fault name in :data:`FAULTS`, injected at that read
            (``"disconnect"`` persists).
        seed: random seed of noise and dropouts.
    """

    def __init__(self, contact: Callable[[torch.Tensor], torch.Tensor], pose: Callable[[], torch.Tensor], *,
                 clock: Callable[[], float] | None = None, noise_std: float = 0.0,
                 drift: tuple[float, float, float] = (0.0, 0.0, 0.0), dropout: float = 0.0,
                 faults: Mapping[int, str] | None = None, seed: int = 0) -> None:
        for k, v in (faults or {}).items():
            if v not in FAULTS:
                raise ValueError(f"unknown fault {v!r} at read {k}; choose from {FAULTS}")
        if not 0.0 <= dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {dropout}")
        self.contact, self.pose = contact, pose
        self._reads = 0
        self.clock = clock if clock is not None else (lambda: self._reads * 1e-3)
        self.noise_std, self.dropout = float(noise_std), float(dropout)
        self.drift = torch.as_tensor(drift, dtype=torch.float64)
        self.faults = dict(faults or {})
        self._gen = torch.Generator().manual_seed(seed)
        self._offset_t0 = 0.0
        self._counter = 0
        self._last: ForceReading | None = None
        self._last_status = 0
        self._disconnected = False

    def true_force_base(self) -> torch.Tensor:
        """`(3,)` noise-free force at the current pose, base frame [N]."""
        return self.contact(self.pose()[:3, 3])

    def read(self) -> ForceReading:
        i = self._reads
        self._reads += 1
        fault = self.faults.get(i)
        if self._disconnected or fault == "disconnect":
            self._disconnected = True
            raise SensorDisconnected("simulated sensor disconnected")
        if fault == "timeout":
            raise SensorTimeout("simulated sensor: no frame within the timeout")
        if fault == "checksum":
            raise ChecksumStorm("simulated sensor: consecutive frames with bad checksums")
        stale = fault == "stale" or (self.dropout > 0 and float(torch.rand((), generator=self._gen)) < self.dropout)
        if stale and self._last is not None:
            return self._last
        T = self.pose()
        f_base = self.contact(T[:3, 3])
        f = T[:3, :3].T @ f_base  # into the sensor (= tool) frame
        t = float(self.clock())
        f = f + self.drift * (t - self._offset_t0)
        if self.noise_std > 0:
            f = f + self.noise_std * torch.randn(3, generator=self._gen, dtype=torch.float64)
        status = 0
        if fault == "overload":
            status |= 1 << 7  # Fz overload flag
        if fault == "spike":
            f = f + torch.tensor([0.0, 0.0, 60.0], dtype=torch.float64)
        self._counter = (self._counter + 1) & 0xFFFF
        # A reading's timestamp must move even when the simulated clock has not (two reads, no motion).
        t = max(t, self._last.timestamp + 1e-6) if self._last is not None else t
        reading = ForceReading(f, status, self._counter, t)
        self._last, self._last_status = reading, status
        return reading

    def tare(self) -> None:
        """Reset the drift (the simulated offset) to zero."""
        self._offset_t0 = float(self.clock())

    def get_state(self) -> dict:
        """Numeric state (noise generator, counters, last sample) for logs: :meth:`set_state` resumes from it."""
        last = self._last
        return {"rng": self._gen.get_state().numpy().copy(),
                "counters": np.array([self._reads, self._counter, int(self._disconnected)], dtype=np.int64),
                "offset_t0": np.array([self._offset_t0]),
                "last": (np.r_[last.force.numpy(), last.status, last.counter, last.timestamp] if last is not None
                         else np.zeros(0))}

    def set_state(self, state: dict) -> None:
        """Restore a state from :meth:`get_state`."""
        self._gen.set_state(torch.as_tensor(np.asarray(state["rng"], dtype=np.uint8)))
        self._reads, self._counter, disc = (int(v) for v in np.asarray(state["counters"]))
        self._disconnected = bool(disc)
        self._offset_t0 = float(np.asarray(state["offset_t0"]).reshape(-1)[0])
        last = np.asarray(state["last"], dtype=np.float64)
        self._last = (ForceReading(torch.as_tensor(last[:3]), int(last[3]), int(last[4]), float(last[5]))
                      if last.size else None)
        self._last_status = self._last.status if self._last is not None else 0

    def __repr__(self) -> str:
        return f"SimulatedForceSensor(noise_std={self.noise_std}, dropout={self.dropout}, faults={self.faults})"

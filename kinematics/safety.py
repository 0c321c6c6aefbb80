"""The one safety gate every robot command passes.

A command that violates a limit is *refused* with :class:`SafetyViolation` naming the limit, the value and
the bound; the gate never clips a command into a different motion. Limits: joint position limits (with a
margin), joint speed, a workspace box for the fingertip along the whole joint-space path, the largest joint
move and the largest Cartesian step.

Every limit is validated where it is set (docs/robot.md; as a UR controller refuses an invalid safety
configuration): a NaN, an infinity, a negative value or a value beyond what the hardware allows raises
``ValueError`` at construction *and* on later assignment (``gate.max_joint_speed = nan`` is refused too), so no
setting can switch a check off.
"""

from __future__ import annotations

import math
from typing import Sequence

import torch

from .dh import UR5_DH
from .ur5 import UR5

__all__ = ["SafetyGate", "SafetyViolation", "LIMIT_RANGES"]

#: Accepted range (exclusive low, inclusive high) of each scalar limit; the highs are what the hardware or a
#: meaningful check allows (UR5 CB3: tool speed up to 1 m/s; joints turn +-2 pi, so no single move exceeds 2 pi).
LIMIT_RANGES: dict[str, tuple[float, float, str]] = {
    "max_tool_speed": (0.0, 1.0, "m/s"),
    "max_cartesian_step": (0.0, 0.1, "m"),
    "max_joint_step": (0.0, math.pi, "rad"),
    "max_joint_move": (0.0, 2 * math.pi, "rad"),
    "joint_margin": (0.0, 0.5, "rad"),
    "path_resolution": (0.0, 0.05, "rad"),
}


class SafetyViolation(RuntimeError):
    """A robot command was refused because it would break a safety limit; nothing was sent."""


def _check_limit(name: str, value) -> float:
    lo, hi, unit = LIMIT_RANGES[name]
    if isinstance(value, (bool, str)) or value is None:
        raise ValueError(f"{name}: expected a number [{unit}], got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number [{unit}], got {value!r}") from None
    if not (math.isfinite(v) and lo < v <= hi):
        raise ValueError(f"{name}: must be finite and in ({lo:g}, {hi:g}] {unit}, got {value!r}; an invalid limit "
                         "would disable its check")
    return v


class _Limit:
    """A scalar limit validated on every assignment (a data descriptor)."""

    def __set_name__(self, owner, name: str) -> None:
        self.name, self.attr = name, "_" + name

    def __get__(self, obj, owner=None):
        return self if obj is None else getattr(obj, self.attr)

    def __set__(self, obj, value) -> None:
        setattr(obj, self.attr, _check_limit(self.name, value))


def _chord_radius(ur5: UR5) -> float:
    """An upper bound R [m] on the distance from any joint axis to the fingertip, from the DH table and tool.

    For a revolute chain, ``|d^2 p / ds^2| <= R (sum_j |dq_j|)^2`` along ``q(s) = q0 + s dq``: every second
    derivative of the fingertip position is a double cross product of unit axes with a lever arm of at most R.
    """
    return sum(abs(r.a) + abs(r.d) for r in UR5_DH) + float(ur5.tool_offset.norm())


class SafetyGate:
    """Checks robot commands against fixed limits before they are sent.

    Args:
        ur5: kinematic model used to map joint paths to fingertip positions.
        workspace_lower: `(3,)` lower corner of the allowed fingertip box in the base frame [m].
        workspace_upper: `(3,)` upper corner of that box [m].
        max_joint_speed: joint speed limit [rad/s] (scalar or `(6,)`), in (0, the UR5's 180 deg/s]; default a
            quarter of that, a conservative speed for contact work.
        max_tool_speed: fingertip speed limit for Cartesian steps [m/s], in (0, 1].
        max_cartesian_step: largest fingertip displacement of one Cartesian step [m], in (0, 0.1].
        max_joint_step: largest joint change of one Cartesian step [rad], in (0, pi].
        max_joint_move: largest joint change of one joint-space move [rad], in (0, 2 pi].
        joint_margin: distance kept from the joint position limits [rad], in (0, 0.5].
        path_resolution: joint-space spacing [rad] at which the fingertip path is sampled against the box, in
            (0, 0.05]. Between samples the path is covered rigorously: each sample is checked against the box
            shrunk by the largest distance the path can stray from its chord (``R |dq|_1^2 / 8``).

    Raises:
        ValueError: any limit that is not finite, not positive or beyond what the hardware allows.
    """

    max_tool_speed = _Limit()
    max_cartesian_step = _Limit()
    max_joint_step = _Limit()
    max_joint_move = _Limit()
    joint_margin = _Limit()
    path_resolution = _Limit()

    def __init__(
        self,
        ur5: UR5,
        workspace_lower: Sequence[float] = (-0.85, -0.85, -0.05),
        workspace_upper: Sequence[float] = (0.85, 0.85, 1.0),
        *,
        max_joint_speed: float | Sequence[float] | None = None,
        max_tool_speed: float = 0.25,
        max_cartesian_step: float = 0.02,
        max_joint_step: float = 0.2,
        max_joint_move: float = math.pi,
        joint_margin: float = 1e-3,
        path_resolution: float = 0.01,
    ) -> None:
        self.ur5 = ur5
        self.set_workspace(workspace_lower, workspace_upper)
        self.max_joint_speed = ur5.max_velocity / 4 if max_joint_speed is None else max_joint_speed
        self.max_tool_speed = max_tool_speed
        self.max_cartesian_step = max_cartesian_step
        self.max_joint_step = max_joint_step
        self.max_joint_move = max_joint_move
        self.joint_margin = joint_margin
        self.path_resolution = path_resolution
        self._chord = _chord_radius(ur5)

    # ------------------------------------------------------------------------------------------ limits
    def set_workspace(self, lower: Sequence[float], upper: Sequence[float]) -> None:
        """Set the fingertip box `(3,)` + `(3,)` [m, base frame]; both corners finite with lower < upper."""
        kw = dict(dtype=self.ur5.dtype, device=self.ur5.device)
        try:
            lo, hi = torch.as_tensor(lower, **kw), torch.as_tensor(upper, **kw)
        except (TypeError, ValueError, RuntimeError) as exc:
            raise ValueError(f"workspace corners must be (3,) numbers [m] ({exc})") from None
        if lo.shape != (3,) or hi.shape != (3,) or not bool(torch.isfinite(lo).all() & torch.isfinite(hi).all()) \
                or bool((lo >= hi).any()):
            raise ValueError("workspace corners must be finite (3,) vectors with lower < upper on every axis [m], got "
                             f"{lower!r} .. {upper!r}")
        self._lower, self._upper = lo, hi

    @property
    def workspace_lower(self) -> torch.Tensor:
        """`(3,)` lower corner of the fingertip box [m] (read-only; use :meth:`set_workspace`)."""
        return self._lower.clone()

    @property
    def workspace_upper(self) -> torch.Tensor:
        """`(3,)` upper corner of the fingertip box [m] (read-only; use :meth:`set_workspace`)."""
        return self._upper.clone()

    @property
    def max_joint_speed(self) -> torch.Tensor:
        """`(6,)` joint speed limits [rad/s]."""
        return self._max_joint_speed.clone()

    @max_joint_speed.setter
    def max_joint_speed(self, value) -> None:
        kw = dict(dtype=self.ur5.dtype, device=self.ur5.device)
        if isinstance(value, (bool, str)) or value is None or (torch.is_tensor(value) and value.dtype == torch.bool):
            raise ValueError(f"max_joint_speed: expected a number or 6 numbers [rad/s], got {value!r}")
        try:
            speed = torch.as_tensor(value, **kw).expand(6).clone()
        except (TypeError, ValueError, RuntimeError) as exc:
            raise ValueError(f"max_joint_speed: expected a number or 6 numbers [rad/s] ({exc})") from None
        if not bool(torch.isfinite(speed).all()) or bool((speed <= 0).any()) or bool(
                (speed > self.ur5.max_velocity).any()):
            raise ValueError(f"max_joint_speed: must be finite, positive and within the UR5's joint speed limits "
                             f"{self.ur5.max_velocity.tolist()} rad/s, got {speed.tolist()}")
        self._max_joint_speed = speed

    def describe(self) -> dict[str, object]:
        """Every limit with its value and unit (for logs and docs)."""
        out = {"workspace_lower [m]": self._lower.tolist(), "workspace_upper [m]": self._upper.tolist(),
               "max_joint_speed [rad/s]": self._max_joint_speed.tolist()}
        out.update({f"{k} [{LIMIT_RANGES[k][2]}]": getattr(self, k) for k in LIMIT_RANGES})
        return out

    # ------------------------------------------------------------------------------------------ checks
    def in_workspace(self, p: torch.Tensor, shrink: torch.Tensor | float = 0.0) -> torch.Tensor:
        """`(...)` bool: fingertip positions `(..., 3)` [m, base frame] inside the workspace box (shrunk by
        ``shrink`` [m] on every side, broadcast over the leading dimensions)."""
        s = torch.as_tensor(shrink, dtype=p.dtype, device=p.device)
        if s.dim():
            s = s.unsqueeze(-1)
        return ((p >= self._lower + s) & (p <= self._upper - s)).all(dim=-1)

    def check_joint_move(self, q_from: torch.Tensor, q_to: torch.Tensor, speed: float | torch.Tensor,
                         *, max_move: float | None = None) -> None:
        """Refuse a joint-space move (linear in joint space, as the UR's moveJ) that breaks a limit.

        Args:
            q_from: `(6,)` current joint positions [rad].
            q_to: `(6,)` target joint positions [rad].
            speed: speed of the leading joint [rad/s].
            max_move: bound on ``max |q_to - q_from|`` [rad]; default ``max_joint_move`` (never above it).

        Raises:
            SafetyViolation: naming the violated limit.
        """
        q_from, q_to = self.ur5._q(q_from), self.ur5._q(q_to)
        if q_to.shape != (6,):
            raise ValueError(f"a joint target has shape (6,), got {tuple(q_to.shape)}")
        lo, hi = self.ur5.lower + self.joint_margin, self.ur5.upper - self.joint_margin
        bad = ((q_to < lo) | (q_to > hi)).nonzero().flatten().tolist()
        if bad:
            j = bad[0]
            raise SafetyViolation(f"joint {j} target {float(q_to[j]):.4f} rad is outside its limits "
                                  f"[{float(lo[j]):.4f}, {float(hi[j]):.4f}] rad")
        dq = q_to - q_from
        biggest = float(dq.abs().max())
        bound = self.max_joint_move if max_move is None else min(float(max_move), self.max_joint_move)
        if not biggest <= bound:
            raise SafetyViolation(f"joint move of {biggest:.4f} rad exceeds the {bound:.4f} rad limit per command")
        speed_t = torch.as_tensor(speed, dtype=dq.dtype, device=dq.device)
        if speed_t.numel() != 1 or not bool(torch.isfinite(speed_t)) or float(speed_t) <= 0:
            raise SafetyViolation(f"joint speed must be positive and finite, got {speed_t.tolist()}")
        # moveJ: every joint arrives together, so joint j moves at speed * |dq_j| / max|dq|.
        if biggest > 0:
            per_joint = float(speed_t) * dq.abs() / biggest
            over = (per_joint > self._max_joint_speed * (1 + 1e-9)).nonzero().flatten().tolist()
            if over:
                j = over[0]
                raise SafetyViolation(f"joint {j} speed {float(per_joint[j]):.4f} rad/s exceeds the limit "
                                      f"{float(self._max_joint_speed[j]):.4f} rad/s")
        self._check_path(q_from, q_to)

    def _check_path(self, q_from: torch.Tensor, q_to: torch.Tensor) -> None:
        """Fingertip box along ``q_from + s (q_to - q_from)``, s in [0, 1]: samples every ``path_resolution`` (max
        norm), each checked against the box shrunk by the chord bound of its segment, so the whole path is covered.
        A move shorter than ``path_resolution`` (a guarded motion's millimetre) is its two ends: their poses are the
        ones the robot has just computed (the arm's pose cache), not a new batch."""
        dq = q_to - q_from
        biggest = float(dq.abs().max())
        n = max(2, int(math.ceil(biggest / self.path_resolution)) + 1)
        if n == 2:
            path = torch.stack([self.ur5.position(q_from), self.ur5.position(q_to)])
        else:
            s = torch.linspace(0.0, 1.0, n, dtype=dq.dtype, device=dq.device)[:, None]
            path = self.ur5.position(q_from + s * dq)
        seg = float(dq.abs().sum()) / (n - 1)
        slack = self._chord * seg * seg / 8.0          # largest distance of the path from a segment's chord
        inside = self.in_workspace(path, slack)
        if not bool(inside.all()):
            k = int((~inside).nonzero()[0])
            p = path[k].tolist()
            raise SafetyViolation(
                f"fingertip would leave the workspace box at {['%.4f' % v for v in p]} m "
                f"({k}/{n - 1} along the move, checked with {slack * 1e3:.3f} mm of chord slack); box "
                f"{self._lower.tolist()} .. {self._upper.tolist()} m")

    def check_cartesian_step(self, dx: torch.Tensor, speed: float) -> None:
        """Refuse a Cartesian fingertip step larger or faster than allowed.

        Args:
            dx: `(3,)` displacement in the base frame [m].
            speed: fingertip speed [m/s].

        Raises:
            SafetyViolation: naming the violated limit.
        """
        dx = torch.as_tensor(dx, dtype=self.ur5.dtype, device=self.ur5.device)
        if dx.shape != (3,) or not bool(torch.isfinite(dx).all()):
            raise SafetyViolation(f"a Cartesian step is 3 finite numbers [m], got {dx}")
        step = float(dx.norm())
        if not step <= self.max_cartesian_step:
            raise SafetyViolation(f"Cartesian step of {step * 1e3:.2f} mm exceeds the "
                                  f"{self.max_cartesian_step * 1e3:.2f} mm limit")
        try:
            speed = float(speed)
        except (TypeError, ValueError):
            raise SafetyViolation(f"fingertip speed must be a number [m/s], got {speed!r}") from None
        if not math.isfinite(speed) or speed <= 0 or speed > self.max_tool_speed:
            raise SafetyViolation(f"fingertip speed {speed} m/s is not in (0, {self.max_tool_speed}] m/s")

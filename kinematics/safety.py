"""The one safety gate every robot command passes.

A command that violates a limit is *refused* with :class:`SafetyViolation` naming the limit, the value and
the bound; the gate never clips a command into a different motion. Limits: joint position limits (with a
margin), joint speed, a workspace box for the fingertip along the whole joint-space path, the largest joint
move and the largest Cartesian step.
"""

from __future__ import annotations

import math
from typing import Sequence

import torch

from .ur5 import UR5

__all__ = ["SafetyGate", "SafetyViolation"]


class SafetyViolation(RuntimeError):
    """A robot command was refused because it would break a safety limit; nothing was sent."""


class SafetyGate:
    """Checks robot commands against fixed limits before they are sent.

    Args:
        ur5: kinematic model used to map joint paths to fingertip positions.
        workspace_lower, workspace_upper: `(3,)` corners of the allowed fingertip box in the base frame [m].
        max_joint_speed: joint speed limit [rad/s] (scalar or `(6,)`); default a quarter of the UR5's
            180 deg/s, a conservative speed for contact work.
        max_tool_speed: fingertip speed limit for Cartesian steps [m/s].
        max_cartesian_step: largest fingertip displacement of one Cartesian step [m].
        max_joint_step: largest joint change of one Cartesian step [rad].
        max_joint_move: largest joint change of one joint-space move [rad].
        joint_margin: distance kept from the joint position limits [rad].
        path_resolution: joint-space spacing [rad] at which the fingertip path is checked against the box.
    """

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
        kw = dict(dtype=ur5.dtype, device=ur5.device)
        self.ur5 = ur5
        self.workspace_lower = torch.as_tensor(workspace_lower, **kw)
        self.workspace_upper = torch.as_tensor(workspace_upper, **kw)
        if self.workspace_lower.shape != (3,) or self.workspace_upper.shape != (3,) or bool(
                (self.workspace_lower >= self.workspace_upper).any()):
            raise ValueError("workspace corners must be (3,) with lower < upper on every axis")
        speed = ur5.max_velocity / 4 if max_joint_speed is None else torch.as_tensor(max_joint_speed, **kw)
        self.max_joint_speed = speed.expand(6).clone()
        if bool((self.max_joint_speed <= 0).any()) or bool((self.max_joint_speed > ur5.max_velocity).any()):
            raise ValueError("max_joint_speed must be positive and within the UR5's joint speed limits")
        self.max_tool_speed = float(max_tool_speed)
        self.max_cartesian_step = float(max_cartesian_step)
        self.max_joint_step = float(max_joint_step)
        self.max_joint_move = float(max_joint_move)
        self.joint_margin = float(joint_margin)
        self.path_resolution = float(path_resolution)

    def in_workspace(self, p: torch.Tensor) -> torch.Tensor:
        """`(...)` bool: fingertip positions `(..., 3)` [m, base frame] inside the workspace box."""
        return ((p >= self.workspace_lower) & (p <= self.workspace_upper)).all(dim=-1)

    def check_joint_move(self, q_from: torch.Tensor, q_to: torch.Tensor, speed: float | torch.Tensor,
                         *, max_move: float | None = None) -> None:
        """Refuse a joint-space move (linear in joint space, as the UR's moveJ) that breaks a limit.

        Args:
            q_from: `(6,)` current joint positions [rad].
            q_to: `(6,)` target joint positions [rad].
            speed: speed of the leading joint [rad/s].
            max_move: bound on ``max |q_to - q_from|`` [rad]; default ``max_joint_move``.

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
        bound = self.max_joint_move if max_move is None else max_move
        if biggest > bound:
            raise SafetyViolation(f"joint move of {biggest:.4f} rad exceeds the {bound:.4f} rad limit per command")
        speed_t = torch.as_tensor(speed, dtype=dq.dtype, device=dq.device)
        if not bool(torch.isfinite(speed_t)) or float(speed_t) <= 0:
            raise SafetyViolation(f"joint speed must be positive and finite, got {float(speed_t)}")
        # moveJ: every joint arrives together, so joint j moves at speed * |dq_j| / max|dq|.
        if biggest > 0:
            per_joint = float(speed_t) * dq.abs() / biggest
            over = (per_joint > self.max_joint_speed * (1 + 1e-9)).nonzero().flatten().tolist()
            if over:
                j = over[0]
                raise SafetyViolation(f"joint {j} speed {float(per_joint[j]):.4f} rad/s exceeds the limit "
                                      f"{float(self.max_joint_speed[j]):.4f} rad/s")
        n = max(2, int(math.ceil(biggest / self.path_resolution)) + 1)
        s = torch.linspace(0.0, 1.0, n, dtype=dq.dtype, device=dq.device)[:, None]
        path = self.ur5.position(q_from + s * dq)
        inside = self.in_workspace(path)
        if not bool(inside.all()):
            k = int((~inside).nonzero()[0])
            p = path[k].tolist()
            raise SafetyViolation(
                f"fingertip would leave the workspace box at {['%.4f' % v for v in p]} m "
                f"({k}/{n - 1} along the move); box {self.workspace_lower.tolist()} .. "
                f"{self.workspace_upper.tolist()} m")

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
        if step > self.max_cartesian_step:
            raise SafetyViolation(f"Cartesian step of {step * 1e3:.2f} mm exceeds the "
                                  f"{self.max_cartesian_step * 1e3:.2f} mm limit")
        if not math.isfinite(speed) or speed <= 0 or speed > self.max_tool_speed:
            raise SafetyViolation(f"fingertip speed {speed} m/s is not in (0, {self.max_tool_speed}] m/s")

"""Robot backends behind one interface: a kinematic simulation and a real UR5 over ur_rtde.

Every motion goes through :class:`kinematics.SafetyGate` before anything is sent. Cartesian steps are
mapped to joints with :meth:`kinematics.UR5.cartesian_step`; when that step does not realise the requested
displacement (joint limits, a singularity, the joint-step scale), the command is refused rather than
executed as a different motion.
"""

from __future__ import annotations

import abc
import importlib
import math
from dataclasses import dataclass
from typing import Any, Sequence

import torch

from .safety import SafetyGate, SafetyViolation
from .ur5 import UR5

__all__ = ["RobotBackend", "SimulatedUR5", "RTDEUR5", "RobotError"]


def _positive(value, name: str, hi: float, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number [{unit}], got {value!r}") from None
    if isinstance(value, bool) or not (math.isfinite(v) and 0 < v <= hi):
        raise ValueError(f"{name}: must be finite and in (0, {hi:g}] {unit}, got {value!r}")
    return v


class RobotError(RuntimeError):
    """The robot failed to execute a command or reports a state the caller must not ignore."""


def _require(module: str) -> Any:
    """Import an optional dependency or raise an error that names the extra to install."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"RTDEUR5 needs the '{module}' module from ur_rtde; install it with "
                          f"`pip install torch_gpioius[robot]` (or `pip install ur_rtde`)") from exc


class RobotBackend(abc.ABC):
    """Common interface: read joints/pose, move in joint space, step the fingertip in Cartesian space, stop.

    Args:
        ur5: kinematic model (its tool offset defines the fingertip).
        gate: safety gate; by default :class:`SafetyGate` with its default limits.
        step_tolerance: largest allowed difference between a requested and a realised Cartesian step, as
            ``abs + rel · |dx|`` [m].
    """

    def __init__(self, ur5: UR5, gate: SafetyGate | None = None, *,
                 step_tolerance: tuple[float, float] = (2e-5, 2e-3)) -> None:
        self.ur5 = ur5
        self.gate = gate if gate is not None else SafetyGate(ur5)
        try:
            a, r = (float(v) for v in step_tolerance)
        except (TypeError, ValueError):
            raise ValueError(f"step_tolerance: expected (absolute [m], relative), got {step_tolerance!r}") from None
        if not (math.isfinite(a) and math.isfinite(r) and 0 < a <= 1e-3 and 0 <= r <= 0.05):
            raise ValueError(f"step_tolerance: need 0 < absolute <= 1 mm and 0 <= relative <= 0.05, got {(a, r)}")
        self.step_tolerance = (a, r)

    # -- state ---------------------------------------------------------------------------------------
    @abc.abstractmethod
    def read_joints(self) -> torch.Tensor:
        """`(6,)` measured joint positions [rad]."""

    def read_pose(self) -> torch.Tensor:
        """`(4, 4)` ``T_base_tool`` from the measured joints."""
        return self.ur5.forward_kinematics(self.read_joints())

    def tool_position(self) -> torch.Tensor:
        """`(3,)` fingertip position in the base frame [m]."""
        return self.read_pose()[:3, 3]

    # -- motion --------------------------------------------------------------------------------------
    @abc.abstractmethod
    def _send_joint_move(self, q: torch.Tensor, speed: float) -> None:
        """Execute an already-checked joint move (blocking)."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop any motion now."""

    def move_joints(self, q: torch.Tensor | Sequence[float], speed: float | None = None) -> None:
        """Move in joint space to ``q`` `(6,)` [rad] at leading-joint ``speed`` [rad/s] (default: the limit).

        Raises:
            SafetyViolation: the move breaks a limit; nothing was sent.
        """
        q = self.ur5._q(q)
        speed = float(self.gate.max_joint_speed.min()) if speed is None else float(speed)
        self.gate.check_joint_move(self.read_joints(), q, speed)
        self._send_joint_move(q, speed)

    def move_to_pose(self, T_base_tool: torch.Tensor, speed: float | None = None) -> torch.Tensor:
        """Reach a fingertip pose via inverse kinematics from the current joints; returns the joints `(6,)`."""
        q = self.ur5.inverse_kinematics(T_base_tool, q_init=self.read_joints())
        self.move_joints(q, speed)
        return q

    def move_cartesian(self, dx: torch.Tensor | Sequence[float], speed: float = 0.02) -> torch.Tensor:
        """Step the fingertip by ``dx`` `(3,)` [m, base frame] at ``speed`` [m/s], orientation held.

        Returns:
            `(3,)` the realised fingertip displacement [m].

        Raises:
            SafetyViolation: the step or the joint move breaks a limit, or the IK step would realise a
                different displacement than asked (joint limit, singularity); nothing was sent.
        """
        dx = torch.as_tensor(dx, dtype=self.ur5.dtype, device=self.ur5.device)
        self.gate.check_cartesian_step(dx, speed)
        q = self.read_joints()
        with torch.no_grad():
            q_next = self.ur5.cartesian_step(q, dx)
            realised = self.ur5.position(q_next) - self.ur5.position(q)
        err = float((realised - dx).norm())
        a, r = self.step_tolerance
        if err > a + r * float(dx.norm()):
            raise SafetyViolation(
                f"the IK step realises {[round(v * 1e3, 3) for v in realised.tolist()]} mm instead of "
                f"{[round(v * 1e3, 3) for v in dx.tolist()]} mm (error {err * 1e3:.3f} mm): near a joint limit "
                f"or singularity; refusing rather than moving elsewhere")
        step = float(dx.norm())
        biggest = float((q_next - q).abs().max())
        joint_speed = biggest * speed / step if step > 0 else float(self.gate.max_joint_speed.min())
        if biggest > 0:
            # near a singularity a slow fingertip step can need fast joints: slow the whole move down so that every
            # joint keeps its limit (as the UR's moveL scales its speed), rather than asking the gate for more
            dq = (q_next - q).abs()
            moving = dq > 0
            cap = float((self.gate.max_joint_speed[moving] * biggest / dq[moving]).min())
            joint_speed = min(joint_speed, cap)
        self.gate.check_joint_move(q, q_next, max(joint_speed, 1e-12), max_move=self.gate.max_joint_step)
        self._send_joint_move(q_next, max(joint_speed, 1e-12))
        return realised


@dataclass
class _Sample:
    t: float
    q: torch.Tensor


class SimulatedUR5(RobotBackend):
    """A kinematic UR5: commands take effect exactly, a simulated clock advances by each move's duration.

    Args:
        ur5: kinematic model.
        q0: `(6,)` initial joints [rad].
        gate: safety gate (default limits if None).

    Attributes:
        time: simulated time [s].
        log: list of (time [s], joints (6,)) after every command, for plots.
    """

    def __init__(self, ur5: UR5, q0: torch.Tensor | Sequence[float], gate: SafetyGate | None = None,
                 **kwargs: Any) -> None:
        super().__init__(ur5, gate, **kwargs)
        q0 = ur5._q(q0)
        if not bool(ur5.within_limits(q0)):
            raise ValueError("q0 is outside the joint limits")
        self._q = q0.clone()
        self.time = 0.0
        self.log: list[_Sample] = [_Sample(0.0, self._q.clone())]
        self.stopped = False

    def read_joints(self) -> torch.Tensor:
        return self._q.clone()

    def _send_joint_move(self, q: torch.Tensor, speed: float) -> None:
        self.time += float((q - self._q).abs().max()) / speed
        self._q = q.detach().clone()
        self.log.append(_Sample(self.time, self._q.clone()))

    def stop(self) -> None:
        self.stopped = True

    def set_state(self, q: torch.Tensor, time: float) -> None:
        """Place the simulated arm at joints ``q`` `(6,)` [rad] and clock ``time`` [s] (resume only; not a move)."""
        q = self.ur5._q(q)
        if not bool(self.ur5.within_limits(q)):
            raise ValueError("set_state: joints outside their limits")
        self._q, self.time = q.clone(), float(time)
        self.log.append(_Sample(self.time, self._q.clone()))

    def trajectory(self) -> tuple[torch.Tensor, torch.Tensor]:
        """`(k,)` times [s] and `(k, 6)` joints [rad] of every executed command."""
        return (torch.tensor([s.t for s in self.log], dtype=torch.float64),
                torch.stack([s.q for s in self.log]))


class RTDEUR5(RobotBackend):
    """A real UR5 (CB3, firmware >= 3.3) over ur_rtde's RTDE control and receive interfaces.

    The controller's TCP must be set to the flange (zero offset): poses are computed here from the measured
    joints with ``ur5.tool_offset``, so the fingertip frame is defined in one place.

    Args:
        host: robot IP address.
        ur5: kinematic model.
        gate: safety gate.
        acceleration: joint acceleration for moveJ [rad/s^2].
        state_tolerance: largest allowed difference [rad] between the joints we last commanded and the
            joints the robot reports before the next command (guards against external motion).
        control: an already-connected ``RTDEControlInterface`` (tests pass mocks); created from ``host`` when None.
        receive: an already-connected ``RTDEReceiveInterface``; created from ``host`` when None.
    """

    def __init__(self, host: str, ur5: UR5, gate: SafetyGate | None = None, *, acceleration: float = 0.5,
                 state_tolerance: float = 2e-3, control: Any = None, receive: Any = None, **kwargs: Any) -> None:
        super().__init__(ur5, gate, **kwargs)
        if control is None:
            control = _require("rtde_control").RTDEControlInterface(host)
        if receive is None:
            receive = _require("rtde_receive").RTDEReceiveInterface(host)
        self.control, self.receive = control, receive
        self.acceleration = _positive(acceleration, "acceleration", 40.0, "rad/s^2")   # UR5 joint limit 40 rad/s^2
        self.state_tolerance = _positive(state_tolerance, "state_tolerance", 0.05, "rad")
        self._expected: torch.Tensor | None = None

    def read_joints(self) -> torch.Tensor:
        q = torch.tensor(list(self.receive.getActualQ()), dtype=self.ur5.dtype, device=self.ur5.device)
        if q.shape != (6,) or not bool(torch.isfinite(q).all()):
            raise RobotError(f"robot reported invalid joint positions {q.tolist()}")
        return q

    def _check_robot_state(self) -> None:
        if self.receive.isProtectiveStopped() or self.receive.isEmergencyStopped():
            raise RobotError("robot is protective- or emergency-stopped; clear it on the pendant first")
        if self._expected is not None:
            drift = float((self.read_joints() - self._expected).abs().max())
            if drift > self.state_tolerance:
                raise RobotError(f"robot joints moved {drift:.4f} rad from the last commanded position "
                                 f"(tolerance {self.state_tolerance} rad); refusing to continue")

    def _send_joint_move(self, q: torch.Tensor, speed: float) -> None:
        self._check_robot_state()
        ok = self.control.moveJ(q.tolist(), float(speed), self.acceleration)
        if ok is False:
            raise RobotError("moveJ was rejected by the robot controller")
        self._expected = q.detach().clone()

    def stop(self) -> None:
        self.control.stopJ(2.0)

    def close(self) -> None:
        """Stop the control script and disconnect."""
        self.control.stopScript()
        self.control.disconnect()
        self.receive.disconnect()

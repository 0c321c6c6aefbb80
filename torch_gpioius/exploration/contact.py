"""The contact controller: turns a planned tangential step into safe motion with force feedback.

Paper Sec. VI-A: contact when ``|F| > 1.0 N``; retreat along the normal while ``|F| > 5.0 N``; motion split
into a tangential part (the planner's step) and a normal part that keeps the fingertip on the inner surface.

Every reading is checked before it is used. A sensing fault (a stale or missing sample, a checksum storm, a
disconnect) stops the robot and raises :class:`ContactFault`; a force fault (an overload bit, a force above
``max_force``, a jump above ``max_force_jump``) retreats along the normal first, then raises.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import torch

from ..sensors.base import ForceReading, ForceSensor, SensorError

__all__ = ["ContactConfig", "ContactController", "ContactFault", "ContactResult"]


class ContactFault(RuntimeError):
    """Motion was stopped (or retreated) because the force signal could not be trusted or was unsafe."""


@dataclass(frozen=True)
class ContactConfig:
    """Thresholds and step sizes (SI units).

    Attributes:
        contact_force: ``|F|`` at or above which the fingertip is in contact [N] (paper: 1.0 N).
        retreat_force: ``|F|`` above which the fingertip retreats along the normal [N] (paper: 5.0 N).
        max_force: ``|F|`` treated as a fault (spike or collision) [N].
        max_force_jump: change of ``|F|`` between consecutive readings treated as a spike [N].
        tangential_step: largest tangential sub-step between two force readings [m].
        normal_step: step along the normal while regulating contact [m].
        max_normal_travel: inward travel without finding contact before contact counts as lost [m].
        retreat_distance: how far a force fault retreats along the normal [m].
        speed: fingertip speed [m/s].
        max_reading_age: a reading older than this (robot clock vs sample time) is stale [s].
        max_step: largest planned step :meth:`ContactController.slide` accepts [m] (a few times the planner's
            alpha = 1 cm). A larger one is refused, never split into many gate-approved sub-steps.
        max_approach: longest approach :meth:`ContactController.approach` accepts [m].
        approach_step: step of the approach while ``|F|`` is below ``near_force`` [m] (then ``normal_step``).
        near_force: ``|F|`` below which the approach takes ``approach_step`` [N].
        tip_radius: radius of the fingertip's sphere around the tool point [m] (0: a point fingertip).
        tip_stiffness: stiffness of the fingertip itself [N/m] (``inf``: rigid). With both, the recorded contact is
            the point of the sphere on the surface: ``tool - (tip_radius - |F| / tip_stiffness) n`` with ``n`` the
            measured force direction (the fingertip deflects back by ``|F| / tip_stiffness`` when pressed).
        floor: height [m, base frame z] of a support plane (the table the object stands on), or None. No move takes
            the fingertip's centre below ``floor + tip_radius``: the part of a move that would is dropped, so the
            fingertip slides along the table instead of passing through it, whatever the planner asks.
    """

    contact_force: float = 1.0
    retreat_force: float = 5.0
    max_force: float = 30.0
    max_force_jump: float = 20.0
    tangential_step: float = 0.002
    normal_step: float = 0.001
    max_normal_travel: float = 0.05
    retreat_distance: float = 0.005
    speed: float = 0.02
    max_reading_age: float = 0.25
    max_step: float = 0.03
    max_approach: float = 2.0
    approach_step: float = 0.001
    near_force: float = 0.3
    tip_radius: float = 0.0
    tip_stiffness: float = math.inf
    floor: float | None = None

    #: Upper ends of the accepted ranges (what the OptoForce OMD-20-SE-40N and a UR5 in contact work allow).
    BOUNDS = {"contact_force": 40.0, "retreat_force": 40.0, "max_force": 40.0, "max_force_jump": 40.0,
              "tangential_step": 0.01, "normal_step": 0.005, "max_normal_travel": 0.2, "retreat_distance": 0.05,
              "speed": 0.25, "max_reading_age": 1.0, "max_step": 0.1, "max_approach": 3.0, "approach_step": 0.01,
              "near_force": 40.0}

    def __post_init__(self) -> None:
        for name, hi in self.BOUNDS.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= hi):
                raise ValueError(f"ContactConfig.{name}: must be finite and in (0, {hi:g}], got {v!r}")
        if not self.contact_force < self.retreat_force < self.max_force:
            raise ValueError("ContactConfig: need 0 < contact_force < retreat_force < max_force, got "
                             f"{self.contact_force}, {self.retreat_force}, {self.max_force}")
        if isinstance(self.tip_radius, bool) or not (isinstance(self.tip_radius, (int, float)) and
                                                      0 <= self.tip_radius <= 0.05):
            raise ValueError(f"ContactConfig.tip_radius: must be in [0, 0.05] m, got {self.tip_radius!r}")
        if isinstance(self.tip_stiffness, bool) or not (isinstance(self.tip_stiffness, (int, float)) and
                                                         self.tip_stiffness > 0):
            raise ValueError(f"ContactConfig.tip_stiffness: must be positive [N/m] (inf: rigid), got "
                             f"{self.tip_stiffness!r}")
        if self.near_force >= self.contact_force:
            raise ValueError("ContactConfig: near_force must be below contact_force")
        if self.tangential_step > self.max_step:
            raise ValueError("ContactConfig: tangential_step must not exceed max_step")
        if self.floor is not None and (isinstance(self.floor, bool) or not isinstance(self.floor, (int, float))
                                       or not (math.isfinite(self.floor) and abs(self.floor) <= 5.0)):
            raise ValueError(f"ContactConfig.floor: must be None or a height within 5 m of the base [m], got "
                             f"{self.floor!r}")


@dataclass
class ContactResult:
    """What one controlled step did.

    Attributes:
        in_contact: whether the step ended in contact (``contact_force <= |F| <= retreat_force``).
        contact: `(3,)` fingertip position at the end of the step [m, base] (the contact point if in contact).
        free_space: `(k, 3)` positions traversed with ``|F| < contact_force`` [m, base].
        path: `(m, 3)` every fingertip position visited [m, base].
        forces: `(m, 3)` the force at each position [N, base frame].
        travel: fingertip path length [m].
    """

    in_contact: bool
    contact: torch.Tensor
    free_space: torch.Tensor
    path: torch.Tensor
    forces: torch.Tensor
    travel: float

    @property
    def force_normal(self) -> torch.Tensor:
        """`(3,)` unit direction of the last measured force (the surface normal seen by the sensor)."""
        f = self.forces[-1]
        return f / f.norm().clamp_min(1e-12)


@dataclass
class _Log:
    path: list = field(default_factory=list)
    forces: list = field(default_factory=list)
    free: list = field(default_factory=list)


def _unit(v: torch.Tensor, name: str) -> torch.Tensor:
    v = torch.as_tensor(v, dtype=torch.float64)
    if v.shape != (3,) or not bool(torch.isfinite(v).all()) or float(v.norm()) < 1e-12:
        raise ValueError(f"{name} must be a finite non-zero (3,) vector, got {v}")
    return v / v.norm()


class ContactController:
    """Force-guarded sliding on the inner surface with a robot backend and a force sensor.

    Args:
        robot: a :class:`kinematics.RobotBackend` (``move_cartesian``, ``read_pose``, ``stop``, and a ``time``
            attribute or ``clock()`` for reading ages; without either, ages are not checked).
        sensor: a :class:`torch_gpioius.sensors.ForceSensor`; its frame is the tool frame.
        config: thresholds and step sizes.
    """

    def __init__(self, robot: Any, sensor: ForceSensor, config: ContactConfig | None = None) -> None:
        self.robot, self.sensor = robot, sensor
        self.config = config if config is not None else ContactConfig()
        self._prev: ForceReading | None = None

    # ---------------------------------------------------------------------------------- sensing
    def _now(self) -> float | None:
        if hasattr(self.robot, "time"):
            return float(self.robot.time)
        if hasattr(self.robot, "clock"):
            return float(self.robot.clock())
        return None

    def _fault(self, message: str, normal: torch.Tensor | None, cause: BaseException | None = None) -> None:
        self.robot.stop()
        if normal is not None:
            try:
                self.robot.move_cartesian(normal * self.config.retreat_distance, self.config.speed)
                message += f"; retreated {self.config.retreat_distance * 1e3:.1f} mm along the normal"
            except Exception as exc:  # the retreat itself was refused: say so, stay stopped
                message += f"; retreat refused ({exc}), robot stopped"
        else:
            message += "; robot stopped"
        raise ContactFault(message) from cause

    def read_force(self, normal: torch.Tensor | None = None) -> torch.Tensor:
        """A checked force reading in the base frame, `(3,)` [N].

        Raises:
            ContactFault: on a sensing or force fault (after stopping or retreating along ``normal``).
        """
        cfg = self.config
        try:
            r = self.sensor.read()
        except SensorError as exc:
            self._fault(f"force sensor failed: {exc}", None, exc)
        prev = self._prev
        # The sensor's own sample counter decides staleness: a frozen DAQ that repeats counter 42 is stale even
        # when the host stamps each read with a new time.
        if prev is not None and r.counter == prev.counter:
            self._fault(f"stale force reading (sample counter {r.counter} repeated: the sensor is frozen or "
                        "stopped streaming)", None)
        now = self._now()
        if now is not None and now - r.timestamp > cfg.max_reading_age:
            self._fault(f"stale force reading ({(now - r.timestamp) * 1e3:.0f} ms old)", None)
        if r.errors:
            self._fault(f"force sensor reports {', '.join(r.errors)}", normal)
        if r.overloaded:
            self._fault(f"force sensor overloaded on {', '.join(r.overloaded)}", normal)
        if not bool(torch.isfinite(r.force).all()):
            self._fault("force reading is not finite", None)
        if r.magnitude > cfg.max_force:
            self._fault(f"force {r.magnitude:.1f} N above the {cfg.max_force:.1f} N limit", normal)
        if prev is not None and abs(r.magnitude - prev.magnitude) > cfg.max_force_jump:
            self._fault(f"force spike: |F| jumped {prev.magnitude:.1f} -> {r.magnitude:.1f} N", normal)
        self._prev = r
        R = self.robot.read_pose()[:3, :3]
        return R @ r.force

    # ---------------------------------------------------------------------------------- motion
    def _above_floor(self, dx: torch.Tensor) -> torch.Tensor:
        """``dx`` without the part that would take the fingertip below the support plane (``config.floor``)."""
        cfg = self.config
        if cfg.floor is None or len(dx) != 3:
            return dx
        z = float(self.robot.read_pose()[2, 3])
        lowest = cfg.floor + cfg.tip_radius
        if z + float(dx[2]) >= lowest:
            return dx
        dx = dx.clone()
        dx[2] = lowest - z              # down to the plane (or back up onto it)
        return dx

    def _move(self, dx: torch.Tensor, log: _Log, normal: torch.Tensor) -> torch.Tensor:
        dx = self._above_floor(dx)
        self.robot.move_cartesian(dx, self.config.speed)
        f = self.read_force(normal)
        p = self.robot.read_pose()[:3, 3].clone()
        log.path.append(p)
        log.forces.append(f)
        if float(f.norm()) < self.config.contact_force:
            log.free.append(p)
        return f

    def _regulate(self, normal: torch.Tensor, f: torch.Tensor, log: _Log) -> tuple[bool, torch.Tensor]:
        """Retreat while ``|F| > retreat_force``, press in while ``|F| < contact_force``."""
        cfg = self.config
        pressed = 0.0
        for _ in range(int(math.ceil(cfg.max_normal_travel / cfg.normal_step)) * 2 + 1):
            mag = float(f.norm())
            if mag > cfg.retreat_force:
                f = self._move(normal * cfg.normal_step, log, normal)
            elif mag < cfg.contact_force:
                if pressed >= cfg.max_normal_travel:
                    return False, f
                f = self._move(-normal * cfg.normal_step, log, normal)
                pressed += cfg.normal_step
            else:
                return True, f
        return cfg.contact_force <= float(f.norm()) <= cfg.retreat_force, f

    def _result(self, in_contact: bool, log: _Log, start: torch.Tensor, last_force: torch.Tensor | None = None
                ) -> ContactResult:
        path = torch.stack(log.path) if log.path else start[None]
        if log.forces:
            forces = torch.stack(log.forces)
        elif last_force is not None:
            # no move was needed (an approach that starts in the contact band): the reading taken at the start is
            # the measured force, and its direction the normal (a zero vector here once ended a run)
            forces = torch.as_tensor(last_force, dtype=torch.float64).reshape(1, 3)
        else:
            forces = torch.zeros(1, 3, dtype=torch.float64)
        free = torch.stack(log.free) if log.free else torch.zeros(0, 3, dtype=torch.float64)
        full = torch.cat([start[None], path])
        travel = float((full[1:] - full[:-1]).norm(dim=-1).sum())
        contact = path[-1].clone()
        cfg = self.config
        if in_contact and (cfg.tip_radius > 0 or math.isfinite(cfg.tip_stiffness)):
            f = forces[-1]
            n = f / f.norm().clamp_min(1e-12)
            deflection = float(f.norm()) / cfg.tip_stiffness if math.isfinite(cfg.tip_stiffness) else 0.0
            contact = contact - (cfg.tip_radius - deflection) * n
        return ContactResult(in_contact, contact, free, path, forces, travel)

    @property
    def max_approach(self) -> float:
        """The longest approach :meth:`approach` accepts [m] (``config.max_approach``)."""
        return float(self.config.max_approach)

    def approach(self, direction: torch.Tensor, max_travel: float = 0.3) -> ContactResult:
        """Move along ``direction`` until contact, then settle into the contact band.

        Args:
            direction: `(3,)` approach direction (base frame), normalised here.
            max_travel: give up (``in_contact=False``) after this distance [m].
        """
        d = _unit(direction, "direction")
        cfg = self.config
        if isinstance(max_travel, bool) or not (isinstance(max_travel, (int, float)) and math.isfinite(max_travel)
                                                and 0 < max_travel <= cfg.max_approach):
            raise ValueError(f"max_travel: must be in (0, {cfg.max_approach}] m (ContactConfig.max_approach), "
                             f"got {max_travel!r}")
        log = _Log()
        start = self.robot.read_pose()[:3, 3].clone()
        f = self.read_force(-d)
        moved = 0.0
        while float(f.norm()) < cfg.contact_force and moved < max_travel:
            step = cfg.approach_step if float(f.norm()) < cfg.near_force else cfg.normal_step
            f = self._move(d * step, log, -d)
            moved += step
        if float(f.norm()) < cfg.contact_force:
            return self._result(False, log, start, f)
        ok, f = self._regulate(-d, f, log)
        return self._result(ok, log, start, f)

    def lift(self, direction: torch.Tensor, *, step: float = 0.005, until_force_below: float = 0.1,
             extra: float = 0.01, max_distance: float = 0.2, inside=None) -> ContactResult:
        """Move away along ``direction`` in ``step`` moves until ``|F|`` drops below ``until_force_below`` (the cover
        no longer pushes) and ``inside(position)`` is False (e.g. beyond the outer surface the camera saw), then
        ``extra`` further; at most ``max_distance`` in all (an evidence-seeking tap).

        Args:
            direction: `(3,)` direction to lift along (the measured force direction: away from the surface).
            step: length of each move [m] (at most ``config.max_step``).
            until_force_below: the force [N] below which the cover counts as left behind.
            extra: distance [m] moved after that.
            max_distance: the longest lift [m].
            inside: optional predicate on the `(3,)` position: keep lifting while it is True.

        Returns:
            :class:`ContactResult` with ``in_contact=False``; its ``free_space`` holds the positions with
            ``|F| < contact_force``.

        Raises:
            ContactFault: a sensing or force fault; SafetyViolation: a move the gate refuses.
        """
        d = _unit(direction, "direction")
        cfg = self.config
        for name, v, hi in (("step", step, cfg.max_step), ("until_force_below", until_force_below, cfg.contact_force),
                            ("extra", extra, 0.1), ("max_distance", max_distance, cfg.max_approach)):
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= hi):
                raise ValueError(f"lift: {name} must be in (0, {hi:g}], got {v!r}")
        log = _Log()
        start = self.robot.read_pose()[:3, 3].clone()
        f = self.read_force(d)
        moved, beyond = 0.0, None
        while moved < max_distance - 1e-12:
            here = log.path[-1] if log.path else start
            if beyond is None and float(f.norm()) < until_force_below and not (inside is not None and inside(here)):
                beyond = moved
            if beyond is not None and moved - beyond >= extra - 1e-12:
                break
            s = min(step, max_distance - moved)
            f = self._move(d * s, log, d)
            moved += s
        return self._result(False, log, start, f)

    def slide(self, step: torch.Tensor, normal: torch.Tensor) -> ContactResult:
        """Execute one planned step: tangential motion in sub-steps, contact regulated along the normal.

        Args:
            step: `(3,)` planned displacement [m, base]; its component along ``normal`` is removed.
            normal: `(3,)` outward surface normal estimate [base]; retreat is along ``+normal``.

        Returns:
            :class:`ContactResult`; ``in_contact=False`` when contact was lost for ``max_normal_travel``.

        Raises:
            ContactFault: a sensing or force fault (the robot was stopped or retreated first).
            SafetyViolation: the planned step is longer than ``config.max_step``; nothing was sent (splitting
                it into many small gate-approved commands would bypass the gate's per-command limit).
        """
        n = _unit(normal, "normal")
        step = torch.as_tensor(step, dtype=torch.float64)
        if step.shape != (3,) or not bool(torch.isfinite(step).all()):
            raise ValueError(f"step must be a finite (3,) vector [m], got {step}")
        cfg = self.config
        if float(step.norm()) > cfg.max_step:
            from kinematics import SafetyViolation

            raise SafetyViolation(f"planned step of {float(step.norm()) * 1e3:.1f} mm exceeds the "
                                  f"{cfg.max_step * 1e3:.1f} mm limit (ContactConfig.max_step); refused, not split")
        t = step - (step @ n) * n
        log = _Log()
        start = self.robot.read_pose()[:3, 3].clone()
        self.read_force(n)
        k = max(1, int(math.ceil(float(t.norm()) / cfg.tangential_step)))
        ok = True
        for _ in range(k):
            f = self._move(t / k, log, n)
            ok, f = self._regulate(n, f, log)
            if not ok:
                break
        return self._result(ok, log, start)

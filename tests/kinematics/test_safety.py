"""The safety gate: every limit validated where it is set, and a property test that no command beyond the joint,
speed, workspace or step limits ever reaches a robot backend, whatever the settings, the planner or the sensor."""

import math

import pytest
import torch
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from kinematics import UR5, SafetyGate, SafetyViolation, SimulatedUR5
from torch_gpioius.exploration.contact import ContactConfig, ContactController, ContactFault
from torch_gpioius.sensors import ForceReading, ForceSensor, SensorError, SensorTimeout

Q0 = [0.0, -1.2, 1.5, -1.9, -1.57, 0.0]
UR = UR5(tool_offset=(0.0, 0.0, 0.05))
BAD = [float("nan"), float("inf"), -float("inf"), -1.0, 0.0, "0.01", True, None]


def t(*v):
    return torch.tensor(v, dtype=torch.float64)


@pytest.mark.parametrize("name", ["max_tool_speed", "max_cartesian_step", "max_joint_step", "max_joint_move",
                                  "joint_margin", "path_resolution", "max_joint_speed"])
@pytest.mark.parametrize("value", BAD + [1e9])
def test_every_limit_is_validated_at_construction_and_on_assignment(name, value):
    if not (name == "max_joint_speed" and value is None):      # None is the documented default there
        with pytest.raises(ValueError, match=name):
            SafetyGate(UR, **{name: value})
    gate = SafetyGate(UR)
    before = gate.describe()
    with pytest.raises(ValueError, match=name):
        setattr(gate, name, value)
    assert gate.describe() == before


@pytest.mark.parametrize("lower, upper", [((0, 0, float("nan")), (1, 1, 1)), ((0, 0, 0), (1, 1, float("inf"))),
                                          ((0, 0, 0), (1, -1, 1)), ((0, 0), (1, 1)), ("abc", (1, 1, 1))])
def test_bad_workspace_boxes_are_refused(lower, upper):
    with pytest.raises(ValueError, match="workspace"):
        SafetyGate(UR, lower, upper)


def test_the_reported_defects_no_longer_run():
    """Each of these settings used to switch its check off and let the command run (issue 14)."""
    q = t(*Q0)
    for kwargs in (dict(joint_margin=float("nan")), dict(joint_margin=-1.0), dict(max_joint_speed=float("nan")),
                   dict(max_joint_move=float("nan")), dict(max_joint_step=float("nan")),
                   dict(path_resolution=1e9), dict(path_resolution=-1.0), dict(path_resolution=0.0),
                   dict(path_resolution=float("nan"))):
        with pytest.raises(ValueError):
            SimulatedUR5(UR, q, SafetyGate(UR, **kwargs))
    robot = SimulatedUR5(UR, q)
    target = q.clone()
    target[0] = 6.6                                   # past the 2 pi hardware limit
    with pytest.raises(SafetyViolation, match="outside its limits"):
        robot.move_joints(target)


def test_a_planned_step_beyond_the_maximum_is_refused_not_split():
    robot = SimulatedUR5(UR, Q0)
    sensor = _ScriptedSensor([t(0.0, 0.0, 2.0)] * 10, robot)
    ctl = ContactController(robot, sensor)
    for step in ([1.0, 0.0, 0.0], [1e12, 0.0, 0.0], [0.031, 0.0, 0.0]):
        n = len(robot.log)
        with pytest.raises(SafetyViolation, match="max_step"):
            ctl.slide(torch.tensor(step, dtype=torch.float64), t(0.0, 0.0, 1.0))
        assert len(robot.log) == n                    # nothing was sent


@pytest.mark.parametrize("field", list(ContactConfig.BOUNDS))
def test_contact_configuration_is_validated(field):
    for value in (float("nan"), float("inf"), -1.0, 0.0, 1e6):
        with pytest.raises(ValueError, match=field):
            ContactConfig(**{field: value})


# ------------------------------------------------------------------------------------------------ property test
class _Recorder(SimulatedUR5):
    """A simulated backend that records every command that reaches it, with the joints it started from."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.sent = []

    def _send_joint_move(self, q, speed):
        self.sent.append((self._q.clone(), q.detach().clone(), float(speed)))
        super()._send_joint_move(q, speed)


class _ScriptedSensor(ForceSensor):
    """Plays a drawn stream of readings (forces in the tool frame, faults as exceptions, repeated counters)."""

    def __init__(self, stream, robot):
        self.stream, self.robot, self.i, self.counter = list(stream), robot, 0, 0

    def read(self):
        item = self.stream[self.i % len(self.stream)]
        self.i += 1
        if isinstance(item, Exception):
            raise item
        if isinstance(item, tuple):                   # (force, status, repeat_counter)
            force, status, repeat = item
        else:
            force, status, repeat = item, 0, False
        if not repeat:
            self.counter = (self.counter + 1) & 0xFFFF
        return ForceReading(force, status, self.counter, float(self.robot.time) + 1e-6 * self.i)

    def tare(self):
        pass


def _assert_every_command_within_limits(robot: _Recorder, gate: SafetyGate, cartesian: bool) -> None:
    """Independent check of what reached the backend: joints, speeds, moves, and the fingertip along the whole
    joint path sampled 64 times against the (unshrunk) box."""
    lo_q, hi_q = UR.lower + gate.joint_margin, UR.upper - gate.joint_margin
    speeds = gate.max_joint_speed
    for q0, q1, speed in robot.sent:
        assert bool(((q1 >= lo_q - 1e-12) & (q1 <= hi_q + 1e-12)).all()), "joint limit"
        dq = q1 - q0
        big = float(dq.abs().max())
        assert big <= gate.max_joint_move + 1e-12, "joint move"
        if cartesian:
            assert big <= gate.max_joint_step + 1e-12, "joint step"
            step = float((UR.position(q1) - UR.position(q0)).norm())
            assert step <= gate.max_cartesian_step + 1e-9, "Cartesian step"
        assert math.isfinite(speed) and speed > 0
        if big > 0:
            assert bool((speed * dq.abs() / big <= speeds * (1 + 1e-9)).all()), "joint speed"
        s = torch.linspace(0, 1, 64, dtype=torch.float64)[:, None]
        tips = UR.position(q0 + s * dq)
        inside = ((tips >= gate.workspace_lower - 1e-12) & (tips <= gate.workspace_upper + 1e-12)).all(-1)
        assert bool(inside.all()), "workspace box"


def limit_value(hi, typical):
    """Any valid limit (invalid ones are refused at construction, tested above), often one large enough for the
    controller's 1-2 mm moves to pass, so that commands do reach the backend: the gate must then hold."""
    return st.one_of(st.floats(1e-4, hi), st.floats(typical, hi))


component = st.floats(-0.03, 0.03)
planned = st.tuples(component, component, component)
# mostly forces in or near the contact band (the controller then moves), sometimes faults of every kind
force = st.tuples(st.floats(-3, 3), st.floats(-3, 3), st.floats(-8, 8)).map(lambda v: t(*v))
readings = st.one_of(
    force, force, force, force, force, force,
    st.tuples(force, st.sampled_from([0, 1 << 7, 2 << 10]), st.booleans()),
    st.sampled_from([t(float("nan"), 0, 0), t(0, 0, 60.0)]),
    st.just(SensorTimeout("drawn timeout")),
)


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(margin=limit_value(0.5, 1e-3), joint_step=limit_value(0.5, 0.05), cart_step=limit_value(0.1, 0.003),
       resolution=limit_value(0.05, 1e-3),
       box_lo=st.tuples(*[st.floats(0.001, 0.3)] * 3), box_hi=st.tuples(*[st.floats(0.001, 0.3)] * 3),
       steps=st.lists(planned, min_size=1, max_size=4),
       speed=st.one_of(st.floats(1e-3, 0.3), st.floats(1e-3, 0.3), st.sampled_from([float("nan"), 0.0, -1.0, 2.0])),
       joint_delta=st.tuples(*[st.floats(-0.5, 0.5)] * 6), joint_speed=st.floats(1e-3, 1.0),
       stream=st.lists(readings, min_size=1, max_size=12))
def test_no_command_beyond_the_limits_ever_reaches_the_backend(margin, joint_step, cart_step, resolution, box_lo,
                                                              box_hi, steps, speed, joint_delta, joint_speed, stream):
    settings_ = dict(joint_margin=margin, max_joint_step=joint_step, max_cartesian_step=cart_step,
                     path_resolution=resolution)
    tip = UR.position(t(*Q0))
    lower, upper = (tip - t(*box_lo)).tolist(), (tip + t(*box_hi)).tolist()
    gate = SafetyGate(UR, lower, upper, **settings_)
    robot = _Recorder(UR, Q0, gate)
    # 1. raw Cartesian steps and a joint move, as a planner or a user might send them
    for dx in steps:
        try:
            robot.move_cartesian(t(*dx), speed)
        except SafetyViolation:
            pass
    try:
        robot.move_joints(robot.read_joints() + t(*joint_delta), joint_speed)
    except (SafetyViolation, ValueError):
        pass
    _assert_every_command_within_limits(robot, gate, cartesian=False)
    event(f"commands sent by raw moves: {min(len(robot.sent), 3)}+")
    # 2. the contact controller fed a drawn sensor stream, sliding along drawn planned steps
    robot2 = _Recorder(UR, Q0, gate)
    ctl = ContactController(robot2, _ScriptedSensor(stream, robot2))
    for dx in steps:
        try:
            ctl.slide(t(*dx), t(0.0, 0.0, 1.0))
        except (ContactFault, SafetyViolation, SensorError, ValueError):
            pass
    try:
        ctl.approach(t(0.0, 0.0, -1.0), max_travel=0.02)
    except (ContactFault, SafetyViolation, SensorError):
        pass
    _assert_every_command_within_limits(robot2, gate, cartesian=True)
    event(f"commands sent by the controller: {min(len(robot2.sent) // 5 * 5, 20)}+")

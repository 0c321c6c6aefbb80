"""Safety gate and robot backends: refusals leave the robot untouched; the RTDE backend against a mock."""

import importlib.util

import pytest
import torch

from kinematics import RTDEUR5, UR5, SafetyGate, SafetyViolation, SimulatedUR5
from kinematics.backends import RobotError

Q0 = [0.0, -1.2, 1.5, -1.9, -1.57, 0.0]


@pytest.fixture()
def ur5():
    return UR5(tool_offset=(0.0, 0.0, 0.05))


@pytest.fixture()
def robot(ur5):
    return SimulatedUR5(ur5, Q0)


def t(*v):
    return torch.tensor(v, dtype=torch.float64)


def test_cartesian_steps_move_the_fingertip_exactly_and_advance_the_clock(robot):
    p0 = robot.tool_position()
    for dx in (t(0.01, 0, 0), t(0, 0.01, 0), t(0, 0, -0.01)):
        realised = robot.move_cartesian(dx, speed=0.02)
        assert torch.allclose(realised, dx, atol=1e-9)
    assert torch.allclose(robot.tool_position() - p0, t(0.01, 0.01, -0.01), atol=1e-9)
    assert robot.time > 0 and len(robot.log) == 4
    times, qs = robot.trajectory()
    assert qs.shape == (4, 6) and bool((times[1:] > times[:-1]).all())


def assert_refused(robot, fn, match):
    q, n = robot.read_joints(), len(robot.log)
    with pytest.raises(SafetyViolation, match=match):
        fn()
    assert torch.equal(robot.read_joints(), q) and len(robot.log) == n


def test_gate_refuses_and_leaves_the_robot_where_it_was(robot, ur5):
    q = robot.read_joints()
    assert_refused(robot, lambda: robot.move_cartesian(t(0.05, 0, 0)), "Cartesian step")
    assert_refused(robot, lambda: robot.move_cartesian(t(0.01, 0, 0), speed=2.0), "fingertip speed")
    assert_refused(robot, lambda: robot.move_joints(q + t(0, 0, 0, 0, 0, 7.0)), "outside its limits")
    assert_refused(robot, lambda: robot.move_joints(q + t(0.1, 0, 0, 0, 0, 0), speed=3.0), "speed")
    assert_refused(robot, lambda: robot.move_joints(q + t(3.5, 0, 0, 0, 0, 0)), "per command")
    assert_refused(robot, lambda: robot.move_cartesian(t(float("nan"), 0, 0)), "finite")


def test_a_cartesian_step_that_needs_fast_joints_is_slowed_not_refused(ur5):
    # A slow joint limit makes the 2 cm/s fingertip speed need joints faster than allowed (as near a singularity):
    # the step still runs, slower, and no joint exceeds its limit (computed from the simulated clock).
    limit = t(0.02, 0.02, 0.02, 0.02, 0.02, 0.02)
    robot = SimulatedUR5(ur5, Q0, gate=SafetyGate(ur5, max_joint_speed=limit))
    q0 = robot.read_joints()
    with torch.no_grad():
        needed = (ur5.cartesian_step(q0, t(0.01, 0, 0)) - q0).abs().max() * 0.02 / 0.01
    assert float(needed) > 0.02                  # the unscaled move would break the limit
    realised = robot.move_cartesian(t(0.01, 0, 0), speed=0.02)
    assert torch.allclose(realised, t(0.01, 0, 0), atol=1e-9)
    times, qs = robot.trajectory()
    speed = (qs[1] - qs[0]).abs() / (times[1] - times[0])
    assert bool((speed <= limit * (1 + 1e-9)).all()) and float(speed.max()) == pytest.approx(0.02, rel=1e-9)


def test_workspace_box_is_checked_along_the_path(ur5):
    # Swinging the base moves the fingertip on an arc: a box around the chord holds both ends, not the arc.
    q_start, q_end = t(*Q0), t(*Q0)
    q_end[0] = 2.5
    ends = ur5.position(torch.stack([q_start, q_end]))
    mid = ur5.position((q_start + q_end) / 2)
    lo, hi = ends.min(0).values - 1e-3, ends.max(0).values + 1e-3
    assert not bool(((mid >= lo) & (mid <= hi)).all())          # precondition: the arc leaves the box
    robot = SimulatedUR5(ur5, Q0, SafetyGate(ur5, workspace_lower=lo.tolist(), workspace_upper=hi.tolist()))
    assert_refused(robot, lambda: robot.move_joints(q_end), "workspace box")
    # A step that would cross the floor of a box is refused, one that stays inside is executed.
    z = float(robot.tool_position()[2])
    robot2 = SimulatedUR5(ur5, Q0, SafetyGate(ur5, workspace_lower=(-1, -1, z - 0.005), workspace_upper=(1, 1, 1)))
    robot2.move_cartesian(t(0, 0, -0.004))
    assert_refused(robot2, lambda: robot2.move_cartesian(t(0, 0, -0.004)), "workspace box")


def test_a_step_the_ik_cannot_realise_is_refused_not_bent(ur5):
    robot = SimulatedUR5(ur5, [0.0, -1.2, 0.0, -1.9, -1.5, 0.0])   # elbow stretched: cannot reach further out
    p = robot.tool_position()
    outward = p / p.norm()
    assert_refused(robot, lambda: robot.move_cartesian(0.01 * outward), "instead of")


def test_bad_gate_configuration():
    ur5 = UR5()
    with pytest.raises(ValueError, match="workspace"):
        SafetyGate(ur5, workspace_lower=(0, 0, 0), workspace_upper=(1, -1, 1))
    with pytest.raises(ValueError, match="speed"):
        SafetyGate(ur5, max_joint_speed=10.0)
    with pytest.raises(ValueError, match="limits"):
        SimulatedUR5(ur5, [0, 0, 7.0, 0, 0, 0])


class FakeControl:
    def __init__(self, receive):
        self.receive, self.calls = receive, []

    def moveJ(self, q, speed, acceleration):
        self.calls.append(("moveJ", list(q), speed, acceleration))
        self.receive.q = list(q)
        return True

    def stopJ(self, a):
        self.calls.append(("stopJ", a))

    def stopScript(self):
        self.calls.append(("stopScript",))

    def disconnect(self):
        self.calls.append(("disconnect",))


class FakeReceive:
    def __init__(self, q):
        self.q, self.protective, self.emergency = list(q), False, False

    def getActualQ(self):
        return list(self.q)

    def isProtectiveStopped(self):
        return self.protective

    def isEmergencyStopped(self):
        return self.emergency

    def disconnect(self):
        pass


def rtde(ur5):
    rec = FakeReceive(Q0)
    ctl = FakeControl(rec)
    return RTDEUR5("192.0.2.1", ur5, control=ctl, receive=rec, acceleration=0.4), ctl, rec


def test_rtde_backend_sends_checked_movej(ur5):
    robot, ctl, rec = rtde(ur5)
    p0 = robot.tool_position()
    robot.move_cartesian(t(0.0, 0.01, 0.0), speed=0.02)
    (name, q, speed, acc), = ctl.calls
    assert name == "moveJ" and acc == 0.4 and 0 < speed <= float(robot.gate.max_joint_speed.min())
    assert torch.allclose(ur5.position(t(*q)) - p0, t(0, 0.01, 0), atol=1e-9)
    robot.stop()
    robot.close()
    assert [c[0] for c in ctl.calls[1:]] == ["stopJ", "stopScript", "disconnect"]


def test_rtde_backend_refuses_unsafe_or_inconsistent_states(ur5):
    robot, ctl, rec = rtde(ur5)
    with pytest.raises(SafetyViolation):
        robot.move_cartesian(t(0.1, 0, 0))
    assert ctl.calls == []
    rec.protective = True
    with pytest.raises(RobotError, match="protective"):
        robot.move_cartesian(t(0.01, 0, 0))
    rec.protective = False
    robot.move_cartesian(t(0.01, 0, 0))
    rec.q[0] += 0.05                      # someone moved the arm between commands
    with pytest.raises(RobotError, match="moved"):
        robot.move_cartesian(t(0.01, 0, 0))
    assert len(ctl.calls) == 1


@pytest.mark.skipif(importlib.util.find_spec("rtde_control") is not None, reason="ur_rtde is installed")
def test_rtde_without_ur_rtde_names_the_extra(ur5):
    import kinematics  # importing works without ur_rtde  # noqa: F401
    with pytest.raises(ImportError, match=r"torch_gpioius\[robot\]"):
        RTDEUR5("192.0.2.1", ur5)

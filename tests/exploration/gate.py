"""A check the exploration tests share: the simulated UR5 stayed within its limits and its safety gate."""


def assert_within_the_gate(robot) -> None:
    """Every joint position the simulated UR5 ``robot`` visited is within its limits, every joint speed within the
    safety gate's, and every fingertip position in the gate's workspace."""
    times, qs = robot.trajectory()
    gate = robot.gate
    assert bool(robot.ur5.within_limits(qs).all())
    speed = (qs[1:] - qs[:-1]).abs() / (times[1:] - times[:-1]).clamp_min(1e-12)[:, None]
    assert float(speed.max()) <= float(gate.max_joint_speed.max()) + 1e-9
    assert bool(gate.in_workspace(robot.ur5.position(qs)).all())

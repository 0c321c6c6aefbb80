"""Contact controller on the simulated UR5 and simulated sensor: contact band, sliding, every fault."""

import pytest
import torch

from kinematics import UR5, SimulatedUR5
from torch_gpioius.exploration.contact import ContactConfig, ContactController, ContactFault
from torch_gpioius.sensors import ForceFieldContact, SimulatedForceSensor, SphereSDF

Q0 = [0.0, -1.2, 1.5, -1.9, -1.57, 0.0]
R_IN, R_OUT = 0.10, 0.13


def setup(faults=None, with_object=True, **sensor_kw):
    ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))
    robot = SimulatedUR5(ur5, Q0)
    p0 = robot.tool_position()
    center = p0 - torch.tensor([0.0, 0.0, R_OUT + 0.02], dtype=torch.float64)   # sphere 2 cm below the tip
    if not with_object:
        center = center - 1.0
    world = ForceFieldContact(SphereSDF(center, R_IN), SphereSDF(center, R_OUT))
    sensor = SimulatedForceSensor(world, robot.read_pose, clock=lambda: robot.time, faults=faults, **sensor_kw)
    return robot, sensor, ContactController(robot, sensor), center


DOWN = torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64)


def test_approach_reaches_the_inner_surface_through_the_cover():
    robot, sensor, ctl, c = setup()
    r = ctl.approach(DOWN)
    f = float(r.forces[-1].norm())
    assert r.in_contact and 1.0 <= f <= 5.0
    depth = R_IN - float((r.contact - c).norm())       # penetration into the inner sphere
    assert 0.0 < depth <= 0.005 + 1e-9                  # 1000 N/m: 1..5 N is 1..5 mm
    # free space: every point passed with |F| < 1 N lies outside the inner sphere (some inside the cover)
    d = (r.free_space - c).norm(dim=-1)
    assert bool((d > R_IN - 1e-3).all()) and bool((d < R_OUT).any())
    assert torch.allclose(r.force_normal, (r.contact - c) / (r.contact - c).norm(), atol=1e-6)


def test_slide_keeps_contact_and_moves_tangentially():
    robot, sensor, ctl, c = setup()
    ctl.approach(DOWN)
    for _ in range(6):
        p = robot.tool_position()
        n = (p - c) / (p - c).norm()
        r = ctl.slide(torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64), n)
        assert r.in_contact and 1.0 <= float(r.forces[-1].norm()) <= 5.0
        assert abs(float((r.contact - c).norm()) - R_IN) < 0.005
    # it went around the sphere: the contact moved along +x by several centimetres
    assert float(robot.tool_position()[0] - (c[0])) > 0.04


def test_lost_contact_is_reported_not_forced():
    robot, sensor, ctl, c = setup(with_object=False)
    r = ctl.approach(DOWN, max_travel=0.03)
    assert not r.in_contact and r.free_space.shape[0] == r.path.shape[0]
    r = ctl.slide(torch.tensor([0.005, 0.0, 0.0], dtype=torch.float64), -DOWN)
    assert not r.in_contact


def test_retreats_while_force_is_above_five_newtons():
    robot, sensor, ctl, c = setup()
    ctl.approach(DOWN)
    # push 6 mm deeper by hand (12 N with the 1000 N/m model's 1..5 mm band): the controller backs off
    robot.move_cartesian(torch.tensor([0.0, 0.0, -0.006], dtype=torch.float64))
    p = robot.tool_position()
    n = (p - c) / (p - c).norm()
    r = ctl.slide(torch.tensor([0.002, 0.0, 0.0], dtype=torch.float64), n)
    assert r.in_contact and float(r.forces[-1].norm()) <= 5.0
    assert any(float(f.norm()) > 5.0 for f in r.forces)


@pytest.mark.parametrize("fault, match, retreats", [
    ("stale", "stale", False),
    ("timeout", "no frame", False),
    ("checksum", "checksum", False),
    ("disconnect", "disconnected", False),
    ("overload", "overloaded on Fz", True),
    ("spike", "force", True),
])
def test_every_fault_stops_or_retreats_and_raises(fault, match, retreats):
    robot, sensor, ctl, c = setup()
    ctl.approach(DOWN)
    p_before = robot.tool_position()
    n = (p_before - c) / (p_before - c).norm()
    sensor.faults[sensor._reads + 2] = fault          # two readings into the next step
    with pytest.raises(ContactFault, match=match) as info:
        ctl.slide(torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64), n)
    assert robot.stopped
    _, qs = robot.trajectory()
    last_move = robot.ur5.position(qs[-1]) - robot.ur5.position(qs[-2])
    if retreats:   # the last motion was the retreat: 5 mm along the step's normal
        assert "retreated 5.0 mm" in str(info.value)
        assert torch.allclose(last_move, ctl.config.retreat_distance * n, atol=1e-9)
    else:          # no motion after the fault: the last command was an ordinary sub-step or normal step
        assert "robot stopped" in str(info.value)
        assert float(last_move.norm()) <= ctl.config.tangential_step + 1e-9


def test_readings_older_than_the_limit_are_stale():
    robot, sensor, ctl, c = setup()
    sensor.clock = lambda: 0.0                # sensor stops time-stamping while the robot's clock runs
    robot.time = 1.0
    with pytest.raises(ContactFault, match="ms old"):
        ctl.approach(DOWN)


def test_config_validation():
    with pytest.raises(ValueError):
        ContactConfig(contact_force=6.0)
    with pytest.raises(ValueError, match="normal_step"):
        ContactConfig(normal_step=0.0)
    robot, sensor, ctl, c = setup()
    with pytest.raises(ValueError, match="normal"):
        ctl.slide(torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64), torch.zeros(3, dtype=torch.float64))


def test_an_approach_that_starts_in_the_contact_band_reports_the_measured_normal():
    """No move is needed when the fingertip already presses with 1-5 N (e.g. a tap's re-approach that the cover
    never let go of): the result still carries the measured force, so its normal is the sensor's, not a zero
    vector that the next slide would refuse."""
    robot, sensor, ctl, c = setup(noise_std=0.0)
    first = ctl.approach(DOWN)
    assert first.in_contact
    again = ctl.approach(DOWN)                       # already in the band: nothing to move
    assert again.in_contact and again.travel == 0.0
    assert torch.allclose(again.force_normal, first.force_normal, atol=1e-9)
    assert float(again.force_normal.norm()) == pytest.approx(1.0)
    ctl.slide(torch.tensor([0.005, 0.0, 0.0], dtype=torch.float64), again.force_normal)   # usable as is

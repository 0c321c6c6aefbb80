"""The force-field world's support plane: nothing passes the table the object stands on (issue 33, item 7)."""

import numpy as np
import pytest
import torch

from torch_gpioius.contact import ContactConfig, ContactController
from torch_gpioius.sim.forcefield import Scene3D, sphere_scene


def _beside_and_down(scene):
    """Move the fingertip 20 cm to the side of the sphere, then approach straight down for 50 cm."""
    hw = scene.hardware()
    for _ in range(2):
        hw.controller.lift(torch.tensor([-1.0, 0.0, 0.0]), step=0.002, extra=0.1, max_distance=0.1)
    return hw, hw.controller.approach(torch.tensor([0.0, 0.0, -1.0]), max_travel=0.5)


def test_the_fingertip_stops_on_the_table_the_sphere_stands_on():
    scene = sphere_scene()
    table = 0.25 - 0.08
    assert scene.support == pytest.approx(table, abs=1e-3)         # the icosphere's lowest vertex
    hw, down = _beside_and_down(scene)
    assert not down.in_contact                                     # no force: the table is no contact
    z = down.path[:, 2].numpy()
    assert z.min() >= scene.support - 1e-9 and z.min() == pytest.approx(scene.support, abs=1e-9)
    assert float(hw.robot.tool_position()[2]) >= scene.support - 1e-9


def test_without_a_table_the_same_move_passes_under_the_object_until_the_gate_stops_it():
    s = sphere_scene()
    bare = Scene3D(s.inner, s.outer, s.start, s.direction, s.range, support=None)
    from kinematics import SafetyViolation

    with pytest.raises(SafetyViolation, match="workspace"):
        _beside_and_down(bare)


def test_bad_supports_are_refused():
    s = sphere_scene()
    for bad in (s.support + 0.01, "table", float("nan"), True):
        with pytest.raises(ValueError, match="support"):
            Scene3D(s.inner, s.outer, s.start, s.direction, s.range, support=bad)
    with pytest.raises(ValueError, match="ContactConfig.floor"):
        ContactConfig(floor=float("inf"))
    low = Scene3D(s.inner, s.outer, s.start, s.direction, s.range, support=s.support - 0.02)
    assert low.fingerprint() != s.fingerprint()


def test_the_floor_keeps_a_round_fingertip_above_the_table():
    class Robot:
        def __init__(self):
            self.p = torch.tensor([0.0, 0.0, 0.1], dtype=torch.float64)

        def read_pose(self):
            T = torch.eye(4, dtype=torch.float64)
            T[:3, 3] = self.p
            return T

        def move_cartesian(self, dx, speed):
            self.p = self.p + dx

    ctl = ContactController(Robot(), sensor=None, config=ContactConfig(floor=0.05, tip_radius=0.01))
    assert torch.allclose(ctl._above_floor(torch.tensor([0.01, 0.0, -0.1], dtype=torch.float64)),
                          torch.tensor([0.01, 0.0, -0.04], dtype=torch.float64))
    up = torch.tensor([0.0, 0.02, 0.01], dtype=torch.float64)
    assert torch.equal(ctl._above_floor(up), up)


"""The real robot's world sizes the estimator's settings to the box its object lies in (its exploration range, or
a reference world's body), as a bag import sizes them to its crop box: checked against the rules' values written
out here, on a simulated UR5 behind the same world class."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

import torch_gpioius as tg
from kinematics import UR5, SafetyGate, SimulatedUR5, tool_rotation
from torch_gpioius.exploration.config import ExploreConfig
from torch_gpioius.sensors.simulated import ForceFieldContact, SimulatedForceSensor, SphereSDF


class _NoCamera:
    def capture(self):                  # never called: the configuration alone is built
        raise AssertionError("no capture expected")


def _world(half: float, reference=None) -> tg.RobotWorld:
    ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))
    centre = np.array([0.45, 0.0, 0.15])
    gate = SafetyGate(ur5, (centre - 0.3).tolist(), (centre + 0.4).tolist(), max_tool_speed=0.05,
                      max_cartesian_step=0.02)
    pose = torch.eye(4, dtype=torch.float64)
    pose[:3, :3] = tool_rotation((0.0, 0.0, -1.0))
    pose[:3, 3] = torch.as_tensor(centre + [0.0, 0.0, 0.2])
    q_home = torch.tensor([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], dtype=torch.float64)
    robot = SimulatedUR5(ur5, ur5.inverse_kinematics(pose, q_init=q_home), gate)
    body = SphereSDF(torch.as_tensor(centre), 0.06)
    sensor = SimulatedForceSensor(ForceFieldContact(body, SphereSDF(torch.as_tensor(centre), 0.07)), robot.read_pose,
                                  clock=lambda: robot.time)
    return tg.RobotWorld(robot, sensor, _NoCamera(), direction=(0.0, 0.0, -1.0),
                         bounds=[centre - half, centre + half], reference=reference)


@pytest.mark.parametrize("half, length, voxel", [(0.12, 0.048, 0.024), (0.5, 0.10, 0.05)])
def test_the_default_settings_are_sized_to_the_exploration_range(half, length, voxel):
    world = _world(half)
    assert world.object_extent == pytest.approx(2 * half, abs=1e-12)
    config = ExploreConfig.from_world(world, "visual-tactile", settings="default")
    assert config.estimator.lengthscale == pytest.approx(length, abs=1e-12)
    assert config.estimator.labels.voxel == pytest.approx(voxel, abs=1e-12)
    # the world's own defaults (the paper's robot study) stay as they are: no rule to apply
    assert ExploreConfig.from_world(world, "visual-tactile").estimator.lengthscale == pytest.approx(0.15)


def test_a_reference_world_gives_its_body_s_extent():
    reference = SimpleNamespace(object_extent=0.3)           # a world with the scanned body: its extent alone is read
    assert _world(0.12, reference=reference).object_extent == pytest.approx(0.3)
    assert _world(0.12, reference=SimpleNamespace(object_extent=None)).object_extent == pytest.approx(0.24)

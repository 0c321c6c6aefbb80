"""The simulated sensors, in one place: a fingertip force sensor over a force field (:mod:`.force`, with the faults a
real one has), a depth camera that casts rays at a mesh (:mod:`.camera`, with a calibration error and lost pixels:
:class:`CameraError`) and a DIGIT-like gel pad (:mod:`.gelpad`). Each answers the interface of its real counterpart
(:class:`~torch_gpioius.sensors.base.ForceSensor`, :class:`~torch_gpioius.sensors.pointcloud.PointCloudSource`,
:class:`~torch_gpioius.sensors.tactile.TactileReading`), so a world built on them runs the same loop as the robot.
The MuJoCo world renders its own camera and reads its own contacts (:mod:`torch_gpioius.sim.mujoco.hardware`)."""

from .camera import AppliedCameraError, CameraError, SimulatedDepthCamera
from .force import FAULTS, ForceFieldContact, SignedDistance, SimulatedForceSensor, SphereSDF
from .gelpad import SimulatedGelPad, pad_pose

__all__ = ["SimulatedForceSensor", "ForceFieldContact", "SphereSDF", "SignedDistance", "FAULTS",
           "SimulatedDepthCamera", "CameraError", "AppliedCameraError", "SimulatedGelPad", "pad_pose"]

"""Sensors behind one interface each, registered by name (:data:`SENSORS`, :func:`register_sensor`): force sensors (the
OptoForce USB DAQ over pyserial, a simulated fingertip sensor), tactile pads (DIGIT/GelSight depth maps,
:mod:`.tactile`) and point-cloud sources (recorded PLY/PCD/XYZ/NPZ files are read by
:class:`torch_gpioius.io.FilePointCloud`). ``import torch_gpioius.sensors`` works without pyserial; constructing
:class:`OptoForceDAQ` on a real port then raises an ImportError naming the ``sensors`` extra.

The simulated sensors of the worlds (a fingertip force sensor, a depth camera with its errors, a gel pad) live in one
place, :mod:`.simulated`; the MuJoCo world's own renderers stay with it (:mod:`torch_gpioius.sim.mujoco.hardware`)."""

from .base import (
    ChecksumStorm,
    ForceReading,
    ForceSensor,
    SensorDisconnected,
    SensorError,
    SensorStale,
    SensorTimeout,
    decode_status,
)
from .pointcloud import MultiViewSource, PinholeCamera, PointCloud, PointCloudSource, look_at
from .optoforce import FrameParser, OptoForceDAQ, encode_config, encode_frame
from .simulated import (FAULTS, CameraError, ForceFieldContact, SimulatedDepthCamera, SimulatedForceSensor,
                        SimulatedGelPad, SphereSDF)
from .registry import SENSORS, SensorEntry, register_sensor
from .tactile import (DIGIT_CALIBRATION, DepthMapTactileSensor, DigitTactileSensor, TactileCalibration, TactileReading,
                      TactileSensor, depth_from_image_message)

__all__ = ["ForceReading", "ForceSensor", "SensorError", "SensorTimeout", "SensorDisconnected", "ChecksumStorm",
           "SensorStale", "decode_status", "OptoForceDAQ", "FrameParser", "encode_config", "encode_frame",
           "SimulatedForceSensor", "ForceFieldContact", "SphereSDF", "FAULTS", "PointCloud", "PointCloudSource",
           "MultiViewSource", "PinholeCamera", "SimulatedDepthCamera", "CameraError", "SimulatedGelPad", "look_at",
           "TactileCalibration", "TactileReading", "TactileSensor", "DepthMapTactileSensor", "DigitTactileSensor",
           "depth_from_image_message",
           "DIGIT_CALIBRATION", "SENSORS", "SensorEntry", "register_sensor"]


def __getattr__(name):
    if name == "FilePointCloud":          # forwarded to io until 0.3; reading files is io's business
        raise AttributeError("torch_gpioius.sensors.FilePointCloud moved to torch_gpioius.io.FilePointCloud (the "
                             "forward from sensors is gone: sensors no longer imports io)")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

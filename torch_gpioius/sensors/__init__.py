"""Sensors behind one interface each: force sensors (the OptoForce USB DAQ over pyserial, a simulated fingertip
sensor) and point-cloud sources (a simulated depth camera, recorded PLY/PCD/XYZ/NPZ files).

``import torch_gpioius.sensors`` works without pyserial; constructing :class:`OptoForceDAQ` on a real port
then raises an ImportError naming the ``sensors`` extra.
"""

from .base import (ChecksumStorm, ForceReading, ForceSensor, SensorDisconnected, SensorError, SensorStale, SensorTimeout,
                   decode_status)
from .pointcloud import (FilePointCloud, PinholeCamera, PointCloud, PointCloudSource, SimulatedDepthCamera,
                         look_at)
from .optoforce import FrameParser, OptoForceDAQ, encode_config, encode_frame
from .simulated import FAULTS, PenaltyContact, SimulatedForceSensor, SphereSDF

__all__ = ["ForceReading", "ForceSensor", "SensorError", "SensorTimeout", "SensorDisconnected", "ChecksumStorm", "SensorStale",
           "decode_status", "OptoForceDAQ", "FrameParser", "encode_config", "encode_frame", "SimulatedForceSensor",
           "PenaltyContact", "SphereSDF", "FAULTS", "PointCloud", "PointCloudSource", "FilePointCloud",
           "PinholeCamera", "SimulatedDepthCamera", "look_at"]

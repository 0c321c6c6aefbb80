"""Force sensors behind one interface: the OptoForce USB DAQ (pyserial) and a simulated fingertip sensor.

``import torch_gpioius.sensors`` works without pyserial; constructing :class:`OptoForceDAQ` on a real port
then raises an ImportError naming the ``sensors`` extra.
"""

from .base import (ChecksumStorm, ForceReading, ForceSensor, SensorDisconnected, SensorError, SensorTimeout,
                   decode_status)
from .optoforce import FrameParser, OptoForceDAQ, encode_config, encode_frame
from .simulated import FAULTS, PenaltyContact, SimulatedForceSensor, SphereSDF

__all__ = ["ForceReading", "ForceSensor", "SensorError", "SensorTimeout", "SensorDisconnected", "ChecksumStorm",
           "decode_status", "OptoForceDAQ", "FrameParser", "encode_config", "encode_frame", "SimulatedForceSensor",
           "PenaltyContact", "SphereSDF", "FAULTS"]

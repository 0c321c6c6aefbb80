"""Sensors by name: force sensors, tactile pads and point-cloud sources, each with what it measures and whether it
is hardware (:mod:`torch_gpioius.core.registry`). A sensor of one's own registers here so that the docs' tables,
a world's ``describe()`` and the tools that list the sensors know it::

    register_sensor("ati_nano17", AtiNano17, measures="force", hardware=True, description="ATI Nano17 over NetFT")
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.registry import Entry, Registry
from .base import ForceSensor
from .optoforce import OptoForceDAQ
from .pointcloud import MultiViewSource, PointCloudSource
from .simulated import SimulatedDepthCamera
from .simulated import SimulatedForceSensor
from .tactile import DepthMapTactileSensor, DigitTactileSensor

__all__ = ["SENSORS", "SensorEntry", "register_sensor", "MEASURES"]

#: What a sensor measures: a force at the fingertip, a tactile pad's depth map, or a point cloud.
MEASURES = ("force", "tactile", "cloud")


@dataclass
class SensorEntry(Entry):
    """A registered sensor.

    Attributes:
        measures: "force" (a :class:`~torch_gpioius.sensors.ForceSensor`), "tactile" (a
            :class:`~torch_gpioius.sensors.TactileSensor`) or "cloud" (a
            :class:`~torch_gpioius.sensors.PointCloudSource`).
        hardware: True for a driver of a real device, False for a simulated or recorded one.
    """

    measures: str = "force"
    hardware: bool = False


#: Every sensor by name.
SENSORS: Registry[type] = Registry("sensor", entry_type=SensorEntry)


def register_sensor(name: str, cls: type, *, measures: str, hardware: bool, aliases=(), description: str = "") -> type:
    """Register a sensor class under ``name``; returns ``cls``.

    Raises:
        ValueError: ``measures`` is not one of :data:`MEASURES`, a force sensor or point-cloud source that does not
            subclass its interface, or a name taken by another class.
    """
    if measures not in MEASURES:
        raise ValueError(f"register_sensor: measures must be one of {MEASURES}, got {measures!r}")
    base = {"force": ForceSensor, "cloud": PointCloudSource}.get(measures)
    if base is not None and not (isinstance(cls, type) and issubclass(cls, base)):
        raise ValueError(f"register_sensor: a {measures} sensor subclasses {base.__name__}; {cls!r} does not")
    if measures == "tactile" and not callable(getattr(cls, "read", None)):
        raise ValueError(f"register_sensor: a tactile sensor reads depth maps (read()); {cls!r} has no read")
    SENSORS.register(name, cls, measures=measures, hardware=bool(hardware), aliases=aliases, description=description)
    return cls


register_sensor("optoforce", OptoForceDAQ, measures="force", hardware=True,
                description="OptoForce 3-axis sensor over its USB DAQ (the paper's)")
register_sensor("simulated_force", SimulatedForceSensor, measures="force", hardware=False,
                description="a fingertip force from a simulated contact model")
register_sensor("digit", DigitTactileSensor, measures="tactile", hardware=True,
                description="a DIGIT gel pad (digit-interface), depth from its image")
register_sensor("depth_map", DepthMapTactileSensor, measures="tactile", hardware=False,
                description="a tactile pad whose depth maps come from a function (simulated or recorded)")
register_sensor("simulated_depth_camera", SimulatedDepthCamera, measures="cloud", hardware=False,
                description="a pinhole depth camera ray-cast against meshes")
register_sensor("multi_view", MultiViewSource, measures="cloud", hardware=False,
                description="several point-cloud sources captured as one (cameras on tripods, a wrist camera)")

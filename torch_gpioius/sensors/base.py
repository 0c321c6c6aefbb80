"""The force-sensor interface, its reading type and its errors."""

from __future__ import annotations

import abc
from dataclasses import dataclass

import torch

__all__ = ["ForceReading", "ForceSensor", "SensorError", "SensorTimeout", "SensorDisconnected", "ChecksumStorm",
           "SensorStale", "decode_status", "STATUS_OVERLOAD_MASK", "STATUS_ERROR_MASK"]

# OptoForce DAQ status word (16 bits), as documented for the DAQ: bits 15-13 DAQ error code (1 DAQ error,
# 2 communication error), bits 12-10 sensor error code (1 not detected, 2 failure, 4 temperature), bits 9-4
# overload flags for Fx, Fy, Fz, Tx, Ty, Tz, bit 3 "several sensors have errors", bits 2-0 the sensor number.
STATUS_ERROR_MASK = 0b1111_1100_0000_0000
STATUS_OVERLOAD_MASK = 0b0000_0011_1111_0000
_DAQ_ERRORS = {1: "DAQ error", 2: "communication error"}
_SENSOR_ERRORS = {1: "sensor not detected", 2: "sensor failure", 4: "temperature error"}
_AXES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")


def decode_status(status: int) -> tuple[list[str], list[str]]:
    """Split an OptoForce status word into (errors, overloaded axes), both lists of names.

    Example:
        >>> decode_status((2 << 13) | (1 << 7))
        (['communication error'], ['Fz'])
    """
    errors = []
    daq, sensor = (status >> 13) & 0b111, (status >> 10) & 0b111
    if daq:
        errors.append(_DAQ_ERRORS.get(daq, f"DAQ error code {daq}"))
    if sensor:
        errors.append(_SENSOR_ERRORS.get(sensor, f"sensor error code {sensor}"))
    overloaded = [axis for i, axis in enumerate(_AXES) if (status >> (9 - i)) & 1]
    return errors, overloaded


@dataclass(frozen=True)
class ForceReading:
    """One timestamped force sample.

    Attributes:
        force: `(3,)` float64 force on the fingertip in the *sensor* frame [N].
        status: the raw 16-bit status word (0 = all well).
        counter: the sensor's sample counter (16-bit, wraps); equal counters mean no new sample.
        timestamp: host monotonic time at which the sample was received [s].
    """

    force: torch.Tensor
    status: int
    counter: int
    timestamp: float

    @property
    def magnitude(self) -> float:
        """``|F|`` [N]."""
        return float(self.force.norm())

    @property
    def errors(self) -> list[str]:
        """Names of the DAQ/sensor errors flagged in ``status`` (empty when none)."""
        return decode_status(self.status)[0]

    @property
    def overloaded(self) -> list[str]:
        """Axes flagged as overloaded in ``status`` (empty when none)."""
        return decode_status(self.status)[1]

    @property
    def ok(self) -> bool:
        """True when the status flags neither an error nor an overload."""
        return self.status & (STATUS_ERROR_MASK | STATUS_OVERLOAD_MASK) == 0


class SensorError(RuntimeError):
    """A force sensor failed in a way the caller must act on (stop or retreat)."""


class SensorTimeout(SensorError):
    """No valid sample arrived within the timeout."""


class SensorDisconnected(SensorError):
    """The sensor's connection was lost."""


class ChecksumStorm(SensorError):
    """Too many consecutive frames failed their checksum: the link is corrupt."""


class SensorStale(SensorError):
    """The sensor's own sample counter did not advance: the device is frozen or repeats old samples."""


class ForceSensor(abc.ABC):
    """A 3-axis force sensor: timestamped readings in newtons in the sensor frame, tare, status."""

    @abc.abstractmethod
    def read(self) -> ForceReading:
        """The newest sample.

        Raises:
            SensorTimeout, SensorDisconnected, ChecksumStorm: see the classes.
        """

    @abc.abstractmethod
    def tare(self) -> None:
        """Zero the sensor at the current load (the fingertip must be free of contact)."""

    @property
    def status(self) -> int:
        """Status word of the last reading (0 before any)."""
        return getattr(self, "_last_status", 0)

    def close(self) -> None:
        """Release the connection (no-op by default)."""

    def __enter__(self) -> "ForceSensor":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

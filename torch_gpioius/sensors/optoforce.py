"""OptoForce 3-axis USB DAQ driver over pyserial.

Written here rather than wrapping the ``optoforce`` package (0.3.0): we need resynchronisation after
garbage with counts of what was skipped, checksum-storm and disconnect errors the contact controller can act
on, host timestamps and "newest sample" reads at 1 kHz; that package exposes none of these.

Protocol (OptoForce DAQ, 3-axis sensors; 1,000,000 baud, 8N1):

* configuration frame, host -> DAQ, 9 bytes: ``AA 00 32 03 speed filter zero`` + 16-bit big-endian
  checksum = sum of bytes 0-6. ``speed``: 0 stop, 1 (1 kHz), 3 (333 Hz), 10 (100 Hz), 33 (30 Hz),
  100 (10 Hz). ``filter``: 0 none, 1..6 = 500, 150, 50, 15, 5, 1.5 Hz low-pass. ``zero``: 255 zeroes the
  sensor at the current load, 0 restores the raw offset.
* data frame, DAQ -> host, 16 bytes: ``AA 07 08 0A``, counter (uint16), status (uint16), Fx, Fy, Fz
  (int16 counts), checksum (uint16) = sum of bytes 0-13; all big-endian.

Counts become newtons through the per-axis sensitivities on the sensor's calibration sheet (counts/N).
"""

from __future__ import annotations

import importlib
import math
import struct
import time
from dataclasses import dataclass
from typing import Any, Sequence

import torch

from .base import ChecksumStorm, ForceReading, ForceSensor, SensorDisconnected, SensorStale, SensorTimeout

__all__ = ["OptoForceDAQ", "FrameParser", "RawFrame", "encode_config", "encode_frame", "DATA_HEADER",
           "CONFIG_HEADER", "SPEED_CODES", "FILTER_CODES"]

DATA_HEADER = bytes([0xAA, 0x07, 0x08, 0x0A])
CONFIG_HEADER = bytes([0xAA, 0x00, 0x32, 0x03])
FRAME_LENGTH = 16
#: sample rate [Hz] -> speed byte
SPEED_CODES = {0: 0, 1000: 1, 333: 3, 100: 10, 30: 33, 10: 100}
#: low-pass cut-off [Hz] (None = no filter) -> filter byte
FILTER_CODES = {None: 0, 500: 1, 150: 2, 50: 3, 15: 4, 5: 5, 1.5: 6}


def _checksum(data: bytes) -> int:
    return sum(data) & 0xFFFF


def encode_config(speed: int = 1, filter: int = 0, zero: int = 0) -> bytes:
    """The 9-byte configuration frame ``AA 00 32 03 speed filter zero`` + checksum."""
    for name, v in (("speed", speed), ("filter", filter), ("zero", zero)):
        if not 0 <= int(v) <= 255:
            raise ValueError(f"config {name} byte must be in 0..255, got {v}")
    body = CONFIG_HEADER + bytes([speed, filter, zero])
    return body + struct.pack(">H", _checksum(body))


def encode_frame(counter: int, status: int, counts: Sequence[int]) -> bytes:
    """The 16-byte data frame for (counter, status, (Fx, Fy, Fz) counts); used by fake DAQs in tests."""
    body = DATA_HEADER + struct.pack(">HHhhh", counter & 0xFFFF, status & 0xFFFF, *counts)
    return body + struct.pack(">H", _checksum(body))


@dataclass(frozen=True)
class RawFrame:
    """A decoded data frame: sample counter, status word, (Fx, Fy, Fz) in counts."""

    counter: int
    status: int
    counts: tuple[int, int, int]


class FrameParser:
    """Incremental parser: bytes in, valid frames out; resynchronises on the header after garbage.

    Attributes:
        bad_checksums: frames dropped for a wrong checksum, in total.
        consecutive_bad: checksum failures since the last valid frame.
        skipped_bytes: bytes discarded while searching for a header.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.bad_checksums = 0
        self.consecutive_bad = 0
        self.skipped_bytes = 0

    def feed(self, data: bytes) -> list[RawFrame]:
        """Append ``data`` and return every complete, valid frame in arrival order."""
        self._buf += data
        out: list[RawFrame] = []
        while True:
            i = self._buf.find(DATA_HEADER)
            if i < 0:
                keep = len(DATA_HEADER) - 1  # a header may straddle the next chunk
                drop = max(0, len(self._buf) - keep)
                self.skipped_bytes += drop
                del self._buf[:drop]
                return out
            if i:
                self.skipped_bytes += i
                del self._buf[:i]
            if len(self._buf) < FRAME_LENGTH:
                return out
            frame = bytes(self._buf[:FRAME_LENGTH])
            (want,) = struct.unpack(">H", frame[14:16])
            if _checksum(frame[:14]) != want:
                self.bad_checksums += 1
                self.consecutive_bad += 1
                self.skipped_bytes += 1
                del self._buf[:1]  # resync: search for the next header after this one's first byte
                continue
            counter, status, fx, fy, fz = struct.unpack(">HHhhh", frame[4:14])
            out.append(RawFrame(counter, status, (fx, fy, fz)))
            self.consecutive_bad = 0
            del self._buf[:FRAME_LENGTH]


class OptoForceDAQ(ForceSensor):
    """OptoForce USB DAQ with a 3-axis sensor (e.g. OMD-20-SE-40N), read over a serial port.

    Args:
        port: serial device (``/dev/ttyACM0``, ``COM3``), a pty path, or a pyserial URL (``loop://``).
        sensitivity: `(3,)` counts per newton for Fx, Fy, Fz (calibration sheet).
        rate: sample rate [Hz], one of ``SPEED_CODES``.
        filter_hz: DAQ low-pass cut-off [Hz], one of ``FILTER_CODES`` (None = off).
        timeout: how long :meth:`read` waits for a valid frame [s], in (0, 10].
        max_bad_frames: consecutive checksum failures that raise :class:`ChecksumStorm`, an integer in [1, 10000].
        serial_port: an already-open pyserial-like object (``read``, ``write``, ``in_waiting``, ``close``);
            ``port`` is then only used in messages.

    Raises:
        ImportError: pyserial is missing (``pip install 'torch_gpioius[sensors]'``).
        SensorDisconnected: the port cannot be opened.
    """

    BAUDRATE = 1_000_000

    def __init__(self, port: str, sensitivity: Sequence[float], *, rate: int = 1000, filter_hz: float | None = 15,
                 timeout: float = 0.1, max_bad_frames: int = 20, serial_port: Any = None) -> None:
        sens = torch.as_tensor(sensitivity, dtype=torch.float64)
        if sens.shape != (3,) or not bool(torch.isfinite(sens).all()) or bool((sens <= 0).any()):
            raise ValueError(f"sensitivity must be 3 positive counts-per-newton values, got {sensitivity}")
        if rate not in SPEED_CODES or rate == 0:
            raise ValueError(f"rate must be one of {sorted(k for k in SPEED_CODES if k)} Hz, got {rate}")
        if filter_hz not in FILTER_CODES:
            raise ValueError(f"filter_hz must be one of {list(FILTER_CODES)}, got {filter_hz}")
        if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not (math.isfinite(timeout)
                                                                                     and 0 < timeout <= 10):
            raise ValueError(f"timeout: must be finite and in (0, 10] s, got {timeout!r} (NaN or inf would make "
                             "read() wait forever)")
        if isinstance(max_bad_frames, bool) or not isinstance(max_bad_frames, int) or not 1 <= max_bad_frames <= 10000:
            raise ValueError(f"max_bad_frames: must be an integer in [1, 10000], got {max_bad_frames!r}")
        self.port, self.sensitivity, self.timeout = port, sens, float(timeout)
        self.max_bad_frames = max_bad_frames
        self._speed, self._filter = SPEED_CODES[rate], FILTER_CODES[filter_hz]
        if serial_port is None:
            try:
                serial = importlib.import_module("serial")
            except ImportError as exc:  # pragma: no cover - depends on the environment
                from ..core.extras import install_hint

                raise ImportError(f"OptoForceDAQ needs pyserial: {install_hint('sensors')}") from exc
            try:
                serial_port = serial.serial_for_url(port, baudrate=self.BAUDRATE, timeout=0.005)
            except (OSError, serial.SerialException) as exc:
                raise SensorDisconnected(f"cannot open OptoForce DAQ at {port}: {exc}") from exc
        self._ser = serial_port
        self.parser = FrameParser()
        self._last: ForceReading | None = None
        self._last_status = 0
        self._write(encode_config(self._speed, self._filter, 0))

    def _write(self, data: bytes) -> None:
        try:
            self._ser.write(data)
        except Exception as exc:  # pyserial raises SerialException (an OSError subclass on posix) or OSError
            raise SensorDisconnected(f"OptoForce DAQ at {self.port}: write failed: {exc}") from exc

    def _read_bytes(self) -> bytes:
        try:
            n = self._ser.in_waiting
            return self._ser.read(max(int(n), 1))
        except Exception as exc:
            raise SensorDisconnected(f"OptoForce DAQ at {self.port} disconnected: {exc}") from exc

    def read(self) -> ForceReading:
        """The newest valid sample: drains what has arrived, waits up to ``timeout`` if nothing new has.

        Returns:
            :class:`ForceReading` with force `(3,)` [N] in the sensor frame; check ``.ok``/``.overloaded``.

        Raises:
            SensorTimeout: no valid frame within ``timeout``.
            SensorDisconnected: the port failed (unplugged, closed).
            ChecksumStorm: ``max_bad_frames`` consecutive frames failed their checksum.
            SensorStale: the newest frame carries the same sample counter as the previous read: the DAQ is
                frozen (host time cannot tell, since every read is stamped anew).
        """
        deadline = time.monotonic() + self.timeout
        newest = None
        while True:
            frames = self.parser.feed(self._read_bytes())
            if self.parser.consecutive_bad >= self.max_bad_frames:
                raise ChecksumStorm(f"OptoForce DAQ at {self.port}: {self.parser.consecutive_bad} consecutive "
                                    f"frames with a bad checksum (link corrupt, wrong baud rate?)")
            if frames:
                newest = frames[-1]
                if getattr(self._ser, "in_waiting", 0):
                    continue  # more queued: keep draining so the reading is the newest one
                break
            if time.monotonic() > deadline:
                raise SensorTimeout(f"OptoForce DAQ at {self.port}: no valid frame in {self.timeout * 1e3:.0f} ms")
        if self._last is not None and newest.counter == self._last.counter:
            raise SensorStale(f"OptoForce DAQ at {self.port}: sample counter {newest.counter} repeated; the DAQ is "
                              "frozen or replays old samples")
        force = torch.tensor(newest.counts, dtype=torch.float64) / self.sensitivity
        reading = ForceReading(force, newest.status, newest.counter, time.monotonic())
        self._last, self._last_status = reading, newest.status
        return reading

    def tare(self) -> None:
        """Zero the sensor at the current load (the DAQ's own zeroing, config byte ``zero = 255``)."""
        self._write(encode_config(self._speed, self._filter, 255))

    def untare(self) -> None:
        """Restore the factory offset (config byte ``zero = 0``)."""
        self._write(encode_config(self._speed, self._filter, 0))

    def close(self) -> None:
        try:
            self._write(encode_config(0, self._filter, 0))  # stop streaming
        except SensorDisconnected:
            pass
        try:
            self._ser.close()
        except Exception:  # closing a port that is already gone is not an error worth raising
            pass

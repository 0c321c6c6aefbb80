"""OptoForce DAQ driver against a fake DAQ speaking the protocol over a pseudo-terminal (and loop://)."""

import os
import struct
import threading
import time
import tty

import pytest
import torch

from torch_gpioius.sensors import (
    ChecksumStorm,
    FrameParser,
    OptoForceDAQ,
    SensorDisconnected,
    SensorStale,
    SensorTimeout,
    decode_status,
    encode_config,
    encode_frame,
)

serial = pytest.importorskip("serial")


def frame(counter, status, fx, fy, fz):
    """A data frame built here byte by byte from the documented layout (independent of encode_frame)."""
    body = bytes([0xAA, 0x07, 0x08, 0x0A]) + counter.to_bytes(2, "big") + status.to_bytes(2, "big")
    body += b"".join(v.to_bytes(2, "big", signed=True) for v in (fx, fy, fz))
    return body + (sum(body) & 0xFFFF).to_bytes(2, "big")


def test_encoders_match_the_documented_layout():
    assert encode_frame(513, 0x0080, (1, -2, 300)) == frame(513, 0x0080, 1, -2, 300)
    cfg = encode_config(speed=1, filter=4, zero=255)
    assert cfg[:7] == bytes([0xAA, 0x00, 0x32, 0x03, 1, 4, 255])
    assert struct.unpack(">H", cfg[7:])[0] == sum(cfg[:7])
    with pytest.raises(ValueError):
        encode_config(speed=300)


def test_status_word_decoding():
    assert decode_status(0) == ([], [])
    errors, overloaded = decode_status((2 << 13) | (4 << 10) | (1 << 9) | (1 << 7))
    assert errors == ["communication error", "temperature error"] and overloaded == ["Fx", "Fz"]


def test_parser_handles_splits_garbage_and_bad_checksums():
    frames = [frame(i, 0, i, -i, 2 * i) for i in range(5)]
    corrupt = bytearray(frame(99, 0, 1, 1, 1))
    corrupt[10] ^= 0xFF
    stream = (
        b"\x00\xaa\x07garbage" + frames[0] + frames[1] + bytes(corrupt) + b"\xaa" + frames[2] + frames[3] + frames[4]
    )
    p = FrameParser()
    out = []
    for i in range(len(stream)):                      # one byte at a time: every split point
        out += p.feed(stream[i:i + 1])
    assert [f.counter for f in out] == [0, 1, 2, 3, 4]
    assert out[3].counts == (3, -3, 6)
    assert p.bad_checksums == 1 and p.skipped_bytes >= len(b"\x00\xAA\x07garbage") + 1
    # A header pattern inside a payload does not derail parsing.
    tricky = frame(7, 0, 0xAA07 - 65536, 0x080A, 5)
    assert [f.counter for f in FrameParser().feed(tricky + frames[0])] == [7, 0]


class FakeDAQ:
    """The DAQ side of a pty: streams the bytes a test gives it, records config frames, can hang up."""

    def __init__(self):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self._slave = slave
        self.configs = []

    def send(self, data: bytes, chunk: int | None = None, pause: float = 0.0):
        chunk = chunk or len(data)
        for i in range(0, len(data), chunk):
            os.write(self.master, data[i:i + chunk])
            if pause:
                time.sleep(pause)

    def poll_config(self, quiet: float = 0.2):
        """Read everything the sensor wrote until the line has been quiet for ``quiet`` s, then record its config
        frames. (Stopping at the first short read lost a second frame that arrived a moment later, on a loaded
        machine: a test's own race, not the driver's.)"""
        import select
        data = b""
        while select.select([self.master], [], [], quiet)[0]:
            data += os.read(self.master, 64)
        for i in range(0, len(data) - 8, 9):
            cfg = data[i:i + 9]
            if cfg[:4] == bytes([0xAA, 0x00, 0x32, 0x03]):
                self.configs.append(tuple(cfg[4:7]))

    def hang_up(self):
        os.close(self.master)

    def close(self):
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


@pytest.fixture()
def daq():
    fake = FakeDAQ()
    yield fake
    fake.close()


SENS = (100.0, 50.0, 25.0)   # counts per newton


def test_valid_stream_gives_newtons_and_the_newest_sample(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.5)
    daq.poll_config()
    assert daq.configs == [(1, 4, 0)]                       # 1 kHz, 15 Hz filter, no zeroing
    daq.send(b"".join(frame(i, 0, 100 * i, 50, -25) for i in range(1, 6)))
    time.sleep(0.05)
    r = sensor.read()
    assert r.counter == 5 and r.ok
    assert torch.allclose(r.force, torch.tensor([5.0, 1.0, -1.0], dtype=torch.float64))
    sensor.close()


def test_split_frames_and_garbage_resynchronise(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.5)
    writer = threading.Thread(target=daq.send, args=(b"\x13\x37\xAA" + frame(1, 0, 200, 0, 0),), kwargs=dict(
        chunk=3, pause=0.005))
    writer.start()
    r = sensor.read()
    writer.join()
    assert r.counter == 1 and torch.allclose(r.force, torch.tensor([2.0, 0.0, 0.0], dtype=torch.float64))
    assert sensor.parser.skipped_bytes >= 3


def test_overload_and_error_bits_are_surfaced(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.5)
    daq.send(frame(1, (1 << 7) | (2 << 10), 0, 0, 32767))
    r = sensor.read()
    assert not r.ok and r.overloaded == ["Fz"] and r.errors == ["sensor failure"]
    assert sensor.status == r.status


def test_bad_checksums_are_skipped_and_a_storm_raises(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.3, max_bad_frames=5)
    bad = bytearray(frame(2, 0, 1, 2, 3))
    bad[-1] ^= 1
    daq.send(bytes(bad) + frame(3, 0, 100, 0, 0))
    assert sensor.read().counter == 3 and sensor.parser.bad_checksums == 1
    daq.send(bytes(bad) * 6)
    with pytest.raises(ChecksumStorm, match="consecutive"):
        sensor.read()


def test_timeout_when_the_stream_stops(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.05)
    with pytest.raises(SensorTimeout, match="no valid frame"):
        sensor.read()


def test_disconnect_mid_stream(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.5)
    daq.send(frame(1, 0, 0, 0, 0) + frame(2, 0, 0, 0, 0)[:7])   # the second frame is cut off by the hang-up
    assert sensor.read().counter == 1
    daq.hang_up()
    with pytest.raises(SensorDisconnected, match="disconnected"):
        sensor.read()


def test_tare_sends_the_zeroing_config(daq):
    sensor = OptoForceDAQ(daq.port, SENS, rate=100, filter_hz=None, timeout=0.5)
    sensor.tare()
    daq.poll_config()
    assert daq.configs == [(10, 0, 0), (10, 0, 255)]


def test_loop_url_and_echoed_config_frames_are_skipped():
    port = serial.serial_for_url("loop://", timeout=0.005)
    sensor = OptoForceDAQ("loop://", SENS, serial_port=port, timeout=0.3)   # the config frame echoes back
    port.write(frame(9, 0, 0, 0, 250))
    r = sensor.read()
    assert r.counter == 9 and torch.allclose(r.force, torch.tensor([0.0, 0.0, 10.0], dtype=torch.float64))


def test_a_frozen_daq_repeating_its_counter_is_stale(daq):
    sensor = OptoForceDAQ(daq.port, SENS, timeout=0.3)
    daq.send(frame(42, 0, 100, 0, 0))
    assert sensor.read().counter == 42
    daq.send(frame(42, 0, 100, 0, 0) * 3)              # new bytes, same sample: host time moved, the DAQ did not
    with pytest.raises(SensorStale, match="counter 42 repeated"):
        sensor.read()


@pytest.mark.parametrize("kwargs, match", [(dict(timeout=float("nan")), "timeout"), (dict(timeout=-1), "timeout"),
                                           (dict(timeout=float("inf")), "timeout"), (dict(max_bad_frames=0), "max_bad"),
                                           (dict(max_bad_frames=2.5), "max_bad"), (dict(timeout="0.1"), "timeout")])
def test_settings_that_would_hang_or_always_fail_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        OptoForceDAQ("loop://", SENS, **kwargs)


def test_bad_configuration_and_missing_port():
    with pytest.raises(ValueError, match="sensitivity"):
        OptoForceDAQ("loop://", (1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="rate"):
        OptoForceDAQ("loop://", SENS, rate=500)
    with pytest.raises(SensorDisconnected, match="cannot open"):
        OptoForceDAQ("/dev/does-not-exist-optoforce", SENS)

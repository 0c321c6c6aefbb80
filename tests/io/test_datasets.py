"""Dataset/log format: round trips, torn tails, corruption, versions, bad fields; fuzzed with hypothesis."""

import struct
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import torch_gpioius as tg
from torch_gpioius.io.datasets import FORMAT_VERSION, MAGIC, DatasetError, LogWriter, TornLogWarning, read_records


def write_raw(path, records):
    """A file written record by record without the writers' validation (what another tool might produce)."""
    from torch_gpioius.io.datasets import _encode
    path.write_bytes(MAGIC + struct.pack(">H", FORMAT_VERSION) + b"".join(_encode(*r) for r in records))
    return path


def small_dataset(n=12, d=2):
    rng = np.random.default_rng(0)
    return tg.Dataset(rng.normal(size=(n, d)), rng.integers(0, 2, n), rng.integers(0, 2, n),
                      np.arange(n) // 3, meta={"theta": 0.1, "noise": 0.006, "source": "test"},
                      trace={"positions": rng.normal(size=(5, d)), "forces": rng.normal(size=(5, 3)),
                             "timestamps": np.arange(5.0)})


def test_round_trip(tmp_path):
    ds = small_dataset(d=3)
    p = tg.save_dataset(ds, tmp_path / "a.gpioius")
    back = tg.load_dataset(p)
    for k in ("x", "y", "task", "step"):
        assert np.array_equal(getattr(back, k), getattr(ds, k))
    assert back.meta["units"] == "m" and back.meta["dim"] == 3 and back.meta["source"] == "test"
    assert np.array_equal(back.trace["forces"], ds.trace["forces"])
    assert back.x.dtype == np.float64 and back.task.dtype == np.int64


def log_with_steps(path, n_steps=5):
    with LogWriter(path, {"dim": 2, "theta": 0.1, "noise": 0.006}) as w:
        w.append("step", {"step": 0}, {"x": np.zeros((3, 2)), "y": np.array([0, 1, 1]), "task": np.array([0, 0, 1]),
                                       "removed": np.zeros(0, np.int64)})
        for k in range(1, n_steps):
            w.append("step", {"step": k}, {"x": np.full((1, 2), float(k)), "y": np.zeros(1), "task": np.zeros(1, int),
                                           "removed": np.array([1]) if k == 2 else np.zeros(0, np.int64)})


def test_log_replay_applies_removals_and_arrival_steps(tmp_path):
    p = tmp_path / "log.gpioius"
    log_with_steps(p)
    ds = tg.load_dataset(p)
    # step 2 removed the row at index 1 (the first free-space point), then added (2, 2)
    assert ds.x[:, 0].tolist() == [0.0, 0.0, 1.0, 2.0, 3.0, 4.0]
    assert ds.step.tolist() == [0, 0, 1, 2, 3, 4]
    assert len(tg.load_dataset(p, upto_step=2)) == 4


def test_torn_tail_is_ignored_with_a_warning_and_resume_truncates_it(tmp_path):
    p = tmp_path / "log.gpioius"
    log_with_steps(p)
    blob = p.read_bytes()
    p.write_bytes(blob[:-10])
    with pytest.warns(TornLogWarning, match="cut off"):
        ds = tg.load_dataset(p)
    assert ds.step.max() == 3
    with pytest.raises(DatasetError, match="truncated"):
        list(read_records(p, allow_torn_tail=False))
    with LogWriter(p, resume=True) as w:
        w.append("step", {"step": 4}, {"x": np.ones((1, 2)), "y": np.zeros(1), "task": np.zeros(1, int)})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert tg.load_dataset(p).step.max() == 4


def test_corruption_before_the_tail_is_an_error(tmp_path):
    p = tmp_path / "log.gpioius"
    log_with_steps(p)
    blob = bytearray(p.read_bytes())
    blob[200] ^= 0xFF   # inside the second record
    p.write_bytes(bytes(blob))
    with pytest.raises(DatasetError, match=r"log.gpioius: .*(CRC|corrupt)"):
        tg.load_dataset(p)


def test_versions_magic_and_header(tmp_path):
    p = tg.save_dataset(small_dataset(), tmp_path / "a.gpioius")
    blob = p.read_bytes()
    future = blob[:len(MAGIC)] + struct.pack(">H", FORMAT_VERSION + 1) + blob[len(MAGIC) + 2:]
    (tmp_path / "v.gpioius").write_bytes(future)
    with pytest.raises(DatasetError, match="format version 2 is not supported"):
        tg.load_dataset(tmp_path / "v.gpioius")
    (tmp_path / "m.gpioius").write_bytes(b"PK\x03\x04" + blob[4:])
    with pytest.raises(DatasetError, match="bad magic"):
        tg.load_dataset(tmp_path / "m.gpioius")
    (tmp_path / "e.gpioius").write_bytes(blob[:len(MAGIC) + 2])
    with pytest.raises(DatasetError, match="no header"):
        tg.load_dataset(tmp_path / "e.gpioius")
    with pytest.raises(DatasetError, match="'units' is 'cm'"):     # the writer refuses what the reader would
        LogWriter(tmp_path / "cm.gpioius", {"dim": 2, "units": "cm"})
    write_raw(tmp_path / "cm.gpioius", [("header", {"dim": 2, "units": "cm"}, {})])
    with pytest.raises(DatasetError, match="'units' is 'cm'"):
        tg.load_dataset(tmp_path / "cm.gpioius")
    with LogWriter(tmp_path / "empty.gpioius", {"dim": 2}):
        pass
    with pytest.raises(DatasetError, match="no observations"):
        tg.load_dataset(tmp_path / "empty.gpioius")


@pytest.mark.parametrize("field, value, match", [
    ("x", np.full((4, 2), np.nan), "'x' contains NaN"),
    ("x", np.zeros((4, 5)), "'x' must have shape"),
    ("y", np.array([0, 1, 2, 0]), "'y': labels must be 0 \\(surface\\), 1 \\(free space\\) or negative .*2"),
    ("y", np.array([0, 1, 0.5, 0]), "'y': labels must be .*0.5"),
    ("y", np.array([0, 1, -1e300, 0]), "'y': labels must be .*down to -20.*-1e\\+300"),    # issue 51, item 12
    ("task", np.array([0, 1, 3, 0]), "'task' must be 0"),
    ("task", np.array([0.5, 0, 0, 0]), "'task' must hold integers"),
    ("step", np.array([0, -1, 0, 0]), "'step' must be >= 0"),
    ("y", np.zeros(3), r"'y' must have shape \(4,\)"),
])
def test_bad_fields_name_the_file_and_field(tmp_path, field, value, match):
    arrays = {"x": np.zeros((4, 2)), "y": np.zeros(4), "task": np.zeros(4, int), "step": np.zeros(4, int)}
    arrays[field] = value
    p = tmp_path / "bad.gpioius"
    with LogWriter(p, {"dim": 2}) as w:
        w.append("observations", {}, arrays)
    with pytest.raises(DatasetError, match=match) as info:
        tg.load_dataset(p)
    assert "bad.gpioius" in str(info.value)


def test_empty_and_one_sided_datasets_refuse_to_fit():
    with pytest.raises(DatasetError, match="empty"):
        tg.Dataset(np.zeros((0, 2)), np.zeros(0), np.zeros(0, int), np.zeros(0, int)).to_model()
    with pytest.raises(DatasetError, match="outer .* only"):
        tg.Dataset(np.zeros((2, 2)), np.zeros(2), np.ones(2, int), np.zeros(2, int)).to_model()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_fuzzed_files_raise_only_dataset_errors(tmp_path, data):
    """Random truncations, byte flips and insertions of a valid log: a Dataset, a warning, or a DatasetError."""
    p = tmp_path / "f.gpioius"
    log_with_steps(p)
    blob = bytearray(p.read_bytes())
    op = data.draw(st.sampled_from(["truncate", "flip", "insert", "garbage"]))
    if op == "truncate":
        blob = blob[:data.draw(st.integers(0, len(blob)))]
    elif op == "flip":
        for _ in range(data.draw(st.integers(1, 5))):
            blob[data.draw(st.integers(0, len(blob) - 1))] ^= data.draw(st.integers(1, 255))
    elif op == "insert":
        i = data.draw(st.integers(0, len(blob)))
        blob[i:i] = data.draw(st.binary(min_size=1, max_size=40))
    else:
        blob = bytearray(data.draw(st.binary(max_size=300)))
    p.write_bytes(bytes(blob))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TornLogWarning)
        try:
            ds = tg.load_dataset(p)
        except DatasetError as exc:
            assert "f.gpioius" in str(exc)
        else:
            assert np.isfinite(ds.x).all() and set(np.unique(ds.y)) <= {0.0, 1.0}


@settings(max_examples=100, deadline=None)
@given(x=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=12),
       y=st.lists(st.integers(-2, 3), min_size=0, max_size=6), d=st.integers(1, 4))
def test_fuzzed_arrays_raise_only_dataset_errors(x, y, d):
    n = len(x) // d
    arr = np.asarray(x[:n * d], dtype=float).reshape(n, d)
    try:
        ds = tg.Dataset(arr, np.asarray(y[:n]), np.zeros(len(y[:n]), int), np.zeros(n, int))
    except DatasetError:
        return
    assert np.isfinite(ds.x).all() and ds.x.shape[1] in (2, 3)


# ------------------------------------------------------------------------------------------ issue 14: integrity
def _record_offsets(blob):
    pos, out = len(MAGIC) + 2, []
    while pos < len(blob):
        out.append(pos)
        pos += 10 + struct.unpack(">I", blob[pos + 2:pos + 6])[0]
    return out


def test_a_corrupt_length_mid_log_is_corruption_not_a_torn_tail(tmp_path):
    p = tmp_path / "log.gpioius"
    log_with_steps(p, n_steps=8)
    blob = bytearray(p.read_bytes())
    offsets = _record_offsets(blob)
    for patch in ("bit20", "1GiB"):
        b = bytearray(blob)
        at = offsets[3] + 2 if patch == "bit20" else offsets[2] + 2
        if patch == "bit20":
            b[at:at + 4] = struct.pack(">I", struct.unpack(">I", b[at:at + 4])[0] ^ (1 << 20))
        else:
            b[at:at + 4] = struct.pack(">I", 1 << 30)
        p.write_bytes(bytes(b))
        with warnings.catch_warnings():
            warnings.simplefilter("error", TornLogWarning)    # no "torn tail" story for a corrupt middle
            with pytest.raises(DatasetError, match="corrupt length|limit"):
                tg.load_dataset(p)
        from torch_gpioius.cli import main
        assert main(["fit", str(p)]) == 2


def test_compressed_payloads_are_refused_before_they_expand(tmp_path):
    import io
    import zipfile
    import zlib
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("kind.npy", b"\x00" * (50 << 20))      # 50 MB of zeros, ~50 kB compressed
    data = buf.getvalue()
    assert len(data) < 1 << 20
    p = tmp_path / "bomb.gpioius"
    p.write_bytes(MAGIC + struct.pack(">H", FORMAT_VERSION) + struct.pack(">2sII", b"RC", len(data), zlib.crc32(data))
                  + data)
    with pytest.raises(DatasetError, match="compressed"):
        tg.load_dataset(p)


def test_the_magic_is_checked_before_the_file_is_read():
    with pytest.raises(DatasetError, match="bad magic"):
        tg.load_dataset("/dev/zero")
    from torch_gpioius.cli import main
    assert main(["fit", "/dev/zero"]) == 2


@pytest.mark.parametrize("meta", [{"theta": -1}, {"theta": float("nan")}, {"theta": "abc"}, {"units": "cm"},
                                  {"theta": True}, {"dim": 2.0}])
def test_saves_refuse_what_the_loader_would_and_keep_the_good_file(tmp_path, meta):
    p = tg.save_dataset(small_dataset(), tmp_path / "good.gpioius")
    before = p.read_bytes()
    bad = small_dataset()
    with pytest.raises(DatasetError):
        bad.meta.update(meta)
        tg.save_dataset(bad, p)
    assert p.read_bytes() == before and not list(tmp_path.glob("*.tmp"))
    with pytest.raises(DatasetError):
        tg.Dataset(bad.x, bad.y, bad.task, bad.step, meta=dict(meta))


def test_string_trace_arrays_and_failed_writes_leave_no_damage(tmp_path, monkeypatch):
    p = tg.save_dataset(small_dataset(), tmp_path / "good.gpioius")
    before = p.read_bytes()
    with pytest.raises(DatasetError, match="trace array"):
        tg.Dataset(np.zeros((2, 2)), np.zeros(2), np.zeros(2, int), np.zeros(2, int),
                   trace={"positions": np.array(["a", "b"])})
    import torch_gpioius.io.datasets as dsm

    def full_disk(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(dsm.os, "fsync", full_disk)
    with pytest.raises(OSError, match="No space"):
        tg.save_dataset(small_dataset(n=20), p)
    assert p.read_bytes() == before and not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("header, step_meta, match", [
    ({"dim": 2.0}, {"step": 0}, "'dim'"), ({"dim": 2, "scene": ["A"]}, {"step": 0}, "'scene'"),
    ({"dim": 2, "theta": True}, {"step": 0}, "'theta'"), ({"dim": 2}, {"step": None}, "'step'"),
    ({"dim": 2}, {"step": [1]}, "'step'"), ({"dim": 2}, {}, "'step' is missing"),
    ({"dim": 2}, {"step": "three"}, "'step'"),
])
def test_malformed_headers_and_steps_name_the_file_and_field(tmp_path, header, step_meta, match):
    p = write_raw(tmp_path / "m.gpioius", [("header", {"units": "m", **header}, {}),
                                           ("step", step_meta, {"x": np.zeros((1, 2)), "y": np.zeros(1),
                                                                "task": np.zeros(1, int)})])
    with pytest.raises(DatasetError, match=match) as info:
        tg.load_dataset(p)
    assert "m.gpioius" in str(info.value)
    from torch_gpioius.cli import main
    assert main(["fit", str(p)]) == 2
    assert main(["replay", str(p), "--out", str(tmp_path / "r"), "--quiet"]) == 2


@pytest.mark.parametrize("x, match", [(np.zeros((3, 2), bool), "real numbers"),
                                      (np.zeros((3, 2), complex), "real numbers")])
def test_boolean_and_complex_coordinates_are_refused(tmp_path, x, match):
    with pytest.raises(DatasetError, match=match):
        tg.Dataset(x, np.zeros(3), np.zeros(3, int), np.zeros(3, int))
    p = write_raw(tmp_path / "b.gpioius", [("header", {"units": "m", "dim": 2}, {}),
                                           ("observations", {}, {"x": x, "y": np.zeros(3), "task": np.zeros(3, int),
                                                                 "step": np.zeros(3, int)})])
    with pytest.raises(DatasetError, match=match):
        tg.load_dataset(p)


def test_a_flipped_bit_in_a_datasets_last_record_is_corruption_not_a_torn_write(tmp_path):
    """A dataset is written whole and atomically (its header says ``file: dataset``): its last record can never be
    torn, so a bad checksum there is an error. A log's may be (its writer can be killed mid-record)."""
    p = tg.save_dataset(small_dataset(), tmp_path / "d.gpioius")
    assert next(read_records(p)).meta["file"] == "dataset"
    blob = bytearray(p.read_bytes())
    blob[-40] ^= 0x01                    # inside the last record (the trace)
    p.write_bytes(bytes(blob))
    with pytest.raises(DatasetError, match="d.gpioius: the last record .* fails its checksum; the header says this "
                                           "file is a dataset"):
        tg.load_dataset(p)
    cut = tmp_path / "cut.gpioius"
    cut.write_bytes(p.read_bytes()[:-30])        # a dataset cut short is corrupt too (e.g. a partial copy)
    with pytest.raises(DatasetError, match="is cut off .* the header says this file is a dataset"):
        tg.load_dataset(cut)
    log = tmp_path / "log.gpioius"
    log_with_steps(log)
    assert next(read_records(log)).meta["file"] == "log"
    blob = bytearray(log.read_bytes())
    blob[-40] ^= 0x01
    log.write_bytes(bytes(blob))
    with pytest.warns(TornLogWarning, match="fails its checksum"):
        tg.load_dataset(log)
    with pytest.raises(DatasetError, match="'file' must be one of"):
        tg.save_dataset(tg.Dataset(np.zeros((1, 2)), [0], [0], [0], meta={"file": "spreadsheet"}), tmp_path / "x")


def test_atomic_writes_use_a_temporary_name_of_their_own(tmp_path, monkeypatch):
    """Two writers of one path never share a temporary file (they used to share ``<name>.tmp`` and one crashed)."""
    import os as _os
    from torch_gpioius.io.outputs import atomic_write

    seen = []
    real = _os.replace

    def spy(src, dst):
        seen.append(str(src))
        return real(src, dst)

    monkeypatch.setattr(_os, "replace", spy)
    atomic_write(tmp_path / "r.json", "{}")
    atomic_write(tmp_path / "r.json", "{}")
    assert len(set(seen)) == 2 and all(str(_os.getpid()) in s for s in seen)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_contact_rows_take_each_contact_once_however_often_it_was_counted():
    """Contacts counted three times in a row (``contact_repeats``) are one contact each; a contact touched again later,
    after other rows, is a touch of its own; free space, inside points and the camera's seen points are none."""
    from torch_gpioius.io.datasets import contact_rows

    a, b = [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]
    x = np.array([a, a, a, [0.1, 0.0, -0.02], [0.2, 0.0, 0.0], b, b, b, a, [0.3, 0.0, 0.0], [0.3, 0.0, 0.0]])
    y = np.array([0, 0, 0, -0.4, 1, 0, 0, 0, 0, 0, 0.0])
    task = np.array([0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1])
    assert np.flatnonzero(contact_rows(x, y, task)).tolist() == [0, 5, 8]
    ds = tg.io.datasets.Dataset(x, y, task, np.arange(len(y)))
    np.testing.assert_array_equal(ds.contact_rows(), contact_rows(x, y, task))
    assert not contact_rows(np.zeros((0, 3)), np.zeros(0), np.zeros(0, int)).any()

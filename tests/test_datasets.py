"""Dataset/log format: round trips, torn tails, corruption, versions, bad fields; fuzzed with hypothesis."""

import struct
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import torch_gpioius as tg
from torch_gpioius.datasets import FORMAT_VERSION, MAGIC, DatasetError, LogWriter, TornLogWarning, read_records


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
    with LogWriter(tmp_path / "cm.gpioius", {"dim": 2, "units": "cm"}):
        pass
    with pytest.raises(DatasetError, match="'units' is 'cm'"):
        tg.load_dataset(tmp_path / "cm.gpioius")
    with LogWriter(tmp_path / "empty.gpioius", {"dim": 2}):
        pass
    with pytest.raises(DatasetError, match="no observations"):
        tg.load_dataset(tmp_path / "empty.gpioius")


@pytest.mark.parametrize("field, value, match", [
    ("x", np.full((4, 2), np.nan), "'x' contains NaN"),
    ("x", np.zeros((4, 5)), "'x' must have shape"),
    ("y", np.array([0, 1, 2, 0]), "'y' must be 0"),
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

"""Logged datasets: one versioned, append-only, crash-safe file format for observations and explorations.

A file is a fixed preamble followed by framed records::

    b"GPIOIUS\\0"  uint16 format version (big-endian)
    record*:  b"RC"  uint32 payload length  uint32 CRC-32 of the payload  payload

Each payload is an uncompressed NPZ archive (read with ``allow_pickle=False``) holding a ``kind`` string, a
JSON ``meta`` string and arrays. The first record is the ``header`` (units, frame, dimension, theta, sigma^2,
voxel size, source, ...). A **dataset** is a header plus ``observations`` records; an **exploration log** is a
header plus one ``step`` record per completed step (the observations that arrived, the indices removed, the
robot/sensor trace and the loop state needed to resume). See docs/data-format.md.

Why not HDF5: a process killed while HDF5 writes can leave the whole file unreadable (its metadata is not
journaled, and SWMR only protects appends to existing datasets); an append-only framed log loses at most the
record being written, which the CRC detects. Why not a plain ``.npz``: a zip cannot be appended to safely.
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ..core.validation import check_metres, label_problem

__all__ = ["FORMAT_VERSION", "FILE_KINDS", "DatasetError", "TornLogWarning", "Record", "Dataset", "LogWriter",
           "read_records", "replay", "save_dataset", "load_dataset", "validate_observations", "check_meta",
           "step_number", "contact_rows"]

MAGIC = b"GPIOIUS\x00"
FORMAT_VERSION = 1
_REC = b"RC"
_REC_HEAD = struct.Struct(">2sII")
#: Largest declared payload of one record [bytes] (a 3-D dataset of 10^7 observations fits in ~320 MB).
_MAX_RECORD = 1 << 29
#: Largest number of arrays in one record payload.
_MAX_MEMBERS = 64
UNITS = "m"
#: What a file is, recorded in its header's ``file`` field: a ``dataset`` is written whole and atomically by
#: :func:`save_dataset` (it can never end in a torn record: a bad last record is corruption); a ``log`` is appended
#: to record by record (:class:`LogWriter`) and may end in a torn record when its writer was killed.
FILE_KINDS = ("dataset", "log")


class DatasetError(ValueError):
    """A dataset or log file is unreadable or holds invalid data; the message names the file and field."""


class TornLogWarning(UserWarning):
    """The last record of a log is incomplete (the writer was killed mid-write); it was ignored."""


@dataclass
class Record:
    """One decoded record: ``kind``, JSON-able ``meta`` and named arrays; ``end`` = byte offset after it."""

    kind: str
    meta: dict
    arrays: dict[str, np.ndarray]
    end: int = 0


def _encode(kind: str, meta: dict, arrays: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    payload = {k: np.asarray(v) for k, v in arrays.items()}
    for k, v in payload.items():
        if v.dtype == object:
            raise DatasetError(f"array {k!r} has dtype object; only numeric and string arrays are stored")
    np.savez(buf, kind=np.array(kind), meta=np.array(json.dumps(meta, allow_nan=True)), **payload)
    data = buf.getvalue()
    return _REC_HEAD.pack(_REC, len(data), zlib.crc32(data)) + data


def _check_members(path: Path, offset: int, data: bytes) -> None:
    """A payload is an NPZ written by ``np.savez``: uncompressed (stored) members whose sizes add up to no more
    than the payload itself. A deflated member could expand a few MB into GBs before anything is validated."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            infos = zf.infolist()
    except (zipfile.BadZipFile, ValueError, OSError) as exc:
        raise DatasetError(f"{path}: record at byte {offset} is not a valid NPZ payload ({exc})") from exc
    if len(infos) > _MAX_MEMBERS:
        raise DatasetError(f"{path}: record at byte {offset} holds {len(infos)} arrays (at most {_MAX_MEMBERS})")
    total = 0
    for info in infos:
        if info.compress_type != zipfile.ZIP_STORED:
            raise DatasetError(f"{path}: record at byte {offset}: array {info.filename!r} is compressed; this format "
                               "stores arrays uncompressed (a compressed member could expand without bound)")
        total += info.file_size
        if info.file_size > len(data) or total > len(data):
            raise DatasetError(f"{path}: record at byte {offset}: array {info.filename!r} declares "
                               f"{info.file_size} bytes, more than the {len(data)}-byte payload")


def _decode(path: Path, offset: int, data: bytes) -> Record:
    _check_members(path, offset, data)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:  # a CRC-valid record that is not an NPZ archive was written by something else
        raise DatasetError(f"{path}: record at byte {offset} is not a valid NPZ payload ({exc})") from exc
    try:
        kind = str(arrays.pop("kind"))
        meta = json.loads(str(arrays.pop("meta")))
    except (KeyError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{path}: record at byte {offset} lacks a valid 'kind'/'meta' field") from exc
    if not isinstance(meta, dict):
        raise DatasetError(f"{path}: record at byte {offset}: 'meta' must be a JSON object")
    return Record(kind, meta, arrays)


def _later_record_exists(blob: bytes) -> bool:
    """Whether ``blob`` (the bytes after a record's header) contains a complete record with a valid CRC.

    A writer killed mid-write leaves a *prefix* of one record at the end of the file, never a complete record
    after it; so a record that claims to run past the end while a valid record follows is corruption (e.g. a
    flipped bit in its length), not a torn tail.
    """
    pos = blob.find(_REC)
    while pos >= 0:
        if len(blob) - pos >= _REC_HEAD.size:
            _, length, crc = _REC_HEAD.unpack_from(blob, pos)
            start = pos + _REC_HEAD.size
            if length <= len(blob) - start and zlib.crc32(blob[start:start + length]) == crc:
                return True
        pos = blob.find(_REC, pos + 1)
    return False


def read_records(path: str | os.PathLike, *, allow_torn_tail: bool = True) -> Iterator[Record]:
    """Decode every complete record of a file, in order, reading it as a stream.

    The magic bytes and version are checked before anything else is read (``gpioius fit /dev/zero`` stops at
    once); each record's declared length is bounded (``_MAX_RECORD``) and its payload must be an uncompressed
    NPZ whose members fit in it.

    Args:
        path: dataset or log file.
        allow_torn_tail: an incomplete *last* record (a writer killed mid-write: a record that runs past the end
            of the file with nothing valid after it, or a last record whose checksum fails) is skipped with a
            :class:`TornLogWarning`; if False it is an error. Corruption anywhere else is always an error.

    Raises:
        DatasetError: not our format, an unsupported version, or a corrupt record (names file and byte offset).
    """
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise DatasetError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    with f:
        head = f.read(len(MAGIC) + 2)
        if len(head) < len(MAGIC) + 2 or head[:len(MAGIC)] != MAGIC:
            raise DatasetError(f"{path}: not a torch_gpioius dataset/log (bad magic bytes)")
        (version,) = struct.unpack(">H", head[len(MAGIC):])
        if version != FORMAT_VERSION:
            raise DatasetError(f"{path}: format version {version} is not supported (this torch_gpioius reads "
                               f"version {FORMAT_VERSION}); convert it with the matching release")
        pos = len(MAGIC) + 2
        atomic = False      # the header says the file was written whole (a dataset): no torn tail is possible
        while True:
            rec_head = f.read(_REC_HEAD.size)
            if not rec_head:
                return
            torn = None
            if len(rec_head) < _REC_HEAD.size:
                torn = "a record header is cut off"
            else:
                tag, length, crc = _REC_HEAD.unpack(rec_head)
                if tag != _REC:
                    raise DatasetError(f"{path}: corrupt record header at byte {pos}")
                if length > _MAX_RECORD:
                    raise DatasetError(f"{path}: record at byte {pos} declares {length} bytes (more than the "
                                       f"{_MAX_RECORD}-byte limit): corrupt length field")
                data = f.read(length)
                start, end = pos + _REC_HEAD.size, pos + _REC_HEAD.size + length
                if len(data) < length:
                    if _later_record_exists(data):
                        raise DatasetError(f"{path}: record at byte {pos} declares {length} bytes, past the end of "
                                           "the file, but complete records follow it: corrupt length field")
                    torn = f"the record at byte {pos} is cut off ({len(data)} of {length} bytes)"
                elif zlib.crc32(data) != crc:
                    if f.read(1):
                        raise DatasetError(f"{path}: record at byte {pos} fails its CRC-32 check (file corrupted)")
                    torn = f"the last record (byte {pos}) fails its checksum"
            if torn is not None:
                if atomic:
                    raise DatasetError(f"{path}: {torn}; the header says this file is a dataset, which is written "
                                       "whole and atomically and so can never end in a torn record: the file is "
                                       "corrupt")
                if not allow_torn_tail:
                    raise DatasetError(f"{path}: truncated: {torn}")
                warnings.warn(f"{path}: {torn}; ignoring it (the writer was probably killed)", TornLogWarning,
                              stacklevel=2)
                return
            rec = _decode(path, pos, data)
            rec.end = end
            if pos == len(MAGIC) + 2 and rec.kind == "header" and rec.meta.get("file") == "dataset":
                atomic = True
            yield rec
            pos = end
            del start


def validate_observations(x: Any, y: Any, task: Any, step: Any, *, where: str, dim: int | None = None) -> tuple:
    """Check and convert observation arrays; raise :class:`DatasetError` naming ``where`` and the field.

    Returns:
        ``x (n, d) float64``, ``y (n,) float64`` in {0, 1}, ``task (n,) int64`` in {0, 1}, ``step (n,) int64`` >= 0.
    """
    raw = {}
    for name, a in (("x", x), ("y", y)):
        try:
            raw[name] = np.asarray(a)
        except (TypeError, ValueError) as exc:
            raise DatasetError(f"{where}: field {name!r} is not numeric ({exc})") from exc
        if raw[name].dtype.kind not in "iuf":   # bool, complex, strings, objects: never converted silently
            raise DatasetError(f"{where}: field {name!r} must hold real numbers, got dtype {raw[name].dtype}")
    try:
        x = raw["x"].astype(np.float64)
        y = raw["y"].astype(np.float64)
        task = np.asarray(task)
        step = np.asarray(step)
    except (TypeError, ValueError) as exc:
        raise DatasetError(f"{where}: observation arrays are not numeric ({exc})") from exc
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise DatasetError(f"{where}: field 'x' must have shape (n, 2) or (n, 3), got {x.shape}")
    if dim is not None and x.shape[1] != dim:
        raise DatasetError(f"{where}: field 'x' has dimension {x.shape[1]} but the header says {dim}")
    n = x.shape[0]
    for name, a in (("y", y), ("task", task), ("step", step)):
        if a.shape != (n,):
            raise DatasetError(f"{where}: field {name!r} must have shape ({n},), got {a.shape}")
    if not np.isfinite(x).all():
        raise DatasetError(f"{where}: field 'x' contains NaN or inf")
    check_metres(x, f"{where}: field 'x'", hint="convert the data to metres, or import it with units='mm'",
                 error=DatasetError)
    if (problem := label_problem(y)) is not None:
        raise DatasetError(f"{where}: field 'y': {problem}")
    if task.dtype.kind not in "iub" and not (task.dtype.kind == "f" and np.isfinite(task).all()
                                             and (task == np.round(task)).all()):
        raise DatasetError(f"{where}: field 'task' must hold integers 0 (inner) or 1 (outer)")
    if not np.isin(task, (0, 1)).all():
        raise DatasetError(f"{where}: field 'task' must be 0 (inner) or 1 (outer)")
    if step.dtype.kind not in "iu" and not (step.dtype.kind == "f" and np.isfinite(step).all()
                                            and (step == np.round(step)).all()):
        raise DatasetError(f"{where}: field 'step' must hold integers")
    if (step < 0).any():
        raise DatasetError(f"{where}: field 'step' must be >= 0")
    return x, y, task.astype(np.int64), step.astype(np.int64)


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def check_meta(meta: dict, where: str) -> dict:
    """Validate header metadata with the reader's rules (the writers call this before writing anything).

    Raises:
        DatasetError: naming ``where`` and the field.
    """
    from ..core.tolerances import tol

    if not isinstance(meta, dict):
        raise DatasetError(f"{where}: header metadata must be a JSON object, got {type(meta).__name__}")
    if meta.get("units") != UNITS:
        raise DatasetError(f"{where}: header field 'units' is {meta.get('units')!r}; torch_gpioius files are in "
                           f"metres ('m'): convert when importing (importers take units=)")
    dim = meta.get("dim")
    if not (isinstance(dim, int) and not isinstance(dim, bool) and dim in (2, 3)):
        raise DatasetError(f"{where}: header field 'dim' must be the integer 2 or 3, got {dim!r}")
    ranges = {"theta": tol.theta_range, "noise": tol.noise_range}
    for k, (lo, hi) in ranges.items():
        v = meta.get(k)
        if v is not None and not (_number(v) and lo <= v <= hi):
            raise DatasetError(f"{where}: header field {k!r} must be a number in [{lo:g}, {hi:g}], got {v!r}")
    v = meta.get("voxel_size")
    if v is not None and not (_number(v) and v > 0):
        raise DatasetError(f"{where}: header field 'voxel_size' must be a positive number [m] or null, got {v!r}")
    v = meta.get("file")
    if v is not None and v not in FILE_KINDS:
        raise DatasetError(f"{where}: header field 'file' must be one of {FILE_KINDS}, got {v!r}")
    for k in ("frame", "source", "scene", "mode", "scene_fingerprint"):
        v = meta.get(k)
        if v is not None and not isinstance(v, str):
            raise DatasetError(f"{where}: header field {k!r} must be a string, got {v!r}")
    try:
        json.dumps(meta, allow_nan=True)
    except (TypeError, ValueError) as exc:
        raise DatasetError(f"{where}: header metadata is not JSON-serialisable ({exc})") from None
    return meta


def _check_header(path: Path, rec: Record) -> dict:
    if rec.kind != "header":
        raise DatasetError(f"{path}: the first record must be the header, found {rec.kind!r}")
    return check_meta(rec.meta, str(path))


def step_number(meta: dict, where: str) -> int:
    """The ``step`` field of a step record: a non-negative integer, or ``DatasetError`` naming the record."""
    v = meta.get("step")
    if v is None and "step" not in meta:
        raise DatasetError(f"{where}: field 'step' is missing")
    if not (isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**62):
        shown = v if not isinstance(v, int) or abs(v) < 10**20 else f"{float(v):.3g}"
        raise DatasetError(f"{where}: field 'step' must be a non-negative integer below 2^62, got {shown!r}")
    return v


def _check_trace(trace: dict, where: str) -> dict[str, np.ndarray]:
    out = {}
    for k, v in trace.items():
        a = np.asarray(v)
        if a.dtype.kind not in "iuf" or a.dtype == bool:
            raise DatasetError(f"{where}: trace array {k!r} must be numeric, got dtype {a.dtype}")
        if not np.isfinite(a).all():
            raise DatasetError(f"{where}: trace array {k!r} contains NaN or inf")
        out[k] = a.astype(np.float64)
    return out


def contact_rows(x: np.ndarray, y: np.ndarray, task: np.ndarray) -> np.ndarray:
    """`(n,)` bool: the rows that are contacts (inner task, y = 0), each contact once: a row equal to the contact row
    before it is the same contact counted again (``ObservationPolicy.contact_repeats`` records a contact k times in
    a row, in an exploration, an import and a bag alike). What counts touches, or takes the first few, reads these."""
    x = np.asarray(x)
    touched = (np.asarray(task) == 0) & (np.asarray(y) == 0)
    at = np.flatnonzero(touched)
    again = np.r_[False, (x[at[1:]] == x[at[:-1]]).all(axis=1)] if len(at) else np.zeros(0, bool)
    touched[at[again]] = False
    return touched


@dataclass
class Dataset:
    """Observations with the step each arrived at, an optional robot/sensor trace, and metadata.

    Attributes:
        x: `(n, d)` positions [m] in ``meta['frame']`` (robot base frame by default).
        y: `(n,)` labels: 0 on a surface, 1 free space.
        task: `(n,)` 0 inner (touch), 1 outer (vision).
        step: `(n,)` exploration step at which each observation arrived (0 = before exploring).
        meta: units ("m"), frame, dim, theta, noise, voxel_size, source, ...
        trace: optional arrays ``positions (m, d)`` [m], ``forces (m, 3)`` [N], ``timestamps (m,)`` [s].
    """

    x: np.ndarray
    y: np.ndarray
    task: np.ndarray
    step: np.ndarray
    meta: dict = field(default_factory=dict)
    trace: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.meta, dict):
            raise DatasetError(f"Dataset: meta must be a dict, got {type(self.meta).__name__}")
        self.x, self.y, self.task, self.step = validate_observations(
            self.x, self.y, self.task, self.step, where="Dataset", dim=self.meta.get("dim"))
        self.meta = check_meta({"units": UNITS, "frame": "base", "dim": int(self.x.shape[1]), **self.meta},
                               "Dataset")
        self.trace = _check_trace(dict(self.trace), "Dataset")

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def contact_rows(self) -> np.ndarray:
        """`(n,)` bool: the contacts' rows, each contact once (:func:`contact_rows`)."""
        return contact_rows(self.x, self.y, self.task)

    def to_model(self, *, settings=None, **kwargs: Any):
        """A :class:`torch_gpioius.GPIOIS` on these observations (GPIS if no outer observation), not yet fit.

        The estimator's settings (kernel, sigma^2) are ``settings`` (an
        :class:`~torch_gpioius.models.estimator.EstimatorSettings` or a preset's name), else the header's
        (``estimator``, else its ``kernel`` and ``noise``; a log of a run with the Matérn-5/2 names it), else the
        inverse multiquadric of 0.1 m and 0.006; an :class:`~torch_gpioius.models.overrides.EstimatorOverrides`
        changes the header's (e.g. ``settings=EstimatorOverrides(noise=0.01)``). ``kwargs`` go to the model
        (``inference``, ``outer_tol``, ``task_covariance``, ...); ``noise`` and ``kernel`` among them are deprecated
        (one release: the same change, with a DeprecationWarning). The outer task's prior mean is the header's
        (``outer_field`` or ``outer_mean``), else 1.
        """
        from ..models.estimator import EstimatorSettings
        from ..models.overrides import EstimatorOverrides, warn_loose

        if len(self) == 0:
            raise DatasetError("the dataset is empty: nothing to fit")
        changes = EstimatorOverrides()
        if isinstance(settings, EstimatorOverrides):
            changes, settings = settings, None
        if settings is None:
            try:
                settings = EstimatorSettings.of_record(self.meta)      # old headers: their kernel and noise
            except ValueError as exc:
                raise DatasetError(str(exc)) from None
        else:
            settings = EstimatorSettings.of(settings)
        loose = {k: kwargs.pop(k) for k in ("kernel", "noise") if kwargs.get(k) is not None}
        if warn_loose("Dataset.to_model", 2, **loose):
            changes = changes.merged(EstimatorOverrides(**loose))
        settings = changes.apply(settings)
        if (self.task == 1).any() and not (self.task == 0).any():
            raise DatasetError("the dataset has outer (visual) observations only; GPIOIS needs touches too")
        model = settings.make_model(self.x, self.y, self.task, **kwargs)
        return model.set_outer_mean(self._outer_mean()) if (self.task == 1).any() else model

    def _outer_mean(self):
        """The outer mean the header records (``outer_field``: a gap field's record; ``outer_mean``: a number; set
        by the gap rules of :func:`~torch_gpioius.io.importers.dataset_from_files`), else 1, the paper's."""
        from ..models.gapfield import GapField

        try:
            if isinstance(self.meta.get("outer_field"), dict):
                return GapField.from_dict(self.meta["outer_field"], "the header's outer_field")
            return float(self.meta.get("outer_mean", 1.0))
        except (TypeError, ValueError) as exc:
            raise DatasetError(f"the header's outer mean: {exc}") from None


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path.parent, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory fds
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def save_dataset(ds: Dataset, path: str | os.PathLike, *, overwrite: bool = True) -> Path:
    """Write ``ds`` atomically (temporary file, fsync, rename): a crash leaves the old file or the new one.

    Everything is validated with the reader's own rules and encoded *before* the file is touched, so a save
    that would write something :func:`load_dataset` refuses fails and leaves a good file in place; a failed
    write (disk full) removes its temporary file. The header records ``file: "dataset"``, so a reader treats a
    bad last record as corruption, never as a torn write. A symbolic link at ``path`` is replaced, not followed.

    Args:
        ds: the dataset.
        path: the file to write.
        overwrite: replace an existing file (the command line passes False unless ``--force``).

    Raises:
        DatasetError: invalid metadata, observations or trace (nothing was written).
        FileExistsError: ``path`` exists and ``overwrite`` is False.
        OSError: the write failed (the previous file, if any, is unchanged).
    """
    path = Path(path)
    if not overwrite and os.path.lexists(path):
        raise FileExistsError(f"{path}: exists; pass --force (overwrite=True) to replace it")
    meta = check_meta({**ds.meta, "file": "dataset"}, f"save_dataset({path})")
    x, y, task, step = validate_observations(ds.x, ds.y, ds.task, ds.step, where=f"save_dataset({path})",
                                             dim=meta["dim"])
    trace = _check_trace(dict(ds.trace), f"save_dataset({path})")
    blob = MAGIC + struct.pack(">H", FORMAT_VERSION) + _encode("header", meta, {}) + _encode(
        "observations", {}, {"x": x, "y": y, "task": task, "step": step}) + (_encode("trace", {}, trace) if trace
                                                                              else b"")
    _atomic_write(path, blob)
    return path


def _atomic_write(path: Path, blob: bytes) -> None:
    from .outputs import atomic_write

    atomic_write(path, blob)


def _open_no_link(path: Path, flags: int, mode: str):
    """``open(path, mode)`` that refuses a symbolic link at ``path`` instead of writing into its target."""
    try:
        fd = os.open(path, flags | getattr(os, "O_NOFOLLOW", 0), 0o644)
    except OSError:
        if os.path.islink(path):
            raise DatasetError(f"{path}: is a symbolic link; a log is written to a plain file, never through a "
                               "link (resume from the file it points to, or remove the link)") from None
        raise
    return os.fdopen(fd, mode)


class LogWriter:
    """Append-only writer: every :meth:`append` is durable (flush + fsync) before it returns.

    Args:
        path: the log file. A new file gets the preamble and ``header`` (``meta``); ``resume=True`` opens an
            existing log, truncates an incomplete last record and appends after the last complete one.
        meta: header metadata (new files only).
    """

    def __init__(self, path: str | os.PathLike, meta: dict | None = None, *, resume: bool = False) -> None:
        self.path = Path(path)
        if resume:
            end = len(MAGIC) + 2
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", TornLogWarning)
                for rec in read_records(self.path):
                    end = rec.end
            self._f = _open_no_link(self.path, os.O_RDWR, "r+b")
            self._f.truncate(end)
            self._f.seek(end)
        else:
            meta = {**(meta or {}), "file": "log"}
            meta.setdefault("units", UNITS)
            check_meta(meta, f"LogWriter({self.path})")
            if os.path.islink(self.path):            # a link at the target is replaced, never followed
                os.unlink(self.path)
            self._f = _open_no_link(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, "wb")
            self._f.write(MAGIC + struct.pack(">H", FORMAT_VERSION))
            self._write(_encode("header", meta, {}))
            _fsync_dir(self.path)

    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._f.flush()
        os.fsync(self._f.fileno())

    def append(self, kind: str, meta: dict, arrays: dict[str, np.ndarray]) -> None:
        """Append one record and make it durable."""
        self._write(_encode(kind, meta, arrays))

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def replay(path: str | os.PathLike) -> Iterator[tuple[Record, Dataset]]:
    """Read a dataset or log once, yielding the observations as they stand after each data record.

    For a log this is the training set after each step (its ``removed`` indices applied, then its new
    observations appended, each with the step it arrived at); for a dataset, after each ``observations`` or
    ``trace`` record.

    Yields:
        ``(record, dataset)`` pairs, in file order; ``dataset.trace`` holds the trace read so far.

    Raises:
        DatasetError: unreadable, corrupt or invalid (names the file and the field).
    """
    path = Path(path)
    records = iter(read_records(path))
    try:
        first = next(records)
    except StopIteration:
        raise DatasetError(f"{path}: no header record (empty or truncated file)") from None
    meta = _check_header(path, first)
    dim = meta["dim"]
    trace: dict[str, list] = {}
    cur = [np.zeros((0, dim)), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)]
    for rec in records:
        where = f"{path}: {rec.kind} record ending at byte {rec.end}"
        if rec.kind in ("observations", "step", "tap", "recovery"):
            step_no = step_number(rec.meta, where) if rec.kind != "observations" else 0
            a = rec.arrays
            if rec.kind != "observations":
                removed = np.asarray(a.get("removed", np.zeros(0, np.int64)))
                if removed.size:
                    if removed.dtype.kind not in "iu" or removed.min() < 0 or removed.max() >= len(cur[0]):
                        raise DatasetError(f"{where}: field 'removed' holds invalid indices")
                    keep = np.ones(len(cur[0]), bool)
                    keep[removed] = False
                    cur = [c[keep] for c in cur]
            if "x" in a:
                n = len(np.asarray(a["x"]))
                step_arr = a.get("step", np.full(n, step_no, np.int64))
                new = validate_observations(a["x"], a.get("y"), a.get("task"), step_arr, where=where, dim=dim)
                cur = [np.concatenate([c, v]) for c, v in zip(cur, new)]
            for k in ("positions", "forces", "timestamps"):
                if k in a:
                    trace.setdefault(k, []).append(np.asarray(a[k], dtype=np.float64))
            yield rec, Dataset(*cur, meta=meta, trace={k: np.concatenate(v) for k, v in trace.items()})
        elif rec.kind == "trace":
            for k, v in rec.arrays.items():
                trace.setdefault(k, []).append(np.asarray(v, dtype=np.float64))
            yield rec, Dataset(*cur, meta=meta, trace={k: np.concatenate(v) for k, v in trace.items()})
        elif rec.kind == "header":
            raise DatasetError(f"{where}: a second header record")
        # unknown kinds from newer minor writers are skipped on purpose (forward compatible within a version)


def load_dataset(path: str | os.PathLike, *, upto_step: int | None = None) -> Dataset:
    """Read a dataset or an exploration log (replaying its adds and removals) into a :class:`Dataset`.

    Args:
        path: the file.
        upto_step: for logs, stop after this step (default: all complete steps).

    Raises:
        DatasetError: unreadable, corrupt, invalid or empty (names the file and the field).
    """
    path = Path(path)
    if upto_step is not None and (isinstance(upto_step, bool) or not isinstance(upto_step, (int, np.integer))
                                  or upto_step < 0):
        raise DatasetError(f"upto_step: must be a step number (an integer >= 0), got {upto_step!r}")
    ds = None
    for rec, state in replay(path):
        if upto_step is not None and rec.kind == "step" and rec.meta["step"] > upto_step:
            break
        ds = state
    if ds is None or len(ds) == 0:
        raise DatasetError(f"{path}: the dataset holds no observations")
    return ds

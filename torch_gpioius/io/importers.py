"""Importers for what users record on their own robots: point clouds (outer) and contact CSVs (inner)."""

from __future__ import annotations

import csv
import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from ..core.validation import MIN_LABEL, check_metres
from ..sensors.pointcloud import PointCloud, PointCloudSource
from ..geometry.voxels import VOXEL_RANGE, voxel_average  # noqa: F401  (re-exported: the 0.2 home of voxel_average)
from .datasets import Dataset, DatasetError

__all__ = ["load_point_cloud", "load_contacts_csv", "voxel_average", "dataset_from_files", "FilePointCloud"]

_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def _scale(units: str, path: Path) -> float:
    if units not in _SCALE:
        raise DatasetError(f"{path}: units must be one of {sorted(_SCALE)}, got {units!r}")
    return _SCALE[units]


def _units_hint(units: str) -> str:
    return f"read as {units!r}; give the file's units: units='mm' in Python, --units mm on the command line"


def _read_pcd(path: Path) -> np.ndarray:
    """x, y, z of an ASCII or binary (uncompressed) PCD file.

    trimesh reads PLY and XYZ but not PCD, and Open3D/PCL are heavy dependencies for one header format.
    """
    data = path.read_bytes()
    header, fields, sizes, types, counts, npoints, fmt = {}, [], [], [], [], None, None
    pos = 0
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            raise DatasetError(f"{path}: PCD header ends before DATA")
        line = data[pos:nl].decode("ascii", "replace").strip()
        pos = nl + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        header[key.upper()] = vals
        if key.upper() == "DATA":
            fmt = vals[0].lower() if vals else None
            break
    try:
        fields = header["FIELDS"]
        sizes = [int(v) for v in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(v) for v in header.get("COUNT", ["1"] * len(fields))]
        npoints = int(header["POINTS"][0])
    except (KeyError, ValueError, IndexError) as exc:
        raise DatasetError(f"{path}: PCD header lacks or garbles FIELDS/SIZE/TYPE/POINTS ({exc})") from exc
    dup = sorted({f for f in fields if fields.count(f) > 1})
    if dup:                                 # the last x would silently win
        raise DatasetError(f"{path}: PCD FIELDS names {dup} more than once ({' '.join(fields)})")
    if any(c < 1 for c in counts) or any(s < 1 for s in sizes):
        raise DatasetError(f"{path}: PCD COUNT and SIZE must be positive integers, got COUNT {counts}, SIZE {sizes}")
    if npoints < 0 or not (len(fields) == len(sizes) == len(types) == len(counts)):
        raise DatasetError(f"{path}: PCD header is inconsistent (POINTS {npoints}, {len(fields)} fields, "
                           f"{len(sizes)} sizes, {len(types)} types, {len(counts)} counts)")
    if not {"x", "y", "z"} <= set(fields):
        raise DatasetError(f"{path}: PCD has no x/y/z fields (fields: {fields})")
    if fmt == "ascii":
        rows = data[pos:].decode("ascii", "replace").split()
        ncol = sum(counts)
        try:
            arr = np.asarray(rows, dtype=np.float64).reshape(-1, ncol)
        except ValueError as exc:
            raise DatasetError(f"{path}: PCD ascii body is not {ncol} numbers per point") from exc
        if len(arr) != npoints:
            raise DatasetError(f"{path}: PCD header declares POINTS {npoints} but the body holds {len(arr)}")
        cols, c = {}, 0
        for f, k in zip(fields, counts):
            cols[f] = c
            c += k
        pts = arr[:, [cols["x"], cols["y"], cols["z"]]]
    elif fmt == "binary":
        kinds = {"F": "f", "I": "i", "U": "u"}
        try:
            dtype = np.dtype([(f, f"<{kinds[t]}{s}", (k,)) if k > 1 else (f, f"<{kinds[t]}{s}")
                              for f, s, t, k in zip(fields, sizes, types, counts)])
        except (KeyError, TypeError) as exc:
            raise DatasetError(f"{path}: unsupported PCD field types {types}/{sizes}") from exc
        if len(data) - pos != npoints * dtype.itemsize:
            raise DatasetError(f"{path}: PCD header declares POINTS {npoints} ({npoints * dtype.itemsize} bytes) but "
                               f"the binary body has {len(data) - pos} bytes")
        rec = np.frombuffer(data, dtype=dtype, count=npoints, offset=pos)
        pts = np.stack([rec["x"], rec["y"], rec["z"]], axis=-1).astype(np.float64)
    else:
        raise DatasetError(f"{path}: PCD DATA {fmt!r} is not supported (ascii or binary)")
    return pts


_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}


def _ply_vertex_count(path: Path) -> int:
    """The vertex count a PLY header declares, checked against the body of a point-cloud PLY.

    trimesh trusts the header: it reads 2 of 4 rows under ``element vertex 2`` and accepts a negative count.
    For a PLY holding only vertices (what a point cloud is), the body must hold exactly the declared rows.
    """
    with open(path, "rb") as f:
        blob = f.read()
    end = blob.find(b"end_header")
    if not blob.startswith(b"ply") or end < 0:
        raise DatasetError(f"{path}: not a PLY file (no 'ply' magic or no 'end_header')")
    lines = blob[:end].decode("ascii", "replace").splitlines()
    fmt, elements = None, []
    for line in lines:
        words = line.split()
        if words[:1] == ["format"] and len(words) > 1:
            fmt = words[1]
        elif words[:1] == ["element"] and len(words) == 3:
            try:
                elements.append([words[1], int(words[2]), []])
            except ValueError:
                raise DatasetError(f"{path}: PLY element count {words[2]!r} is not an integer") from None
        elif words[:1] == ["property"] and elements:
            elements[-1][2].append(words[1:])
    vertex = [e for e in elements if e[0] == "vertex"]
    if not vertex:
        raise DatasetError(f"{path}: PLY header has no 'element vertex' line")
    n = vertex[0][1]
    if n < 0:
        raise DatasetError(f"{path}: PLY header declares a negative vertex count ({n})")
    if len(elements) == 1:                                   # a point cloud: the body must match exactly
        body = blob[end + len(b"end_header"):]
        body = body[1:] if body[:1] == b"\n" else body[2:] if body[:2] == b"\r\n" else body
        if fmt == "ascii":
            rows = [r for r in body.decode("ascii", "replace").splitlines() if r.strip()]
            if len(rows) != n:
                raise DatasetError(f"{path}: PLY header declares {n} vertices but the body holds {len(rows)} rows")
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            props = vertex[0][2]
            if all(len(pr) == 2 and pr[0] in _PLY_SIZES for pr in props):
                size = sum(_PLY_SIZES[pr[0]] for pr in props)
                if len(body) != n * size:
                    raise DatasetError(f"{path}: PLY header declares {n} vertices ({n * size} bytes) but the body has "
                                       f"{len(body)} bytes")
    return n


#: The largest ``points`` array an NPZ cloud may hold [bytes]: 50 million points (a depth camera gives about 0.3
#: million a frame). A compressed member states its expanded size, which is checked before anything is expanded.
MAX_CLOUD_BYTES = 50_000_000 * 3 * 8


def _check_npz_points(path: Path) -> None:
    """Refuse an NPZ whose ``points`` member would expand beyond :data:`MAX_CLOUD_BYTES`, or whose array header
    declares more elements than the member holds (numpy allocates the declared shape before reading): a 4.6 MB zip
    bomb reached 4.9 GB before a MemoryError."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as zf:
            info = next((i for i in zf.infolist() if i.filename in ("points", "points.npy")), None)
            if info is None:
                return                          # np.load names the missing array
            if info.file_size > MAX_CLOUD_BYTES:
                raise DatasetError(f"{path}: 'points' expands to {info.file_size / 1e9:.2g} GB, more than the "
                                   f"{MAX_CLOUD_BYTES / 1e9:.2g} GB a cloud may hold (voxel-average or crop it first)")
            with zf.open(info) as f:
                version = np.lib.format.read_magic(f)
                header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                          else np.lib.format.read_array_header_2_0)(f, max_header_size=10_000)
                shape, _, dtype = header
                declared = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
                if dtype.hasobject or declared > info.file_size:
                    raise DatasetError(f"{path}: 'points' declares shape {shape} of {dtype}, "
                                       f"{declared / 1e6:.3g} MB, in a member of {info.file_size / 1e6:.3g} MB")
    except DatasetError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise DatasetError(f"{path}: not a readable NPZ point cloud ({type(exc).__name__}: {exc})") from None


def load_point_cloud(path: str | os.PathLike, *, units: str = "m", voxel: float | None = None,
                     drop_nonfinite: bool = True) -> np.ndarray:
    """Read a point cloud (PLY or XYZ via trimesh, PCD, or NPZ with a ``points`` array) as `(n, 3)` [m].

    Args:
        path: the file; the format follows the extension.
        units: units of the file's coordinates ("m", "cm", "mm"); converted to metres.
        voxel: if given, average into voxels of this edge [m] (paper: 0.05).
        drop_nonfinite: drop NaN/inf points (depth cameras mark missing pixels that way); if False they are
            an error.

    ``voxel=None`` keeps every point; ``voxel=0`` (or any size outside ``VOXEL_RANGE``) is an error, never a
    silent skip.

    Raises:
        DatasetError: unreadable file, no points, wrong shape.
    """
    path = Path(path)
    scale = _scale(units, path)
    ext = path.suffix.lower()
    try:
        if ext == ".pcd":
            pts = _read_pcd(path)
        elif ext == ".npz":
            _check_npz_points(path)
            with np.load(path, allow_pickle=False) as z:
                if "points" not in z.files:
                    raise DatasetError(f"{path}: NPZ point cloud needs a 'points' array (has {z.files})")
                raw = np.asarray(z["points"])
                if raw.dtype.kind not in "iuf":   # complex, bool, strings: never converted silently
                    raise DatasetError(f"{path}: 'points' must hold real numbers, got dtype {raw.dtype}")
                pts = raw.astype(np.float64)
        elif ext in (".ply", ".xyz"):
            import trimesh

            declared = _ply_vertex_count(path) if ext == ".ply" else None
            geom = trimesh.load(path, process=False)
            pts = np.asarray(getattr(geom, "vertices", np.zeros((0, 3))), dtype=np.float64)
            faces = len(getattr(geom, "faces", ()))
            if faces:
                import warnings

                warnings.warn(f"{path}: holds a mesh ({faces} faces), not a point cloud: its {len(pts)} vertices are "
                              "used as the camera's points (a depth camera's capture has no faces; a scan's mesh "
                              "samples the surface unevenly)", UserWarning, stacklevel=2)
            if declared is not None and declared != len(pts):
                raise DatasetError(f"{path}: PLY header declares {declared} vertices, the file holds {len(pts)}")
        else:
            raise DatasetError(f"{path}: unknown point-cloud format {ext!r} (use .ply, .pcd, .xyz or .npz)")
    except DatasetError:
        raise
    except Exception as exc:
        raise DatasetError(f"{path}: not a readable {ext[1:].upper()} point cloud ({type(exc).__name__}: {exc})") \
            from exc
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise DatasetError(f"{path}: points must have shape (n, 3), got {pts.shape}")
    finite = np.isfinite(pts).all(axis=1)
    if not finite.all():
        if not drop_nonfinite:
            raise DatasetError(f"{path}: {int((~finite).sum())} points are NaN or inf")
        pts = pts[finite]
    if len(pts) == 0:
        raise DatasetError(f"{path}: the point cloud holds no (finite) points")
    pts = pts * scale
    check_metres(pts, str(path), hint=_units_hint(units), error=DatasetError)
    if voxel is None:
        return pts
    try:
        return voxel_average(pts, voxel)
    except ValueError as exc:
        raise DatasetError(f"{path}: {exc}") from None


_LABELS = {"0": 0.0, "1": 1.0, "contact": 0.0, "surface": 0.0, "free": 1.0, "free_space": 1.0}
#: The distance [m] over which labels rise from 0 on a surface to 1 in free space (``ObservationPolicy.ramp`` of the
#: defaults, and the camera free space of :func:`dataset_from_files`): a point ``d`` inside is labelled ``-d / ramp``.
_RAMP = 0.05


def _number(text: str) -> float:
    """``float(text)``, refusing what Python's float takes but a file's number never is: ``0.5_0`` (digits grouped
    by underscores) was read as 0.5.

    Raises:
        ValueError: not a plain decimal number.
    """
    if "_" in text:
        raise ValueError(f"not a number: {text!r}")
    return float(text)


def _label(row: dict, path, line: int, scale: float) -> float:
    """A row's label: a kind's (``contact``, ``free``, ...), ``inside`` with its ``depth`` [CSV units] behind the
    surface (``-depth / 5 cm``, the free-space ramp continued inside, as the exploration labels its inside points),
    or a negative number given as the label itself."""
    label, depth = row.get("label", "").lower(), row.get("depth", "")
    if label == "inside":
        try:
            d = _number(depth) * scale
        except ValueError:
            raise DatasetError(f"{path}:{line}: an inside point needs its depth behind the surface in the depth "
                               f"column (a positive number in the file's units), got {depth!r}") from None
        if not (np.isfinite(d) and d > 0):
            raise DatasetError(f"{path}:{line}: depth {depth!r} must be a positive number (how far inside the "
                               "body the point lies)")
        if -d / _RAMP < MIN_LABEL:
            raise DatasetError(f"{path}:{line}: depth {depth!r} is {d:g} m behind the surface, more than "
                               f"{-MIN_LABEL * _RAMP:g} m: a units mistake?")
        return -d / _RAMP
    if depth:
        raise DatasetError(f"{path}:{line}: depth {depth!r} is given for a {label!r} row; depth belongs to inside "
                           "points only")
    if label in _LABELS:
        return _LABELS[label]
    try:
        value = _number(label)
    except ValueError:
        value = math.nan
    if np.isfinite(value) and MIN_LABEL <= value < 0:
        return value
    if np.isfinite(value) and value < MIN_LABEL:
        raise DatasetError(f"{path}:{line}: label {label!r} is below {MIN_LABEL:g} (a point 1 m inside at the 5 cm "
                           "ramp); an inside point's label is -depth / 5 cm: a units or sign mistake?")
    raise DatasetError(f"{path}:{line}: label {label!r} must be one of {sorted(_LABELS) + ['inside']} or a negative "
                       "number (a point inside the body)")


def load_contacts_csv(path: str | os.PathLike, *, units: str = "m") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read inner observations from a CSV with a header ``x,y[,z],label[,step][,depth]`` (and optionally each
    contact's normal or force, :func:`read_contacts_csv`).

    ``label`` is ``contact``/``surface``/0 (y = 0), ``free``/``free_space``/1 (y = 1), or a point known to lie inside
    the body: ``inside`` with its ``depth`` behind the surface (in the file's units; y = -depth / 5 cm, as the
    exploration labels the points behind its contacts), or a negative label given directly; ``step`` defaults to 0.

    Returns:
        ``x (n, d)`` [m], ``y (n,)``, ``step (n,)``.

    Raises:
        DatasetError: naming the file, the line and the field.
    """
    x, y, step, _ = read_contacts_csv(path, units=units)
    return x, y, step


#: The columns of a contact's direction: its outward surface normal, or the force the surface exerted on the
#: fingertip (which points out of the body too; its size is not used).
_NORMAL_COLUMNS = {"n": ("nx", "ny", "nz"), "f": ("fx", "fy", "fz")}


def read_contacts_csv(path: str | os.PathLike, *, units: str = "m"):
    """:func:`load_contacts_csv` with each contact's outward direction, as gpis-touch and GPisMap take normals: columns
    ``nx,ny[,nz]`` (the outward surface normal) or ``fx,fy[,fz]`` (the force the surface exerted on the fingertip,
    which points out of the body; any units, only its direction is used). A contact row without them, and every
    other row, has none (NaN). With them, the estimator places an inside point behind each contact, as an
    exploration places it behind the force it measured.

    Returns:
        ``x (n, d)`` [m], ``y (n,)``, ``step (n,)``, ``normal (n, d)``: unit outward directions, NaN rows where none.

    Raises:
        DatasetError: naming the file, the line and the field (both kinds of direction given, a zero or
            non-numeric one, a direction on a row that is not a contact).
    """
    path = Path(path)
    scale = _scale(units, path)
    try:
        # utf-8-sig: a spreadsheet's "CSV UTF-8" starts with a byte-order mark, which read as part of the first
        # column's name ('\ufeffx')
        with open(path, newline="", encoding="utf-8-sig") as f:
            delimiter = _delimiter(f.readline())
            f.seek(0)
            reader = csv.DictReader(f, delimiter=delimiter)
            rows = list(reader)
            header = [c.strip().lower() for c in reader.fieldnames or [] if c is not None]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DatasetError(f"{path}: cannot read CSV ({exc})") from exc
    if not rows:
        raise DatasetError(f"{path}: no rows (expected a header x,y[,z],label and at least one row)")
    cols = [c.strip().lower() for c in rows[0].keys() if c is not None]
    dup = sorted({c for c in header if header.count(c) > 1})
    if dup:                                # csv.DictReader keeps the last of two columns of one name
        raise DatasetError(f"{path}: the header names column(s) {dup} more than once ({header}); each column once")
    dims = ["x", "y", "z"] if "z" in cols else ["x", "y"]
    if not {"x", "y", "label"} <= set(cols):
        raise DatasetError(f"{path}: header must contain x, y[, z] and label, got {cols}")
    kinds = [k for k, names in _NORMAL_COLUMNS.items() if any(c in cols for c in names)]
    if len(kinds) > 1:
        raise DatasetError(f"{path}: the header gives both normals (nx, ny, nz) and forces (fx, fy, fz); give one")
    direction = _NORMAL_COLUMNS[kinds[0]][:len(dims)] if kinds else None
    if direction is not None and not set(direction) <= set(cols):
        raise DatasetError(f"{path}: a contact's direction needs the columns {list(direction)}, got {cols}")
    xs, ys, steps, normals = [], [], [], []
    for i, row in enumerate(rows, start=2):
        if None in row:
            raise DatasetError(f"{path}:{i}: the row has more fields than the header ({len(cols)} columns: {cols})")
        if any(v is None for v in row.values()):
            raise DatasetError(f"{path}:{i}: the row has fewer fields than the header ({len(cols)} columns: {cols})")
        row = {k.strip().lower(): v.strip() for k, v in row.items()}
        try:
            p = [_number(row[d]) for d in dims]
        except (KeyError, ValueError):
            comma = delimiter != "," and any("," in (row.get(d) or "") for d in dims)
            raise DatasetError(f"{path}:{i}: coordinates {[row.get(d) for d in dims]} are not numbers"
                               + (" (decimal commas? write a point: 0.5, not 0,5)" if comma else "")) from None
        if not np.isfinite(p).all():
            raise DatasetError(f"{path}:{i}: coordinates contain NaN or inf")
        y = _label(row, path, i, scale)
        try:
            st = int(row["step"]) if row.get("step") else 0
        except ValueError:
            raise DatasetError(f"{path}:{i}: step {row.get('step')!r} is not an integer") from None
        if not 0 <= st < 2**62:
            raise DatasetError(f"{path}:{i}: step {row.get('step')} is out of range (a step number from 0 to 2^62)")
        xs.append(p)
        ys.append(y)
        steps.append(st)
        normals.append(_direction(row, direction, y, path, i) if direction else np.full(len(dims), np.nan))
    xs = np.asarray(xs) * scale
    check_metres(xs, str(path), hint=_units_hint(units), error=DatasetError, lines=np.arange(2, len(xs) + 2))
    ys, steps, normals = np.asarray(ys), np.asarray(steps, dtype=np.int64), np.asarray(normals, dtype=np.float64)
    first = _first_occurrences(xs, ys, normals)
    if len(first) < len(xs):
        # a row recorded twice is one observation: counted three times it weighed three times in the fit
        import warnings

        warnings.warn(f"{path}: {len(xs) - len(first)} of {len(xs)} rows repeat an earlier row (the same point, label "
                      "and direction); merged, each observation counted once", UserWarning, stacklevel=2)
        xs, ys, steps, normals = xs[first], ys[first], steps[first], normals[first]
    return xs, ys, steps, normals


def _delimiter(header: str) -> str:
    """The separator of a contacts CSV from its header line: ``,``, or ``;`` or a tab where the header is one column
    of names so separated (a spreadsheet's export in a locale with decimal commas)."""
    line = header.lstrip("\ufeff")
    if "," in line:
        return ","
    for sep in (";", "\t"):
        if sep in line:
            return sep
    return ","


def _first_occurrences(x: np.ndarray, y: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """`(k,)` sorted indices of the rows that do not repeat an earlier row exactly (point, label and direction)."""
    key = np.column_stack([x, y[:, None], np.nan_to_num(normals, nan=np.inf)])
    _, first = np.unique(key, axis=0, return_index=True)
    return np.sort(first)


def _direction(row: dict, columns: tuple, label: float, path: Path, line: int) -> np.ndarray:
    """A row's unit outward direction from its normal or force columns (NaN where empty)."""
    raw = [row.get(c, "") for c in columns]
    if all(v == "" for v in raw):
        return np.full(len(columns), np.nan)
    if label != 0.0:
        raise DatasetError(f"{path}:{line}: {', '.join(columns)} belong to contact rows (label contact), not to a "
                           f"row labelled {row.get('label')!r}")
    try:
        v = np.array([_number(c) for c in raw])
    except ValueError:
        raise DatasetError(f"{path}:{line}: {', '.join(columns)} {raw} are not numbers") from None
    n = float(np.linalg.norm(v))
    if not (np.isfinite(v).all() and n > 0):
        raise DatasetError(f"{path}:{line}: {', '.join(columns)} {raw} is not a direction (zero, NaN or inf)")
    return v / n


def dataset_from_files(contacts_csv: str | os.PathLike, point_cloud=None, *, units: str = "m", settings="default",
                       source: str = "import", camera_origin=None, contact_spacing: float | None = None,
                       camera_bound=None, table: float | None = None, **deprecated) -> Dataset:
    """A user's contacts (inner, task 0) and camera captures (outer, task 1, step 0) labelled as an exploration with
    the same estimator settings labels them, in one Dataset.

    The estimator's settings (:class:`~torch_gpioius.models.estimator.EstimatorSettings`, the ``"default"`` preset
    unless told) decide the labels exactly as in a simulated run: each capture's seen surface (y = 0), its free space
    along its own rays (y = 1, near and, with ``vision_free_far``, far), inside points behind the seen surface along
    the cloud's normals (estimated from the points and turned towards the capture's camera) and behind each contact
    along its normal or force (:func:`read_contacts_csv`), every inside point that other observations contradict
    dropped, and the camera's inside points retracted when the contacts show the cover standing off the body by
    more than ``vision_inside_gap``. The voxel and the kernel's length follow the settings' rules from the clouds'
    largest extent (the contacts' without a cloud).

    Args:
        contacts_csv: the contacts (:func:`read_contacts_csv`).
        point_cloud: the camera's cloud, in the contacts' frame (:func:`load_point_cloud`), a list of clouds (several
            captures, e.g. from two sides), or None.
        units: both files' units ("m", "cm", "mm").
        settings: an :class:`~torch_gpioius.models.estimator.EstimatorSettings` or a preset's name ("default",
            "paper"), or changes to the default preset (an
            :class:`~torch_gpioius.models.overrides.EstimatorOverrides`: ``EstimatorOverrides(voxel=0.02)``; the
            voxel and the length rules still size what they hold to the clouds).
        source: the dataset's ``source``.
        camera_origin: `(3,)` the camera's optical centre in the same frame and units, or None; with several clouds,
            a list of origins, one per cloud (None for a cloud whose camera is unknown: its points, no free space and
            no inside points).
        contact_spacing: thin the file's rows so that no two of one kind (contacts; free space; inside points) lie
            closer than this [m] (in metres, whatever ``units``), keeping the first in the file's order; None keeps
            every row. An exact fit's memory grows with the square and its time with the cube of the observations: a
            thousand contacts 3 mm apart under a 4 cm kernel say little more than a few hundred 5 mm apart.
        camera_bound: the largest error each capture's pose (its camera's calibration) may have, a
            :class:`~torch_gpioius.sensors.simulated.CameraError` or its text (``"6mm,1deg"``): each capture with
            a camera origin is moved rigidly about it to agree with the contacts and the other captures
            (:func:`~torch_gpioius.sensors.extrinsics.correct_captures`, the contacts' directions where the file
            gives them), within that bound, before it is labelled; a correction beyond half the bound is warned of.
            None: the captures as given.
        table: with ``camera_bound``, the height (z, in ``units``) of the table the object stands on, which the
            robot knows (touch it): each capture's points on the table around the object (within the bound's reach
            of that height, away from the object's footprint) are held to it as well, which fixes the rotations
            about horizontal axes and the height that contacts on a few faces leave loose (give the clouds with the
            table around the object, uncropped; its points are then taken out of the captures, not labelled as the
            cover). None: no table.
        **deprecated: ``voxel`` ("auto", an edge [m], or 0 / None: every point) and ``noise`` (sigma^2), for one
            release: give ``settings=EstimatorOverrides(voxel=..., noise=...)``.

    Returns:
        A :class:`Dataset` whose ``meta["estimator"]`` holds the settings used (the voxel resolved),
        ``meta["cover_gap"]`` the gap the contacts show under the seen cover [m] (NaN with too few contacts), with
        ``cover_offset`` in the settings the outer mean the gap rules set (``meta["outer_mean"]`` or
        ``meta["outer_field"]``, a :class:`~torch_gpioius.models.gapfield.GapField`'s record), and with
        ``camera_bound`` ``meta["camera_corrections"]`` (each capture's correction, what fixed it, the
        contacts' misfit before and after).

    Raises:
        DatasetError: an unreadable file, units that cannot be metres, a 3-D cloud with 2-D contacts, a bad
            ``camera_origin``, as many origins as clouds missing, contacts far outside the clouds (each names the
            file or argument).
        TypeError: a keyword it does not take.
    """
    from ..exploration.observations import cover_gap, inside_checked_by_step, vision_observations
    from ..models.overrides import loose_keywords

    loose = loose_keywords("dataset_from_files", deprecated, ("voxel", "noise"))
    est = _import_settings(settings, "auto" if "voxel" not in deprecated else loose["voxel"], loose["noise"])
    x_in, y_in, step_in, normal_in = read_contacts_csv(contacts_csv, units=units)
    dim = x_in.shape[1]
    if contact_spacing is not None:
        x_in, y_in, step_in, normal_in = _thinned_rows(contacts_csv, x_in, y_in, step_in, normal_in, contact_spacing)
    if not (y_in == 0).any():
        import warnings

        warnings.warn(f"{contacts_csv}: no contact rows (label contact): nothing touched the inner shape, so its "
                      "estimate is what the camera's observations carry over", UserWarning, stacklevel=2)
    if camera_origin is not None and point_cloud is None:
        raise DatasetError("camera_origin: gives the free space in front of a point cloud; pass point_cloud too")
    several = isinstance(point_cloud, (list, tuple))
    files = list(point_cloud) if several else ([] if point_cloud is None else [point_cloud])
    if several:
        origins = [None] * len(files) if camera_origin is None else list(camera_origin)
        if len(origins) != len(files):
            raise DatasetError(f"camera_origin: {len(origins)} origin(s) for {len(files)} point clouds; give one per "
                               "cloud (None where a camera is unknown)")
    else:
        origins = [camera_origin] * len(files)
    captures = [_capture(f, o, units, dim) for f, o in zip(files, origins)]
    if captures:
        everything = np.concatenate([c.points for c in captures])
        est = _sized(est, float(np.max(everything.max(axis=0) - everything.min(axis=0))))
    else:                                           # contacts alone: the length from their extent
        est = _sized(est, float(np.max(x_in.max(axis=0) - x_in.min(axis=0))))
    # the contacts' directions turned outward where the data say they point in (before any correction: it pairs
    # contacts with the seen surface facing their way)
    normal_in = _outward(contacts_csv, x_in, y_in, normal_in,
                         np.concatenate([c.points for c in captures]) if captures else None)
    corrections = None
    if camera_bound is not None and captures:
        captures, corrections = _corrected(files, captures, x_in, y_in, normal_in, camera_bound,
                                           None if table is None else _table_height(table, units))
        everything = np.concatenate([c.points for c in captures])
    outer = np.zeros((0, dim)), np.zeros(0)
    if captures:
        from ..sensors.pointcloud import PointCloud

        try:
            outer = vision_observations(PointCloud.merge(captures), est.labels)
        except ValueError as exc:
            raise DatasetError(f"{', '.join(map(str, files))}: {exc}") from None
        # the box of every capture together: one view may see only the top of the body, away from the contacts
        _check_together(contacts_csv, x_in, y_in, " + ".join(map(str, files)), everything)
        # the middle of the box of everything observed: inside the body, and less pulled to the seen side than a mean
        every = np.concatenate([everything, x_in[y_in == 0]])
        centre = (every.min(axis=0) + every.max(axis=0)) / 2
        for k, (f, o, c) in enumerate(zip(files, origins, captures)):
            _check_camera(f, c.points, o, units)
            _check_facing(f, k, len(files), c.points, c.origin, centre)
    inner, inner_steps = _inner_with_inside_points(x_in, y_in, normal_in, step_in, est.labels)
    x_checked, y_checked, keep = inside_checked_by_step(inner.x, inner.y, inner_steps, est.labels, outer[0], outer[1])
    inner = dataclasses.replace(inner, x=x_checked, y=y_checked)     # inside_halvings: some moved up their line
    behind = inner.y < 0
    if behind.sum() >= 5 and (~keep[behind]).mean() > 0.25:
        import warnings

        depth = est.labels.touch_inside
        warnings.warn(f"{contacts_csv}: {int((~keep[behind]).sum())} of {int(behind.sum())} inside points behind the "
                      "contacts lie where other observations show free space or the seen surface, and were dropped. "
                      "The contacts' directions point out of the body by the data's own account, so either the body "
                      f"is thinner than the inside points' depth ({depth * 100:.3g} cm) where they were dropped (a "
                      "neck, a handle, a wall: they came out on its far side, and dropping them was right), or the "
                      "files are not in one frame (a camera whose calibration is off by millimetres does this too: "
                      "camera_bound, gpioius fit --camera-bound, corrects each capture from the contacts)",
                      UserWarning, stacklevel=2)
    inner, inner_steps = inner.subset(keep), inner_steps[keep]
    gap, offset = math.nan, None
    if captures and est.labels.vision_inside_gap is not None:
        seen = outer[0][outer[1] == 0]
        gap = cover_gap(x_in[y_in == 0], seen, reach=max(0.02, est.labels.voxel or 0.0))
        if est.labels.cover_offset:                       # the gap rules of an exploration, applied at its end
            outer, offset = _gap_rules(x_in[y_in == 0], outer, est.labels)
        elif gap > est.labels.vision_inside_gap:          # the cover stands off: its inside points lie in the gap
            keep = outer[1] >= 0
            outer = outer[0][keep], outer[1][keep]
    steps = np.r_[inner_steps, np.zeros(len(outer[1]), np.int64)]
    x = np.concatenate([inner.x, outer[0]])
    y = np.concatenate([inner.y, outer[1]])
    task = np.r_[np.zeros(len(inner), np.int64), np.ones(len(outer[1]), np.int64)]
    meta = {"source": source, "voxel_size": est.labels.voxel if captures else None, "estimator": est.to_dict(),
            "cover_gap": None if not math.isfinite(gap) else float(gap),
            # the files read: what a command writing the estimate must never overwrite
            "inputs": [str(p) for p in (contacts_csv, *files)]}
    meta["kernel"], meta["noise"] = est.kernel.describe(), float(est.noise)
    if offset is not None:                                 # the outer mean the gap rules set (Dataset.to_model)
        meta.update(offset)

    def metres(o):
        return None if o is None else [float(v) * _SCALE[units] for v in np.asarray(o, dtype=float).ravel()]

    if camera_origin is not None:
        meta["camera_origin"] = [metres(o) for o in origins] if several else metres(camera_origin)
    if corrections is not None:
        meta["camera_corrections"] = corrections.as_record()
    return Dataset(x, y, task, steps, meta=meta)


def _gap_rules(contacts: np.ndarray, outer: tuple[np.ndarray, np.ndarray], policy) -> tuple[tuple, dict | None]:
    """The camera's observations ``outer`` (`(m, d)` points, `(m,)` labels) after the gap rules an exploration with
    ``policy.cover_offset`` applies step by step, applied once to all the ``contacts`` `(k, d)`: the inside points
    retracted (without ``vision_inside_deep``) or continued down to the gap (with it; a place at a time with
    ``cover_gap_field``), and the outer mean that stands for the gap: ``{"outer_mean": m}`` or ``{"outer_field":
    record}`` for :meth:`Dataset.to_model`, None when the rules leave the paper's mean."""
    import torch

    from ..exploration.observations import deepen_vision_inside, offset_outer_mean, retract_vision_inside
    from ..models.gpiois import GPIOIS

    x = np.concatenate([contacts, outer[0]])
    y = np.concatenate([np.zeros(len(contacts)), outer[1]])
    task = np.r_[np.zeros(len(contacts), np.int64), np.ones(len(outer[1]), np.int64)]
    model = GPIOIS(torch.as_tensor(x), torch.as_tensor(y), torch.as_tensor(task))   # its data only: never fitted
    retract_vision_inside(model, contacts, policy)
    offset_outer_mean(model, contacts, policy)
    deep = deepen_vision_inside(model, contacts, policy)
    keep = (model.train_inputs[1].squeeze(-1) == 1).numpy()
    ox, oy = model.train_inputs[0].numpy()[keep], model.train_targets.numpy()[keep]
    if deep is not None:
        ox, oy = np.concatenate([ox, deep.x]), np.concatenate([oy, deep.y])
    if model.outer_field is not None:
        return (ox, oy), {"outer_field": model.outer_field.as_dict()}
    return (ox, oy), ({"outer_mean": model.outer_mean} if model.outer_mean != 1.0 else None)


def _table_height(table, units: str) -> float:
    """``table`` (:func:`dataset_from_files`'s) in metres; DatasetError naming it when not a finite number."""
    if isinstance(table, bool) or not isinstance(table, (int, float)) or not math.isfinite(table):
        raise DatasetError(f"table: the table's height (z, in the files' units), got {table!r}")
    return float(table) * _SCALE[units]


#: Of a user's capture, the points within this [m] horizontally of the object's (those more than the band above the
#: table) are the object's foot, not the table (:func:`_on_the_table`).
TABLE_CLEARANCE = 0.02


def _on_the_table(points: np.ndarray, origin: np.ndarray, table: float, bound) -> np.ndarray:
    """`(n,)` which of a capture's ``points`` lie on the table at height ``table`` [m]: within the band the
    calibration ``bound`` can move them by at that distance from the camera ``origin`` (at least 1 cm) and more than
    :data:`TABLE_CLEARANCE` horizontally from every point above the band (the object and its cover)."""
    from scipy.spatial import cKDTree

    reach = float(np.median(np.linalg.norm(points - origin, axis=1))) if len(points) else 1.0
    band = max(0.01, bound.translation + bound.rotation * reach)
    near = np.abs(points[:, 2] - table) <= band
    above = points[:, 2] > table + band
    if not near.any() or not above.any():
        return near
    d, _ = cKDTree(points[above][:, :2]).query(points[near][:, :2])
    on = near.copy()
    on[near] = d > TABLE_CLEARANCE
    return on


def _corrected(files, captures, x_in: np.ndarray, y_in: np.ndarray, normal_in: np.ndarray, bound,
               table: float | None = None):
    """The captures corrected from the contacts (``normal_in``: their outward directions, NaN rows without) within
    ``bound`` (:func:`dataset_from_files`'s ``camera_bound``) and, with ``table`` [m], from each capture's points on
    the table as well, and the :class:`~torch_gpioius.sensors.extrinsics.CaptureCorrections`; a large correction is
    warned of by file."""
    import warnings

    from ..sensors.extrinsics import correct_captures
    from ..sensors.simulated.camera import CameraError
    from ..sensors.pointcloud import PointCloud

    try:
        bound = CameraError.parse(bound).check_bound()
    except ValueError as exc:
        raise DatasetError(str(exc) if str(exc).startswith("camera_bound") else f"camera_bound: {exc}") from None
    if x_in.shape[1] != 3:
        raise DatasetError("camera_bound: corrects the captures of a 3-D scene; these contacts are 2-D")
    if any(c.origin is None for c in captures):
        raise DatasetError("camera_bound: a capture's pose is corrected about its camera: give each cloud its "
                           "camera origin (--camera-origin)")
    contact = y_in == 0
    # the directions the file gives (normals or forces, already turned outward): a contact is paired with a capture's
    # surface facing its way; without any, every contact and no facing test
    given = contact & np.isfinite(normal_in).all(axis=1)
    use, directions = (given, normal_in[given]) if given.any() else (contact, None)
    held = captures
    if table is not None:                  # each capture's table apart from its object (PointCloud.support)
        held = []
        for c in captures:
            on = _on_the_table(c.points, np.asarray(c.origin, dtype=np.float64), table, bound)
            held.append(PointCloud(c.points[~on], c.origin, support=c.points[on]))
    found = correct_captures(held, x_in[use], directions, max_translation=bound.translation,
                             max_rotation=bound.rotation, support=table)
    for line in found.warnings([str(f) for f in files]):
        warnings.warn(line, UserWarning, stacklevel=3)
    # (with a table, its points leave the captures: they are not the object's cover)
    return [PointCloud(f.apply(c.points), c.origin) for c, f in zip(held, found.captures)], found


def _capture(path, origin, units: str, dim: int):
    """One capture as a :class:`~torch_gpioius.sensors.PointCloud` [m] with its camera (or None): every finite
    point of the file, in metres."""
    from ..sensors.pointcloud import PointCloud

    pts = load_point_cloud(path, units=units)
    if pts.shape[1] != dim:
        raise DatasetError(f"{path}: a 3-D point cloud needs a 3-D contact CSV (x, y, z)")
    if origin is None:
        return PointCloud(pts)
    try:
        o = np.asarray(origin, dtype=np.float64).reshape(-1) * _scale(units, Path(path))
    except (TypeError, ValueError):
        raise DatasetError(f"camera_origin: expected 3 numbers, got {origin!r}") from None
    if o.shape != (3,) or not np.isfinite(o).all():
        raise DatasetError(f"camera_origin: expected 3 finite numbers, got {origin!r}")
    check_metres(np.vstack([pts, o]), f"{path} with camera_origin",
                 hint="the camera origin is in the cloud's frame and units", error=DatasetError)
    return PointCloud(pts, o)


def _thinned_rows(path, x, y, step, normal, spacing):
    """The rows of each kind (contact, free, inside) thinned to ``spacing`` [m] (:func:`dataset_from_files`)."""
    from ..core.validation import as_length
    from ..exploration.observations import thin_indices

    try:
        spacing = as_length(spacing, "contact_spacing", hi=0.5)
    except ValueError as exc:
        raise DatasetError(str(exc)) from None
    kinds = np.where(y == 0, 0, np.where(y > 0, 1, 2))
    keep = np.sort(np.concatenate([np.flatnonzero(kinds == k)[thin_indices(x[kinds == k], spacing, x[:0], 0.0)]
                                   for k in (0, 1, 2)]))
    if len(keep) < len(y):
        import warnings

        warnings.warn(f"{path}: {len(y) - len(keep)} of {len(y)} rows dropped, lying within {spacing * 1000:g} mm of "
                      f"an earlier row of their kind (contact_spacing); {int((y[keep] == 0).sum())} contacts kept",
                      UserWarning, stacklevel=3)
    return x[keep], y[keep], step[keep], normal[keep]


def _sized(est, extent: float):
    """The settings' rules applied to an object of largest extent ``extent`` [m]; a single point has no size, and
    leaves the settings' own values."""
    return est.for_extent(extent) if extent > 0 else est


def _import_settings(settings, voxel, noise):
    """:func:`dataset_from_files`'s settings before they are sized to the files: a preset's name or an
    :class:`~torch_gpioius.models.estimator.EstimatorSettings`, or changes to the default preset (an
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides`); the deprecated ``voxel`` (other than "auto") and
    ``noise`` folded in, with a DeprecationWarning.

    Raises:
        DatasetError: a bad setting (names it).
    """
    from ..models.estimator import EstimatorSettings
    from ..models.overrides import EstimatorOverrides, warn_loose

    changes = settings if isinstance(settings, EstimatorOverrides) else EstimatorOverrides()
    loose = {}
    if noise is not None:
        loose["noise"] = noise
    if not (isinstance(voxel, str) and voxel == "auto"):
        if isinstance(voxel, str):
            raise DatasetError(f"voxel: expected 'auto', an edge [m] or 0, got {voxel!r}")
        loose["voxel"] = 0.0 if voxel is None else voxel
    try:
        if warn_loose("dataset_from_files", 3, **loose):
            changes = changes.merged(EstimatorOverrides(**loose))
        base = "default" if isinstance(settings, EstimatorOverrides) else settings
        return changes.apply(EstimatorSettings.of(base))
    except ValueError as exc:
        raise DatasetError(str(exc)) from None


def _inner_with_inside_points(x: np.ndarray, y: np.ndarray, normal: np.ndarray, step: np.ndarray, labels):
    """The contacts' rows, each contact ``labels.contact_repeats`` times and, with a normal, followed by its inside
    point ``labels.touch_inside`` behind it (as an exploration records a touch), and each row's step."""
    from ..exploration.observations import Observations

    surface = np.flatnonzero(y == 0)
    points, inside, of = labels.behind_contacts(x[surface], normal[surface])
    rows = np.r_[np.arange(len(y)), surface[of]]                  # each inside point after its contact
    order = np.argsort(np.r_[np.arange(len(y)) * 2, surface[of] * 2 + 1], kind="stable")
    xs = np.concatenate([x, points.reshape(-1, x.shape[1])])[order]
    ys = np.r_[y, inside][order]
    steps = np.asarray(step)[rows][order]
    times = np.where(ys == 0, labels.contact_repeats, 1)          # a contact k times: its noise sigma^2 / k
    return (Observations(np.repeat(xs, times, axis=0), np.repeat(ys, times), np.zeros(int(times.sum()), np.int64),
                         source="touch"), np.repeat(steps, times))


def _check_together(contacts_csv, x_in: np.ndarray, y_in: np.ndarray, cloud, pts: np.ndarray) -> None:
    """Refuse contacts that lie far outside the clouds' box (with :func:`_check_camera`, the checks that the files
    are in one frame and one unit: a cloud 1.5 m from the contacts gave a correlation of -0.76, a camera inside the
    object -0.67, each read out as a finding).

    The contacts touch the body under the cover the camera saw, so they lie inside the box of every capture together
    or near it: the median contact may lie at most ``max(5 cm, a quarter of the box's diagonal)`` outside it (one
    capture alone may see only the body's top). A file of free-space rows alone is held to the free space's reach,
    ``max(15 cm, the box's diagonal)``: the fingertip moves through the air around the body, not on it. ``pts``
    `(m, d)` [m] are the captures' points.

    Raises:
        DatasetError: naming both files and the distance.
    """
    contacts = (y_in == 0).any()
    touched = x_in[y_in == 0] if contacts else x_in
    seen = pts
    lo, hi = seen.min(axis=0), seen.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    outside = np.linalg.norm(np.maximum(lo - touched, 0.0) + np.maximum(touched - hi, 0.0), axis=1)
    allowed = max(0.05, 0.25 * diagonal) if contacts else max(0.15, diagonal)
    if float(np.median(outside)) > allowed:
        what = "contacts" if contacts else "free-space rows (the file has no contacts)"
        raise DatasetError(
            f"{contacts_csv} and {cloud}: the {what} lie {np.median(outside) * 100:.1f} cm (median) outside the "
            f"cloud's box [{_fmt(lo)} .. {_fmt(hi)}] m, more than {allowed * 100:.1f} cm: the files are not in one "
            "frame or not in one unit (--units applies to both; a cloud in another frame needs transforming first)")


def _check_camera(cloud, seen: np.ndarray, origin, units: str) -> None:
    """Warn of a camera origin inside its own capture's convex hull (a camera sees a surface from outside it)."""
    if origin is None or len(seen) <= seen.shape[1] + 1:
        return
    o = np.asarray(origin, dtype=np.float64).reshape(-1) * _scale(units, Path(cloud))
    from scipy.spatial import Delaunay, QhullError

    sample = seen if len(seen) <= 4000 else seen[np.linspace(0, len(seen) - 1, 4000).astype(int)]
    try:
        inside = Delaunay(sample).find_simplex(o[None, :])[0] >= 0
    except QhullError:              # a flat cloud has no volume to lie inside
        return
    if inside:
        import warnings

        warnings.warn(f"{cloud}: the camera origin {_fmt(o)} m lies inside the cloud's convex hull; a camera sees a "
                      "surface from outside it, so its free space would lie inside the body. Is the origin in the "
                      "cloud's frame and units?", UserWarning, stacklevel=3)


#: Below this share of a capture's points facing its camera origin, the origin is named as doubtful.
FACING_SHARE = 0.5


def _check_facing(cloud, k: int, n: int, seen: np.ndarray, origin, centre: np.ndarray) -> None:
    """Warn of a camera origin that its own capture's points face away from: a camera sees the near side of a body,
    so the body's inside (``centre``, the middle of every observation) lies behind each seen point as the camera looks
    at it, ``(centre - p) . (p - origin) > 0``. Swapped origins (two clouds, two ``--camera-origin`` in the wrong
    order) or an origin in other units than its cloud put most points facing away: the correlation fell from 1.00 to
    0.09 without a word. Points at a capture's rim, seen at grazing angles, may face either way: below
    :data:`FACING_SHARE` of them facing the origin is what is named."""
    if origin is None or len(seen) < 10:
        return
    facing = float(np.mean(np.einsum("ij,ij->i", centre - seen, seen - np.asarray(origin)) > 0))
    if facing < FACING_SHARE:
        import warnings

        which = f"capture {k + 1} of {n} ({cloud})" if n > 1 else str(cloud)
        warnings.warn(f"{which}: only {100 * facing:.0f} % of its points face its camera origin {_fmt(origin)} m "
                      "(a camera sees the near side of a body): is the origin that capture's own (several origins in "
                      "the order of the clouds), in the cloud's frame and units?", UserWarning, stacklevel=3)


def _outward(contacts_csv, x: np.ndarray, y: np.ndarray, normal: np.ndarray, seen: np.ndarray | None) -> np.ndarray:
    """The contacts' directions turned out of the body where the data say they point into it (all flipped together,
    with a warning): a file's normals or forces of the wrong sign put every inside point outside (contacts alone:
    1.76 cm against 0.27 cm, silently).

    The data vote on the sign: each free-space row against the direction of its nearest contact (free space lies
    outside), each contact against the direction to its nearest seen point (the cover lies outside the body), and
    each contact against the direction from the contacts' middle (a body's surface faces away from its inside)."""
    surface = (y == 0) & np.isfinite(normal).all(axis=1)
    if surface.sum() < 3:
        return normal
    c, n = x[surface], normal[surface]
    from scipy.spatial import cKDTree

    votes = {}
    free = x[y == 1]
    if len(free):
        _, j = cKDTree(c).query(free)
        votes["free rows"] = np.einsum("ij,ij->i", free - c[j], n[j])
    if seen is not None and len(seen):
        _, j = cKDTree(seen).query(c)
        votes["the seen surface"] = np.einsum("ij,ij->i", seen[j] - c, n)
    votes["the contacts' middle"] = np.einsum("ij,ij->i", c - c.mean(axis=0), n)
    signs = np.concatenate([np.sign(v) for v in votes.values()])
    if signs.sum() >= 0:
        return normal
    import warnings

    said = ", ".join(f"{k} {int((v < 0).sum())} of {len(v)}" for k, v in votes.items())
    warnings.warn(f"{contacts_csv}: the contacts' normals (or forces) point into the body by the data's own account "
                  f"(inward by {said}): turned round. A contact's direction is the surface's outward normal, or the "
                  "force the surface exerted on the fingertip", UserWarning, stacklevel=3)
    out = normal.copy()
    out[surface] = -n
    return out


def _fmt(v) -> str:
    return "(" + ", ".join(f"{float(a):.3g}" for a in np.asarray(v).ravel()) + ")"


class FilePointCloud(PointCloudSource):
    """A recorded point cloud (PLY, PCD, XYZ or NPZ with ``points``), e.g. a saved Kinect frame.

    Args:
        path: the file (format from the extension; see :func:`load_point_cloud`).
        units: the file's units ("m", "cm", "mm").
        T_base_camera: `(4, 4)` pose of the frame the file is written in, in the base frame (identity: the file
            is already in the base frame).
        origin: `(3,)` optical centre in the *file's* frame [file units converted to m]; None if unknown.
    """

    def __init__(self, path: str | os.PathLike, *, units: str = "m", T_base_camera=None, origin=None) -> None:
        self.path, self.units = path, units
        self.T_base_camera = np.eye(4) if T_base_camera is None else np.asarray(T_base_camera, dtype=np.float64)
        if self.T_base_camera.shape != (4, 4) or not np.isfinite(self.T_base_camera).all():
            raise ValueError("T_base_camera: expected a finite (4, 4) homogeneous transform")
        self.origin = None if origin is None else np.asarray(origin, dtype=np.float64)

    def capture(self) -> PointCloud:
        pts = load_point_cloud(self.path, units=self.units)
        R, t = self.T_base_camera[:3, :3], self.T_base_camera[:3, 3]
        origin = None if self.origin is None else R @ self.origin + t
        return PointCloud(pts @ R.T + t, origin)

"""Importers for what users record on their own robots: point clouds (outer) and contact CSVs (inner)."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from .datasets import Dataset, DatasetError

__all__ = ["load_point_cloud", "load_contacts_csv", "voxel_average", "dataset_from_files"]

_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def _scale(units: str, path: Path) -> float:
    if units not in _SCALE:
        raise DatasetError(f"{path}: units must be one of {sorted(_SCALE)}, got {units!r}")
    return _SCALE[units]


def voxel_average(points: np.ndarray, voxel: float) -> np.ndarray:
    """Average the points in each occupied cubic voxel (the paper's 5 cm Kinect averaging).

    Args:
        points: `(n, d)` [m].
        voxel: edge length [m]; voxels are aligned to the origin of the frame.

    Returns:
        `(k, d)` one mean point per occupied voxel, in lexicographic voxel order.
    """
    if not voxel > 0:
        raise ValueError(f"voxel size must be positive, got {voxel}")
    keys = np.floor(points / voxel).astype(np.int64)
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    sums = np.zeros((inv.max() + 1, points.shape[1]))
    np.add.at(sums, inv, points)
    return sums / np.bincount(inv)[:, None]


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
    if not {"x", "y", "z"} <= set(fields):
        raise DatasetError(f"{path}: PCD has no x/y/z fields (fields: {fields})")
    if fmt == "ascii":
        rows = data[pos:].decode("ascii", "replace").split()
        ncol = sum(counts)
        try:
            arr = np.asarray(rows, dtype=np.float64).reshape(-1, ncol)
        except ValueError as exc:
            raise DatasetError(f"{path}: PCD ascii body is not {ncol} numbers per point") from exc
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
        if len(data) - pos < npoints * dtype.itemsize:
            raise DatasetError(f"{path}: PCD binary body is truncated")
        rec = np.frombuffer(data, dtype=dtype, count=npoints, offset=pos)
        pts = np.stack([rec["x"], rec["y"], rec["z"]], axis=-1).astype(np.float64)
    else:
        raise DatasetError(f"{path}: PCD DATA {fmt!r} is not supported (ascii or binary)")
    return pts


def load_point_cloud(path: str | os.PathLike, *, units: str = "m", voxel: float | None = None,
                     drop_nonfinite: bool = True) -> np.ndarray:
    """Read a point cloud (PLY or XYZ via trimesh, PCD, or NPZ with a ``points`` array) as `(n, 3)` [m].

    Args:
        path: the file; the format follows the extension.
        units: units of the file's coordinates ("m", "cm", "mm"); converted to metres.
        voxel: if given, average into voxels of this edge [m] (paper: 0.05).
        drop_nonfinite: drop NaN/inf points (depth cameras mark missing pixels that way); if False they are
            an error.

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
            with np.load(path, allow_pickle=False) as z:
                if "points" not in z.files:
                    raise DatasetError(f"{path}: NPZ point cloud needs a 'points' array (has {z.files})")
                pts = np.asarray(z["points"], dtype=np.float64)
        elif ext in (".ply", ".xyz"):
            import trimesh

            geom = trimesh.load(path, process=False)
            pts = np.asarray(getattr(geom, "vertices", np.zeros((0, 3))), dtype=np.float64)
        else:
            raise DatasetError(f"{path}: unknown point-cloud format {ext!r} (use .ply, .pcd, .xyz or .npz)")
    except DatasetError:
        raise
    except Exception as exc:
        raise DatasetError(f"{path}: cannot read point cloud ({type(exc).__name__}: {exc})") from exc
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
    return voxel_average(pts, voxel) if voxel else pts


_LABELS = {"0": 0.0, "1": 1.0, "contact": 0.0, "surface": 0.0, "free": 1.0, "free_space": 1.0}


def load_contacts_csv(path: str | os.PathLike, *, units: str = "m") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read inner observations from a CSV with a header ``x,y[,z],label[,step]``.

    ``label`` is ``contact``/``surface``/0 (y = 0) or ``free``/``free_space``/1 (y = 1); ``step`` defaults to 0.

    Returns:
        ``x (n, d)`` [m], ``y (n,)``, ``step (n,)``.

    Raises:
        DatasetError: naming the file, the line and the field.
    """
    path = Path(path)
    scale = _scale(units, path)
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise DatasetError(f"{path}: cannot read CSV ({exc})") from exc
    if not rows:
        raise DatasetError(f"{path}: no rows (expected a header x,y[,z],label and at least one row)")
    cols = [c.strip().lower() for c in rows[0].keys() if c is not None]
    dims = ["x", "y", "z"] if "z" in cols else ["x", "y"]
    if not {"x", "y", "label"} <= set(cols):
        raise DatasetError(f"{path}: header must contain x, y[, z] and label, got {cols}")
    xs, ys, steps = [], [], []
    for i, row in enumerate(rows, start=2):
        row = {(k or "").strip().lower(): (v or "").strip() for k, v in row.items()}
        try:
            p = [float(row[d]) for d in dims]
        except (KeyError, ValueError):
            raise DatasetError(f"{path}:{i}: coordinates {[row.get(d) for d in dims]} are not numbers") from None
        if not np.isfinite(p).all():
            raise DatasetError(f"{path}:{i}: coordinates contain NaN or inf")
        label = row.get("label", "").lower()
        if label not in _LABELS:
            raise DatasetError(f"{path}:{i}: label {label!r} must be one of {sorted(_LABELS)}")
        try:
            st = int(row["step"]) if row.get("step") else 0
        except ValueError:
            raise DatasetError(f"{path}:{i}: step {row.get('step')!r} is not an integer") from None
        xs.append(p)
        ys.append(_LABELS[label])
        steps.append(st)
    return np.asarray(xs) * scale, np.asarray(ys), np.asarray(steps, dtype=np.int64)


def dataset_from_files(contacts_csv: str | os.PathLike, point_cloud: str | os.PathLike | None = None, *,
                       units: str = "m", voxel: float | None = 0.05, theta: float | None = None,
                       noise: float | None = None, source: str = "import") -> Dataset:
    """Combine a contact CSV (inner, task 0) and a point cloud (outer surface, task 1, step 0) into a Dataset."""
    x_in, y_in, step_in = load_contacts_csv(contacts_csv, units=units)
    parts = [(x_in, y_in, np.zeros(len(x_in), np.int64), step_in)]
    if point_cloud is not None:
        pts = load_point_cloud(point_cloud, units=units, voxel=voxel)
        if pts.shape[1] != x_in.shape[1]:
            raise DatasetError(f"{point_cloud}: a 3-D point cloud needs a 3-D contact CSV (x, y, z)")
        parts.append((pts, np.zeros(len(pts)), np.ones(len(pts), np.int64), np.zeros(len(pts), np.int64)))
    x, y, task, step = (np.concatenate(a) for a in zip(*parts))
    meta = {"source": source, "voxel_size": voxel if point_cloud is not None else None}
    if theta is not None:
        meta["theta"] = theta
    if noise is not None:
        meta["noise"] = noise
    return Dataset(x, y, task, step, meta=meta)

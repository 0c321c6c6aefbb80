"""Input checks shared by the models: every public entry point validates before it mutates state."""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

__all__ = ["as_points", "as_labels", "label_problem", "LABELS", "as_tasks", "as_int", "as_float", "as_bounds",
           "task_id", "TASK_NAMES", "check_metres", "as_length", "MAX_SCENE_EXTENT", "MAX_COORDINATE", "MAX_LENGTH",
           "as_noise", "NOISE_RANGE"]

#: Largest extent of a scene's data [m]: a robot's tabletop workspace is ~2 m and an uncropped depth camera sees
#: ~8 m; data larger than this are almost always in millimetres (an object of 15 cm is 150 "m" across then).
MAX_SCENE_EXTENT = 10.0
#: Largest coordinate accepted [m] (positions in a robot's base frame or a camera's).
MAX_COORDINATE = 50.0
#: Largest length a setting may take [m] (a travel budget, a step, a distance): larger is a units mistake.
MAX_LENGTH = 20.0

#: What a label says: 0 on a surface (touched or seen), 1 in free space (the paper's two), and a negative value at a
#: point known to lie inside a body, ``-depth / ramp`` (the free-space ramp continued inside: a point 2 cm behind a
#: contact with the free-space point 5 cm out is -0.4; beyond the paper, see docs/method-notes.md).
#: The lowest label accepted: a point 1 m behind a surface at the defaults' 5 cm ramp. Further down is a units or sign
#: mistake (a CSV label of -1e6 fitted a K_t of 2.6e10 and a correlation of 0.0000 [-0.00, 0.00]; -1e308 ended in
#: "Eigenvalues did not converge").
MIN_LABEL = -20.0
LABELS = f"0 (surface), 1 (free space) or negative (inside, down to {MIN_LABEL:g})"


def label_problem(y) -> str | None:
    """Why the labels ``y`` (an array or tensor) are not labels, naming up to five bad values (NaN and inf
    included), or None when each is 0, 1 or a finite negative number not below :data:`MIN_LABEL`."""
    a = np.asarray(y.detach().cpu() if torch.is_tensor(y) else y, dtype=np.float64).reshape(-1)
    bad = ((a != 0) & (a != 1) & ~(a < 0)) | ~np.isfinite(a) | (a < MIN_LABEL)
    if bad.any():
        return f"labels must be {LABELS}, got {sorted(set(a[bad].tolist()))[:5]}"
    return None


#: Task names accepted beside the ids: 0 is the inner (tactile) shape, 1 the outer (visual) one.
TASK_NAMES = {"inner": 0, "outer": 1}


def _tensor(value, name: str) -> Tensor:
    if value is None:
        raise ValueError(f"{name}: missing (got None)")
    if isinstance(value, str):
        raise ValueError(f"{name}: expected numbers, got the string {value!r}")
    try:
        return torch.as_tensor(value)
    except Exception as exc:
        raise ValueError(f"{name}: cannot be converted to a tensor ({type(exc).__name__}: {exc})") from None


def as_int(value, name: str, lo: int, hi: int | None = None, *, allow_none: bool = False) -> int | None:
    """An integer within ``[lo, hi]`` (no upper limit if ``hi`` is None), or None where ``allow_none``; otherwise
    ``ValueError`` naming the field. Booleans and floats are refused, as :func:`as_float` refuses strings."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo or \
            (hi is not None and value > hi):
        within = f"in [{lo}, {hi}]" if hi is not None else f">= {lo}"
        raise ValueError(f"{name}: must be an integer {within}{' or None' if allow_none else ''}, got {value!r}")
    return int(value)


def as_float(value, name: str, *, lo: float | None = None, hi: float | None = None, positive: bool = False,
             unit: str = "") -> float:
    """A finite real number within ``[lo, hi]`` (and > 0 if ``positive``), or ``ValueError`` naming the field.

    Booleans, strings, NaN, inf and complex numbers are refused: a limit or a hyper-parameter given as ``True``
    or ``"0.1"`` is a mistake, never silently converted.
    """
    unit = f" {unit}" if unit else ""
    if isinstance(value, (bool, str, bytes)) or value is None:
        raise ValueError(f"{name}: expected a finite number{unit}, got {value!r}")
    try:
        if torch.is_tensor(value):
            if value.numel() != 1 or value.is_complex() or value.dtype == torch.bool:
                raise TypeError
            v = float(value.detach().reshape(()))
        else:
            if isinstance(value, complex):
                raise TypeError
            v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a finite number{unit}, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name}: must be finite{unit}, got {v}")
    if positive and not v > 0:
        raise ValueError(f"{name}: must be positive{unit}, got {v}")
    if lo is not None and v < lo:
        raise ValueError(f"{name}: {v:g}{unit} is below the supported minimum {lo:g}{unit}")
    if hi is not None and v > hi:
        raise ValueError(f"{name}: {v:g}{unit} is above the supported maximum {hi:g}{unit}")
    return v


def check_metres(x, where: str, *, hint: str = "pass units='mm' (or --units mm) for a file in millimetres",
                 error: type[ValueError] = ValueError, lines=None) -> None:
    """Refuse `(n, d)` positions that cannot be metres: an extent above :data:`MAX_SCENE_EXTENT` or a coordinate
    beyond :data:`MAX_COORDINATE` (a dataset in millimetres is 1000x too large, and every later step -- the kernel,
    the grid, the correlation -- goes wrong without a word).

    With ``lines`` (`(n,)` the file's line of each position), a few positions far from all the others (a typing
    mistake: one row of 1e300 among rows in metres) are named by their lines instead of blaming the units.

    Raises:
        ValueError: (``error``, a subclass of it such as a reader's ``DatasetError``) naming ``where``, the measured
            size and the likely units, or the lines of the stray positions.
    """
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2 or not len(a):
        return
    extent = float((a.max(0) - a.min(0)).max())
    reach = float(np.abs(a).max())
    if (extent > MAX_SCENE_EXTENT or reach > MAX_COORDINATE) and lines is not None and len(a) > 2:
        far = np.abs(a - np.median(a, axis=0)).max(axis=1) > MAX_SCENE_EXTENT / 2
        rest = a[~far]
        fits = len(rest) and float((rest.max(0) - rest.min(0)).max()) <= MAX_SCENE_EXTENT and \
            float(np.abs(rest).max()) <= MAX_COORDINATE
        if far.sum() <= max(3, len(a) // 20) and fits:
            stray = np.flatnonzero(far)
            named = ", ".join(f"line {int(lines[i])} ({', '.join(f'{v:.4g}' for v in a[i])})" for i in stray)
            raise error(f"{where}: {named} lie{'s' if len(stray) == 1 else ''} far from every other point (the others "
                        f"fit in {float((rest.max(0) - rest.min(0)).max()):.3g} m): a typing mistake in "
                        f"{'that row' if len(stray) == 1 else 'those rows'}?")
    if extent > MAX_SCENE_EXTENT or reach > MAX_COORDINATE:
        size = f"{extent:.4g} m across" if extent > MAX_SCENE_EXTENT else f"{reach:.4g} m from the origin"
        likely = "millimetres" if extent > 100 * MAX_SCENE_EXTENT or reach > 100 * MAX_COORDINATE else \
            "millimetres or centimetres"
        raise error(f"{where}: the points are {size}; positions must be in metres, and these are probably in "
                         f"{likely} ({hint}; at most {MAX_SCENE_EXTENT:g} m across and {MAX_COORDINATE:g} m from the "
                         "origin are accepted)")


#: The sigma^2 a user may set, at every door (``EstimatorSettings``, scene files, ``gpioius study --noise``): the
#: models take a wider range for the library's own use (``tol.noise_range``); below 1e-8 the exact engines fall back
#: to dense arithmetic, and above 100 the labels (0 to 1) are noise.
NOISE_RANGE = (1e-8, 100.0)


def as_noise(value, name: str = "noise") -> float:
    """sigma^2 set by a user, in :data:`NOISE_RANGE` (the one check every door makes).

    Raises:
        ValueError: naming ``name``, the value and the range.
    """
    return as_float(value, name, lo=NOISE_RANGE[0], hi=NOISE_RANGE[1], positive=True)


#: The largest inside-point depth and cover gap a user may set [m] (``touch_inside``, ``vision_inside``,
#: ``vision_inside_gap``), at every door: scene files read them against it, worlds build with it.
INSIDE_DEPTH_MAX = 0.1

#: The kernel lengths a user may set [m], at every door (the command line's --lengthscale and --theta, scene files,
#: ``KernelChoice``, ``theta=``): below a millimetre each observation stands alone (no touch spacing is that fine)
#: and the estimate has no surface; above 10 m one length spans any robot's workspace many times over.
KERNEL_LENGTH = (1e-3, 10.0)


def as_kernel_length(value, name: str = "lengthscale") -> float:
    """A kernel's length set by a user [m], in :data:`KERNEL_LENGTH`.

    Raises:
        ValueError: naming ``name``, the value and what is wrong with it.
    """
    v = as_float(value, name, positive=True, unit="m")
    lo, hi = KERNEL_LENGTH
    if v < lo:
        raise ValueError(f"{name}: {v:g} m is below {lo * 1000:g} mm; a kernel's length is in metres and spans several "
                         "touches (a fifth of the object by default): shorter, each observation stands alone and the "
                         "estimate has no surface")
    if v > hi:
        raise ValueError(f"{name}: {v:g} m is above {hi:g} m; a kernel's length is in metres (was it given in "
                         "millimetres or centimetres?)")
    return v


def as_length(value, name: str, *, hi: float = MAX_LENGTH, positive: bool = True) -> float:
    """A length setting [m]: finite, positive, at most ``hi`` (a larger one is a units mistake, named as such).

    Raises:
        ValueError: naming ``name``.
    """
    v = as_float(value, name, positive=positive, unit="m")
    if v > hi:
        raise ValueError(f"{name}: {v:g} m is above {hi:g} m; lengths are in metres (was it given in millimetres or "
                         "centimetres?)")
    return v


def task_id(task, name: str = "task") -> int:
    """One task given as 0 / 1 or "inner" / "outer" -> 0 or 1."""
    if isinstance(task, str):
        if task.lower() not in TASK_NAMES:
            raise ValueError(f"{name}: must be 0 / 'inner' or 1 / 'outer', got {task!r}")
        return TASK_NAMES[task.lower()]
    if torch.is_tensor(task) and task.numel() == 1 and not task.is_floating_point():
        task = int(task)
    if isinstance(task, bool) or not isinstance(task, int) or task not in (0, 1):
        raise ValueError(f"{name}: must be 0 / 'inner' or 1 / 'outer', got {task!r}")
    return task


def as_points(x, name: str = "x", dim: int | None = None, dtype: torch.dtype = torch.float64,
              device: torch.device | None = None, allow_empty: bool = False) -> Tensor:
    """Return ``x`` as an ``(n, d)`` floating tensor or raise ``ValueError`` naming the problem."""
    t = _tensor(x, name)
    if t.dim() != 2:
        raise ValueError(f"{name}: expected a 2-D tensor of shape (n, d), got shape {tuple(t.shape)}")
    if t.shape[0] == 0 and not allow_empty:
        raise ValueError(f"{name}: empty data (0 points)")
    if t.shape[1] == 0:
        raise ValueError(f"{name}: points have dimension 0")
    if dim is not None and t.shape[1] != dim:
        raise ValueError(f"{name}: expected points of dimension {dim}, got dimension {t.shape[1]}")
    if t.is_complex() or t.dtype == torch.bool:
        raise ValueError(f"{name}: expected real coordinates, got dtype {t.dtype}")
    t = t.to(dtype=dtype, device=device)
    if not torch.isfinite(t).all():
        bad = (~torch.isfinite(t)).any(-1).nonzero().flatten()[:5].tolist()
        raise ValueError(f"{name}: contains NaN or inf coordinates (first bad rows: {bad})")
    return t


def as_labels(y, n: int, name: str = "y", dtype: torch.dtype = torch.float64,
              device: torch.device | None = None) -> Tensor:
    """Return labels as an ``(n,)`` float tensor: 0 on a surface, 1 in free space, negative inside (:data:`LABELS`)."""
    t = _tensor(y, name)
    if t.dim() != 1:
        raise ValueError(f"{name}: expected a 1-D tensor of labels, got shape {tuple(t.shape)}")
    if t.shape[0] != n:
        raise ValueError(f"{name}: length {t.shape[0]} does not match the {n} points")
    if t.is_complex():
        raise ValueError(f"{name}: expected real labels {LABELS}, got dtype {t.dtype}")
    t = t.to(dtype=dtype, device=device)
    if not torch.isfinite(t).all():
        raise ValueError(f"{name}: contains NaN or inf labels")
    if (problem := label_problem(t)) is not None:
        raise ValueError(f"{name}: {problem}")
    return t


def as_tasks(task, n: int, name: str = "task", device: torch.device | None = None) -> Tensor:
    """Return task ids as an ``(n,)`` long tensor with values in {0 (inner), 1 (outer)}.

    ``task`` may be one id or name for all points (0 / "inner", 1 / "outer"), or a sequence of them.
    """
    if isinstance(task, (str, int)) and not isinstance(task, bool):
        task = torch.full((n,), task_id(task, name))
    elif isinstance(task, (list, tuple)) and task and all(isinstance(v, str) for v in task):
        task = torch.tensor([task_id(v, name) for v in task])
    t = _tensor(task, name)
    if t.dim() != 1:
        raise ValueError(f"{name}: expected a 1-D tensor of task ids, got shape {tuple(t.shape)}")
    if t.shape[0] != n:
        raise ValueError(f"{name}: length {t.shape[0]} does not match the {n} points")
    if t.is_complex() or t.dtype == torch.bool:
        raise ValueError(f"{name}: task ids must be integers 0 (inner) or 1 (outer), got dtype {t.dtype}")
    if t.is_floating_point():
        if not torch.isfinite(t).all() or not (t == t.round()).all():
            raise ValueError(f"{name}: task ids must be integers 0 (inner) or 1 (outer)")
    if not ((t == 0) | (t == 1)).all():
        bad = sorted(set(t[(t != 0) & (t != 1)].tolist()))[:5]
        raise ValueError(f"{name}: task ids must be 0 (inner) or 1 (outer), got {bad}")
    return t.to(dtype=torch.long, device=device)


def as_bounds(bounds, dim: int, name: str = "bounds") -> np.ndarray:
    """Validate a box (boxes as the ecosystem writes them, like trimesh's ``mesh.bounds``) given as `(2, d)`
    `[min corner; max corner]` [m] and return it as a float64 array.

    Raises:
        ValueError: wrong shape (a `(d, 2)` box of [min, max] rows is named as such), NaN/inf, or min >= max.
    """
    try:
        b = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a (2, {dim}) array [min corner; max corner] [m], got {bounds!r}") from None
    if b.shape != (2, dim):
        hint = (" (that is the [min, max]-per-axis layout: pass its transpose, e.g. mesh.bounds or "
                "np.asarray(b).T)") if b.shape == (dim, 2) else ""
        raise ValueError(f"{name}: expected shape (2, {dim}) = [min corner; max corner] like trimesh's mesh.bounds, "
                         f"got {b.shape}{hint}")
    if not np.isfinite(b).all():
        raise ValueError(f"{name}: contains NaN or inf")
    if not (b[1] > b[0]).all():
        hint = " (an [[min, max] per axis] box? transpose it)" if dim == 2 else ""
        raise ValueError(f"{name}: the max corner must exceed the min corner on every axis, got {b.tolist()}{hint}")
    return b


def as_device(device, name: str = "device") -> torch.device | None:
    """Validate a device name or ``torch.device`` (None stays None) by placing a float64 scalar on it.

    Raises:
        ValueError: an unknown device name, or one this torch build or machine cannot use (names it).
    """
    if device is None:
        return None
    try:
        dev = torch.device(device)
        if dev.type not in ("cpu", "cuda", "mps", "xpu"):     # meta, privateuse, ...: tensors without values
            raise RuntimeError(f"device type {dev.type!r} holds no data to compute with")
        torch.zeros(1, dtype=torch.float64, device=dev).item()
    except (RuntimeError, AssertionError, TypeError, NotImplementedError) as exc:
        # CUDA's messages run over several lines of debugging advice: the first says what went wrong
        why = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"{name}: cannot use {device!r} here ({why}); available: {', '.join(available_devices())}") \
            from None
    return dev


def available_devices() -> list[str]:
    """The devices this torch build and machine can compute on ("cpu", "cuda:0", ...)."""
    out = ["cpu"]
    if torch.cuda.is_available():
        out += [f"cuda:{i}" for i in range(torch.cuda.device_count())]
    mps = getattr(torch.backends, "mps", None)
    if mps is not None and mps.is_available():
        out.append("mps")
    return out

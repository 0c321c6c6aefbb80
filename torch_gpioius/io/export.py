"""Write estimated surfaces for other tools: meshes (PLY, OBJ, STL, GLB, OFF through trimesh) in 3-D, polylines
(SVG, DXF, or a PLY/OBJ line set) in 2-D, coloured by the posterior variance."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..core.validation import as_bounds
from ..geometry.surfaces import data_bounds, grid_resolution  # noqa: F401  (grid_resolution: re-exported, its 0.3 home)
from .datasets import DatasetError
from .outputs import FileClaim, atomic_write, check_distinct

__all__ = ["export_run", "export_model", "write_estimate", "write_surface", "surface_bytes", "curves_svg",
           "grid_resolution", "check_format",
           "MESH_FORMATS", "CURVE_FORMATS"]

#: File endings trimesh writes meshes to.
MESH_FORMATS = (".ply", ".obj", ".stl", ".glb", ".off")
#: File endings a 2-D estimate (closed polylines) is written to.
CURVE_FORMATS = (".svg", ".dxf", ".ply", ".obj")


def _colours(variance: np.ndarray, prior: float) -> np.ndarray:
    """`(n, 4)` uint8 RGBA: matplotlib's Purples over variance / prior variance in [0, 1]."""
    from matplotlib import colormaps

    return (colormaps["Purples"](np.clip(variance / prior, 0.0, 1.0)) * 255).round().astype(np.uint8)


def write_surface(surface, variance, path: str | os.PathLike | FileClaim, prior: float) -> Path:
    """Write one estimated surface (atomically: a link at ``path`` is replaced, never followed).

    Args:
        surface: a :class:`trimesh.Trimesh` (3-D) or a list of `(m, 2)` closed polylines [m] (2-D).
        variance: `(V,)` posterior variance at the mesh vertices, or a list of `(m,)` per polyline.
        path: output file, or a :class:`~torch_gpioius.io.outputs.FileClaim` held on it (written through the claim);
            the ending picks the format (:data:`MESH_FORMATS` / :data:`CURVE_FORMATS`).
        prior: prior variance, to which the colours are scaled.

    Units: meshes and PLY/OBJ line sets are in metres (the base frame, as everything here); SVG and DXF drawings
    are in millimetres, and an SVG stands upright (its y axis points down, so y is negated) and declares its size
    in millimetres.

    Returns:
        the path written. PLY meshes also carry the variance as a vertex property ``variance``.

    Raises:
        ValueError: a format that does not suit the surface.
    """
    claim = path if isinstance(path, FileClaim) else None
    path = claim.target if claim is not None else Path(path)
    data = surface_bytes(surface, variance, path, prior)
    if claim is not None:
        return claim.write(data)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(path, data)


def surface_bytes(surface, variance, path: str | os.PathLike, prior: float) -> bytes | str:
    """What :func:`write_surface` writes to ``path`` (its ending picks the format), without writing it."""
    import trimesh

    path = Path(path)
    ext = path.suffix.lower()
    if isinstance(surface, trimesh.Trimesh):
        if ext not in MESH_FORMATS:
            raise ValueError(f"{path}: a 3-D estimate is a mesh; write one of {', '.join(MESH_FORMATS)}")
        mesh = surface.copy()
        mesh.visual.vertex_colors = _colours(np.asarray(variance), prior)
        mesh.vertex_attributes["variance"] = np.asarray(variance, dtype=np.float64)
        if ext == ".ply":
            return trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=True)
        return mesh.export(file_type=ext[1:])
    if ext not in CURVE_FORMATS:
        raise ValueError(f"{path}: a 2-D estimate is a set of closed curves; write one of {', '.join(CURVE_FORMATS)}")
    curves = [np.asarray(c, dtype=np.float64) for c in surface]
    if ext == ".svg":
        return curves_svg(curves)
    if ext == ".dxf":
        # drawings are in millimetres, the unit CAD and drawing programs expect (metres made an SVG 0.3 units wide)
        flip = np.array([1000.0, 1000.0])
        entities, vertices = [], []
        for c in curves:
            start = sum(len(v) for v in vertices)
            vertices.append(c * flip)
            entities.append(trimesh.path.entities.Line(np.arange(start, start + len(c))))
        p = trimesh.path.Path2D(entities=entities, vertices=np.concatenate(vertices))
        return p.export(file_type="dxf")
    # PLY / OBJ: a line set in the z = 0 plane with the variance as colours
    vertices = np.concatenate([np.column_stack([c, np.zeros(len(c))]) for c in curves])
    offsets = np.cumsum([0] + [len(c) for c in curves])
    edges = np.concatenate([np.column_stack([np.arange(a, b - 1), np.arange(a + 1, b)])
                            for a, b in zip(offsets[:-1], offsets[1:])])
    colours = _colours(np.concatenate([np.asarray(v) for v in variance]), prior)
    if ext == ".ply":
        # trimesh writes no edges to PLY: a minimal ASCII PLY with vertex colours and edge elements
        lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property double x", "property double y",
                 "property double z", "property uchar red", "property uchar green", "property uchar blue",
                 f"element edge {len(edges)}", "property int vertex1", "property int vertex2", "end_header"]
        lines += [f"{x!r} {y!r} {z!r} {r} {g} {b}" for (x, y, z), (r, g, b, _) in zip(vertices.tolist(), colours)]
        lines += [f"{a} {b}" for a, b in edges]
        return "\n".join(lines) + "\n"
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    for a, b in zip(offsets[:-1], offsets[1:]):
        lines.append("l " + " ".join(str(i + 1) for i in range(a, b)))
    return "\n".join(lines) + "\n"


def curves_svg(curves: list[np.ndarray], colour: str = "#d62728") -> str:
    """An SVG drawing of closed curves `(m, 2)` [m] in millimetres, upright, with axes.

    The curves are unfilled strokes (``<g id="estimate">``); a frame with ticks every 10, 20 or 50 mm, their labels
    and the axis names sit in a group of their own (``<g id="axes">``) that a drawing program can hide or delete.
    The document declares its size in millimetres and one user unit is 1 mm. Written here because trimesh's SVG
    export fills every closed path in black and draws no axes.
    """
    mm = [np.asarray(c, dtype=np.float64) * np.array([1000.0, -1000.0]) for c in curves]   # SVG's y points down
    pts = np.concatenate(mm)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = float(max((hi - lo).max(), 1.0))
    step = next(t for t in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000) if span / t <= 8)
    x_ticks = np.arange(np.ceil(lo[0] / step) * step, hi[0] + 1e-9, step)
    y_ticks = np.arange(np.ceil(-hi[1] / step) * step, -lo[1] + 1e-9, step)        # in the drawing's y (up)
    font = max(span / 40, 2.5)
    pad = np.array([4.5 * font, 3.0 * font])                                        # room for the labels
    x0, y0 = lo[0] - pad[0], lo[1] - font
    width, height = hi[0] - lo[0] + pad[0] + font, hi[1] - lo[1] + pad[1] + font

    def num(v: float) -> str:
        return f"{v:.3f}".rstrip("0").rstrip(".")

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.3f}mm" height="{height:.3f}mm" '
           f'viewBox="{x0:.3f} {y0:.3f} {width:.3f} {height:.3f}">',
           f'<g id="axes" stroke="#888888" stroke-width="{font / 12:.3f}" fill="none" font-family="sans-serif">',
           f'<rect x="{lo[0]:.3f}" y="{lo[1]:.3f}" width="{hi[0] - lo[0]:.3f}" height="{hi[1] - lo[1]:.3f}"/>']
    tick = font / 2
    for t in x_ticks:
        out.append(f'<line x1="{t:.3f}" y1="{hi[1]:.3f}" x2="{t:.3f}" y2="{hi[1] + tick:.3f}"/>')
        out.append(f'<text x="{t:.3f}" y="{hi[1] + tick + font:.3f}" font-size="{font:.3f}" text-anchor="middle" '
                   f'stroke="none" fill="#555555">{num(t)}</text>')
    for t in y_ticks:
        out.append(f'<line x1="{lo[0] - tick:.3f}" y1="{-t:.3f}" x2="{lo[0]:.3f}" y2="{-t:.3f}"/>')
        out.append(f'<text x="{lo[0] - tick - font / 4:.3f}" y="{-t + font / 3:.3f}" font-size="{font:.3f}" '
                   f'text-anchor="end" stroke="none" fill="#555555">{num(t)}</text>')
    out.append(f'<text x="{(lo[0] + hi[0]) / 2:.3f}" y="{hi[1] + tick + 2.2 * font:.3f}" font-size="{font:.3f}" '
               'text-anchor="middle" stroke="none" fill="#555555">x [mm]</text>')
    cx, cy = lo[0] - 3.6 * font, (lo[1] + hi[1]) / 2
    out.append(f'<text x="{cx:.3f}" y="{cy:.3f}" font-size="{font:.3f}" text-anchor="middle" stroke="none" '
               f'fill="#555555" transform="rotate(-90 {cx:.3f} {cy:.3f})">y [mm]</text>')
    out.append("</g>")
    out.append(f'<g id="estimate" fill="none" stroke="{colour}" stroke-width="{font / 6:.3f}" '
               'stroke-linejoin="round">')
    for c in mm:
        closed = len(c) > 2 and np.allclose(c[0], c[-1])
        body = " L".join(f"{x:.4f},{y:.4f}" for x, y in (c[:-1] if closed else c))
        out.append(f'<path d="M{body}{" Z" if closed else ""}"/>')
    out.append("</g>")
    out.append("</svg>")
    return "\n".join(out) + "\n"


def export_run(run: str | os.PathLike, mesh: str | os.PathLike | None = None, *,
               outer: str | os.PathLike | None = None, step: int | None = None,
               resolution: float | None = None, bounds=None, force: bool = False) -> dict:
    """Write the estimated inner (and outer) surface of a log or dataset after ``step`` (default: the last).

    The model is rebuilt with the run's own learned K_t at that step (no re-learning; datasets are fitted).

    Args:
        run: exploration log or dataset (``.gpioius``).
        mesh: file for the inner estimate ``{mu_in = 0}``.
        outer: file for the outer estimate ``{mu_out = 0}`` (visual-tactile runs).
        step: which step (the last recorded one at or before it).
        resolution: grid spacing [m] (default 5 mm in 2-D, 1 cm in 3-D).
        bounds: `(2, d)` box `[min; max]` [m] (default: the observations padded by 5 cm).
        force: replace existing files (a link there is replaced, never followed).

    2-D curves go to SVG and DXF in millimetres (SVG upright, sized in mm), to PLY and OBJ in metres; see
    :func:`write_surface` and docs/data-format.md.

    Returns:
        ``{"step", "inner", "outer", "vertices", "faces"}`` (paths written, and the inner mesh's size in 3-D).

    Raises:
        DatasetError / ValueError: unreadable run, a format that does not suit, no surface in the box, an outer
            export of a run without outer observations, both outputs naming one file, a bad resolution.
        FileExistsError: an output exists and ``force`` is False.
    """
    from contextlib import ExitStack

    from .outputs import check_not_inputs

    if mesh is None and outer is None:
        raise ValueError("export: nothing to write (give a mesh and/or an outer file)")
    check_distinct(**{"--mesh": mesh, "--outer": outer})
    check_not_inputs({"--mesh": mesh, "--outer": outer}, [run])
    with ExitStack() as held:
        # each output claimed until written: a second export of the same file is refused at once
        claims = [None if t is None else held.enter_context(FileClaim(t, force, "export")) for t in (mesh, outer)]
        if Path(run).is_dir():
            return _export_fit(Path(run), *claims, step, resolution, bounds)
        return _export_log(run, *claims, step, resolution, bounds)


def _export_log(run, mesh: FileClaim | None, outer: FileClaim | None, step, resolution, bounds) -> dict:
    """:func:`export_run` of a log or dataset, its outputs claimed."""
    from ..geometry.metrics import prior_variance
    from .runs import estimate_surface, load_run

    history = load_run(run)
    if step is not None and (isinstance(step, bool) or not isinstance(step, (int, np.integer))):
        raise ValueError(f"export: step must be a step number, got {step!r}")
    if step is not None and not history.steps[0] <= int(step) <= history.steps[-1]:
        # both ends alike: a step past the end (`--step 40` on a 10-step log) is refused as one before the start
        raise ValueError(f"export: step {step} is outside the run's steps {history.steps[0]}-{history.steps[-1]} "
                         f"({len(history.steps)} recorded); omit --step for the last")
    k = history.steps[-1] if step is None else history.nearest_step(int(step))
    model = history.model_at(k)
    ds = history.states[k]
    dim = history.dim
    box = data_bounds(ds.x) if bounds is None else as_bounds(bounds, dim)
    res = grid_resolution(resolution, dim)
    out = {"step": k, "inner": None, "outer": None}
    # every check before anything is written: a refused export leaves no partial output
    for claim in (mesh, outer):
        if claim is not None:
            check_format(claim.target, dim)
    if outer is not None and getattr(model, "num_tasks", 1) < 2:
        raise ValueError(f"export: {history.path.name} has no outer model at step {k} (a tactile-only run); "
                         "drop --outer")
    surfaces = {}
    for task, target in ((0, mesh), (1, outer)):
        if target is None:
            continue
        surface, var = estimate_surface(model, box, res, task)
        if surface is None or (dim == 2 and not surface):
            raise DatasetError(f"export: the {'inner' if task == 0 else 'outer'} estimate at step {k} does not cross "
                               "the box of the observations")
        surfaces[task] = (surface, var, target)
    for task, (surface, var, target) in surfaces.items():
        out["inner" if task == 0 else "outer"] = str(write_surface(surface, var, target, prior_variance(model, task)))
        if task == 0 and dim == 3:
            out.update(vertices=len(surface.vertices), faces=len(surface.faces))
    return out


def export_model(model, path: str | os.PathLike, bounds, resolution: float, task: int = 0) -> Path | None:
    """Write the estimate ``{mu_task = 0}`` of a fitted model inside ``bounds`` `(2, d)` [m] at ``resolution`` [m].

    Returns:
        the path written, or None when the level set does not cross the box (nothing is written then).
    """
    from ..geometry.metrics import prior_variance
    from .runs import estimate_surface

    bounds = np.asarray(bounds, dtype=np.float64)
    surface, var = estimate_surface(model, bounds, resolution, task)
    if surface is None or (bounds.shape[1] == 2 and not surface):
        return None
    return write_surface(surface, var, path, prior_variance(model, task))


def check_format(path: str | os.PathLike, dim: int) -> None:
    """Refuse a file ending that does not suit a ``dim``-D estimate (:data:`MESH_FORMATS` in 3-D,
    :data:`CURVE_FORMATS` in 2-D), before any work.

    Raises:
        ValueError: naming the file and the endings that suit.
    """
    allowed = MESH_FORMATS if dim == 3 else CURVE_FORMATS
    if Path(path).suffix.lower() not in allowed:
        raise ValueError(f"{path}: a {dim}-D estimate is {'a mesh' if dim == 3 else 'a set of closed curves'}; write "
                         f"one of {', '.join(allowed)}")


def write_estimate(model, bounds, path: str | os.PathLike | FileClaim, resolution: float, task: int = 0) -> str:
    """:func:`export_model`, refusing what it cannot write: a format that does not suit the model's dimension, or an
    estimate that does not cross ``bounds`` `(2, d)` [m].

    Returns:
        the path written, as a string.

    Raises:
        ValueError: a format that does not suit (names the file and the formats that do).
        DatasetError: no surface in the box.
    """
    bounds = np.asarray(bounds, dtype=np.float64)
    check_format(path.target if isinstance(path, FileClaim) else path, bounds.shape[1])
    written = export_model(model, path, bounds, resolution, task)
    if written is None:
        raise DatasetError(f"{path}: the {'inner' if task == 0 else 'outer'} estimate does not cross the box of the "
                           "observations: nothing to write")
    return str(written)


def _export_fit(folder: Path, mesh, outer, step, resolution, bounds) -> dict:
    """:func:`export_run` of a ``gpioius fit --out`` folder: its checkpoint's estimate."""
    from .checkpoints import load_checkpoint

    if not (folder / "model.pt").is_file():
        raise ValueError(f"export: {folder} is a folder without model.pt (give a log, a dataset or a `gpioius fit "
                         "--out` folder)")
    if step is not None:
        raise ValueError("export: --step applies to a log; a fit folder holds one model")
    model = load_checkpoint(folder / "model.pt")
    x = model.train_inputs[0].detach().cpu().numpy()
    dim = x.shape[1]
    box = data_bounds(x, pad=0.05) if bounds is None else as_bounds(bounds, dim)
    res = grid_resolution(resolution, dim)
    for claim in (mesh, outer):
        if claim is not None:
            check_format(claim.target, dim)
    if outer is not None and getattr(model, "num_tasks", 1) < 2:
        raise ValueError(f"export: {folder} holds a tactile-only model; drop --outer")
    out = {"step": None, "inner": None, "outer": None}
    for key, target, task in (("inner", mesh, 0), ("outer", outer, 1)):
        if target is not None:
            out[key] = write_estimate(model, box, target, res, task)
    return out

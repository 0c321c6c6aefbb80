"""Write estimated surfaces for other tools: meshes (PLY, OBJ, STL, GLB, OFF through trimesh) in 3-D, polylines
(SVG, DXF, or a PLY/OBJ line set) in 2-D, coloured by the posterior variance."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._validation import as_bounds
from ..surfaces import data_bounds, grid_resolution  # noqa: F401  (grid_resolution: re-exported, its 0.3 home)
from .datasets import DatasetError
from .outputs import atomic_write, check_distinct, check_new_file

__all__ = ["export_run", "export_model", "write_surface", "grid_resolution", "MESH_FORMATS", "CURVE_FORMATS"]

#: File endings trimesh writes meshes to.
MESH_FORMATS = (".ply", ".obj", ".stl", ".glb", ".off")
#: File endings a 2-D estimate (closed polylines) is written to.
CURVE_FORMATS = (".svg", ".dxf", ".ply", ".obj")


def _colours(variance: np.ndarray, prior: float) -> np.ndarray:
    """`(n, 4)` uint8 RGBA: matplotlib's Purples over variance / prior variance in [0, 1]."""
    from matplotlib import colormaps

    return (colormaps["Purples"](np.clip(variance / prior, 0.0, 1.0)) * 255).round().astype(np.uint8)


def write_surface(surface, variance, path: str | os.PathLike, prior: float) -> Path:
    """Write one estimated surface (atomically: a link at ``path`` is replaced, never followed).

    Args:
        surface: a :class:`trimesh.Trimesh` (3-D) or a list of `(m, 2)` closed polylines [m] (2-D).
        variance: `(V,)` posterior variance at the mesh vertices, or a list of `(m,)` per polyline.
        path: output file; the ending picks the format (:data:`MESH_FORMATS` / :data:`CURVE_FORMATS`).
        prior: prior variance, to which the colours are scaled.

    Units: meshes and PLY/OBJ line sets are in metres (the base frame, as everything here); SVG and DXF drawings
    are in millimetres, and an SVG stands upright (its y axis points down, so y is negated) and declares its size
    in millimetres.

    Returns:
        the path written. PLY meshes also carry the variance as a vertex property ``variance``.

    Raises:
        ValueError: a format that does not suit the surface.
    """
    import trimesh

    path = Path(path)
    ext = path.suffix.lower()
    if isinstance(surface, trimesh.Trimesh):
        if ext not in MESH_FORMATS:
            raise ValueError(f"{path}: a 3-D estimate is a mesh; write one of {', '.join(MESH_FORMATS)}")
        mesh = surface.copy()
        mesh.visual.vertex_colors = _colours(np.asarray(variance), prior)
        mesh.vertex_attributes["variance"] = np.asarray(variance, dtype=np.float64)
        path.parent.mkdir(parents=True, exist_ok=True)
        if ext == ".ply":
            return atomic_write(path, trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=True))
        return atomic_write(path, mesh.export(file_type=ext[1:]))
    if ext not in CURVE_FORMATS:
        raise ValueError(f"{path}: a 2-D estimate is a set of closed curves; write one of {', '.join(CURVE_FORMATS)}")
    curves = [np.asarray(c, dtype=np.float64) for c in surface]
    path.parent.mkdir(parents=True, exist_ok=True)
    if ext in (".svg", ".dxf"):
        # drawings are in millimetres, the unit CAD and drawing programs expect (metres made an SVG 0.3 units wide);
        # SVG's y axis points down, so y is negated there and the drawing stands upright
        flip = np.array([1000.0, -1000.0 if ext == ".svg" else 1000.0])
        entities, vertices = [], []
        for c in curves:
            start = sum(len(v) for v in vertices)
            vertices.append(c * flip)
            entities.append(trimesh.path.entities.Line(np.arange(start, start + len(c))))
        p = trimesh.path.Path2D(entities=entities, vertices=np.concatenate(vertices))
        text = p.export(file_type=ext[1:])
        if ext == ".svg":
            (x0, y0), (x1, y1) = p.bounds
            text = text.replace('width="100%"', f'width="{x1 - x0:.3f}mm"', 1).replace(
                'height="100%"', f'height="{y1 - y0:.3f}mm"', 1)
        return atomic_write(path, text)
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
        return atomic_write(path, "\n".join(lines) + "\n")
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    for a, b in zip(offsets[:-1], offsets[1:]):
        lines.append("l " + " ".join(str(i + 1) for i in range(a, b)))
    return atomic_write(path, "\n".join(lines) + "\n")


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
    from ..metrics import prior_variance
    from .runs import estimate_surface, load_run

    if mesh is None and outer is None:
        raise ValueError("export: nothing to write (give a mesh and/or an outer file)")
    check_distinct(**{"--mesh": mesh, "--outer": outer})
    for target in (mesh, outer):
        if target is not None:
            check_new_file(target, force, "export")
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
    for target in (mesh, outer):
        if target is not None:
            ext = Path(target).suffix.lower()
            allowed = MESH_FORMATS if dim == 3 else CURVE_FORMATS
            if ext not in allowed:
                kind = "a mesh" if dim == 3 else "a set of closed curves"
                raise ValueError(f"{target}: a {dim}-D estimate is {kind}; write one of {', '.join(allowed)}")
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
    from ..metrics import prior_variance
    from .runs import estimate_surface

    bounds = np.asarray(bounds, dtype=np.float64)
    surface, var = estimate_surface(model, bounds, resolution, task)
    if surface is None or (bounds.shape[1] == 2 and not surface):
        return None
    return write_surface(surface, var, path, prior_variance(model, task))

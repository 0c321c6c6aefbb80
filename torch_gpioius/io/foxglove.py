"""Write a run as an MCAP file with Foxglove schemas, so a ROS user can scrub it in Foxglove (the ``foxglove``
extra, ``foxglove-sdk``).

Topics, all in the run's frame (``base``, or ``scene`` in 2-D, lifted to z = 0):

* ``/gpioius/cloud`` (``foxglove.PointCloud``, once): the camera's outer observations (surface and free space);
* ``/gpioius/inside`` (``foxglove.PointCloud``, each exported step; runs with points known to lie inside only,
  :data:`INSIDE_TOPIC`): the points labelled below zero so far, behind the touches and behind the seen surface;
* ``/gpioius/contacts``, ``/gpioius/free_space`` (``foxglove.PointCloud``, each exported step): the touches so far;
* ``/gpioius/path`` (``foxglove.SceneUpdate`` with a line strip): the fingertip's path so far;
* ``/gpioius/estimate`` (``foxglove.SceneUpdate``): the inner estimate, a triangle list in 3-D or a line list in 2-D,
  coloured by its posterior variance (white certain, purple prior);
* ``/gpioius/metrics`` (JSON): step, similarity, correlation, Hausdorff distance, for Foxglove's plot panel;
* ``/gpioius/pad`` (``foxglove.SceneUpdate`` with a line loop; tactile-patch runs only, :data:`PAD_TOPIC`): the
  outline of the gel pad read at the step.

Message times are the run's step numbers in seconds from the start of the file (a step's wall time is not what a
viewer scrubs by).
"""

from __future__ import annotations

import math
import os
import secrets
from pathlib import Path

import numpy as np

__all__ = ["export_mcap", "MCAP_TOPICS", "PAD_TOPIC", "INSIDE_TOPIC"]

MCAP_TOPICS = ("/gpioius/cloud", "/gpioius/contacts", "/gpioius/free_space", "/gpioius/path", "/gpioius/estimate",
               "/gpioius/metrics")
#: The pad's outline per step, written for runs whose log records the gel pad (``touch="patch"``).
PAD_TOPIC = "/gpioius/pad"
#: The points known to lie inside (labels below zero, either task) per step, for runs that have them.
INSIDE_TOPIC = "/gpioius/inside"


def _lift(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64).reshape(len(x), -1)
    return np.column_stack([x, np.zeros(len(x))]) if x.shape[1] == 2 else x


def export_mcap(run: str | os.PathLike, path: str | os.PathLike, *, every: int | None = None,
                resolution: float | None = None, force: bool = False) -> dict:
    """Write a log or dataset as MCAP with Foxglove schemas (see the module docstring for the topics).

    Args:
        run: exploration log or dataset (``.gpioius``).
        path: the ``.mcap`` file to write (refused if it exists, unless ``force``; written to a temporary file and
            renamed, so a link there is replaced, never followed).
        every: export every k-th step (the last always); default about 50 steps in all.
        resolution: grid spacing of the estimates [m] (default 5 mm in 2-D, 1.5 cm in 3-D).
        force: replace an existing file.

    Returns:
        ``{"path", "steps", "messages"}``.

    Raises:
        ImportError: without ``foxglove-sdk``. FileExistsError: ``path`` exists. FileNotFoundError: its folder does
            not exist (names it). DatasetError: an unreadable run. ValueError: a bad resolution or step.
    """
    try:
        import foxglove  # noqa: F401
    except ImportError as exc:  # pragma: no cover - extra missing
        from ..core.extras import install_hint

        raise ImportError(f"MCAP export needs the 'foxglove' extra: {install_hint('foxglove')}") from exc
    from ..geometry.surfaces import grid_resolution
    from .outputs import check_new_file
    from .runs import load_run

    path = check_new_file(path, force, "MCAP")
    if path.suffix.lower() != ".mcap":
        raise ValueError(f"export: {path}: an MCAP file must end in .mcap")
    history = load_run(run)
    steps = history.steps
    k_every = every or max(1, len(steps) // 50)
    if isinstance(k_every, bool) or not isinstance(k_every, int) or k_every < 1:
        raise ValueError(f"export: every must be a positive integer, got {every!r}")
    chosen = steps[::k_every]
    if chosen[-1] != steps[-1]:
        chosen.append(steps[-1])
    res = grid_resolution(resolution, history.dim, 0.005, 0.015)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    try:
        n_messages = _write_mcap(tmp, history, chosen, res)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return {"path": str(path), "steps": len(chosen), "messages": n_messages}


def _write_mcap(file: Path, history, chosen: list[int], res: float) -> int:
    """Write the chosen steps of a run to ``file``; returns the number of messages."""
    import foxglove
    from foxglove import channels as ch
    from foxglove import messages as fm
    from matplotlib import colormaps

    steps = history.steps
    frame = str(history.meta.get("frame", "base"))
    cmap = colormaps["Purples"]

    def cloud_msg(points: np.ndarray, t: int):
        p = _lift(points).astype(np.float32) if len(points) else np.zeros((0, 3), np.float32)
        f32 = fm.PackedElementFieldNumericType.Float32
        return fm.PointCloud(timestamp=fm.Timestamp(t, 0), frame_id=frame, pose=fm.Pose(
            position=fm.Vector3(x=0.0, y=0.0, z=0.0), orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            point_stride=12, fields=[fm.PackedElementField(name=n, offset=4 * i, type=f32)
                                     for i, n in enumerate("xyz")], data=p.tobytes())

    def colour(v: float, prior: float):
        r, g, b, _ = cmap(min(max(0.3 + 0.7 * v / prior, 0.0), 1.0))
        return fm.Color(r=float(r), g=float(g), b=float(b), a=1.0)

    def pts(a: np.ndarray):
        return [fm.Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in _lift(a)]

    ctx = foxglove.Context()
    n_messages = 0
    with foxglove.open_mcap(str(file), context=ctx):
        cloud = ch.PointCloudChannel("/gpioius/cloud", context=ctx)
        contacts = ch.PointCloudChannel("/gpioius/contacts", context=ctx)
        free = ch.PointCloudChannel("/gpioius/free_space", context=ctx)
        path_ch = ch.SceneUpdateChannel("/gpioius/path", context=ctx)
        estimate = ch.SceneUpdateChannel("/gpioius/estimate", context=ctx)
        metrics = foxglove.Channel("/gpioius/metrics", context=ctx)
        has_pads = any("pad_pose" in history.params.get(k, {}) for k in steps)
        pad_ch = ch.SceneUpdateChannel(PAD_TOPIC, context=ctx) if has_pads else None
        has_inside = bool((history.states[steps[-1]].y < 0).any())
        inside_ch = ch.PointCloudChannel(INSIDE_TOPIC, context=ctx) if has_inside else None
        first = history.states[steps[0]]
        # the camera's surface and free space (its inside points, labels below 0, have their own topic)
        cloud.log(cloud_msg(first.x[(first.task == 1) & (first.y >= 0)], 0), log_time=0)
        n_messages += 1
        for k in chosen:
            t_ns = int(k) * 1_000_000_000
            ds = history.states[k]
            contacts.log(cloud_msg(ds.x[(ds.task == 0) & (ds.y == 0)], k), log_time=t_ns)
            free.log(cloud_msg(ds.x[(ds.task == 0) & (ds.y == 1)], k), log_time=t_ns)
            n_messages += 2
            if inside_ch is not None:
                inside_ch.log(cloud_msg(ds.x[ds.y < 0], k), log_time=t_ns)
                n_messages += 1
            if history.trajectory is not None:
                trail = history.trajectory[history.trajectory_step <= k]
                if len(trail) > 1:
                    line = fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, thickness=2.0,
                                            scale_invariant=True, points=pts(trail),
                                            color=fm.Color(r=1.0, g=0.55, b=0.0, a=1.0))
                    path_ch.log(fm.SceneUpdate(entities=[fm.SceneEntity(timestamp=fm.Timestamp(k, 0), frame_id=frame,
                                                                          id="path", lines=[line])]), log_time=t_ns)
                    n_messages += 1
            if pad_ch is not None and "pad_pose" in history.params.get(k, {}):
                corners = history.pad_footprints(k)[-1]
                loop = fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineLoop, thickness=2.0, scale_invariant=True,
                                        points=pts(corners), color=fm.Color(r=0.78, g=0.12, b=0.47, a=1.0))
                pad_ch.log(fm.SceneUpdate(entities=[fm.SceneEntity(timestamp=fm.Timestamp(k, 0), frame_id=frame,
                                                                     id="pad", lines=[loop])]), log_time=t_ns)
                n_messages += 1
            entity = _estimate_entity(history, k, ds, res, frame, colour, pts)
            if entity is not None:
                estimate.log(fm.SceneUpdate(entities=[entity]), log_time=t_ns)
                n_messages += 1
            p = history.params.get(k, {})
            row = {"step": int(k)}
            for key in ("similarity", "correlation", "hausdorff"):
                v = p.get(key, math.nan)
                row[key] = None if v is None or not math.isfinite(v) else float(v)
            metrics.log(row, log_time=t_ns)
            n_messages += 1
    return n_messages


def _estimate_entity(history, k: int, ds, res: float, frame: str, colour, pts):
    """The estimate at step ``k`` as a Foxglove scene entity coloured by its variance (a triangle list in 3-D, line
    strips in 2-D), or None before the first contact or where the estimate has no surface."""
    from foxglove import messages as fm

    from ..geometry.metrics import prior_variance
    from ..geometry.surfaces import data_bounds
    from .runs import estimate_surface

    if not ((ds.task == 0) & (ds.y == 0)).any():
        return None
    model = history.model_at(k)
    surface, var = estimate_surface(model, data_bounds(ds.x), res, 0)
    prior = prior_variance(model, 0)
    if history.dim == 3 and surface is not None:
        tri = fm.TriangleListPrimitive(points=pts(surface.vertices), colors=[colour(v, prior) for v in var],
                                       indices=[int(i) for i in surface.faces.reshape(-1)])
        return fm.SceneEntity(timestamp=fm.Timestamp(k, 0), frame_id=frame, id="estimate", triangles=[tri])
    if history.dim == 2 and surface:
        lines = [fm.LinePrimitive(type=fm.LinePrimitiveLineType.LineStrip, thickness=3.0, scale_invariant=True,
                                  points=pts(c), colors=[colour(x, prior) for x in v]) for c, v in zip(surface, var)]
        return fm.SceneEntity(timestamp=fm.Timestamp(k, 0), frame_id=frame, id="estimate", lines=lines)
    return None

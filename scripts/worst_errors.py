"""Where does a finished run's estimate miss the body most, and what observed that place? On study logs.

For each log of a study of ``examples/scenes/real/*.toml`` (or another folder of scene files, ``--scenes``), the
run's world is rebuilt from its record (world, object, seed, settings), the final model from the log, and the
estimate measured as the studies measure it. Then, in both directions of the Hausdorff distance:

* the worst sample (estimate -> body: a piece of estimate off the body; body -> estimate: a piece of body the
  estimate misses), where it lies in the body's bounding box (0-1 per axis, z up), and how far the nearest contact
  and the nearest seen point (outer task, y = 0) are from it;
* the share of samples more than ``--far`` (2 cm) off;
* for the estimate's far samples, the observations within 3 cm of them, by task and label (surface, inside y < 0,
  free y > 0), and the outer task's posterior mean there (below its prior: the camera's data say "inside").

It separates the limits docs/results-real.md reports ("Where the accuracy goals stand"): a thin part the estimate
rounds off (the body -> estimate worst sample lies on the part, the camera's points beside it), an unobserved
concavity (no data within a few centimetres), and a piece of estimate the camera's data put there (many camera
inside points near the far samples, the outer mean below zero). The world must be a simulated one (its true shape
is needed): a study of built-in objects, or of scene files in ``--scenes``.

    python scripts/worst_errors.py outputs/real_ff_tight_judged/logs/*visual-tactile*.gpioius
    python scripts/worst_errors.py outputs/benchmark/primitives-tight/logs/primitives-006_visual-tactile_0.gpioius
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np
import torch
from scipy.spatial import cKDTree

from torch_gpioius.geometry import predict_mean_task
from torch_gpioius.io.datasets import contact_rows
from torch_gpioius.io.runs import load_run
from torch_gpioius.sim.meshes import MeshDistance
from torch_gpioius.studies.study import make_world
from torch_gpioius.geometry.surfaces import surface_samples

SPACING = 0.003     # the studies' sample spacing [m]
NEAR = 0.03         # "observed near a far sample" [m]


def world_of(log: Path, scenes: Path):
    """The world a study log ran in, from the study's record beside it (``../runs/<name>.json``)."""
    record = json.loads((log.parent.parent / "runs" / f"{log.stem}.json").read_text())
    if str(record.get("scene_hash", "")).startswith("set:"):         # an object of a set (gpioius study --objects)
        from torch_gpioius.sim.objectsets import object_set

        cover = record["scene_hash"].rsplit(":", 1)[1]
        family, _, index = record["object"].rpartition("-")
        obj = object_set(f"{family}:{int(index)}")[0]
        return make_world(record["world"], record["object"], int(record["seed"]), settings=record.get("settings"),
                          set_object=obj, cover=cover)
    scene = scenes / f"{record['object']}.toml"
    return make_world(record["world"], record["object"], int(record["seed"]),
                      scene=str(scene) if scene.exists() else None, settings=record.get("settings"))


def visual_tactile_finals(logs, scenes: Path):
    """``(log, run, world, final model, final data)`` of each visual-tactile log among ``logs`` (the others are
    skipped): what the offline studies of finished runs start from."""
    for log in logs:
        run = load_run(log)
        if run.meta.get("mode") != "visual-tactile":
            continue
        last = run.steps[-1]
        yield log, run, world_of(log, scenes), run.model_at(last), run.states[last]


def offline_parser(doc: str) -> argparse.ArgumentParser:
    """The command line of a study of finished runs' final data: the logs and ``--scenes`` (the study's scene
    files), described by the first line of ``doc``."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"), help="the study's scene files")
    return parser


def final_arrays(args):
    """``(log, run, world, model, x, y, task, contacts)`` of each visual-tactile log of ``args`` (an
    :func:`offline_parser`'s), the final data as arrays and the contacts `(k, d)` in the order they were made, each
    once (a run that counted a contact several times, ``contact_repeats``, holds it in as many rows); one torch thread
    and warnings off, as the offline studies run."""
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    for log, run, world, model, data in visual_tactile_finals(args.logs, args.scenes):
        x, y, task = np.asarray(data.x), np.asarray(data.y), np.asarray(data.task)
        yield log, run, world, model, x, y, task, x[contact_rows(x, y, task)]


def worst_errors(log: Path, scenes: Path, far: float = 0.02) -> dict | None:
    """The worst misses of a study log's final estimate (None when it has no surface in the range).

    Returns:
        ``hausdorff`` [m] as the studies measure it; per direction (``"estimate->body"``, ``"body->estimate"``) a
        dict with ``worst`` [m] (exact point-to-mesh distance of the worst sample), ``point`` `(3,)` (that sample,
        base frame [m]), ``box`` `(3,)` (its place in the body's bounding box, 0-1 per axis), ``touch`` and
        ``camera`` [m] (the nearest contact and seen point; NaN when the run has none) and ``share`` (of samples
        more than ``far`` off); ``near`` (observations within
        :data:`NEAR` of the estimate's far samples, by ``(task, kind)``; empty when none is far) and ``outer_mean``
        (the outer task's median posterior mean there; NaN without one).
    """
    run = load_run(log)
    world = world_of(log, scenes)
    step = run.steps[-1]
    model, data = run.model_at(step), run.states[step]
    x, y, t = np.asarray(data.x), np.asarray(data.y), np.asarray(data.task)
    measured = world.measure(model, None)
    if measured.surface is None:
        return None
    est = surface_samples(measured.surface, SPACING)
    est = est[world.in_range(est)]
    body = world.inner_samples_in_range(SPACING)
    to_body = np.asarray(MeshDistance(world.inner, signed=False)(est), dtype=float)
    to_est = np.asarray(MeshDistance(measured.surface, signed=False)(body), dtype=float)
    lo, hi = world.inner.bounds
    trees = {name: cKDTree(pts) if len(pts) else None
             for name, pts in (("touch", x[(t == 0) & (y == 0)]), ("camera", x[(t == 1) & (y == 0)]))}
    out = {"hausdorff": float(measured.hausdorff), "near": {}, "outer_mean": float("nan")}
    for name, d, pts in (("estimate->body", to_body, est), ("body->estimate", to_est, body)):
        i = int(np.argmax(d))
        out[name] = {"worst": float(d[i]), "point": pts[i], "box": (pts[i] - lo) / (hi - lo),
                     "share": float(np.mean(d > far)),
                     **{k: float("nan") if tree is None else float(tree.query(pts[i])[0]) for k, tree in trees.items()}}
    bad = est[to_body > far]
    if len(bad):
        close = cKDTree(bad).query(x)[0] < NEAR
        out["near"] = {(task, kind): int((close & (t == k) & sel).sum())
                       for k, task in ((0, "touch"), (1, "camera"))
                       for kind, sel in (("surface", y == 0), ("inside", y < 0), ("free", y > 0))}
        if getattr(model, "num_tasks", 1) > 1:
            with torch.no_grad():
                out["outer_mean"] = float(np.median(predict_mean_task(model, torch.as_tensor(bad), 1).cpu().numpy()))
    return out


def report(log: Path, scenes: Path, far: float) -> str:
    """:func:`worst_errors` of one log as the lines this script prints."""
    w = worst_errors(log, scenes, far)
    if w is None:
        return f"{log.stem}: no estimate in the range"
    lines = [f"{log.stem}: H {w['hausdorff'] * 100:.1f} cm"]
    for name in ("estimate->body", "body->estimate"):
        d = w[name]
        lines.append(f"{name} worst {d['worst'] * 100:.1f} cm at box {np.round(d['box'], 2).tolist()} "
                     f"(touch {d['touch'] * 100:.1f}, camera {d['camera'] * 100:.1f} cm), "
                     f"{d['share']:.1%} over {far * 100:g} cm")
    if w["near"]:
        counts = ", ".join(f"{task} {kind} {n}" for (task, kind), n in w["near"].items())
        mean = "" if np.isnan(w["outer_mean"]) else f"; outer mean there {w['outer_mean']:+.2f}"
        lines.append(f"near the far estimate: {counts}{mean}")
    return "\n    ".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+", type=Path)
    ap.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"), help="the study's scene files")
    ap.add_argument("--far", type=float, default=0.02, help="'off' beyond this distance [m]")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    for log in args.logs:
        print(report(log, args.scenes, args.far), flush=True)


if __name__ == "__main__":
    main()

"""Active visuo-tactile exploration (Sec. IV-B, V): approach, plan, slide, settle, observe, re-learn, repeat."""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
import torch
from tqdm.auto import tqdm

from .datasets import DatasetError, LogWriter, TornLogWarning, read_records, replay
from .gpiois import GPIOIS, INNER, OUTER
from .gpis import GPIS
from .metrics import hausdorff_distance, uncertainty_measure
from .planning import ZeroPenalty, plan_direction
from .surfaces import closed_curves, evaluate_grid, zero_level_curves

__all__ = ["ObservationPolicy", "Trace", "explore", "gone_around", "largest_uncovered_gap"]

MODES = ("visual-tactile", "tactile")


@dataclass(frozen=True)
class ObservationPolicy:
    """Which observations the simulated sensors produce (see docs/method-notes.md for the evidence).

    Attributes:
        vision_spacing: spacing of the outer-boundary points seen by the camera (y = 0, task outer) [m].
        vision_free_offset: distance outside the outer boundary of the camera's free-space points
            (y = 1, task outer) [m]; ``None`` disables them.
        free_space_spacing: spacing of free-space samples along the path the toucher occupied
            (approach, lost-contact presses; y = 1, task inner) [m].
        free_space_margin: free-space samples closer than this to any contact are not recorded [m]; keeps the
            inner Gram block well conditioned (trap 2 of issue 3).
    """

    vision_spacing: float = 0.02
    vision_free_offset: float | None = 0.05
    free_space_spacing: float = 0.02
    free_space_margin: float = 0.02


@dataclass
class Trace:
    """Per-step records of one exploration (record 0 is the state right after the first contact).

    Attributes:
        hausdorff: `(n,)` Hausdorff distance [m] between the estimated inner shape {mu_in = 0} and the true inner
            boundary (eq. 24); NaN while the estimate has no closed curve.
        uncertainty: `(n,)` uncertainty measure (eq. 23) over the estimated inner shape; NaN without a curve.
        similarity: `(n,)` K_t[0,1] / K_t[0,0] (NaN in tactile mode).
        travel: `(n,)` toucher travel since the first contact [m].
        path: `(k, 2)` every position the toucher occupied, approach included [m].
        contacts: `(n, 2)` contact positions [m].
        model: the final fitted model (``GPIOIS`` or ``GPIS``).
        step_time: `(n,)` wall time of each planning step (plan + ingest + re-learn) [s].
        terminated: "once-around" (``gone_around``) or "max_steps".
        task_covariance: `(n, 2, 2)` learned K_t per record (NaN in tactile mode).
        retracted: free-space samples removed because a later contact landed within the margin.
        sim_time: `(n,)` robot clock at each record [s] (3-D runs on a robot; empty in 2-D).
        final_mesh: 3-D only: the last estimated inner surface within the exploration range (``trimesh``).
    """

    mode: str
    scene_name: str
    hausdorff: np.ndarray
    uncertainty: np.ndarray
    similarity: np.ndarray
    travel: np.ndarray
    path: np.ndarray
    contacts: np.ndarray
    model: object
    step_time: np.ndarray
    terminated: str
    task_covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    retracted: int = 0
    sim_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    final_mesh: object = None

    @property
    def n_steps(self) -> int:
        return len(self.travel)

    def records(self) -> list[dict]:
        """Per-step records as dicts (JSON/CSV friendly)."""
        out = []
        for i in range(self.n_steps):
            row = {"object": self.scene_name, "mode": self.mode, "step": i, "travel_m": float(self.travel[i]),
                   "hausdorff_m": float(self.hausdorff[i]), "uncertainty": float(self.uncertainty[i]),
                   "similarity": float(self.similarity[i])}
            row.update({f"contact_{a}": float(v) for a, v in zip("xyz", self.contacts[i])})
            row["step_time_s"] = float(self.step_time[i])
            if len(self.sim_time):
                row["robot_time_s"] = float(self.sim_time[i])
            out.append(row)
        return out


def largest_uncovered_gap(points: np.ndarray, centre: np.ndarray) -> tuple[float, float]:
    """Largest angular gap between contacts seen from ``centre``, and the chord between its two ends.

    Sorts the contacts' angles about ``centre``; the largest circular difference between neighbours is the
    sector no contact has visited.

    Returns:
        ``(gap_angle [rad], gap_chord [m])``; ``(2 pi, inf)`` for fewer than 2 points.
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        return 2 * math.pi, math.inf
    rel = p - np.asarray(centre, dtype=np.float64)
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    order = np.argsort(ang)
    a = ang[order]
    gaps = np.diff(np.append(a, a[0] + 2 * math.pi))
    k = int(np.argmax(gaps))
    i, j = order[k], order[(k + 1) % len(order)]
    return float(gaps[k]), float(np.linalg.norm(p[i] - p[j]))


def gone_around(points: np.ndarray, centre: np.ndarray | None, max_gap: float) -> bool:
    """Termination rule: the contacts surround ``centre`` with no unvisited sector wider than ``max_gap``.

    "Once around the inner shape" is read as angular coverage about a point inside the estimate: every
    direction from it has been visited, except sectors whose two bounding contacts lie at most ``max_gap`` [m]
    apart (a gap the GP bridges at its length scale). Coverage rather than the path's winding number, because
    the variance-driven planner may turn back a few centimetres short of closing its loop, where little
    variance is left, and close it later from the other side.
    """
    if centre is None or len(points) < 3:
        return False
    angle, chord = largest_uncovered_gap(points, centre)
    return angle < math.pi / 2 and chord <= max_gap


def _free_space_along(a: np.ndarray, b: np.ndarray, spacing: float, contacts: np.ndarray, margin: float,
                      include_end: bool = True) -> np.ndarray:
    """Samples every ``spacing`` on segment a->b that are at least ``margin`` from every contact."""
    length = float(np.linalg.norm(b - a))
    if length == 0:
        pts = a[None]
    else:
        n = int(math.floor(length / spacing))
        s = np.arange(0, n + 1) * spacing
        if include_end and (len(s) == 0 or s[-1] < length - 1e-12):
            s = np.append(s, length)
        pts = a + np.outer(s / length, b - a)
    if len(contacts):
        d = np.linalg.norm(pts[:, None, :] - contacts[None, :, :], axis=-1).min(axis=1)
        pts = pts[d >= margin]
    return pts


def _inner_mask(model) -> np.ndarray:
    return (model.train_inputs[1].squeeze(-1) == INNER).numpy()


def retract_free_space(model, contact: np.ndarray, margin: float) -> np.ndarray:
    """Remove the inner free-space observations closer than ``margin`` [m] to a new ``contact``.

    Keeps the free-space margin at all times: free space recorded earlier (e.g. pressed along an edge not yet
    touched) is retracted once a contact lands within the margin of it (trap 2, docs/method-notes.md).

    Returns:
        `(k,)` indices (into the observations before the call) that were removed.
    """
    free_in = model.train_targets.numpy() == 1
    if isinstance(model, GPIOIS):
        free_in &= _inner_mask(model)
    too_close = free_in & (np.linalg.norm(model.train_inputs[0].numpy() - contact, axis=1) < margin)
    if too_close.any():
        model.remove_observations(torch.as_tensor(too_close))
    return np.flatnonzero(too_close)


def _estimate_metrics(model, scene, bounds, resolution):
    """Hausdorff (eq. 24), uncertainty (eq. 23) and the centroid of the estimated region {mu_in < 0}."""
    field_ = evaluate_grid(model, bounds, resolution, INNER)
    curves = zero_level_curves(model, bounds, resolution, INNER, field=field_)
    unc = uncertainty_measure(model, curves, INNER) if curves else float("nan")
    inside = field_.mean < 0
    centre = None
    if inside.any():
        gx, gy = np.meshgrid(*field_.axes, indexing="ij")
        centre = np.array([gx[inside].mean(), gy[inside].mean()])
    if not closed_curves(curves):
        return float("nan"), unc, centre
    return hausdorff_distance(curves, [scene.inner_boundary], spacing=2e-3), unc, centre


def _restore(path: str | os.PathLike, params: dict) -> dict:
    """Rebuild the exploration state after the last complete step of a log written by :func:`explore`."""
    import warnings

    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always", TornLogWarning)
        records = list(read_records(path))
        states = [ds for rec, ds in replay(path) if rec.kind == "step"]
    if not records or records[0].kind != "header":
        raise DatasetError(f"{path}: no header record; not an exploration log")
    header = records[0].meta
    for key, want in params.items():
        have = header.get(key)
        if have != want and not (isinstance(want, float) and isinstance(have, float) and math.isclose(have, want)):
            raise ValueError(f"{path}: cannot resume: the log was written with {key}={have!r}, this call asks "
                             f"{key}={want!r}")
    steps = [r for r in records[1:] if r.kind == "step"]
    if not steps:
        raise DatasetError(f"{path}: the log has no complete step to resume from")
    end = [r for r in records[1:] if r.kind == "end"]
    contacts, path_pts = [], []
    rec = {"h": [], "u": [], "s": [], "travel": [], "time": [], "kt": []}
    for r in steps:
        if int(r.meta["step"]) != len(rec["h"]):
            raise DatasetError(f"{path}: step records out of order at step {r.meta['step']}")
        contacts.append(r.arrays["contact"])
        path_pts.extend(list(r.arrays["path"]))
        for key in ("h", "u", "s", "travel", "time"):
            rec[key].append(float(r.meta[key]))
        rec["kt"].append(r.arrays["kt"])
    last, data = steps[-1], states[-1]    # the training set after the last step (removals and additions replayed)
    theta, noise = header["theta"], header["noise"]
    if header["mode"] == "visual-tactile":
        model = GPIOIS(data.x, data.y, data.task, theta=theta, noise=noise,
                       task_covariance=torch.as_tensor(last.arrays["kt"]))
    else:
        model = GPIS(data.x, data.y, theta=theta, noise=noise)
    prev = last.arrays["previous"]
    return {"model": model, "contacts": contacts, "path": path_pts, "rec": rec,
            "travel": float(last.meta["travel"]), "retracted": int(last.meta["retracted"]),
            "previous": None if np.isnan(prev).any() else torch.as_tensor(prev),
            "steps": int(last.meta["step"]), "terminated": end[-1].meta["terminated"] if end else None}


def explore(scene, mode: str = "visual-tactile", step: float = 0.01, theta: float | None = None,
            noise: float | None = None, max_steps: int = 400, penalty=None, policy: ObservationPolicy | None = None,
            metrics_resolution: float | None = None, progress: bool = False, min_steps: int = 10,
            closure_gap: float = 0.05, log: str | os.PathLike | None = None,
            resume_from: str | os.PathLike | None = None, **options) -> Trace:
    """Run one simulated exploration of a 2-D or 3-D scene and record per-step metrics.

    A ``Scene3D`` runs the robot loop of :func:`torch_gpioius.exploration3d.explore_3d` (simulated UR5, force
    sensor, depth camera; stops after ``max_travel`` = 1.5 m of fingertip travel; paper defaults theta = 0.15,
    sigma^2 = 0.08, range penalty of eq. 25, 2 cm metrics grid); its extra keyword ``options`` are
    ``max_travel``, ``voxel``, ``metrics_every``, ``robot`` and ``camera``. The rest of this docstring is the
    2-D protocol.

    Protocol (both modes alike): vision once before exploration (visual-tactile only: outer boundary points and
    free space outside it); approach from ``scene.start`` along ``scene.direction`` to the first contact, the
    approach path giving inner free space; then repeat: plan d* (eq. 19) at the contact, move x' = x + d*,
    settle onto the inner surface (``Scene2D.settle``), record the contact (y = 0) and the free space occupied
    on the way (y = 1, at least ``policy.free_space_margin`` from any contact), update the model and re-learn
    K_t. Stops when the contacts have gone once around the inner shape (``gone_around``: seen from the centroid
    of the current estimated region {mu_in < 0}, no sector wider than ``closure_gap`` is unvisited; after at
    least ``min_steps`` steps) or after ``max_steps``. The centroid of the estimate, unlike the contacts' mean,
    lies inside the shape and away from the path.

    Args:
        scene: a ``Scene2D``.
        mode: "visual-tactile" (GPIOIS on vision + touch) or "tactile" (GPIS on touch only).
        step: alpha, the sliding step [m].
        theta: IMQ kernel parameter [m] (default 0.1 in 2-D, 0.15 in 3-D).
        noise: sigma^2 (default 0.006 in 2-D, 0.08 in 3-D).
        max_steps: cap on planning steps.
        penalty: C(x) (default ``ZeroPenalty``, as in the 2-D study).
        policy: ``ObservationPolicy``.
        metrics_resolution: grid spacing for the per-step estimated curve [m] (default 0.01; 3-D 0.02).
        progress: show a tqdm progress bar.
        min_steps: steps before the winding test applies.
        closure_gap: widest unvisited gap (chord between its bounding contacts) that still counts as once
            around [m]; default theta_x / 2 of the paper.
        log: write a crash-safe exploration log here (docs/data-format.md): one record per completed step,
            durable (fsync) before the next step begins.
        resume_from: continue the run logged in this file from its last complete step (the parameters must
            match the log's header; appends to it). The resumed run ends where an uninterrupted one would.

    Returns:
        ``Trace``.
    """
    if getattr(scene, "dim", 2) == 3:
        from .exploration3d import explore_3d

        if resume_from is not None:
            raise ValueError("resume_from: resuming is supported for 2-D scenes only (a 3-D run also needs the "
                             "robot's state); start a new run")
        return explore_3d(scene, mode, step, 0.15 if theta is None else theta, 0.08 if noise is None else noise,
                          max_steps=max_steps, penalty=penalty, policy=policy, progress=progress, log=log,
                          metrics_resolution=0.02 if metrics_resolution is None else metrics_resolution,
                          **options)
    if options:
        raise TypeError(f"explore: options {sorted(options)} apply to 3-D scenes only")
    theta = 0.1 if theta is None else theta
    noise = 0.006 if noise is None else noise
    metrics_resolution = 0.01 if metrics_resolution is None else metrics_resolution
    if mode not in MODES:
        raise ValueError(f"mode: must be one of {MODES}, got {mode!r}")
    if not (step > 0 and max_steps >= 0):
        raise ValueError("step must be > 0 and max_steps >= 0")
    policy = policy or ObservationPolicy()
    penalty = penalty or ZeroPenalty()
    bounds = scene.bounds(0.1)

    params = {"scene": scene.name, "mode": mode, "step_length": step, "theta": theta, "noise": noise,
              "max_steps": max_steps, "min_steps": min_steps, "closure_gap": closure_gap,
              "metrics_resolution": metrics_resolution, "policy": dataclasses.asdict(policy),
              "penalty": type(penalty).__name__}
    rec = {"h": [], "u": [], "s": [], "travel": [], "time": [], "kt": []}
    centre = None   # centroid of the estimated inner region, updated by record()
    if resume_from is not None and log is not None and os.path.abspath(log) != os.path.abspath(resume_from):
        raise ValueError("resume_from appends to its own log; pass log=None or the same path")
    if resume_from is not None:
        state = _restore(resume_from, params)
        model = state["model"]
        contacts, path, rec = state["contacts"], state["path"], state["rec"]
        travel, retracted, previous = state["travel"], state["retracted"], state["previous"]
        done, terminated = state["steps"], state["terminated"]
        writer = LogWriter(resume_from, resume=True) if terminated is None else None
    else:
        contact = scene.first_contact()
        contacts = [contact]
        approach_free = _free_space_along(scene.start, contact, policy.free_space_spacing, contact[None],
                                          policy.free_space_margin)
        path = [scene.start, contact]
        x_in = np.concatenate([contact[None], approach_free])
        y_in = np.concatenate([[0.0], np.ones(len(approach_free))])

        if mode == "visual-tactile":
            seen = scene.sample_boundary("outer", policy.vision_spacing)
            x_out, y_out = [seen], [np.zeros(len(seen))]
            if policy.vision_free_offset is not None:
                free = scene.sample_offset("outer", policy.vision_free_offset, policy.vision_spacing)
                x_out.append(free)
                y_out.append(np.ones(len(free)))
            x_out, y_out = np.concatenate(x_out), np.concatenate(y_out)
            model = GPIOIS(np.concatenate([x_in, x_out]), np.concatenate([y_in, y_out]),
                           np.r_[np.full(len(x_in), INNER), np.full(len(x_out), OUTER)], theta=theta, noise=noise)
        else:
            model = GPIS(x_in, y_in, theta=theta, noise=noise)
        travel, retracted, previous, done, terminated = 0.0, 0, None, 0, None
        writer = None

    def record(travel: float, dt: float) -> None:
        nonlocal centre
        h, u, centre = _estimate_metrics(model, scene, bounds, metrics_resolution)
        rec["h"].append(h)
        rec["u"].append(u)
        rec["s"].append(model.similarity if mode == "visual-tactile" else float("nan"))
        rec["kt"].append(model.task_covariance.numpy() if mode == "visual-tactile" else np.full((2, 2), np.nan))
        rec["travel"].append(travel)
        rec["time"].append(dt)

    def log_step(k: int, x_new, y_new, removed, path_new) -> None:
        if writer is None:
            return
        n = len(x_new)
        # step 0 logs the whole initial set (both tasks); later steps add inner observations only (GPIS: task 0)
        if k == 0 and mode == "visual-tactile":
            task_new = model.train_inputs[1].reshape(-1).numpy()
        else:
            task_new = np.full(n, INNER, dtype=np.int64)
        writer.append("step", {"step": k, "travel": travel, "retracted": retracted, "h": rec["h"][-1],
                               "u": rec["u"][-1], "s": rec["s"][-1], "time": rec["time"][-1]},
                      {"x": np.asarray(x_new), "y": np.asarray(y_new), "task": task_new,
                       "removed": np.asarray(removed, dtype=np.int64), "path": np.asarray(path_new),
                       "contact": contacts[-1], "kt": rec["kt"][-1],
                       "previous": (np.full(2, np.nan) if previous is None else previous.numpy())})

    if resume_from is None:
        t0 = time.perf_counter()
        model.fit()
        record(0.0, time.perf_counter() - t0)
        if log is not None:
            writer = LogWriter(log, {"dim": 2, "frame": "scene", "source": "torch_gpioius.explore",
                                     "theta": theta, "noise": noise, **params})
            log_step(0, model.train_inputs[0].numpy(), model.train_targets.numpy(), [], path)
    bar = tqdm(total=max_steps, initial=done, desc=f"{scene.name or 'scene'} {mode}", disable=not progress,
               leave=False)
    for k in range(done + 1, max_steps + 1 if terminated is None else 0):
        t0 = time.perf_counter()
        x = contacts[-1]
        plan = plan_direction(model, torch.as_tensor(x), step=step, penalty=penalty, previous=previous)
        d = plan.direction.numpy()
        previous = plan.direction
        moved = x + d
        # Compliant settling onto the nearest inner-surface point (Scene2D.settle). Pressing along the
        # estimated inward normal instead was tried and dropped (docs/method-notes.md, section 3).
        settled = scene.settle(moved)
        travel += float(np.linalg.norm(d) + np.linalg.norm(settled - moved))
        path += [moved, settled]
        contacts.append(settled)
        new_x, new_y = [settled[None]], [np.zeros(1)]
        if not scene.is_inside_inner(moved) and np.linalg.norm(settled - moved) >= policy.free_space_margin:
            free = _free_space_along(moved, settled, policy.free_space_spacing, np.asarray(contacts),
                                     policy.free_space_margin)
            new_x.append(free)
            new_y.append(np.ones(len(free)))
        new_x, new_y = np.concatenate(new_x), np.concatenate(new_y)
        removed = retract_free_space(model, settled, policy.free_space_margin)
        retracted += len(removed)
        if mode == "visual-tactile":
            model.add_observations(new_x, new_y, INNER)
        else:
            model.add_observations(new_x, new_y)
        # warm start from the previous K_t (also after a resume, where fit_result is not restored)
        model.fit(multi_start=False) if isinstance(model, GPIOIS) else model.fit()
        dt = time.perf_counter() - t0
        record(travel, dt)
        log_step(k, new_x, new_y, removed, [moved, settled])
        bar.update(1)
        if len(contacts) > min_steps and gone_around(np.asarray(contacts), centre, closure_gap):
            terminated = "once-around"
            break
    bar.close()
    terminated = terminated or "max_steps"
    if writer is not None:
        writer.append("end", {"terminated": terminated, "steps": len(rec["h"]) - 1}, {})
        writer.close()
    return Trace(mode=mode, scene_name=scene.name, hausdorff=np.asarray(rec["h"]), uncertainty=np.asarray(rec["u"]),
                 similarity=np.asarray(rec["s"]), travel=np.asarray(rec["travel"]), path=np.asarray(path),
                 contacts=np.asarray(contacts), model=model, step_time=np.asarray(rec["time"]),
                 terminated=terminated, task_covariance=np.asarray(rec["kt"]), retracted=retracted)

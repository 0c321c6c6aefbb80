"""One active visuo-tactile exploration loop for every world (Sec. IV-B, V, VI).

Vision once (visual-tactile mode), approach to the first contact, then repeat: plan d* at the contact (eq. 19),
let the contact controller execute it (tangential motion, force-guarded contact), record the contact and the
free space crossed, update the model, re-learn K_t; until a stop rule fires. The loop talks to the world only
through its :class:`~torch_gpioius.exploration.world.Hardware` (robot, force sensor, point-cloud source, contact
controller) and its metrics; it never asks which world it runs in.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from .._progress import progress as progress_reporter
from .._validation import as_float
from ..io.datasets import LogWriter
from ..models.gpiois import GPIOIS, INNER, OUTER
from ..models.gpis import GPIS
from ..planning import plan_direction
from .observations import ObservationPolicy, retract_free_space, thin_points, vision_observations
from .stopping import OnceAround, StopRule, TravelBudget
from .trace import Trace
from .world import Hardware, World

__all__ = ["explore", "MODES", "EVIDENCE"]

MODES = ("visual-tactile", "tactile")
#: Evidence-seeking policies beyond the paper (``None`` is the paper's exploration).
EVIDENCE = (None, "taps")


@dataclass
class _State:
    """Everything the loop carries from step to step (and a resume restores)."""

    model: object
    contacts: list = field(default_factory=list)
    path: list = field(default_factory=list)
    travel: float = 0.0
    retracted: int = 0
    previous: torch.Tensor | None = None
    normal: torch.Tensor | None = None
    steps: int = 0
    taps: int = 0
    last_tap: int = 0
    terminated: str | None = None
    centre: np.ndarray | None = None
    surface: object = None
    rec: dict = field(default_factory=lambda: {k: [] for k in ("h", "ht", "u", "s", "rho", "ci", "travel", "time",
                                                                 "kt", "sim", "taps", "regions")})


def _check_int(value, name: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= int(value) <= hi:
        raise ValueError(f"{name}: must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def explore(world: World, mode: str = "visual-tactile", *, evidence: str | None = None, step: float | None = None,
            theta: float | None = None, noise: float | None = None, max_steps: int | None = None,
            max_travel: float | None = None, stop: tuple[StopRule, ...] | None = None,
            policy: ObservationPolicy | None = None, penalty=None, metrics_every: int | None = None,
            metrics_resolution: float | None = None, interval_every: int | None = None, regions: int | None = None,
            progress: bool = False,
            log: str | os.PathLike | None = None, resume_from: str | os.PathLike | None = None) -> Trace:
    """Explore ``world`` and record per-step metrics: the same loop for every world.

    Protocol (both modes alike): visual-tactile mode captures one point cloud before exploring (outer surface
    points, y = 0, and the free space in front of them, y = 1; ``policy``). The fingertip approaches along
    ``world.direction`` to the first contact; the approach's free space is inner free space. Then each step plans
    d* (eq. 19, L = V_in + C) at the contact, the world's contact controller executes it, the contact (y = 0) and
    the free space crossed (y = 1, thinned, kept ``policy.free_space_margin`` from every contact, with earlier
    samples retracted when a new contact lands closer) are added, and K_t is re-learned (warm-started). The
    run stops on the world's stop rules (2-D: once around the shape; robot study: 1.5 m of travel), after
    ``max_steps``, when contact is lost, or when the robot refuses a command.

    Every world-specific setting is the world's (``world.defaults``: theta, sigma^2, alpha, stop rules, observation
    policy; its hardware, camera and range penalty); the arguments below override them for one run.

    Args:
        world: a :class:`~torch_gpioius.exploration.world.World` (``tg.sim.Scene2D``, ``tg.sim.Scene3D``,
            ``tg.sim.MujocoScene``, ``tg.RobotWorld``).
        mode: "visual-tactile" (GPIOIS on vision + touch) or "tactile" (GPIS on touch only).
        evidence: None (the paper's exploration) or "taps" (evidence-seeking taps, visual-tactile only; see
            :mod:`torch_gpioius.exploration.evidence`).
        step: alpha, the planned step [m], in (0, 0.1].
        theta: IMQ kernel parameter [m]; noise: sigma^2.
        max_steps: cap on planning steps.
        max_travel: fingertip travel budget since the first contact [m] (adds or replaces a ``TravelBudget``).
        stop: stop rules replacing the world's.
        policy: the observation policy.
        penalty: C(x) replacing the world's.
        metrics_every: ground-truth metrics every k steps (and always at the last).
        metrics_resolution: grid of the metrics [m] (default: the world's).
        interval_every: compute the profile-likelihood interval of the task correlation every k steps
            (visual-tactile; default: never, it costs a few fits).
        regions: visual-tactile with a similarity per region of the outer shape (:class:`torch_gpioius.LocalGPIOIS`
            with this many regions) instead of one (GPIOIS).
        progress: report progress (a bar on a terminal, plain lines otherwise).
        log: write a crash-safe exploration log here (docs/data-format.md): one record per completed step, durable
            (fsync) before the next step begins.
        resume_from: continue the run logged in this file from its last complete step (same world, parameters
            and hardware state; appends to the log). The resumed run ends where an uninterrupted one would.

    Returns:
        :class:`~torch_gpioius.exploration.trace.Trace`.

    Raises:
        ValueError: an invalid argument (names it), or a log that does not match this run on resume.
    """
    if not isinstance(world, World):
        raise TypeError(f"world: expected a torch_gpioius World (Scene2D, Scene3D, MujocoScene, RobotWorld), got "
                        f"{type(world).__name__}")
    if mode not in MODES:
        raise ValueError(f"mode: must be one of {MODES}, got {mode!r}")
    if evidence not in EVIDENCE:
        raise ValueError(f"evidence: must be one of {EVIDENCE}, got {evidence!r}")
    if evidence is not None and mode != "visual-tactile":
        raise ValueError("evidence: evidence-seeking taps are about the similarity; they need mode='visual-tactile'")
    if regions is not None:
        regions = _check_int(regions, "regions", 1, 64)
        if mode != "visual-tactile":
            raise ValueError("regions: a similarity per region needs mode='visual-tactile'")
    d = world.defaults
    step = as_float(d.step if step is None else step, "step", lo=1e-4, hi=0.1, positive=True, unit="m")
    theta = d.theta if theta is None else theta
    noise = d.noise if noise is None else noise
    max_steps = _check_int(d.max_steps if max_steps is None else max_steps, "max_steps", 0, 100_000)
    metrics_every = _check_int(d.metrics_every if metrics_every is None else metrics_every, "metrics_every", 1,
                               1_000_000)
    if interval_every is not None:
        interval_every = _check_int(interval_every, "interval_every", 1, 1_000_000)
    if metrics_resolution is not None:
        metrics_resolution = as_float(metrics_resolution, "metrics_resolution", lo=1e-3, hi=0.5, unit="m")
    rules = tuple(d.stop if stop is None else stop)
    if max_travel is not None:
        rules = tuple(r for r in rules if not isinstance(r, TravelBudget)) + (TravelBudget(max_travel),)
    policy = policy or d.policy
    penalty = penalty if penalty is not None else world.penalty()
    if resume_from is not None and log is not None and os.path.abspath(log) != os.path.abspath(resume_from):
        raise ValueError("resume_from appends to its own log; pass log=None or the same path")

    params = {**world.describe(), "mode": mode, "evidence": evidence, "step_length": step, "theta": float(theta),
              "noise": float(noise), "max_steps": max_steps, "stop": [r.describe() for r in rules],
              "metrics_every": metrics_every, "metrics_resolution": metrics_resolution,
              "interval_every": interval_every, "regions": regions, "policy": dataclasses.asdict(policy),
              "penalty": type(penalty).__name__}
    hw = world.hardware()
    taps = None
    if evidence == "taps":
        from .evidence import TapPolicy

        taps = TapPolicy()
        params["tap_policy"] = dataclasses.asdict(taps)

    writer = None
    if resume_from is not None:
        from .resume import restore_run

        s = restore_run(resume_from, params, world, hw)
        if s.terminated is None:
            writer = LogWriter(resume_from, resume=True)
    else:
        s = _start(world, hw, mode, theta, noise, policy, d.approach_travel, regions)

    def measure(final: bool) -> None:
        k = s.steps
        if k % metrics_every == 0 or final:
            m = world.measure(s.model, np.asarray(s.contacts), metrics_resolution)
            s.centre, s.surface = m.centre, m.surface
            vals = (m.hausdorff, m.hausdorff_touched, m.uncertainty)
        else:
            vals = (math.nan,) * 3
        for key, v in zip(("h", "ht", "u"), vals):
            s.rec[key].append(float(v))

    def record(dt: float, final: bool) -> None:
        measure(final)
        vt = mode == "visual-tactile"
        s.rec["s"].append(s.model.similarity if vt else math.nan)
        s.rec["rho"].append(s.model.correlation if vt else math.nan)
        ci = (math.nan, math.nan)
        if regions is not None:
            s.rec["regions"].append(s.model.region_correlations().numpy())
        elif vt and interval_every is not None and (s.steps % interval_every == 0 or final):
            ci = s.model.similarity_interval(kind="correlation")
        s.rec["ci"].append(tuple(float(v) for v in ci))
        s.rec["kt"].append(s.model.task_covariance.numpy() if vt else np.full((2, 2), np.nan))
        s.rec["travel"].append(s.travel)
        s.rec["time"].append(dt)
        s.rec["sim"].append(float(getattr(hw.robot, "time", math.nan)))
        s.rec["taps"].append(s.taps)

    def log_step(x_new, y_new, task_new, removed, res) -> None:
        if writer is None:
            return
        r = s.rec
        meta = {"step": s.steps, "travel": s.travel, "retracted": s.retracted, "taps": s.taps, "h": r["h"][-1],
                "ht": r["ht"][-1], "u": r["u"][-1], "s": r["s"][-1], "rho": r["rho"][-1], "ci": list(r["ci"][-1]),
                "time": r["time"][-1], "sim_time": r["sim"][-1]}
        arrays = {"x": np.asarray(x_new), "y": np.asarray(y_new), "task": np.asarray(task_new, dtype=np.int64),
                  "removed": np.asarray(removed, dtype=np.int64), "contact": s.contacts[-1], "kt": r["kt"][-1],
                  "previous": np.full(world.dim, np.nan) if s.previous is None else s.previous.numpy(),
                  "normal": np.full(world.dim, np.nan) if s.normal is None else s.normal.numpy(),
                  "path": res.path.numpy(), "positions": res.path.numpy(), "forces": res.forces.numpy(),
                  "timestamps": np.full(len(res.path), r["sim"][-1])}
        if regions is not None:
            arrays["local_params"] = s.model.params.numpy()
        arrays.update({f"world_{k}": np.asarray(v) for k, v in world.snapshot(hw).items()})
        writer.append("step", meta, arrays)

    estimate_rules = [r for r in rules if isinstance(r, OnceAround)]
    motion_rules = [r for r in rules if not isinstance(r, OnceAround)]

    if resume_from is None:
        t0 = time.perf_counter()
        s.model.fit()
        record(time.perf_counter() - t0, final=max_steps == 0)
        if log is not None:
            writer = LogWriter(log, {"frame": "base" if world.dim == 3 else "scene", "source": "torch_gpioius.explore",
                                     **params})
            vt = mode == "visual-tactile"
            task0 = s.model.train_inputs[1].reshape(-1).numpy() if vt else np.zeros(len(s.model.train_targets))
            log_step(s.model.train_inputs[0].numpy(), s.model.train_targets.numpy(), task0, [], s.first)
        del s.first

    budget = next((r.max_travel for r in motion_rules if isinstance(r, TravelBudget)), None)
    bar = progress_reporter(round(budget * 100) if budget else max_steps,
                            f"{world.name or 'world'} {mode}{' [cm]' if budget else ''}", progress)
    if budget:
        bar.update(min(round(s.travel * 100), round(budget * 100)))
    else:
        bar.update(s.steps)
    while s.terminated is None:
        if s.steps + s.taps >= max_steps:          # a tap counts as a step of the budget
            s.terminated = "max_steps"
            break
        s.steps += 1
        t0 = time.perf_counter()
        x = s.contacts[-1]
        plan = plan_direction(s.model, torch.as_tensor(x), step=step, penalty=penalty, previous=s.previous)
        s.previous = plan.direction
        t_plan = time.perf_counter() - t0
        try:
            res = hw.controller.slide(plan.direction, s.normal)
        except RuntimeError as exc:   # ContactFault, SafetyViolation, RobotError: the robot refused or stopped
            s.steps -= 1
            s.terminated = f"refused: {exc}"
            break
        s.travel += res.travel
        s.path.extend(res.path.numpy())
        if not res.in_contact:
            res = _recover(s, hw, res)
            if res is None:
                s.steps -= 1
                s.terminated = "lost-contact"
                break
        s.normal = res.force_normal
        t1 = time.perf_counter()
        x_new, y_new, removed = _ingest(s, res, policy, mode)
        tap = taps.tap(s, hw, world, policy) if taps is not None and taps.due(s) else None
        t2 = time.perf_counter()
        if mode == "visual-tactile":
            s.model.fit(multi_start=False)
        else:
            s.model.fit()
        dt = t_plan + (time.perf_counter() - t1)   # plan + ingest + re-learn; motion excluded
        done = next((reason for r in motion_rules if (reason := r.check(s.contacts, s.travel, None))), None)
        record(dt, final=done is not None)
        log_step(x_new, y_new, np.zeros(len(x_new), np.int64), removed, res)
        if tap is not None and writer is not None:
            x_tap, y_tap, removed_tap, _ = tap
            writer.append("tap", {"step": s.steps, "taps": s.taps, "travel": s.travel},
                          {"x": x_tap, "y": y_tap, "task": np.zeros(len(x_tap), np.int64),
                           "removed": np.asarray(removed_tap, dtype=np.int64), "contact": s.contacts[-1],
                           "normal": s.normal.numpy(),
                           **{f"world_{k}": np.asarray(v) for k, v in world.snapshot(hw).items()}})
        del t2
        if budget:
            bar.update(min(round(s.travel * 100), round(budget * 100)) - bar.n)
        else:
            bar.update(1)
        done = done or next((reason for r in estimate_rules
                             if (reason := r.check(np.asarray(s.contacts), s.travel, s.centre))), None)
        if done:
            s.terminated = done
    bar.close()
    if (mode == "visual-tactile" and regions is None and interval_every is not None and s.rec["ci"]
            and math.isnan(s.rec["ci"][-1][0])):           # the final record always gets its interval
        s.rec["ci"][-1] = tuple(float(v) for v in s.model.similarity_interval(kind="correlation"))
    if len(s.rec["h"]) > 1 and math.isnan(s.rec["h"][-1]):   # always measure the final estimate
        m = world.measure(s.model, np.asarray(s.contacts), metrics_resolution)
        s.rec["h"][-1], s.rec["ht"][-1], s.rec["u"][-1], s.surface = m.hausdorff, m.hausdorff_touched, \
            m.uncertainty, m.surface
    if writer is not None:
        writer.append("end", {"terminated": s.terminated, "steps": len(s.rec["h"]) - 1}, {})
        writer.close()
    r = s.rec
    return Trace(mode=mode, scene_name=world.name, hausdorff=np.asarray(r["h"]), uncertainty=np.asarray(r["u"]),
                 similarity=np.asarray(r["s"]), travel=np.asarray(r["travel"]), path=np.asarray(s.path),
                 contacts=np.asarray(s.contacts), model=s.model, step_time=np.asarray(r["time"]),
                 terminated=s.terminated, task_covariance=np.asarray(r["kt"]).reshape(-1, 2, 2),
                 retracted=s.retracted, sim_time=np.asarray(r["sim"]),
                 final_mesh=s.surface if world.dim == 3 else None, hausdorff_touched=np.asarray(r["ht"]),
                 correlation=np.asarray(r["rho"]), correlation_interval=np.asarray(r["ci"]).reshape(-1, 2),
                 taps=np.asarray(r["taps"], dtype=np.int64), world=type(world).__name__, evidence=evidence,
                 region_correlation=np.asarray(r["regions"]).reshape(len(r["h"]), -1) if regions else
                 np.zeros((len(r["h"]), 0)))


def _start(world: World, hw: Hardware, mode: str, theta: float, noise: float, policy: ObservationPolicy,
           approach_travel: float, regions: int | None = None) -> _State:
    """Vision (visual-tactile), approach to the first contact, and the initial model."""
    x_out = y_out = None
    if mode == "visual-tactile":
        crop = world.crop_box()
        if crop is not None and policy.crop_margin is not None:
            crop = crop + np.array([[-policy.crop_margin], [policy.crop_margin]])
        elif policy.crop_margin is None:
            crop = None
        x_out, y_out = vision_observations(hw.camera.capture(), policy, crop)
    first = hw.controller.approach(torch.as_tensor(world.direction), max_travel=approach_travel)
    if not first.in_contact:
        raise RuntimeError(f"approach from {np.round(world.start, 4).tolist()} along "
                           f"{np.round(world.direction, 4).tolist()} found no contact")
    contact = first.contact.numpy()
    free = thin_points(first.free_space.numpy(), policy.free_space_spacing, contact[None], policy.free_space_margin)
    x_in = np.concatenate([contact[None], free])
    y_in = np.r_[0.0, np.ones(len(free))]
    if mode == "visual-tactile":
        args = (np.concatenate([x_in, x_out]), np.concatenate([y_in, y_out]),
                np.r_[np.full(len(x_in), INNER), np.full(len(x_out), OUTER)])
        if regions is not None:
            from ..models.local import LocalGPIOIS

            model = LocalGPIOIS(*args, regions=regions, theta=theta, noise=noise)
        else:
            model = GPIOIS(*args, theta=theta, noise=noise)
    else:
        model = GPIS(x_in, y_in, theta=theta, noise=noise)
    s = _State(model=model, contacts=[contact], path=list(first.path.numpy()), normal=first.force_normal)
    s.first = first
    return s


def _recover(s: _State, hw: Hardware, lost):
    """Contact was lost during a step (the surface curved away, or a cover dragged the fingertip): a re-approach
    from where the fingertip is, along the estimated inward normal there, for at most 10 cm; if that finds nothing,
    one towards the last contact, for its distance + 5 cm. Returns the merged result of the step and the
    re-approaches, or None (the run then ends on "lost-contact")."""
    from ..geometry import surface_geometry

    def approach(direction, reach: float):
        try:
            r = hw.controller.approach(direction, max_travel=reach)
        except RuntimeError:          # refused or faulted: no re-approach
            return None
        s.travel += r.travel
        s.path.extend(r.path.numpy())
        return r

    res = lost
    here = lost.path[-1]
    geo = surface_geometry(s.model, here.reshape(1, -1).to(s.model.train_inputs[0]), 0)
    if bool(geo.normal_defined[0]):
        back = approach(-geo.normal[0], 0.1)
        if back is not None:
            res = _then(res, back)
            if back.in_contact:
                return res
    # the estimate's normal led nowhere (an outer-shape normal can point past a loose cover's gap): head back
    # towards the last contact, which is on the object, as an operator would
    here = res.path[-1]
    to_last = torch.as_tensor(s.contacts[-1], dtype=here.dtype) - here
    dist = float(to_last.norm())
    if not dist > 1e-6:
        return None
    limit = getattr(getattr(hw.controller, "config", None), "max_approach", None)
    back = approach(to_last / dist, min(dist + 0.05, limit) if limit else dist + 0.05)
    if back is None or not back.in_contact:
        return None
    return _then(res, back)


def _then(a, b):
    """Result ``a`` followed by result ``b``, as one: ``b``'s end state, both paths, readings and free space."""
    from ..contact import ContactResult

    return ContactResult(b.in_contact, b.contact, torch.cat([a.free_space, b.free_space]), torch.cat([a.path, b.path]),
                         torch.cat([a.forces, b.forces]), a.travel + b.travel)


def _ingest(s: _State, res, policy: ObservationPolicy, mode: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Add a controlled step's contact (y = 0) and thinned free space (y = 1) to the model, retracting free space
    that the new contact shows to be too close; returns the added observations and the removed indices."""
    settled = res.contact.numpy()
    s.contacts.append(settled)
    free = thin_points(res.free_space.numpy(), policy.free_space_spacing, np.asarray(s.contacts),
                       policy.free_space_margin)
    x_new = np.concatenate([settled[None], free])
    y_new = np.r_[0.0, np.ones(len(free))]
    removed = retract_free_space(s.model, settled, policy.free_space_margin)
    s.retracted += len(removed)
    if mode == "visual-tactile":
        s.model.add_observations(x_new, y_new, INNER)
    else:
        s.model.add_observations(x_new, y_new)
    return x_new, y_new, removed

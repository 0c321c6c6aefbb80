"""One active visuo-tactile exploration loop for every world (Sec. IV-B, V, VI).

Vision once (visual-tactile), the approach to the first contact, then each step is a short pipeline:

    plan d* (eq. 19) -> touch (the contact controller slides) -> observe (the touch model's batch)
    -> evidence (an evidence policy, if one is due) -> learn (add, re-learn K_t) -> notify recorders -> stop?

The loop talks to the world through its :class:`~torch_gpioius.exploration.world.Hardware`, to the parts through
their contracts (:mod:`torch_gpioius.exploration.protocols`), and never asks which world, model, touch, policy or
recorder it has. Logs, resume and metrics are recorders plugged in from above (``torch_gpioius.explore`` adds the
crash-safe log of :mod:`torch_gpioius.io.logs`).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np
import torch

from ..core.moved import renamed
from .contact import ContactResult
from ..geometry.differential import surface_geometry
from .planning import plan_direction
from .config import LEARN_SIZE, ExploreConfig, Run
from .calibration import camera_table, capture_views, correct_at_start, correct_camera, vision_crop
from .observations import (Observations, deepen_vision_inside, drop_contradicted_inside, offset_outer_mean,
                           renew_deep_vision_inside, retract_free_space, retract_vision_inside, thin_points,
                           vision_observations)
from .recorders import IntervalRecorder, MetricsRecorder, ProgressRecorder
from .state import ExplorationState, StepRecord
from .touch import contact_observations
from .timing import PartClock
from .trace import Trace
from .world import World

__all__ = ["run", "begin", "step", "ingest", "ingest_evidence", "unstall", "recover", "reapproach_reach"]


#: What the old second ``explore`` (this module's, and ``torch_gpioius.exploration``'s) says when asked for.
EXPLORE_MOVED = ("one explore, with the crash-safe log and resume; the loop itself is "
                 "torch_gpioius.exploration.run")


__getattr__ = renamed(__name__, {"explore": ("torch_gpioius", "explore", EXPLORE_MOVED)})


def run(world: World, config: ExploreConfig, *, recorders=(), progress: bool = False,
        state: ExplorationState | None = None, hardware=None) -> Trace:
    """The loop: :func:`begin` (or a restored ``state`` with its ``hardware``), then steps until a rule stops it.

    Returns:
        the :class:`~torch_gpioius.exploration.trace.Trace` of the run.
    """
    ctx = Run(world, hardware or world.hardware(), config, resumed=state is not None)
    config.touch.bind(ctx.hardware)                          # a patch touch reads the world's pad
    observers = [MetricsRecorder(), IntervalRecorder(), *recorders, ProgressRecorder(progress)]
    with PartClock(world, ctx.hardware) as clock:            # where the run's time goes (Trace.time_split)
        state = state if state is not None else begin(ctx)
        for r in observers:
            r.start(ctx, state)
        while state.terminated is None:
            state.terminated = step(ctx, state, observers)
        for r in observers:
            r.end(ctx, state)
    if state.unconverged_fits:
        from ..models.gpiois import FitNotConvergedWarning

        warnings.warn(f"explore: K_t's fit stopped short of the gradient tolerance (at its iteration cap, or its last "
                      "steps gaining less than the likelihood's rounding) at "
                      f"{state.unconverged_fits} of {state.steps} steps; the best K_t found is used, within rounding "
                      "of the optimum where the likelihood is flat", FitNotConvergedWarning, stacklevel=3)
    trace = Trace.from_state(state, world, config)
    trace.time_split = clock.split()
    return trace


def step(ctx: Run, state: ExplorationState, observers) -> str | None:
    """One step of the pipeline; returns why the run stops here, or None to go on."""
    cfg, hw = ctx.config, ctx.hardware
    if _capped(state, cfg):
        return "max_steps"
    t0 = time.perf_counter()
    plan = plan_direction(state.model, torch.as_tensor(state.contact), step=cfg.step, penalty=cfg.penalty,
                          previous=state.previous, measured_normal=state.normal)
    direction = plan.direction.detach().cpu()               # the robot side is CPU, whatever the model's device
    state.previous = direction
    t_plan = time.perf_counter() - t0
    try:
        touch = hw.controller.slide(direction, state.normal)
    except RuntimeError as exc:                                 # ContactFault, SafetyViolation, RobotError
        return f"refused: {exc}"
    _moved(state, touch)
    if not touch.in_contact:
        left = None if cfg.budget is None else cfg.budget - state.travel
        if left is not None and left <= 0:           # the budget is spent: no re-approach past it
            return "travel"
        if (touch := recover(state, hw, touch, left)) is None:
            return lost_contact_end(state, cfg.budget)
    state.steps += 1
    state.normal = touch.force_normal
    t1 = time.perf_counter()
    record = StepRecord(step=state.steps, travel=0.0, touch=touch)
    corrections = state.camera_corrections
    record.observations, record.removed = ingest(state, cfg, touch)
    toucher = _TimedToucher(hw.controller)          # the step's time leaves out the motion of evidence actions
    if cfg.evidence is not None and cfg.evidence.due(state):
        state.last_evidence = state.steps
        evidence = cfg.evidence.gather(state, toucher)
        if evidence is not None:
            record.evidence.append(ingest_evidence(state, cfg, evidence))
    stalled = unstall(ctx, state, record, toucher)
    if state.camera_corrections is not corrections:              # this step corrected the camera's captures
        record.camera_corrections = state.camera_corrections
    _fit(state.model, cfg, state)
    _describe(record, state, ctx, step_time=t_plan + time.perf_counter() - t1 - toucher.motion)
    stop = stalled or _first(r.check(state) for r in cfg.stop if not r.uses_estimate)
    # the step cap ends the run at the next step's start: this record is the last one, measured before it is logged
    record.final = stop is not None or _capped(state, cfg)
    state.records.append(record)
    for r in observers:
        r.step(ctx, state, record)
    return stop or _first(r.check(state) for r in cfg.stop if r.uses_estimate)


def begin(ctx: Run) -> ExplorationState:
    """Vision (when the mode uses it), the approach to the first contact, the first model and its fit: the state
    with record 0."""
    cfg, hw, world = ctx.config, ctx.hardware, ctx.world
    outer = captures = crop = start_fix = plain = None
    table = camera_table(hw, cfg.policy)
    if cfg.uses_vision:
        from ..sensors.pointcloud import PointCloud

        crop = vision_crop(world, cfg.policy)
        captures = capture_views(hw.camera)          # each view's, merged as the camera's own capture merges them
        # with a bound and a known table: the captures held to it before the first touch (the contacts later)
        seen, start_fix = correct_at_start(captures, cfg.policy, crop, table)
        merged = PointCloud.merge(seen)
        x_out, y_out = vision_observations(merged, cfg.policy, crop)
        outer = Observations(x_out, y_out, np.ones(len(x_out), np.int64), source="vision")
        if cfg.policy.ray_smoothing and cfg.policy.voxel:
            # the same capture as the paper labels it, for the simple baselines alone (not the model's)
            plain = vision_observations(merged, dataclasses.replace(cfg.policy, ray_smoothing=None), crop)
    first = hw.controller.approach(torch.as_tensor(world.direction), max_travel=cfg.approach_travel)
    if not first.in_contact:
        raise RuntimeError(f"approach from {np.round(world.start, 4).tolist()} along "
                           f"{np.round(world.direction, 4).tolist()} found no contact")
    contact = first.contact.numpy()
    inner = cfg.touch.observations(first, contact[None], cfg.policy, 0)
    if outer is not None:
        inner = drop_contradicted_inside(inner, cfg.policy, outer.x, outer.y)
    state = ExplorationState(model=cfg.make_model(inner, outer), contacts=[contact], path=list(first.path.numpy()),
                             normal=first.force_normal, crop=crop,
                             captures=captures if cfg.policy.camera_bound is not None else None,
                             table=table, camera_corrections=start_fix, vision_plain=plain)
    t0 = time.perf_counter()
    state.model.fit()
    record = StepRecord(step=0, travel=0.0, touch=first, final=cfg.max_steps == 0,
                        observations=Observations.concat([inner, outer], source="start"),
                        camera_corrections=start_fix)
    _describe(record, state, ctx, step_time=time.perf_counter() - t0)
    state.records.append(record)
    return state


def ingest(state: ExplorationState, cfg: ExploreConfig, touch: ContactResult) -> tuple[Observations, np.ndarray]:
    """The touch's observations into the model: the contact joins the contacts, free space recorded earlier too
    close to it is retracted, the batch is added. Returns the batch and the retracted indices."""
    state.contacts.append(touch.contact.numpy())
    obs = cfg.touch.observations(touch, np.asarray(state.contacts), cfg.policy, state.steps)
    removed, obs = _learn(state, obs, cfg, state.contact)
    return obs, removed


def ingest_evidence(state: ExplorationState, cfg: ExploreConfig,
                    evidence) -> tuple[Observations, np.ndarray, str, np.ndarray]:
    """An evidence policy's touches (or a stall's recovery) into the state and the model: travel and path, the free
    space they crossed (y = 1), and the contact where the fingertip came back to rest (y = 0, when it moved
    ``evidence.min_move``). Returns the batch, the retracted indices, the evidence's kind and the path its touches
    took `(m, d)` [m] (logged, so that a resumed run and a replay have the whole path)."""
    if evidence.kind == "recovery":
        state.recoveries += 1
    else:
        state.taps += 1
    state.travel += float(sum(t.travel for t in evidence.touches))     # one sum, then added (as the tap did)
    path = (np.concatenate([t.path.numpy() for t in evidence.touches]) if evidence.touches
            else np.zeros((0, state.dim)))
    state.path.extend(path)
    free = np.concatenate([t.free_space.numpy() for t in evidence.touches]) if evidence.touches else None
    xs, removed = [], np.zeros(0, dtype=np.int64)
    if evidence.contact is not None:
        contact = np.asarray(evidence.contact, dtype=np.float64)
        if np.linalg.norm(contact - state.contact) >= evidence.min_move:
            removed = retract_free_space(state.model, contact, cfg.policy.free_space_margin)
            state.retracted += len(removed)
            xs.append(contact_observations(contact, cfg.policy, state.steps, "evidence"))
        state.contacts[-1] = contact
        state.normal = evidence.normal
    if free is not None and len(free):
        free = thin_points(free, cfg.policy.free_space_spacing, np.asarray(state.contacts),
                           cfg.policy.free_space_margin)
        if len(free):
            xs.append(Observations(free, np.ones(len(free)), np.zeros(len(free), np.int64), step=state.steps,
                                   source="evidence"))
    if not xs:
        return Observations.empty(state.dim, state.steps, "evidence"), removed, evidence.kind, path
    obs = Observations.concat(xs)
    _add(state.model, obs)
    return obs, removed, evidence.kind, path


def unstall(ctx: Run, state: ExplorationState, record: StepRecord, toucher=None) -> str | None:
    """The no-progress rule (:mod:`~torch_gpioius.exploration.recovery`): recover when the run is stalled, plan afresh
    afterwards; "stalled" once ``max_recoveries`` recoveries in a row left it stalled. The recovery moves through
    ``toucher`` (default: the hardware's contact controller)."""
    rule = ctx.config.stall
    verdict = None if rule is None else rule.stalled(state)
    if not verdict:
        if verdict is False:
            state.failed_recoveries = 0
        return None
    if state.failed_recoveries >= rule.max_recoveries:
        return "stalled"
    state.failed_recoveries, state.last_recovery, state.previous = state.failed_recoveries + 1, state.steps, None
    evidence = rule.recover(state, toucher if toucher is not None else ctx.hardware.controller)
    if evidence is not None:
        record.evidence.append(ingest_evidence(state, ctx.config, evidence))
    return None


def _learn(state: ExplorationState, obs: Observations, cfg: ExploreConfig,
           contact: np.ndarray) -> tuple[np.ndarray, Observations]:
    """Retract free space the new contact shows to be too close, keep what a touch model's ``select`` keeps of the
    batch (a patch's informative points), then add it; the retracted indices and the batch added."""
    margin = cfg.touch.retraction_margin or cfg.policy.free_space_margin
    before = int(state.model.train_targets.shape[0])
    removed = retract_free_space(state.model, contact, margin)
    state.retracted += len(removed)
    camera = retract_vision_inside(state.model, np.asarray(state.contacts), cfg.policy, state.gap_check)
    removed = _also_removed(removed, before, camera)
    if offset_outer_mean(state.model, np.asarray(state.contacts), cfg.policy, state.gap_check):
        # the gap field moved: the deep inside points placed from it are placed again below
        removed = _also_removed(removed, before, renew_deep_vision_inside(state.model, cfg.policy))
    deep = deepen_vision_inside(state.model, np.asarray(state.contacts), cfg.policy, state.gap_check)
    corrected = None
    if state.captures is not None:       # ObservationPolicy.camera_bound: the captures corrected from the contacts
        gone, corrected, found = correct_camera(state.model, state.captures, np.asarray(state.contacts), cfg.policy,
                                                state.crop, state.table)
        if corrected is not None:        # the camera's rows replaced by the corrected captures'
            state.camera_corrections = found
            deep = None                  # continued from the rows just replaced: done from the new ones next step
            removed = _also_removed(removed, before, gone)
    obs = cfg.touch.select(state.model, obs)
    if (obs.y < 0).any():                # the model's data leave the device only when there is something to check
        obs = drop_contradicted_inside(obs, cfg.policy, state.model.train_inputs[0].cpu().numpy(),
                                       state.model.train_targets.cpu().numpy())
    if deep is not None:                 # the camera's inside points continued down to the gap, in this step's batch
        obs = Observations.concat([obs, deep])                       # the step and source of the touch
    if corrected is not None:
        obs = Observations.concat([obs, corrected])
    _add(state.model, obs)
    return removed, obs


def _also_removed(removed: np.ndarray, before: int, gone: np.ndarray) -> np.ndarray:
    """``removed`` (indices into the step's ``before`` rows of data, as the log and replays read them) with ``gone``:
    indices into the rows left after ``removed``, which a later removal of the same step returns."""
    if not len(gone):
        return removed
    return np.sort(np.concatenate([removed, np.delete(np.arange(before), removed)[gone]]))


def _fit(model, cfg: ExploreConfig, state: ExplorationState) -> None:
    """Re-learn warm-started, and from fixed starts too every ``restart_every`` steps (decided by the step number,
    so a resumed run restarts where the uninterrupted one did), with the kernel's length and sigma^2 first on those
    steps when ``learn`` is "length" or "all" (from the configured values each time; not on the first fit, whose
    data are nearly all the camera's: learned there, a 2.7 cm length held a duck's run at 1.3 cm Chamfer); a touch
    model's ``fit_options`` (patches: the ``min_gain`` rule) go to a model whose ``fit`` takes them (GPIOIS; GPIS
    learns nothing else)."""
    from ..models.gpiois import FitNotConvergedWarning

    options = {k: v for k, v in cfg.touch.fit_options().items() if k in model.FIT_OPTIONS}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", FitNotConvergedWarning)
        restart = cfg.restart_every is not None and state.steps > 0 and state.steps % cfg.restart_every == 0
        if restart and cfg.learn != "task":
            model.learn_hyperparameters(*LEARN_SIZE, start=cfg.initial_hyperparameters,
                                        learn_noise=cfg.learn == "all")
        model.fit(multi_start=restart, **options)
    for w in caught:                     # counted, and said once at the end of the run; others passed on
        if issubclass(w.category, FitNotConvergedWarning):
            state.unconverged_fits += 1
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _add(model, obs: Observations) -> None:
    model.add_observations(obs.x, obs.y, obs.task)


def _moved(state: ExplorationState, touch: ContactResult) -> None:
    state.travel += touch.travel
    state.path.extend(touch.path.numpy())


def _describe(record: StepRecord, state: ExplorationState, ctx: Run, step_time: float) -> None:
    """The record's motion, its contact's ground truth where the world knows it, and the model's values."""
    m = state.model
    record.travel, record.taps, record.retracted, record.step_time = (
        state.travel,
        state.taps,
        state.retracted,
        step_time,
    )
    record.recoveries = state.recoveries
    record.reapproaches, record.reapproach_travel = state.reapproaches, state.reapproach_travel
    record.robot_time = ctx.hardware.robot_time()
    truth = ctx.world.contact_truth(ctx.hardware, state.contact)
    if truth is not None:
        record.contact_distance = float(truth.distance)
        record.contact_on_body = math.nan if truth.on_body is None else float(bool(truth.on_body))
    summary = m.step_summary()                               # the model's contract: no probing its kind
    record.similarity, record.correlation = summary["similarity"], summary["correlation"]
    if summary["task_covariance"] is not None:
        record.task_covariance = summary["task_covariance"]
    record.truncation, record.noise = summary["truncation"], summary["noise"]
    if math.isfinite(summary["fit_gap"]):
        record.fit_gap = summary["fit_gap"]
    if math.isfinite(summary["length"]):
        record.length = summary["length"]
    if summary["region_correlation"] is not None:
        record.region_correlation = summary["region_correlation"]


class _TimedToucher:
    """The contact controller with the wall time of its motions (``approach``, ``lift``, ``slide``) summed in
    ``motion`` [s]: a step's ``step_time`` is planning, ingesting and re-learning, motion excluded, and an evidence
    action (a tap, a reach, a recovery) plans and moves within one call."""

    MOVES = ("approach", "lift", "slide")

    def __init__(self, toucher):
        self._toucher, self.motion = toucher, 0.0

    def __getattr__(self, name):
        attr = getattr(self._toucher, name)
        if name not in self.MOVES:
            return attr

        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return attr(*args, **kwargs)
            finally:
                self.motion += time.perf_counter() - t0
        return timed


def _capped(state: ExplorationState, cfg: ExploreConfig) -> bool:
    """Whether the step cap is reached (evidence actions and recoveries count as steps)."""
    return state.steps + state.taps + state.recoveries >= cfg.max_steps


def _first(reasons):
    return next((r for r in reasons if r), None)


def lost_contact_end(state: ExplorationState, budget: float | None) -> str:
    """Why a run whose re-approach found nothing ends: "travel" when the re-approach spent what was left of the travel
    budget (the run ends by its budget: on pybullet's blobs 0-99 under tight covers, all 38 "lost contact" endings of
    the benchmark were re-approaches that spent the last of a 0.6 m budget, and counted as failed runs; run again,
    each ends so, on the same path), else "lost-contact"."""
    if budget is not None and state.travel >= budget - 1e-9:
        return "travel"
    return "lost-contact"


def reapproach_reach(controller) -> float:
    """How far [m] the first re-approach after a lost contact goes along the estimate's inward normal: twice the
    controller's search for lost contact (``config.max_normal_travel``), 10 cm for a controller without one.

    The fingertip has just pressed that far along the measured normal and found nothing; where the estimate's normal
    is right the surface lies within about as much, and where it is wrong a longer leg only spends travel before the
    leg back to the last contact. The force-field world sizes its search to the body
    (:func:`torch_gpioius.sim.forcefield.lost_contact_search`): a lying rod 1.6 cm thick (pybullet's blob 104) spent
    10 cm on every such leg, 88 % of its travel on re-approaches, and ended with four contacts.
    """
    search = getattr(getattr(controller, "config", None), "max_normal_travel", None)
    return 0.1 if search is None else 2.0 * float(search)


def recover(state: ExplorationState, hw, lost: ContactResult, budget_left: float | None = None
            ) -> ContactResult | None:
    """Contact was lost during a step (the surface curved away, or a cover dragged the fingertip): a re-approach
    from where the fingertip is, along the estimated inward normal there, for at most twice the controller's own
    search for lost contact (``config.max_normal_travel``; 10 cm with its default 5 cm, :func:`reapproach_reach`); if
    that finds nothing, one towards the last contact, for its distance + 5 cm. Neither goes past ``budget_left`` [m]
    of the travel budget (a run ends at most one step past it). Each re-approach is counted in
    ``state.reapproaches`` and its travel in ``state.reapproach_travel``. Returns the merged result of the step and
    the re-approaches, or None (the run then ends on "lost-contact")."""
    left = [math.inf if budget_left is None else budget_left]

    def approach(direction, reach: float):
        reach = min(reach, left[0])
        if not reach > 1e-6:
            return None
        try:
            r = hw.controller.approach(direction, max_travel=reach)
        except RuntimeError:          # refused or faulted: no re-approach
            return None
        _moved(state, r)
        state.reapproaches += 1
        state.reapproach_travel += r.travel
        left[0] -= r.travel
        return r

    res = lost
    here = lost.path[-1]
    geo = surface_geometry(state.model, here.reshape(1, -1).to(state.model.train_inputs[0]), 0)
    if bool(geo.normal_defined[0]):
        back = approach(-geo.normal[0], reapproach_reach(hw.controller))
        if back is not None:
            res = _then(res, back)
            if back.in_contact:
                return res
    # the estimate's normal led nowhere (an outer-shape normal can point past a loose cover's gap): head back
    # towards the last contact, which is on the object, as an operator would
    here = res.path[-1]
    to_last = torch.as_tensor(state.contact, dtype=here.dtype) - here
    dist = float(to_last.norm())
    if not dist > 1e-6:
        return None
    limit = hw.approach_limit()
    back = approach(to_last / dist, min(dist + 0.05, limit) if limit else dist + 0.05)
    if back is None or not back.in_contact:
        return None
    return _then(res, back)


def _then(a: ContactResult, b: ContactResult) -> ContactResult:
    """Result ``a`` followed by result ``b``, as one: ``b``'s end state, both paths, readings and free space."""
    return ContactResult(b.in_contact, b.contact, torch.cat([a.free_space, b.free_space]), torch.cat([a.path, b.path]),
                         torch.cat([a.forces, b.forces]), a.travel + b.travel)

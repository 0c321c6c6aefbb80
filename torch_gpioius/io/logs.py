"""Exploration logs: the crash-safe log as a recorder of the exploration, and resuming a run from it.

The log is a ``.gpioius`` file (:mod:`torch_gpioius.io.datasets`) with a ``header`` (the world and the settings),
one ``step`` record per completed step, one ``tap`` record per evidence action after the step it followed, and an
``end`` record. Each record is durable (flushed and fsynced) before the next step begins, so a killed process loses
at most the step it was in. Field names are those of
:data:`torch_gpioius.exploration.state.RECORD_FIELDS`; logs written before they were (``h``, ``s``, ``rho``, ``ci``,
``sim_time``, ...) are read through :func:`step_values`.
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np
import torch

from ..exploration.calibration import camera_table, capture_views, vision_crop
from ..exploration.protocols import Recorder
from ..geometry.metrics import SHAPE_METRICS
from ..exploration.state import ExplorationState, StepRecord
from .datasets import DatasetError, LogWriter, TornLogWarning, read_records, replay, step_number

__all__ = ["LogRecorder", "restore_run", "step_values", "load_logged_hyperparameters", "OLD_FIELD_NAMES"]

#: Step-record fields of logs written before the one vocabulary, and their names now.
OLD_FIELD_NAMES = {"h": "hausdorff", "ht": "hausdorff_touched", "u": "uncertainty", "s": "similarity",
                   "rho": "correlation", "ci": "correlation_interval", "time": "step_time", "sim_time": "robot_time"}
_VALUES = ("travel", "hausdorff", "hausdorff_touched", "uncertainty", "estimate", *SHAPE_METRICS, "similarity",
           "correlation", "step_time",
           "robot_time", "contact_distance", "contact_on_body", "truncation", "fit_gap", "length", "noise")


def step_values(meta: dict, where: str = "a step record") -> dict:
    """A step record's values by their current names (old names mapped; NaN where absent or null).

    Raises:
        DatasetError: a value of the wrong type (a list where a number belongs, a count that is not a whole
            number), naming ``where`` and the field.
    """
    m = {OLD_FIELD_NAMES.get(k, k): v for k, v in meta.items()}

    def number(key: str, default=math.nan) -> float:
        v = m.get(key)
        if v is None:
            return default
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise DatasetError(f"{where}: field {key!r} must be a number or null, got {_shown(v)}")
        try:
            return float(v)
        except OverflowError:
            raise DatasetError(f"{where}: field {key!r} is out of range ({_shown(v)})") from None

    def count(key: str) -> int:
        v = number(key, 0.0)
        if not (math.isfinite(v) and v >= 0 and v == int(v) and v < 2**62):
            raise DatasetError(f"{where}: field {key!r} must be a count (a whole number >= 0), got {_shown(m[key])}")
        return int(v)

    out = {k: number(k) for k in _VALUES}
    ci = m.get("correlation_interval") or [math.nan, math.nan]
    if not isinstance(ci, (list, tuple)) or len(ci) != 2 or not all(
            v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for v in ci):
        raise DatasetError(f"{where}: field 'correlation_interval' must be two numbers, got {_shown(ci)}")
    out["correlation_interval"] = tuple(math.nan if v is None else float(v) for v in ci)
    for key in ("taps", "recoveries", "reapproaches", "retracted"):
        out[key] = count(key)
    out["reapproach_travel"] = number("reapproach_travel", 0.0)
    return out


def _shown(v) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def load_logged_hyperparameters(model, state, where: str):
    """``model`` with the kernel length and noise a step record logged (its ``hyperparameters``, the raw
    parameters of a run that learned them; None: the model as it is).

    Raises:
        DatasetError: the logged state does not fit the model (names ``where``).
    """
    if state is not None:
        try:
            model.load_hyperparameter_state(state)
        except ValueError as exc:
            raise DatasetError(f"{where}: the logged hyperparameters: {exc}") from None
    return model


def logged_gap_field(meta: dict, arrays: dict, where: str):
    """The outer mean's gap field a step record logged (``meta["outer_field"]``, its numbers; ``arrays``'
    ``outer_field_points`` and ``outer_field_gaps``), as a :class:`~torch_gpioius.models.gapfield.GapField`.

    Raises:
        DatasetError: the record is not a gap field (names ``where``).
    """
    from ..models.gapfield import GapField

    try:
        return GapField.from_dict({**meta["outer_field"], "points": arrays["outer_field_points"],
                                   "gaps": arrays["outer_field_gaps"]}, where)
    except (KeyError, ValueError) as exc:
        raise DatasetError(f"{where}: the logged gap field: {exc}") from None


def _num(v) -> float | None:
    return None if v is None else float(v)


class LogRecorder(Recorder):
    """Writes the crash-safe exploration log at ``path`` (see the module docstring); appends to it on resume.

    Args:
        path: the log file (a new run replaces it; a resumed run appends after its last complete step).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = path
        self.writer: LogWriter | None = None

    def start(self, run, state) -> None:
        if run.resumed:
            if state.terminated is None:
                self.writer = LogWriter(self.path, resume=True)
            return
        header = {"frame": "base" if run.dim == 3 else "scene", "source": "torch_gpioius.explore",
                  **run.world.describe(), **run.config.describe()}
        self.writer = LogWriter(self.path, header)
        self._write(run, state, state.records[0])

    def step(self, run, state, record) -> None:
        self._write(run, state, record)

    def end(self, run, state) -> None:
        if self.writer is not None:
            self.writer.append("end", {"terminated": state.terminated, "steps": len(state.records) - 1}, {})
            self.writer.close()
            self.writer = None

    def _write(self, run, state, record: StepRecord) -> None:
        if self.writer is None:
            return
        dim = run.dim
        world = {f"world_{k}": np.asarray(v) for k, v in run.world.snapshot(run.hardware).items()}
        obs = record.observations
        touch = record.touch
        meta = {"step": record.step, "travel": record.travel, "retracted": record.retracted, "taps": record.taps,
                "recoveries": record.recoveries, "reapproaches": record.reapproaches,
                "reapproach_travel": record.reapproach_travel,
                "hausdorff": record.hausdorff, "hausdorff_touched": record.hausdorff_touched,
                "uncertainty": record.uncertainty, "estimate": record.estimate,
                **{name: getattr(record, name) for name in SHAPE_METRICS}, "similarity": record.similarity,
                "correlation": record.correlation,
                "correlation_interval": list(record.correlation_interval), "step_time": record.step_time,
                "robot_time": record.robot_time, "contact_distance": record.contact_distance,
                "contact_on_body": record.contact_on_body, "truncation": record.truncation,
                "fit_gap": record.fit_gap, "length": record.length, "noise": record.noise}
        if hasattr(state.model, "outer_mean"):      # the cover's offset (ObservationPolicy.cover_offset)
            meta["outer_mean"] = state.model.outer_mean
        field = getattr(state.model, "outer_field", None)
        if field is not None:                       # the gap a place at a time (ObservationPolicy.cover_gap_field)
            meta["outer_field"] = {k: v for k, v in field.as_dict().items() if k not in ("points", "gaps")}
        if record.camera_corrections is not None:  # the step that corrected the camera's captures (camera_bound)
            meta["camera_corrections"] = record.camera_corrections
        if run.config.learn != "task":  # learned length and noise, raw, so that resume restores them exactly
            meta["hyperparameters"] = state.model.hyperparameter_state()
        fit_state = getattr(state.model, "fit_state", None)
        fit_hessian = np.full((3, 3), np.nan)
        if callable(fit_state):                     # the min_gain rule's memory (patch runs), so resume decides alike
            fit_hessian, meta["fit_relearned"], meta["held_fits"] = fit_state()
        path = touch.path.numpy() if touch is not None else np.zeros((0, dim))
        arrays = {"x": obs.x, "y": obs.y, "task": obs.task, "removed": np.asarray(record.removed, dtype=np.int64),
                  "contact": state.contact, "kt": np.asarray(record.task_covariance, dtype=np.float64),
                  "previous": np.full(dim, np.nan) if state.previous is None else state.previous.numpy(),
                  "normal": np.full(dim, np.nan) if state.normal is None else state.normal.numpy(),
                  "path": path, "positions": path,
                  "forces": touch.forces.numpy() if touch is not None else np.zeros((0, 3)),
                  "timestamps": np.full(len(path), record.robot_time), "fit_hessian": fit_hessian}
        if obs.normal is not None:
            arrays["normals"] = obs.normal
        arrays.update(run.config.touch.footprint())       # a patch's pad at this step (the viewer draws it)
        if field is not None:
            arrays["outer_field_points"], arrays["outer_field_gaps"] = field.points.numpy(), field.gaps.numpy()
        if hasattr(state.model, "region_correlations"):
            arrays["local_params"] = state.model.params.detach().cpu().numpy()
        self.writer.append("step", meta, {**arrays, **world})
        for ev_obs, removed, kind, ev_path in record.evidence:
            self.writer.append(kind, {"step": record.step, "taps": state.taps, "recoveries": state.recoveries,
                                      "reapproaches": state.reapproaches, "reapproach_travel": state.reapproach_travel,
                                      "travel": state.travel},
                               {"x": ev_obs.x, "y": ev_obs.y, "task": ev_obs.task,
                                "removed": np.asarray(removed, dtype=np.int64), "contact": state.contact,
                                "path": np.asarray(ev_path, dtype=np.float64).reshape(-1, dim),
                                "normal": state.normal.numpy(), **world})


#: Header keys a resumed run need not match: where the world's scene file lies (a folder moved, a log written before
#: the key existed); its geometry is compared by ``scene_fingerprint``.
_NOT_COMPARED = frozenset({"scene_file"})


#: Header keys added since logs were first written: a log without one resumes on the keys it has (``estimator``
#: holds the estimator's settings whole; the log's ``kernel``, ``noise`` and ``policy`` say the same of older runs).
_ADDED = frozenset({"estimator"})


def _kernel_now(description):
    """A kernel's description as the kernel describes itself now (an inverse multiquadric's ``theta`` is its
    ``lengthscale``)."""
    if isinstance(description, dict) and description.get("kernel") == "InverseMultiquadric" and "theta" in description:
        description = {**{k: v for k, v in description.items() if k != "theta"}, "lengthscale": description["theta"]}
    return description


def _same(have, want) -> bool:
    if isinstance(want, float) and isinstance(have, (int, float)) and not isinstance(have, bool):
        return math.isclose(have, want, rel_tol=1e-12, abs_tol=0.0)
    if isinstance(want, dict) and isinstance(have, dict):
        # a field added since the log was written, at its off value (None, False), means what its absence meant
        # (the shipped example's policy lacks vision_free_far: None, which is no far free-space point either way)
        absent = [k for k in set(want) ^ set(have) if (want if k in want else have)[k] not in (None, False)]
        return not absent and all(_same(have[k], want[k]) for k in set(want) & set(have))
    if isinstance(want, (list, tuple)) and isinstance(have, (list, tuple)):
        return len(want) == len(have) and all(_same(a, b) for a, b in zip(have, want))
    return have == want


def _check_header(path, records: list, world, config) -> None:
    """Refuse a log whose header names another world (its geometry) or other settings than this run's.

    Raises:
        DatasetError: no header; ValueError: a setting differs (names it).
    """
    if not records or records[0].kind != "header":
        raise DatasetError(f"{path}: no header record; not an exploration log")
    header = records[0].meta
    want = {**world.describe(), **config.describe()}
    for key, value in want.items():
        if key in _NOT_COMPARED or (key in _ADDED and key not in header):
            continue
        have = _kernel_now(header.get(key)) if key == "kernel" else header.get(key)
        if not _same(have, value):
            what = "world geometry" if key == "scene_fingerprint" else key
            raise ValueError(f"{path}: cannot resume: the log was written with {key}={have!r}, this call asks "
                             f"{key}={value!r} (different {what})")


def _step_record(i: int, v: dict, arrays: dict) -> StepRecord:
    """The :class:`StepRecord` of step ``i`` from its logged values ``v`` (:func:`step_values`) and arrays."""
    names = ("travel", "hausdorff", "hausdorff_touched", "uncertainty", "estimate", *SHAPE_METRICS, "similarity",
             "correlation", "correlation_interval", "step_time", "robot_time", "taps", "recoveries", "retracted",
             "reapproaches", "reapproach_travel", "contact_distance", "contact_on_body", "truncation", "fit_gap",
             "length", "noise")
    return StepRecord(step=i, task_covariance=np.asarray(arrays["kt"], dtype=np.float64),
                      **{name: v[name] for name in names})


def restore_run(path: str | os.PathLike, world, hardware, config) -> ExplorationState:
    """The state of a run after the last complete step of its log (written by ``torch_gpioius.explore(log=...)``).

    The log's header must name the same world (its geometry fingerprint, not just its name) and the same settings;
    the hardware is put back into the state logged with the last step (the robot's joints and clock, the sensor's
    noise generator, the physics), so the resumed run continues exactly where the killed one stopped.

    Args:
        path: the log.
        world: the world of the run; hardware: a fresh ``world.hardware()``; config: the run's
            :class:`~torch_gpioius.exploration.config.ExploreConfig`.

    Raises:
        ValueError: the log was written by a different run (names the setting).
        DatasetError: the log is unreadable or holds no complete step.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TornLogWarning)
        records = list(read_records(path))
        states = [ds for rec, ds in replay(path) if rec.kind in ("step", "tap", "recovery")]
    _check_header(path, records, world, config)
    steps = [r for r in records[1:] if r.kind == "step"]
    if not steps:
        raise DatasetError(f"{path}: the log has no complete step to resume from")
    end = [r for r in records[1:] if r.kind == "end"]
    taps = [r for r in records[1:] if r.kind in ("tap", "recovery")]
    state = ExplorationState(model=None)
    for r in records[1:]:       # the path in the order the fingertip took it: each step's, then its evidence actions'
        if r.kind in ("step", "tap", "recovery") and "path" in r.arrays:    # (logs before 2026-11 kept no tap path)
            state.path.extend(list(np.asarray(r.arrays["path"], dtype=np.float64).reshape(-1, world.dim)))
    for i, r in enumerate(steps):
        where = f"{path}: step record {i}"
        if step_number(r.meta, where) != i:
            raise DatasetError(f"{where}: steps out of order (found step {r.meta['step']})")
        state.contacts.append(np.asarray(r.arrays["contact"], dtype=np.float64))
        v = step_values(r.meta, f"{path}: step record ending at byte {r.end}")
        rec = _step_record(i, v, r.arrays)
        state.records.append(rec)
    last, data = steps[-1], states[-1]    # the training set after the last step or tap (everything replayed)
    model = config.model_for(data.x, data.y, data.task)           # in the log's order, as the run built it
    v = step_values(last.meta, f"{path}: step record ending at byte {last.end}")
    if config.learn != "task":                                     # what the run had learned by its last step
        load_logged_hyperparameters(model, last.meta.get("hyperparameters"), f"{path}: last step record")
    if "local_params" in last.arrays and hasattr(model, "region_correlations"):
        model.set_params(last.arrays["local_params"])
        for rec in state.records:
            rec.region_correlation = np.full(model.regions, np.nan)
    elif hasattr(model, "task_covariance"):
        model.task_covariance = torch.as_tensor(last.arrays["kt"])
        if isinstance(last.meta.get("outer_mean"), (int, float)):       # logged since 2026-11-27
            model.set_outer_mean(float(last.meta["outer_mean"]))
        if isinstance(last.meta.get("outer_field"), dict):               # logged since 2026-11-29
            model.set_outer_mean(logged_gap_field(last.meta, last.arrays, f"{path}: last step record"))
        if "fit_hessian" in last.arrays and callable(getattr(model, "restore_fit_state", None)):
            model.restore_fit_state(last.arrays["fit_hessian"], last.meta.get("fit_relearned", True),
                                    last.meta.get("held_fits", 0))
    state.model = model
    state.travel, state.retracted, state.taps, state.recoveries = (v["travel"], v["retracted"], v["taps"],
                                                                   v["recoveries"])
    state.reapproaches, state.reapproach_travel = v["reapproaches"], v["reapproach_travel"]
    state.steps = step_number(last.meta, f"{path}: last step")
    for name in ("previous", "normal"):
        a = np.asarray(last.arrays.get(name, np.full(world.dim, np.nan)), dtype=np.float64)
        setattr(state, name, None if np.isnan(a).any() else torch.as_tensor(a))
    state.terminated = end[-1].meta["terminated"] if end else None
    after = taps[-1] if taps and taps[-1].meta.get("step") == state.steps else last
    if after is not last:                        # the last step ended with a tap: its travel, contact and state
        state.travel = float(after.meta["travel"])
        state.taps = int(after.meta["taps"])
        state.recoveries = int(after.meta.get("recoveries", state.recoveries))
        state.reapproaches = int(after.meta.get("reapproaches", state.reapproaches))
        state.reapproach_travel = float(after.meta.get("reapproach_travel", state.reapproach_travel))
        state.contacts[-1] = np.asarray(after.arrays["contact"], dtype=np.float64)
        state.normal = torch.as_tensor(np.asarray(after.arrays["normal"], dtype=np.float64))
    for i, r in enumerate(steps):                # the steps that corrected the camera's captures, and what they did
        if isinstance(r.meta.get("camera_corrections"), dict):
            state.camera_corrections = state.records[i].camera_corrections = r.meta["camera_corrections"]
    if config.policy.camera_bound is not None and config.uses_vision:
        # the views captured again, to be corrected as the contacts come (a fresh simulated camera gives the run's
        # first capture; a real one, another)
        state.captures, state.crop = capture_views(hardware.camera), vision_crop(world, config.policy)
        state.table = camera_table(hardware, config.policy)
    state.last_evidence = max((int(t.meta["step"]) for t in taps if t.kind == "tap"), default=0)
    state.last_recovery = max((int(t.meta["step"]) for t in taps if t.kind == "recovery"), default=0)
    world.restore(hardware, {k[len("world_"):]: v for k, v in after.arrays.items() if k.startswith("world_")})
    return state


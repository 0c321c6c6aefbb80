"""Studies as statistics: objects x modes x seeds (x worlds), one task per run, on Ray when installed.

``gpioius study --world 2d|3d|mujoco --objects A,D --modes visual-tactile,tactile --seeds N --out DIR``
(or :func:`run_sweep`) runs every (object, mode, seed) once and writes, as each run finishes:

* ``DIR/runs/<object>_<mode>_<seed>.json``: the run's summary and per-step series (atomic: written to a temporary
  file and renamed, so a killed run leaves nothing half-written and a re-run skips finished runs);
* ``DIR/logs/<object>_<mode>_<seed>.gpioius``: its crash-safe exploration log.

Then it aggregates: ``DIR/runs.csv`` (one row per run: ``object, mode, seed, final_hausdorff``, ...),
``DIR/summary.json`` (``{object: {mode: {"final_hausdorff": {"median", "lo", "hi", ...}, "n", ...}}}`` plus the
paired differences and the claims), ``DIR/summary.md`` and the figures.

A seed perturbs the world (:meth:`torch_gpioius.exploration.world.World.perturbed`): the start within a 2 cm disc
across the approach, the approach direction within 10 degrees, the force-sensor and the camera noise; seed 0 is
the unperturbed world. Each run uses one torch thread.

**Distributed.** With the ``ray`` extra each run is a Ray task (``num_cpus=1``, retried up to 3 times if its worker
dies; a retried run starts afresh and overwrites its own log, and its result file is written once, atomically, so
nothing is lost or duplicated). By default a local Ray starts embedded in the command (``workers`` CPUs); with
``address`` the command joins an existing cluster. Without Ray the runs execute sequentially in-process.
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any
from pathlib import Path

import numpy as np

from .._validation import as_device, as_float
from ..metrics import SHAPE_METRICS
from .stats import median_interval, paired_difference

__all__ = ["run_sweep", "SweepSettings", "RunSpec", "run_one", "aggregate", "read_run_file", "RunFileError", "MODES",
           "WORLDS", "FRACTIONS", "MAX_SEEDS"]  # noqa: F822 (WORLDS: the module's __getattr__)

#: Modes a sweep can run: the paper's two, and the evidence-seeking and local-similarity variants.
MODES = ("visual-tactile", "tactile", "visual-tactile+taps", "local", "local+taps", "visual-tactile+reach",
         "tactile+reach")
#: Fractions of the reference travel at which the Hausdorff distance is reported.
FRACTIONS = (0.10, 0.25, 0.50, 1.00)
#: A contact counts as "within" when it lies this close to the true body [m] (``contacts_within`` of a run).
CONTACT_WITHIN = 0.01
#: Metrics every k steps in worlds with a travel budget (the robot study's 150 steps; every step in 2-D).
BUDGET_METRICS_EVERY = 5


def __getattr__(name):
    # the world names and their objects come from the registry (a world registered later is a sweep world too)
    if name == "WORLDS":
        from ..exploration.registry import world_names

        return tuple(w for w in world_names() if w != "robot")
    if name == "DEFAULT_OBJECTS":
        from ..exploration.registry import world_entry, world_names

        return {w: world_entry(w).object_names for w in world_names() if w != "robot"}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep (``world`` is a registered world's name)."""

    world: str
    object: str
    mode: str
    seed: int
    out: str
    smoke: bool = False
    max_travel: float | None = None
    max_steps: int | None = None
    threads: int = 1
    scene: str | None = None        # a scene file (torch_gpioius.sim.scenefile) instead of a built-in object
    voxel: float | None = None      # camera voxel edge [m] (0: every point); None: the world's own (0.05)
    touch: str = "point"            # "point" (the fingertip's contact) or "patch" (a gel pad's depth map)
    outer_tol: float | None = None  # visual-tactile with a truncated outer basis (GPIOIS(outer_tol=)); None: exact
    device: str | None = None       # where the model's arithmetic runs ("cuda"); None: the CPU
    settings: str | None = None     # 3-D worlds: "default" or "paper" (World.with_settings); None: the world's own
    learn: str | None = None        # "task", "length" or "all" (explore(learn=)); None: the world's own
    views: tuple | None = None      # 3-D worlds: the camera's views (World.with_views); None: the world's own
    kernel: Any = None              # a KernelChoice (a kernel's name and length scale); None: the world's own
    noise: float | None = None      # sigma^2; None: the world's own
    scene_hash: str | None = None   # the scene file's content (scenefile.scene_fingerprint): a run of an edited
    #                                 scene is another run, whatever its name
    set_object: Any = None          # an object of a set (sim.objectsets.SetObject) instead of a built-in object
    cover: str | None = None        # a set object's cover: "tight" or "wide" (sim.objectsets.COVERS)

    @property
    def key(self) -> str:
        return f"{self.object}_{self.mode}_{self.seed}"


def make_world(world: str, name: str, seed: int, smoke: bool = False, scene: str | None = None,
               settings: str | None = None, views=None, set_object=None, cover: str | None = None):
    """The world of one run: the named object (or the scene file ``scene``), perturbed by ``seed`` (seed 0: the
    unperturbed object), under ``settings`` in place of its own (3-D worlds: "default" or "paper"), seen by
    ``views`` in place of the settings' (3-D worlds: ``with_views``); or an object of a set
    (:mod:`torch_gpioius.sim.objectsets`) under ``cover``, in the force-field world, the library's default settings
    unless told."""
    if set_object is not None:
        from ..sim.objectsets import set_scene

        made = set_scene(set_object, cover or "tight", settings=settings or "default", seed=seed,
                         **({"resolution": 0.006} if smoke else {}))
    elif scene is not None:
        from ..sim.scenefile import load_scene

        made = load_scene(scene, world=world, seed=seed, smoke=smoke, settings=settings)
    else:
        from ..exploration.registry import make_world as registry_make_world

        made = registry_make_world(world, name, seed, smoke)
        made = made if settings is None else made.with_settings(settings)
    if views is None:
        return made
    viewed = made.with_views(views)
    viewed.scene_file = made.scene_file          # the same scene file, seen otherwise
    return viewed


def _world_budget(world) -> float | None:
    """The travel budget [m] of a world's own stop rules (the robot study's 1.5 m), or None (e.g. once around)."""
    from ..exploration.stopping import TravelBudget

    return next((r.max_travel for r in world.defaults.stop if isinstance(r, TravelBudget)), None)


def _explore_kwargs(spec: RunSpec, world) -> dict:
    mode, evidence = spec.mode, None
    for suffix in ("+taps", "+reach"):
        if mode.endswith(suffix):
            mode, evidence = mode[: -len(suffix)], suffix[1:]
    kw: dict = {"evidence": evidence}
    if mode == "local":
        kw["mode"], kw["regions"] = "visual-tactile", 4
    else:
        kw["mode"] = mode
    budget = _world_budget(world)
    if budget is not None:
        kw["metrics_every"] = BUDGET_METRICS_EVERY
        kw["max_travel"] = spec.max_travel if spec.max_travel is not None else (0.06 if spec.smoke else budget)
    if spec.max_steps is not None:
        kw["max_steps"] = spec.max_steps
    elif spec.smoke:
        kw["max_steps"] = 12 if budget is None else 40
    if kw["mode"] == "visual-tactile":
        kw["interval_every"] = 1000 if spec.smoke else 10
    if spec.voxel is not None:
        kw["policy"] = world.defaults.policy.with_voxel(spec.voxel)
    if spec.touch != "point":
        kw["touch"] = spec.touch
    if spec.outer_tol is not None and kw["mode"] == "visual-tactile" and "regions" not in kw:
        kw["outer_tol"] = spec.outer_tol
    if spec.learn is not None:
        kw["learn"] = spec.learn
    if spec.kernel:
        kw["kernel"] = spec.kernel.apply(world.defaults.kernel)
    if spec.noise is not None:
        kw["noise"] = spec.noise
    if spec.device is not None:
        kw["device"] = spec.device
    return kw


def _atomic_json(path: Path, data: dict) -> None:
    from ..io.outputs import atomic_write

    atomic_write(path, json.dumps(data, allow_nan=True))


class RunFileError(ValueError):
    """A run's result file (``runs/<key>.json``) is unreadable or invalid; the message names the file and field."""


_SERIES = ("travel", "hausdorff", "hausdorff_touched", "uncertainty", "similarity", "correlation", "correlation_lo",
           "correlation_hi")


def _number(v, *, allow_nan: bool = True) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and (allow_nan or math.isfinite(v))


def _worlds() -> tuple:
    from ..exploration.registry import world_names

    return tuple(w for w in world_names() if w != "robot")


def _current_names(run: dict) -> dict:
    """A run file in the current names (files of earlier releases: ``travel_m``, ``wall_s``, ``median_step_ms``,
    world ``2d`` / ``3d``, no ``budget``)."""
    from ..exploration.registry import canonical_world_name

    if not isinstance(run.get("world"), str):
        return run
    old_world = run["world"]
    run = {**run, "world": canonical_world_name(old_world)}
    if "travel_m" in run and "travel" not in run:
        run["travel"] = run.pop("travel_m")
    if "wall_s" in run and "wall_time" not in run:
        run["wall_time"] = run.pop("wall_s")
    if "median_step_ms" in run and "median_step_time" not in run:
        v = run.pop("median_step_ms")
        run["median_step_time"] = v / 1e3 if _number(v) else v
    if "budget" not in run:
        run["budget"] = None if old_world == "2d" else 1.5
    return run


def read_run_file(path: str | Path) -> dict:
    """Read and validate one run's result file (what :func:`run_one` writes).

    Checks the fields aggregation reads: names and seed, counts, travel and times, and the per-step series (equal
    lengths; numbers or NaN; distances, uncertainty and travel not negative; correlations in [-1, 1]).

    Raises:
        RunFileError: naming the file and the first bad field (a truncated or edited file, or a foreign one).
    """
    path = Path(path)
    try:
        run = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise RunFileError(f"{path}: not a readable run result ({type(exc).__name__}: {exc})") from None
    if not isinstance(run, dict):
        raise RunFileError(f"{path}: a run result is a JSON object, got {type(run).__name__}")

    def bad(field: str, why: str):
        return RunFileError(f"{path}: field {field!r} {why}")

    run = _current_names(run)

    for k in ("world", "object", "mode", "terminated"):
        if not isinstance(run.get(k), str):
            raise bad(k, f"must be a string, got {run.get(k)!r}")
    if run["world"] not in _worlds():
        raise bad("world", f"must be one of {_worlds()}, got {run['world']!r}")
    if run["mode"] not in MODES:
        raise bad("mode", f"must be one of {MODES}, got {run['mode']!r}")
    for k in ("seed", "steps", "taps"):
        v = run.get(k)
        if not (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
            raise bad(k, f"must be a non-negative integer, got {v!r}")
    for k in ("travel", "wall_time"):
        v = run.get(k)
        if not (_number(v, allow_nan=False) and v >= 0):
            raise bad(k, f"must be a non-negative number, got {v!r}")
    if not _number(run.get("median_step_time")):
        raise bad("median_step_time", f"must be a number or NaN, got {run.get('median_step_time')!r}")
    if run.get("budget") is not None and not (_number(run["budget"], allow_nan=False) and run["budget"] > 0):
        raise bad("budget", f"must be a positive travel [m] or null, got {run['budget']!r}")
    v = run.setdefault("recoveries", 0)                 # files of 0.3.0 and earlier have none of these three
    if not (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
        raise bad("recoveries", f"must be a non-negative integer, got {v!r}")
    v = run.setdefault("reapproaches", 0)               # files written before re-approaches were counted: 0
    if not (isinstance(v, int) and not isinstance(v, bool) and v >= 0):
        raise bad("reapproaches", f"must be a non-negative integer, got {v!r}")
    v = run.setdefault("reapproach_travel", 0.0)
    if not (_number(v, allow_nan=False) and v >= 0):
        raise bad("reapproach_travel", f"must be a non-negative distance [m], got {v!r}")
    for k in ("contacts_on_body", "contacts_within"):
        v = run.setdefault(k, math.nan)
        if not (_number(v) and (math.isnan(v) or 0.0 <= v <= 1.0)):
            raise bad(k, f"must be a fraction in [0, 1] or NaN, got {v!r}")
    series = run.get("series")
    if not isinstance(series, dict):
        raise bad("series", "is missing or not an object")
    lengths = set()
    # the required series, then those recorded since (the field's metrics, the estimate's 0 / 1 / NaN)
    for k in (*_SERIES, *(k for k in (*SHAPE_METRICS, "estimate") if k in series)):
        v = series.get(k)
        if not isinstance(v, list) or not all(_number(e) for e in v):
            raise bad(f"series.{k}", "must be a list of numbers (NaN where not measured)")
        a = np.asarray(v, dtype=float)
        if k in ("travel", "hausdorff", "hausdorff_touched", "uncertainty") and (a < 0).any():
            raise bad(f"series.{k}", f"holds a negative value ({float(a[a < 0][0])!r}); it is a distance or a "
                                     "variance")
        if k.startswith("correlation") and (np.abs(a[np.isfinite(a)]) > 1 + 1e-9).any():
            raise bad(f"series.{k}", "holds a correlation outside [-1, 1]")
        if k == "estimate" and not all(math.isnan(e) or e in (0, 1) for e in v):
            raise bad("series.estimate", "must be a list of 0, 1 or NaN (1: the estimate has a surface to judge)")
        lengths.add(len(v))
    if len(lengths) != 1 or 0 in lengths:
        raise bad("series", f"its lists must be non-empty and of one length, got lengths {sorted(lengths)}")
    return run


def run_one(spec: RunSpec) -> dict:
    """Run one (object, mode, seed) and write its result file; returns the result (also when already on disk)."""
    from ..session import explore
    from ..threads import torch_threads

    out = Path(spec.out)
    result_path = out / "runs" / f"{spec.key}.json"
    if _finished(result_path, spec):
        return read_run_file(result_path)
    for sub in ("runs", "logs", "running"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    marker = out / "running" / f"{spec.key}.pid"
    marker.write_text(str(os.getpid()))
    t0 = time.perf_counter()
    with torch_threads(spec.threads):
        try:
            world = make_world(spec.world, spec.object, spec.seed, spec.smoke, spec.scene, spec.settings, spec.views,
                               spec.set_object, spec.cover)
        except (ValueError, RuntimeError, OSError) as exc:
            # a scene that cannot be built (a cover that does not close, a mesh that will not load) is a failed
            # row with its cause; the study goes on and writes its tables
            record = scene_failure_record(spec, exc, time.perf_counter() - t0)
            _atomic_json(result_path, record)
            marker.unlink(missing_ok=True)
            return record
        kw = _explore_kwargs(spec, world)
        try:
            # the folder is ours: a run that crashed before is done again over its own log
            trace = explore(world, log=out / "logs" / f"{spec.key}.gpioius", overwrite=True, **kw)
        except RuntimeError as exc:
            # the approach found no contact or the robot refused it (a perturbed approach past a thin part of the
            # object): the run failed before any estimate; it is recorded as such, and the sweep goes on
            trace = None
            record = _no_start_record(spec, kw, exc, time.perf_counter() - t0)
    if trace is not None:
        record = _record(spec, kw, trace, time.perf_counter() - t0)
        record["n_outer"] = _n_outer(trace.model)
        record["n_vision_inside"] = _n_outer(trace.model, inside=True)
        # the outer task's prior mean at the end (1: the paper's; 1 - gap / ramp once the touches set it)
        record["outer_mean"] = float(getattr(trace.model, "outer_mean", math.nan))
    policy = kw.get("policy", world.defaults.policy)
    record["voxel"] = policy.voxel or 0.0
    # the inside points' depths [m] (0: the paper's labels only)
    record["touch_inside"], record["vision_inside"] = policy.touch_inside or 0.0, policy.vision_inside or 0.0
    record["vision_inside_gap"] = policy.vision_inside_gap or 0.0      # 0: the camera's inside points always kept
    record["touch"] = spec.touch
    if getattr(world, "views", None):                 # the camera's views (force-field world)
        record["views"] = "+".join(world.views)
    if spec.settings is not None:
        record["settings"] = spec.settings
    if spec.scene_hash is not None:
        record["scene_hash"] = spec.scene_hash
    if spec.device is not None:
        record["device"] = spec.device
    if "outer_tol" in kw and trace is not None:      # the truncated outer basis: its setting and largest bound
        record["outer_tol"] = kw["outer_tol"]
        record["max_truncation"] = float(np.nanmax(trace.truncation)) if len(trace.truncation) else math.nan
    if trace is not None and len(trace.fit_gap):     # how far a held or tracked K_t was from its optimum [nats]
        record["max_fit_gap"] = float(np.nanmax(trace.fit_gap))
    if trace is not None and len(trace.length):      # the kernel's length and sigma^2 at the end (as learned)
        record["length"], record["noise"] = float(trace.length[-1]), float(trace.noise[-1])
    record["learn"] = kw.get("learn") or getattr(world.defaults, "learn", "task")
    if trace is not None:               # the estimator's settings the run used, as its log's header records them
        record["estimator"] = _logged_estimator(out / "logs" / f"{spec.key}.gpioius")
    record["kernel"] = kw.get("kernel", world.defaults.kernel).kind
    if trace is not None and getattr(trace.model, "regions", None) and len(trace.region_correlation):
        # the local model's regions: the seen surface coloured by its correlation, and each region over the run
        from .figures import figure_regions

        record["region_correlation"] = np.asarray(trace.region_correlation)[-1].tolist()
        figure_regions(trace, out / "figures" / f"regions_{spec.key}.png",
                       f"{spec.world} {spec.object}, {spec.mode}, seed {spec.seed}")
    _atomic_json(result_path, record)
    try:
        marker.unlink()
    except OSError:
        pass
    return record


def _no_start_record(spec: RunSpec, kw: dict, exc: Exception, wall_time: float) -> dict:
    """The result of a run that failed before its first contact: terminated "refused: <why>", no estimate."""
    nan = [math.nan]
    return {"world": spec.world, "object": spec.object, "mode": spec.mode, "seed": spec.seed,
            "terminated": f"refused: approach: {exc}", "steps": 0, "travel": 0.0, "budget": kw.get("max_travel"),
            "wall_time": wall_time, "median_step_time": math.nan, "taps": 0, "recoveries": 0,
            "contacts_on_body": math.nan, "contacts_within": math.nan,
            "series": {"travel": [0.0], **{k: nan for k in _SERIES if k != "travel"}, "estimate": [0.0]}}


def _logged_estimator(log: Path) -> dict | None:
    """The ``estimator`` of a log's header (None where it records none)."""
    from ..io.datasets import read_records

    try:
        header = next(iter(read_records(log)))
    except (StopIteration, OSError, ValueError):
        return None
    value = header.meta.get("estimator")
    return value if isinstance(value, dict) else None


def scene_failure_record(spec: RunSpec, exc: BaseException, wall_time: float = 0.0) -> dict:
    """The result of a run whose world could not be built: terminated "refused: scene: <why>", no estimate."""
    record = _no_start_record(spec, {"max_travel": spec.max_travel}, exc, wall_time)
    record["terminated"] = f"refused: scene: {exc}"
    if spec.scene_hash is not None:
        record["scene_hash"] = spec.scene_hash
    return record


def _record(spec: RunSpec, kw: dict, trace, wall_time: float) -> dict:
    """A finished run's result."""
    return {"world": spec.world, "object": spec.object, "mode": spec.mode, "seed": spec.seed,
            "terminated": trace.terminated, "steps": trace.n_steps - 1, "travel": float(trace.travel[-1]),
            "budget": kw.get("max_travel"), "wall_time": wall_time,
            **{f"{k}_step_time": v for k, v in trace.step_time_summary().items()},
            "taps": int(trace.taps[-1]) if len(trace.taps) else 0,
            "recoveries": int(trace.recoveries[-1]) if len(trace.recoveries) else 0,
            "reapproaches": int(trace.reapproaches[-1]) if len(trace.reapproaches) else 0,
            "reapproach_travel": float(trace.reapproach_travel[-1]) if len(trace.reapproach_travel) else 0.0,
            "has_estimate": trace.has_estimate,
            **{f"contacts_{k}": v for k, v in trace.contacts_on_body(CONTACT_WITHIN).items()},
            "series": {"travel": trace.travel.tolist(), "hausdorff": trace.hausdorff.tolist(),
                       "hausdorff_touched": trace.hausdorff_touched.tolist(),
                       "uncertainty": trace.uncertainty.tolist(), "similarity": trace.similarity.tolist(),
                       "correlation": trace.correlation.tolist(),
                       "correlation_lo": trace.correlation_interval[:, 0].tolist(),
                       "correlation_hi": trace.correlation_interval[:, 1].tolist(),
                       "estimate": trace.estimate.tolist(),
                       **{name: values.tolist() for name, values in trace.shape.items()}}}


def _n_outer(model, inside: bool = False) -> int:
    """Outer (camera) points in a run's final model (GPIOIS, LocalGPIOIS), with ``inside`` only the camera's inside
    points (y < 0; 0 once a wide cover's gap retracted them); 0 for tactile-only GPIS."""
    task = getattr(model, "train_task", None)
    if task is None:
        return 0
    outer = task == 1
    return int((outer & (model.train_targets < 0)).sum() if inside else outer.sum())


def _set_aside(path: Path, suffix: str = "invalid", why: str = "damaged or foreign result") -> Path:
    """Rename a result file to ``<name>.<suffix>`` (kept for inspection) so that its run is done again."""
    import warnings

    bad = path.with_name(path.name + "." + suffix)
    os.replace(path, bad)
    warnings.warn(f"{path}: {why}, renamed to {bad.name}; the run will be done again", RuntimeWarning, stacklevel=3)
    return bad


def _finished(path: Path, spec: RunSpec | None = None) -> bool:
    """Whether a run's result file exists, is valid and (with ``spec``) is a run of the same scene: a damaged one is
    set aside, and so is one of a scene file since edited (another mesh, another gap: its ``scene_hash`` differs),
    so the run is done again."""
    if not path.exists():
        return False
    try:
        run = read_run_file(path)
    except RunFileError:
        _set_aside(path)
        return False
    if spec is not None and spec.scene_hash is not None and run.get("scene_hash") != spec.scene_hash:
        _set_aside(path, "stale", f"a run of the scene file as it was before it changed (scene_hash "
                                  f"{run.get('scene_hash')}, now {spec.scene_hash})")
        return False
    return True


# ---------------------------------------------------------------------------------------------- aggregation
def _last_finite(v) -> float:
    v = np.asarray(v, dtype=float)
    ok = np.flatnonzero(np.isfinite(v))
    return float(v[ok[-1]]) if len(ok) else math.nan


def _at_travel(series: dict, key: str, distance: float) -> float:
    """The value of the first measured record at or after ``distance`` of travel (NaN where that estimate had no
    surface: a later step's value never stands in for it); the final record's if the run ended before. Run files
    without the ``estimate`` series: the first finite value, as they were read then."""
    t = np.asarray(series["travel"], dtype=float)
    v = np.asarray(series[key], dtype=float)
    est = series.get("estimate")
    if est:
        measured = ~np.isnan(np.asarray(est, dtype=float))
        ok = np.flatnonzero(measured & (t >= distance - 1e-12))
        return float(v[ok[0]] if len(ok) else v[-1])
    ok = np.flatnonzero(np.isfinite(v) & (t >= distance - 1e-12))
    if len(ok):
        return float(v[ok[0]])
    return _last_finite(v)


def _reference_travel(run: dict, runs_by_key: dict) -> float:
    """The travel budget of a budgeted run (the robot study); else the tactile run of the same object and seed (the
    paper's 2-D table), or the run's own travel."""
    if run.get("budget"):
        return float(run["budget"])
    tactile = runs_by_key.get((run["object"], "tactile", run["seed"]))
    return float((tactile or run)["travel"])


def failure(run: dict) -> str:
    """Why a run failed, or "" if it did not: "stalled" (the no-progress rule gave up), "approach: <why>" (no first
    contact: the approach missed the body or the robot refused it), "robot stop: <why>" (the
    safety layer or the contact controller stopped the robot before the run's own end), "lost contact", "step cap"
    (the step budget ran out before the travel budget) or "no estimate" (no estimated surface inside the range at
    the end). A failed run stays in every statistic (see :mod:`torch_gpioius.studies.stats`)."""
    t = run["terminated"]
    if t == "stalled":
        return "stalled"
    if t.startswith("refused: scene"):
        return "scene: " + t[len("refused: scene"):].lstrip(": ")[:60]
    if t.startswith("refused: approach"):
        return "approach: " + _short_reason(t[len("refused: approach"):].lstrip(": "))
    if t.startswith("refused"):
        return "robot stop: " + _short_reason(t[len("refused"):].lstrip(": "))
    if t == "lost-contact":
        return "lost contact"
    if t == "max_steps" and run.get("budget") and run["travel"] < 0.999 * run["budget"]:
        return "step cap"
    if not _has_final_estimate(run):
        return "no estimate"
    return ""


def _has_final_estimate(run: dict) -> bool:
    """Whether the run's final estimate has a surface to judge: its last record says so where it was recorded
    (runs since the ``estimate`` series); older run files: some Hausdorff distance was measured."""
    est = run["series"].get("estimate")
    if est:
        return not est[-1] == 0.0
    return math.isfinite(_last_finite(run["series"]["hausdorff"]))


def _final(run: dict, key: str) -> float:
    """A metric of the final estimate: the last record's value (always measured; NaN when the run ended with no
    estimate, never an earlier step's value). Older run files without the ``estimate`` series: the last measured
    value, as they were read then."""
    s = run["series"]
    if s.get("estimate"):
        return float(s[key][-1]) if _has_final_estimate(run) else math.nan
    return _last_finite(s[key])


def _short_reason(why: str) -> str:
    """A robot stop's message in a few words for a table cell."""
    low = why.lower()
    for key, label in (("did not follow", "arm stuck"), ("found no contact", "no contact"), ("overload", "overload"),
                       ("inverse kinematics", "IK refused"), ("ik ", "IK refused"), ("joint speed", "joint speed"),
                       ("joint limit", "joint limit"), ("workspace", "workspace"), ("force", "force limit"),
                       ("timeout", "sensor timeout"), ("stale", "sensor stale")):
        if key in low:
            return label
    return why[:40] or "refused"


def failures_text(reasons) -> str:
    """``"0"`` or ``"2: 1 stalled, 1 no estimate"`` from the runs' :func:`failure` reasons."""
    from collections import Counter

    counts = Counter(r for r in reasons if r)
    if not counts:
        return "0"
    return f"{sum(counts.values())}: " + ", ".join(f"{n} {why}" for why, n in sorted(counts.items()))


def _row(run: dict, runs_by_key: dict) -> dict:
    s = run["series"]
    ref = _reference_travel(run, runs_by_key)
    row = {"world": run["world"], "object": run["object"], "mode": run["mode"], "seed": run["seed"],
           "failed": failure(run),
           "final_hausdorff": _final(run, "hausdorff"),
           "final_hausdorff_touched": _final(run, "hausdorff_touched"),
           "final_uncertainty": _final(run, "uncertainty"),
           **{f"final_{k}": _final(run, k) if k in s else math.nan for k in SHAPE_METRICS},
           # no estimate: no estimated surface agrees with the truth at any distance
           **({f"final_{k}": 0.0 for k in SHAPE_METRICS if k.startswith("fscore")}
              if "fscore_5mm" in s and not _has_final_estimate(run) else {}),
           "final_correlation": _last_finite(s["correlation"]),
           "final_correlation_lo": _last_finite(s["correlation_lo"]),
           "final_correlation_hi": _last_finite(s["correlation_hi"]),
           "final_similarity": _last_finite(s["similarity"]),
           "travel": run["travel"], "steps": run["steps"], "terminated": run["terminated"], "taps": run["taps"],
           "recoveries": run["recoveries"], "reapproaches": run.get("reapproaches", 0),
           "reapproach_share": run.get("reapproach_travel", 0.0) / run["travel"] if run["travel"] > 0 else 0.0,
           "has_estimate": _has_final_estimate(run),
           "contacts_on_body": run["contacts_on_body"],
           "contacts_within": run["contacts_within"],
           "wall_time": run["wall_time"], "median_step_time": run["median_step_time"],
           # older run files have the median alone
           "p95_step_time": run.get("p95_step_time", math.nan), "max_step_time": run.get("max_step_time", math.nan),
           "reference_travel": ref,
           "voxel": run.get("voxel", math.nan), "n_outer": run.get("n_outer", math.nan),
           "touch_inside": run.get("touch_inside", 0.0), "vision_inside": run.get("vision_inside", 0.0),
           "vision_inside_gap": run.get("vision_inside_gap", 0.0),
           "n_vision_inside": run.get("n_vision_inside", math.nan),
           # the outer task's prior mean at the end (runs before 2026-11-27: the paper's 1; touch alone: NaN)
           "final_outer_mean": run.get("outer_mean", 1.0 if run["mode"] != "tactile" else math.nan),
           "max_truncation": run.get("max_truncation", 0.0), "max_fit_gap": run.get("max_fit_gap", math.nan),
           # what the run learned (older runs: K_t alone, length and noise not recorded)
           "learn": run.get("learn", "task"), "final_length": run.get("length", math.nan),
           "final_noise": run.get("noise", math.nan)}
    for f in FRACTIONS:
        p = int(round(100 * f))
        row[f"hausdorff_{p}"] = _at_travel(s, "hausdorff", f * ref)
        row[f"uncertainty_{p}"] = _at_travel(s, "uncertainty", f * ref)
        for k in ("chamfer", "fscore_5mm", "bias", "unseen"):
            row[f"{k}_{p}"] = _at_travel(s, k, f * ref) if k in s else math.nan
    return row


def aggregate(out: str | Path, specs: list[RunSpec] | None = None, smoke: bool = False, world: str | None = None,
              max_travel: float | None = None) -> dict:
    """Read the run files of ``out`` (those of ``specs``, or every finished run of ``world`` there: a folder
    accumulates runs, e.g. more modes or seeds later) and write runs.csv, summary.json/md and figures."""
    out = Path(out)
    paths = ([out / "runs" / f"{s.key}.json" for s in specs] if specs is not None
             else sorted((out / "runs").glob("*.json")))
    runs = [read_run_file(p) for p in paths if p.exists()]
    if world is not None:
        runs = [r for r in runs if r["world"] == world]
    if not runs:
        raise ValueError(f"{out}: no finished runs to aggregate")
    by_key = {(r["object"], r["mode"], r["seed"]): r for r in runs}
    rows = sorted((_row(r, by_key) for r in runs), key=lambda x: (x["object"], x["mode"], x["seed"]))
    fields = list(rows[0])
    with open(out / "runs.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    summary = _summarize(rows)
    claims = None if smoke else _claims(summary)
    (out / "summary.json").write_text(json.dumps({**summary, "claims": claims}, indent=1, allow_nan=True))
    (out / "summary.md").write_text(_markdown(rows[0]["world"], summary, claims, len(rows)))
    from .sweep_figures import figure_paired, figure_similarity_bands, figure_transition_bands

    for obj in sorted({r["object"] for r in runs}):
        figure_transition_bands(obj, [r for r in runs if r["object"] == obj], out / f"transitions_{obj}.png")
    figure_similarity_bands(runs, out / "similarity_bands.png")
    figure_paired(rows, out / "paired_final_hausdorff.png")
    if any(math.isfinite(r.get("final_chamfer", math.nan)) for r in rows):      # 3-D worlds and the 2-D one alike
        figure_paired(rows, out / "paired_final_chamfer.png", key="final_chamfer")
    return {"rows": rows, "summary": summary, "claims": claims}


METRICS = ["final_hausdorff", "final_hausdorff_touched", "final_uncertainty", "final_correlation",
           "final_similarity"] + [f"hausdorff_{int(round(100 * f))}" for f in FRACTIONS] + [
    "final_chamfer", "final_fscore_1mm", "final_fscore_5mm", "final_fscore_10mm", "final_fscore_20mm", "final_bias",
    "final_hausdorff_observed", "final_unseen", "chamfer_25", "fscore_5mm_25"]
#: Metrics where NaN means "the mode has no such value" (a tactile run has no correlation), not a failure; every
#: other metric is a distance or a variance, where NaN is "no estimate" and counts as the worst value.
NOT_APPLICABLE_METRICS = ("final_correlation", "final_similarity", "contacts_on_body", "contacts_within",
                          # a higher F-score is better (a run with no estimate has 0, set in its row), the bias is
                          # signed, the unseen share is not an error: NaN there is "not measured" (older runs)
                          "final_fscore_1mm", "final_fscore_5mm", "final_fscore_10mm", "final_fscore_20mm",
                          "final_bias", "final_unseen", "fscore_5mm_25")


def _policy(metric: str) -> str:
    return "drop" if metric in NOT_APPLICABLE_METRICS else "worst"


def _summarize(rows: list[dict]) -> dict:
    """``{object: {mode: {metric: median_interval, "n": runs}}}`` and paired VT - T differences per object."""
    out: dict = {"objects": {}, "paired": {}}
    objects = sorted({r["object"] for r in rows})
    modes = sorted({r["mode"] for r in rows})
    for obj in objects:
        out["objects"][obj] = {}
        for mode in modes:
            rs = [r for r in rows if r["object"] == obj and r["mode"] == mode]
            if not rs:
                continue
            entry = {m: median_interval([r[m] for r in rs], failed=_policy(m)) for m in METRICS}
            entry["n"] = len(rs)
            entry["failed"] = sum(bool(r["failed"]) for r in rs)
            entry["failures"] = failures_text(r["failed"] for r in rs)
            for m in ("taps", "travel", "recoveries", "reapproaches", "reapproach_share", "contacts_on_body",
                      "contacts_within"):
                entry[m] = median_interval([r[m] for r in rs], failed="drop")
            out["objects"][obj][mode] = entry
        tactile = {r["seed"]: r for r in rows if r["object"] == obj and r["mode"] == "tactile"}
        for mode in modes:
            if mode == "tactile":
                continue
            other = {r["seed"]: r for r in rows if r["object"] == obj and r["mode"] == mode}
            seeds = sorted(set(tactile) & set(other))
            if not seeds:
                continue
            out["paired"].setdefault(obj, {})[mode] = {
                m: paired_difference([other[s][m] for s in seeds], [tactile[s][m] for s in seeds], failed="worst")
                for m in ("final_hausdorff", "hausdorff_10", "hausdorff_25", "hausdorff_50")}
    return out


# ---------------------------------------------------------------------------------------------- claims
def _cm(v: float) -> str:
    return "n/a" if math.isnan(v) else ("inf" if math.isinf(v) else f"{100 * v:.1f}")


def no_harm_margin(t: dict) -> float:
    """The "no harm" margin [m] of a tactile-only :func:`~torch_gpioius.studies.stats.median_interval` ``t``: 10 % of
    its median, at least 0.5 cm (0.5 cm where tactile-only failed)."""
    return max(0.1 * t["median"], 0.005) if math.isfinite(t["median"]) else 0.005


def _no_harm(summary: dict, obj: str, mode: str = "visual-tactile") -> tuple[bool | None, str]:
    """"No harm": the upper end of the 95 % interval of the median paired difference VT - T of the final Hausdorff
    distance is at most max(10 % of the median tactile value, 0.5 cm)."""
    pair = summary["paired"].get(obj, {}).get(mode, {}).get("final_hausdorff")
    t = summary["objects"][obj].get("tactile", {}).get("final_hausdorff")
    if pair is None or t is None or pair["n"] == 0:
        return None, "no paired runs"
    allowed = no_harm_margin(t)
    return bool(pair["hi"] <= allowed), (f"median VT - T {_cm(pair['median'])} cm, 95 % interval [{_cm(pair['lo'])}, "
                                         f"{_cm(pair['hi'])}] cm (allowed {_cm(allowed)} cm), Wilcoxon p = "
                                         f"{pair['p_wilcoxon']:.3g}, n = {pair['n']}")


def _early_benefit(summary: dict, obj: str, key: str, mode: str = "visual-tactile") -> tuple[bool | None, str]:
    """"Accurate from the beginning": at the given point of travel the 95 % interval of the median paired
    difference VT - T lies below 0, and the median visual-tactile distance is at most half the tactile one."""
    pair = summary["paired"].get(obj, {}).get(mode, {}).get(key)
    vt = summary["objects"][obj].get(mode, {}).get(key)
    t = summary["objects"][obj].get("tactile", {}).get(key)
    if pair is None or vt is None or t is None:
        return None, "no paired runs"
    holds = pair["hi"] < 0 and vt["median"] <= 0.5 * t["median"]
    return bool(holds), (f"VT {_cm(vt['median'])} [{_cm(vt['lo'])}, {_cm(vt['hi'])}] cm vs T {_cm(t['median'])} "
                         f"[{_cm(t['lo'])}, {_cm(t['hi'])}] cm; paired VT - T {_cm(pair['median'])} "
                         f"[{_cm(pair['lo'])}, {_cm(pair['hi'])}] cm, p = {pair['p_wilcoxon']:.3g}")


#: The fewest seeds per object and mode on which a claim is judged: with n seeds the order-statistic interval of a
#: median covers at most 1 - 2^(1-n) (93.75 % at 5, 96.9 % at 6) and the smallest two-sided Wilcoxon p is 2^(1-n); a
#: study of 2 seeds judged "holds: yes" beside its own table's 50 % coverage and p = 0.5.
MIN_SEEDS_TO_JUDGE = 6


def _claims(summary: dict) -> list[dict]:
    """The paper's claims about the objects present (A-D: Sec. V; E-H: Sec. VI), each judged by a stated rule."""
    objs = summary["objects"]
    claims = []
    seeds = min((e["n"] for modes in objs.values() for e in modes.values()), default=0)
    too_few = seeds < MIN_SEEDS_TO_JUDGE

    def add(claim: str, rule: str, result: tuple[bool | None, str]) -> None:
        holds, measured = result
        if too_few:          # a 95 % interval needs 6 seeds: fewer cannot hold or fail a claim
            holds, measured = None, (f"too few seeds to judge ({seeds}; a 95 % interval of a median and a Wilcoxon "
                                     f"p below 0.05 need {MIN_SEEDS_TO_JUDGE}): {measured}")
        claims.append({"claim": claim, "rule": rule, "holds": holds, "measured": measured})

    rule_early = ("95 % interval of the median paired VT - T below 0 and median VT <= half median T")
    rule_harm = ("upper end of the 95 % interval of the median paired VT - T (final) <= max(10 % of median T, 0.5 cm)")
    # Sec. V, objects A-D
    if "A" in objs:
        add("A: visual-tactile close to the inner shape from the beginning (25 % of travel)", rule_early,
            _early_benefit(summary, "A", "hausdorff_25"))
    if "B" in objs:
        add("B: VT better early (10 % of travel)", rule_early, _early_benefit(summary, "B", "hausdorff_10"))
        add("B: about equal at the end", rule_harm + ", both ways",
            _equal(summary, "B"))
    if "D" in objs:
        add("D: both reach about the same final Hausdorff", rule_harm + ", both ways", _equal(summary, "D"))
    if "A" in objs and "D" in objs:
        a = objs["A"].get("visual-tactile", {}).get("final_correlation")
        d = objs["D"].get("visual-tactile", {}).get("final_correlation")
        if a and d:
            add("Final similarity A clearly above D (task correlation)", "95 % intervals of the medians disjoint, A "
                "above", (bool(a["lo"] > d["hi"]), f"A {a['median']:.2f} [{a['lo']:.2f}, {a['hi']:.2f}] vs D "
                          f"{d['median']:.2f} [{d['lo']:.2f}, {d['hi']:.2f}]"))
    # Sec. VI, objects E-H
    for obj in ("E", "G"):
        if obj in objs:
            add(f"{obj} (tight): visual-tactile accurate from the beginning (10 % of travel)", rule_early,
                _early_benefit(summary, obj, "hausdorff_10"))
    if "F" in objs and "visual-tactile" in objs["F"]:
        vt = objs["F"]["visual-tactile"]
        add("F (loose, arm recognisable): estimate first affected by the outer shape, then shrinks to the inner",
            "median VT Hausdorff at the end below its value at 10 % (intervals disjoint)",
            (bool(vt["final_hausdorff"]["hi"] < vt["hausdorff_10"]["lo"]),
             f"VT {_cm(vt['hausdorff_10']['median'])} cm at 10 % -> {_cm(vt['final_hausdorff']['median'])} "
             "cm at the end"))
    if "H" in objs:
        add("H (loose garment): no harm from vision", rule_harm, _no_harm(summary, "H"))
    corr = {o: objs[o]["visual-tactile"]["final_correlation"] for o in objs if "visual-tactile" in objs[o]}
    if "H" in corr and len(corr) > 1 and set(corr) <= set("EFGH"):
        others = [c["lo"] for o, c in corr.items() if o != "H"]
        add("Fig. 10: H has the lowest similarity (task correlation)",
            "H's median the lowest and the upper end of its 95 % interval below every other lower end",
            (bool(corr["H"]["hi"] < min(others)), ", ".join(f"{o} {c['median']:.2f} [{c['lo']:.2f}, {c['hi']:.2f}]"
                                                            for o, c in sorted(corr.items()))))
    for obj in sorted(objs):
        if obj != "H":                         # H has its own "no harm" claim above
            add(f"{obj}: no harm from vision", rule_harm, _no_harm(summary, obj))
    return claims


def _equal(summary: dict, obj: str) -> tuple[bool | None, str]:
    pair = summary["paired"].get(obj, {}).get("visual-tactile", {}).get("final_hausdorff")
    t = summary["objects"][obj].get("tactile", {}).get("final_hausdorff")
    if pair is None or t is None or pair["n"] == 0:
        return None, "no paired runs"
    allowed = no_harm_margin(t)
    return bool(-allowed <= pair["lo"] and pair["hi"] <= allowed), (
        f"paired VT - T {_cm(pair['median'])} [{_cm(pair['lo'])}, {_cm(pair['hi'])}] cm (allowed +-{_cm(allowed)} cm)")


def _markdown(world: str, summary: dict, claims: list[dict] | None, n_runs: int) -> str:
    lines = [f"{n_runs} runs ({world} world). Medians over seeds with distribution-free 95 % intervals "
             "(order statistics; the coverage is stated where fewer seeds make it lower). H: Hausdorff distance of the "
             "whole estimated zero set to the true inner surface, at 10 / 25 / 50 % of the reference travel and at "
             "the end; H touched: the touched estimate only; rho: task correlation; S: the paper's ratio. Failed "
             "runs (stalled, stopped by the robot, no estimate) stay in every statistic; a run with no estimate "
             "counts as inf, worse than any distance. On body: the median fraction of a run's contacts where the "
             "fingertip touched the body itself (not only the cover); '-' where the world cannot tell. Travel: the "
             "median travel [m]; re-approach: the median share of it spent re-approaching after lost contact. The "
             "field's metrics at the end: Chamfer, the mean surface-to-surface distance; F 5 mm, the "
             "F-score at 5 mm; bias, the median signed distance of the true surface from the estimate (negative: the "
             "estimate lies inside); unseen, the share of the true surface more than 2 cm from every observation.", "",
             "| object | mode | n (interval coverage) | failed (why) | H 10 % [cm] | H 25 % [cm] | H 50 % [cm] | "
             "H final [cm] | H touched final [cm] | U final | rho final | S final (paper) | on body | travel [m] | "
             "re-approach | Chamfer final [cm] | F 5 mm final | bias final [cm] | unseen final |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def cell(d: dict, scale: float = 100.0, fmt: str = ".1f") -> str:
        if d["n"] == 0:
            return "-"
        return f"{scale * d['median']:{fmt}} [{scale * d['lo']:{fmt}}, {scale * d['hi']:{fmt}}]"

    for obj, modes in sorted(summary["objects"].items()):
        for mode, e in sorted(modes.items()):
            cov = e["final_hausdorff"]["coverage"]
            on_body = e.get("contacts_on_body", {"n": 0})
            lines.append(f"| {obj} | {mode} | {e['n']} ({100 * cov:.0f} %) | {e['failures']} | "
                         f"{cell(e['hausdorff_10'])} | "
                         f"{cell(e['hausdorff_25'])} | "
                         f"{cell(e['hausdorff_50'])} | {cell(e['final_hausdorff'])} | "
                         f"{cell(e['final_hausdorff_touched'])} | {cell(e['final_uncertainty'], 1, '.3f')} | "
                         f"{cell(e['final_correlation'], 1, '.2f')} | {cell(e['final_similarity'], 1, '.2f')} | "
                         f"{cell(on_body, 1, '.2f')} | {cell(e.get('travel', {'n': 0}), 1, '.2f')} | "
                         f"{cell(e.get('reapproach_share', {'n': 0}), 100, '.0f')} % | "
                         f"{cell(e.get('final_chamfer', {'n': 0}))} | "
                         f"{cell(e.get('final_fscore_5mm', {'n': 0}), 1, '.2f')} | "
                         f"{cell(e.get('final_bias', {'n': 0}))} | {cell(e.get('final_unseen', {'n': 0}), 1, '.2f')} |")
    lines += ["", "Paired differences (same seed): mode - tactile, final Hausdorff [cm], with the Wilcoxon signed-rank "
              "p-value; a pair where one side has no estimate is a loss for it (inf).", "",
              "| object | mode | n | pairs with a failure | median [95 % interval] | wins / losses | p |",
              "|---|---|---|---|---|---|---|"]
    for obj, modes in sorted(summary["paired"].items()):
        for mode, d in sorted(modes.items()):
            p = d["final_hausdorff"]
            lines.append(f"| {obj} | {mode} | {p['n']} | {p['failed']} | {cell(p)} | {p['wins']} / {p['losses']} | "
                         f"{p['p_wilcoxon']:.3g} |")
    if claims is None:
        lines += ["", "Smoke sweep: the paper's claims are not judged on it."]
    else:
        lines += ["", "| claim | rule | measured | holds |", "|---|---|---|---|"]
        for c in claims:
            holds = "not judged" if c["holds"] is None else ("yes" if c["holds"] else "**no**")
            lines.append(f"| {c['claim']} | {c['rule']} | {c['measured']} | {holds} |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------- execution
def _ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


#: Most seeds a sweep accepts per object and mode (a study over more is a mistake, not a request).
MAX_SEEDS = 10_000


def run_sweep(world: str = "planar", objects=None, modes=("visual-tactile", "tactile"), seeds: int = 10,
              out: str | Path = "outputs/study", workers: int | None = None, address: str | None = None,
              max_travel: float | None = None, max_steps: int | None = None, smoke: bool = False,
              progress: bool = True, threads: int = 1, backend: str = "auto", force: bool = False,
              scenes=(), voxel: float | None = None, touch: str = "point", outer_tol: float | None = None,
              device: str | None = None, settings: str | None = None, learn: str | None = None,
              views=None, kernel=None, noise: float | None = None, cover: str | None = None) -> dict:
    """Run objects x modes x seeds and aggregate (see the module docstring for the outputs).

    The output folder belongs to one world's study: a new or empty folder, or one a study of the same world wrote
    (runs accumulate there; finished runs are skipped, damaged result files are set aside and their runs done
    again). While a sweep runs it holds a lock on the folder, so a second sweep into it is refused at once.

    Args:
        world: a registered world: "planar" (2-D), "forcefield" or "mujoco" (3-D), or one registered later (older
            names, "2d", "3d" and "penalty", are accepted with a warning).
        objects: names (default: the world's paper objects); repeated names count once. A name with a colon is an
            object set of :mod:`torch_gpioius.sim.objectsets` (``primitives:0-49``, ``pybullet-random:0-49``,
            ``pybullet:duck,teddy``, ``folder:PATH``): each of its objects, sized and standing on the table, is run
            in the force-field world under ``cover``.
        modes: among :data:`MODES`; repeated modes count once.
        seeds: seeds 0 .. seeds-1 per object and mode (at most :data:`MAX_SEEDS`).
        out: output folder.
        workers: parallel runs (default: the CPU count).
        address: join an existing Ray cluster instead of starting one.
        max_travel: travel budget per run in the 3-D worlds [m] (default 1.5).
        max_steps: cap on steps per run.
        smoke: tiny runs for CI; the claims are not judged.
        progress: report progress.
        threads: torch threads per run.
        backend: "auto" (Ray when installed), "ray" or "local" (sequential, in-process).
        force: write into a non-empty folder that is not this world's study folder.
        scenes: scene files (:mod:`torch_gpioius.sim.scenefile`) to run as objects too, named by their ``name``;
            with scenes and no ``objects``, only the scenes run. Only the 3-D worlds build scene files.
        voxel: edge of the camera's voxels [m] (0: every camera point; None: each world's own, 0.05 as the
            paper). A study folder holds one setting: compare settings across folders (docs/results-resolution.md).
        touch: "point" (the paper's fingertip contact) or "patch" (a gel pad's depth map at each contact; the
            force-field world has a pad); a study folder holds one.
        outer_tol: the visual-tactile runs with a truncated outer basis (``GPIOIS(outer_tol=...)``, an approximation
            for thousands of camera points; each record's ``truncation`` bounds its effect); None: exact. A study
            folder holds one setting.
        device: where each run's model computes ("cuda" for a GPU, float64; None: the CPU). Not part of the
            folder's identity: runs on either device answer the same question (the trajectories differ by the
            chaos of rounding, as on two CPUs); each run's record says where it ran.
        settings: the 3-D worlds' settings, "default" or "paper" (the paper's fixed camera and 5 cm voxels;
            ``Scene3D.with_settings``, ``MujocoScene.with_settings``), for scene files and built-in objects alike;
            None: each file's own, the paper's for the built-in objects. A study folder holds one setting.
        learn: "task" (K_t alone), "length" (the kernel's length too) or "all" (the length and sigma^2;
            ``explore(learn=)``); None: each world's own. A study folder holds one setting.
        views: the 3-D worlds' simulated camera views in place of the settings' (names from
            ``torch_gpioius.sim.forcefield.VIEWS``, a count or "paper": the fixed camera alone; ``with_views``);
            None: each world's own. A study folder holds one setting.
        kernel: a kernel's name ("imq", the paper's inverse multiquadric, "matern52", or a registered kind) or a
            :class:`~torch_gpioius.kernels.KernelChoice` (a name and a length scale [m]; where ``learn`` learns the
            length, where it starts); None: each world's own.
        noise: sigma^2 (where ``learn="all"`` learns it, where it starts); None: each world's own. ``kernel`` and
            ``noise`` too: one setting per folder.
        cover: the cover of the object sets' objects, "tight" (8 mm) or "wide" (4 cm); default tight; one per
            folder.

    Returns:
        ``{"runs", "skipped", "seconds", "backend", "rows", "summary", "claims"}``.

    Raises:
        ValueError: a bad argument (names it).
        FileExistsError: ``out`` holds something else and ``force`` is False.
        RuntimeError: another sweep is writing to ``out``.
    """
    sweep = SweepSettings.checked(
        world=world, objects=objects, modes=modes, seeds=seeds, out=out, workers=workers, address=address,
        max_travel=max_travel, max_steps=max_steps, smoke=smoke, progress=progress, threads=threads, backend=backend,
        force=force, scenes=scenes, voxel=voxel, touch=touch, outer_tol=outer_tol, device=device,
        settings=settings, learn=learn, views=views, kernel=kernel, noise=noise, cover=cover)
    return sweep.run()


def _kernel_choice(kernel):
    """A study's kernel setting as a :class:`~torch_gpioius.kernels.KernelChoice` (None: each world's own).

    Raises:
        ValueError: an unknown name or a bad length, or another type.
    """
    from ..kernels import KernelChoice

    if kernel is None:
        return None
    if isinstance(kernel, str):
        kernel = KernelChoice(kernel)
    if not isinstance(kernel, KernelChoice):
        raise ValueError(f"kernel: expected a kernel's name or a KernelChoice, got {type(kernel).__name__}")
    from ..tolerances import tol

    if kernel.lengthscale is not None:
        as_float(kernel.lengthscale, "lengthscale", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True,
                 unit="m")
    return kernel or None


@dataclass(frozen=True)
class SweepSettings:
    """Everything one sweep runs with, checked once (:meth:`checked`), then run in short steps (:meth:`run`): claim
    and lock the folder, plan the runs, execute those not yet done, aggregate. Fields as :func:`run_sweep`'s
    arguments; ``scene_files`` maps a scene's name to its file."""

    world: str
    objects: tuple
    modes: tuple
    seeds: int
    out: Path
    workers: int | None
    address: str | None
    max_travel: float | None
    max_steps: int | None
    smoke: bool
    progress: bool
    threads: int
    backend: str
    force: bool
    scene_files: dict
    voxel: float | None
    touch: str
    outer_tol: float | None
    device: str | None
    settings: str | None = None
    learn: str | None = None
    views: tuple | None = None
    kernel: Any = None                                  # a KernelChoice, or None
    noise: float | None = None
    scene_hashes: dict = field(default_factory=dict)    # a scene's name -> scenefile.scene_fingerprint
    set_objects: dict = field(default_factory=dict)     # an object set's object's name -> its SetObject
    cover: str | None = None                            # the set objects' cover

    @classmethod
    def checked(cls, *, world, objects, modes, seeds, out, workers, address, max_travel, max_steps, smoke, progress,
                threads, backend, force, scenes, voxel, touch, outer_tol, device, settings=None,
                learn=None, views=None, kernel=None, noise=None, cover=None) -> "SweepSettings":
        """The settings, each checked before anything runs (raises ValueError naming the argument)."""
        from ..exploration.registry import canonical_world_name, world_entry

        world = canonical_world_name(world, warn=True)
        if world not in _worlds():
            raise ValueError(f"world: must be one of {_worlds()}, got {world!r}")
        entry = world_entry(world)
        scene_files = _scene_files(scenes, world)
        set_objects, objects = _set_objects(objects, world, cover)
        objects = tuple(dict.fromkeys(objects or ([] if scene_files or set_objects else entry.object_names)))
        clash = sorted(set(objects) & (set(scene_files) | set(set_objects)))
        if clash:
            raise ValueError(f"scenes: {clash} are also the names of objects; rename the scene (its name key)")
        modes = _checked_modes(modes)
        workers = _checked_workers(workers, address)
        if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= MAX_SEEDS:
            raise ValueError(f"seeds: must be an integer in [1, {MAX_SEEDS}], got {seeds!r}")
        for name in objects:        # fail before starting anything
            if name not in entry.object_names:
                raise ValueError(f"objects: unknown {name!r} in the {world} world; choose among {entry.object_names}")
        if voxel is not None:
            from ..exploration.observations import check_voxel

            voxel = check_voxel(voxel)
            if getattr(entry.cls, "dim", 3) != 3:
                raise ValueError(f"voxel: the {world} world's camera view is sampled at its spacing, not "
                                 "voxel-averaged; --voxel applies to the 3-D worlds")
        if touch not in ("point", "patch"):
            raise ValueError(f"touch: must be 'point' or 'patch', got {touch!r}")
        if outer_tol is not None:
            outer_tol = as_float(outer_tol, "outer_tol", positive=True)
            if touch == "patch":
                raise ValueError("outer_tol: patch runs use the batched engine, which has no truncated outer basis")
        if device is not None:
            device = str(as_device(device))      # fails here, before any run, on a device this machine lacks
        if settings is not None:
            from ..sim.forcefield import SETTINGS

            if settings not in SETTINGS:
                raise ValueError(f"settings: must be one of {SETTINGS}, got {settings!r}")
            if world not in ("forcefield", "mujoco"):
                raise ValueError(f"settings: applies to the 3-D worlds (forcefield, mujoco: their scene files and "
                                 f"objects), not {world}")
        if learn is not None:
            from ..exploration.config import as_learn

            as_learn(learn)
            if any(m == "local" for m in modes):
                raise ValueError(f"learn: the local mode has a similarity per region; learn={learn!r} does not apply")
        if views is not None:
            from ..sim.forcefield import as_views

            views = as_views(views)
            if world not in ("forcefield", "mujoco"):
                raise ValueError(f"views: the simulated camera views are the 3-D worlds' (forcefield, mujoco), not "
                                 f"{world}'s")
        kernel = _kernel_choice(kernel)
        if noise is not None:
            from ..tolerances import tol

            noise = as_float(noise, "noise", lo=tol.noise_range[0], hi=tol.noise_range[1], positive=True)
        from ..sim.scenefile import scene_fingerprint

        hashes = {name: scene_fingerprint(path) for name, path in scene_files.items()}
        return cls(world, objects, modes, seeds, Path(out), workers, address, max_travel, max_steps, smoke, progress,
                   threads, backend, force, scene_files, voxel, touch, outer_tol, device, settings, learn, views,
                   kernel, noise, hashes, set_objects, (cover or "tight") if set_objects else None)

    def run(self) -> dict:
        """Claim and lock the folder, run what is not done yet, aggregate (see :func:`run_sweep`)."""
        from ..io.outputs import FolderLock

        out = self._claim()
        with FolderLock(out, "gpioius study"):
            running = self._prepare(out)
            specs = self._specs(out)
            todo = [s for s in specs if not _finished(out / "runs" / f"{s.key}.json", s)]
            skipped = len(specs) - len(todo)
            t0 = time.perf_counter()
            try:
                used = self._execute(self._built_first(todo))
            finally:
                if running.exists() and not any(running.iterdir()):
                    running.rmdir()
            seconds = time.perf_counter() - t0
            result = aggregate(out, None, self.smoke, world=self.world, max_travel=self.max_travel)
        result.update(runs=len(specs), skipped=skipped, seconds=seconds, backend=used)
        return result

    def _claim(self) -> Path:
        from ..io.outputs import claim_folder

        # every setting, None where it is the world's own: a folder of one setting refuses runs of another either
        # way (a key left out of the call would not be compared); older folders lack the newer keys, which reads as
        # None, the setting they ran with
        identity = {"outer_tol": self.outer_tol, "settings": self.settings, "learn": self.learn,
                    "views": None if self.views is None else "+".join(self.views), "noise": self.noise,
                    "cover": self.cover,
                    # a folder's kernel as the command line names it (the earlier folders' keys)
                    "kernel": self.kernel.name if self.kernel else None,
                    "theta": self.kernel.lengthscale if self.kernel else None}
        return claim_folder(self.out, "study", self.force, world=self.world, voxel=self.voxel,
                            touch=None if self.touch == "point" else self.touch, **identity)   # older: point runs

    @staticmethod
    def _prepare(out: Path) -> Path:
        """The folder's ``runs/`` and a ``running/`` without stale markers (the lock is held: nobody else runs)."""
        (out / "runs").mkdir(parents=True, exist_ok=True)
        running = out / "running"
        for stale in running.glob("*.pid") if running.exists() else []:
            stale.unlink(missing_ok=True)
        return running

    def _specs(self, out: Path) -> list[RunSpec]:
        # (name, scene file, identity, set object) of every object: a set's object is identified by its source,
        # size and cover, a scene file's by its content
        objects = [(o, None, None, None) for o in self.objects]
        objects += [(o, path, self.scene_hashes.get(o), None) for o, path in self.scene_files.items()]
        objects += [(o, None, f"set:{obj.source}:{obj.size!r}:{self.cover}", obj)
                    for o, obj in self.set_objects.items()]
        return [RunSpec(self.world, o, m, s, str(out), self.smoke, self.max_travel, self.max_steps, self.threads,
                        scene, self.voxel, self.touch, self.outer_tol, self.device, self.settings, self.learn,
                        self.views, self.kernel, self.noise, identity, obj, self.cover if obj is not None else None)
                for o, scene, identity, obj in objects for m in self.modes for s in range(self.seeds)]

    def _built_first(self, todo: list[RunSpec]) -> list[RunSpec]:
        """Build each scene file that has runs to do once, before the first run: a scene that cannot be built (a
        cover that does not close, a mesh that will not load) gets a failed row for each of its runs, with the cause,
        and the other runs go ahead (a 30-run study used to die at such a scene after 29 minutes of runs)."""
        broken: dict[str, BaseException] = {}
        for name in dict.fromkeys(s.object for s in todo if s.scene is not None):
            spec = next(s for s in todo if s.object == name)
            try:
                make_world(self.world, name, 0, self.smoke, spec.scene, self.settings, self.views)
            except (ValueError, RuntimeError, OSError) as exc:
                broken[name] = exc
        for spec in todo:
            if spec.object in broken:
                out = Path(spec.out) / "runs"
                out.mkdir(parents=True, exist_ok=True)
                _atomic_json(out / f"{spec.key}.json", scene_failure_record(spec, broken[spec.object]))
        if broken and self.progress:
            for name, exc in broken.items():
                print(f"study: scene {name!r} cannot be built, its runs are failed rows: {exc}", file=sys.stderr)
        return [s for s in todo if s.object not in broken]

    def _execute(self, todo: list[RunSpec]) -> str:
        """Run ``todo`` on Ray or in-process; returns how (for the report)."""
        from .._progress import progress as reporter

        use_ray = self.backend == "ray" or (self.backend == "auto" and _ray_available()
                                            and (len(todo) > 1 or self.address))
        bar = reporter(len(todo), f"study ({self.world})", self.progress)
        try:
            if todo and use_ray:
                try:
                    _run_on_ray(todo, self.workers, self.address, bar)
                    where = (f" at {self.address}" if self.address
                             else f" (local, {self.workers or os.cpu_count()} workers)")
                    return "Ray" + where
                except RayStartError as exc:
                    if self.address:               # a cluster the user named: its failure is theirs to see
                        raise ValueError(f"address: {exc}") from None
                    print(f"study: {exc}; running the runs in this process, one after another", file=sys.stderr,
                          flush=True)
                    todo = [s for s in todo if not _finished(Path(s.out) / "runs" / f"{s.key}.json", s)]
            for spec in todo:
                bar.set_postfix_str(spec.key)
                run_one(spec)
                bar.update(1)
            return "in-process (sequential)"
        finally:
            bar.close()


def _checked_workers(workers, address: str | None) -> int | None:
    """``workers`` as a positive integer, capped at this machine's cores for a local run (each worker is a process
    with its own runs; ``--workers 1000`` started one Ray process per run), with a warning that says so. On a
    cluster (``address``) the cluster's CPUs bound it instead."""
    if workers is None:
        return None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: must be a positive integer, got {workers!r}")
    cores = os.cpu_count() or 1
    if address is None and workers > cores:
        import warnings

        warnings.warn(f"workers: {workers} parallel runs on {cores} cores would only compete for them; running "
                      f"{cores} at a time (pass --address to run more on a Ray cluster)", UserWarning, stacklevel=3)
        return cores
    return workers


def _checked_modes(modes) -> tuple:
    modes = tuple(dict.fromkeys(modes))
    bad = [m for m in modes if m not in MODES]
    if bad:
        raise ValueError(f"modes: unknown {bad}; choose among {MODES}")
    if not modes:
        raise ValueError("modes: at least one mode is needed")
    return modes


def _set_objects(objects, world: str, cover) -> tuple[dict, list]:
    """``({name: SetObject}, the other names)``: the object sets among ``objects`` (names with a colon) expanded,
    checked before anything runs (force-field world only, a known cover).

    Raises:
        ValueError: a set in another world, a bad set name or range, an unknown cover, or a cover without a set.
    """
    from ..sim.objectsets import COVERS, object_set

    sets, plain = {}, []
    for name in objects or ():
        if isinstance(name, str) and ":" in name:
            if world != "forcefield":
                raise ValueError(f"objects: the object sets ({name!r}) are built in the forcefield world, not {world}")
            sets.update((o.name, o) for o in object_set(name))
        else:
            plain.append(name)
    if cover is not None and cover not in COVERS:
        raise ValueError(f"cover: must be one of {sorted(COVERS)}, got {cover!r}")
    if cover is not None and not sets:
        raise ValueError("cover: applies to the objects of an object set (e.g. --objects primitives:0-49)")
    return sets, plain


def _scene_files(scenes, world: str) -> dict[str, str]:
    """``{name: absolute path}`` of scene files, checked before anything runs (duplicate names refused)."""
    from ..sim.scenefile import SCENE_WORLDS, read_scene

    if isinstance(scenes, (str, Path)):
        scenes = [scenes]
    out: dict[str, str] = {}
    for path in scenes or ():
        if world not in SCENE_WORLDS:
            raise ValueError(f"scenes: the {world} world does not build scene files; use one of {SCENE_WORLDS}")
        spec = read_scene(path)
        if spec.name in out:
            raise ValueError(f"scenes: two scene files are named {spec.name!r} ({out[spec.name]}, {path})")
        out[spec.name] = str(Path(path).resolve())
    return out


class _DropMessage:
    """A logging filter that drops records whose message starts with ``prefix``."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix

    def filter(self, record) -> bool:
        return not record.getMessage().startswith(self.prefix)


def _quiet_ray_auth_banner() -> None:
    """Drop the notice a new local Ray cluster logs on every start ("Token authentication is enabled for this Ray
    cluster. Set RAY_AUTH_MODE=disabled to opt out ..."). Ray's behaviour is left as it is (token authentication
    stays on by default); only that one message is not printed. Setting ``RAY_AUTH_MODE`` instead would have to
    happen before Ray is imported, or its cached settings disagree with the cluster it starts."""
    import logging

    log = logging.getLogger("ray._private.authentication.authentication_token_setup")
    if not any(isinstance(f, _DropMessage) for f in log.filters):
        log.addFilter(_DropMessage("Token authentication is enabled for this Ray cluster"))


class RayStartError(RuntimeError):
    """Ray could not start (a memory limit, a node that timed out during startup): a local study runs in-process."""


def _run_on_ray(specs: list[RunSpec], workers: int | None, address: str | None, bar) -> None:
    import ray

    started_here = not ray.is_initialized()
    _quiet_ray_auth_banner()
    if started_here:
        kw = dict(include_dashboard=False, log_to_driver=False, configure_logging=False,
                  runtime_env={"env_vars": {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}})
        try:
            if address:
                ray.init(address=address, **kw)
            else:
                ray.init(num_cpus=workers or os.cpu_count(), **kw)
        except Exception as exc:         # Ray raises its own and plain exceptions alike ("node timed out ...")
            try:
                ray.shutdown()
            except Exception:            # pragma: no cover - nothing was started
                pass
            raise RayStartError(f"Ray could not start ({type(exc).__name__}: {' '.join(str(exc).split())[:160]})") \
                from None
    try:
        task = ray.remote(num_cpus=1, max_retries=3, retry_exceptions=False)(run_one)
        pending = {task.remote(s): s for s in specs}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                spec = pending.pop(ref)
                ray.get(ref)        # re-raises a run's own error (after Ray's retries of worker deaths)
                bar.set_postfix_str(spec.key)
                bar.update(1)
    finally:
        if started_here:
            ray.shutdown()

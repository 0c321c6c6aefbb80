"""A study's runs (:mod:`.sweep`): the modes, one run's specification (:class:`RunSpec`), the world and arguments it
explores with, running it (:func:`run_one`), and its result file (``DIR/runs/<object>_<mode>_<seed>.json``: written
atomically, read back checked by :func:`read_run_file`)."""

from __future__ import annotations

import json
import math
import dataclasses
import os
import time
from dataclasses import dataclass
from typing import Any
from pathlib import Path

import numpy as np

from ..geometry.metrics import SHAPE_METRICS

__all__ = ["BASE_MODES", "FRACTIONS", "CONTACT_WITHIN", "BUDGET_METRICS_EVERY", "sweep_modes", "RunSpec", "make_world",
           "run_one", "read_run_file", "RunFileError", "scene_failure_record", "atomic_json", "finished",
           "study_worlds", "asked_travel", "SMOKE_TRAVEL", "preset_digest"]


#: The modes of exploration a sweep runs: the paper's two and the local similarity (``regions``); each also with an
#: evidence policy that serves it, as ``MODE+POLICY`` (:data:`MODES`, from the policies' registry).
BASE_MODES = ("visual-tactile", "tactile", "local")
#: Fractions of the reference travel at which the Hausdorff distance is reported.
FRACTIONS = (0.10, 0.25, 0.50, 1.00)
#: A contact counts as "within" when it lies this close to the true body [m] (``contacts_within`` of a run).
CONTACT_WITHIN = 0.01
#: Metrics every k steps in worlds with a travel budget (the robot study's 150 steps; every step in 2-D).
BUDGET_METRICS_EVERY = 5
#: The travel of a smoke run in a world with a travel budget [m].
SMOKE_TRAVEL = 0.06


def sweep_modes() -> tuple:
    """Every mode a sweep can run: :data:`BASE_MODES`, then each with each registered evidence policy that serves it
    (``visual-tactile+taps``; a policy registered later adds its own)."""
    from ..exploration.policies import EVIDENCE_POLICIES

    return BASE_MODES + tuple(f"{m}+{p.name}" for p in EVIDENCE_POLICIES.entries() for m in BASE_MODES
                              if m in p.modes)


def __getattr__(name):
    # the world names, their objects and the modes come from the registries (a world or policy registered later is
    # a sweep's too)
    if name == "WORLDS":
        return study_worlds()
    if name == "DEFAULT_OBJECTS":
        from ..exploration.registry import world_entry

        return {w: world_entry(w).object_names for w in study_worlds()}
    if name == "MODES":
        return sweep_modes()
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
    touch: str = "point"            # "point" (the fingertip's contact) or "patch" (a gel pad's depth map)
    outer_tol: float | None = None  # visual-tactile with a truncated outer basis (GPIOIS(outer_tol=)); None: exact
    device: str | None = None       # where the model's arithmetic runs ("cuda"); None: the CPU
    settings: str | None = None     # 3-D worlds: "default" or "paper" (World.with_settings); None: the world's own
    views: tuple | None = None      # 3-D worlds: the camera's views (World.with_views); None: the world's own
    scene_hash: str | None = None   # the scene file's content (scenefile.scene_fingerprint): a run of an edited
    #                                 scene is another run, whatever its name
    set_object: Any = None          # an object of a set (sim.objectsets.SetObject) instead of a built-in object
    cover: str | None = None        # a set object's cover: a name of sim.objectsets.COVERS
    metrics_every: Any = None       # k steps or "schedule" (explore(metrics_every=)); None: every 5 steps under a
    #                                 travel budget, every step elsewhere
    camera_error: str | None = None  # the simulated cameras' extrinsic error ("6mm,1deg"; Scene3D.with_camera_error)
    camera_bound: str | None = None  # the captures corrected from the contacts within it, as asked (the record's)
    estimator: Any = None           # the changes to the world's estimator settings (EstimatorOverrides: the voxel,
    #                                 kernel, sigma^2, what is learned, the camera bound, any label); None: its own

    @property
    def key(self) -> str:
        return f"{self.object}_{self.mode}_{self.seed}"


def make_world(world: str, name: str, seed: int, smoke: bool = False, scene: str | None = None,
               settings: str | None = None, views=None, set_object=None, cover: str | None = None,
               camera_error: str | None = None):
    """The world of one run: the named object (or the scene file ``scene``), perturbed by ``seed`` (seed 0: the
    unperturbed object), under ``settings`` in place of its own (3-D worlds: "default" or "paper"), seen by
    ``views`` in place of the settings' (3-D worlds: ``with_views``) through cameras off by ``camera_error``
    (``with_camera_error``: "6mm,1deg", "2x,20%holes"); or an object of a set (:mod:`torch_gpioius.sim.objectsets`)
    under ``cover``, in the force-field world, the library's default settings unless told."""
    made = _make_world(world, name, seed, smoke, scene, settings, views, set_object, cover)
    if camera_error is None:
        return made
    if not hasattr(made, "with_camera_error"):
        raise ValueError(f"camera_error: the {world} world's cameras take no simulated camera error")
    erred = made.with_camera_error(camera_error)
    erred.scene_file = getattr(made, "scene_file", None)
    return erred


def _make_world(world: str, name: str, seed: int, smoke: bool, scene: str | None, settings: str | None, views,
                set_object, cover: str | None):
    """:func:`make_world` before the camera error."""
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
    mode, _, evidence = spec.mode.partition("+")
    kw: dict = {"evidence": evidence or None}
    if mode == "local":
        kw["mode"], kw["regions"] = "visual-tactile", 4
    else:
        kw["mode"] = mode
    budget = _world_budget(world)
    if budget is not None:
        kw["metrics_every"] = BUDGET_METRICS_EVERY
    if spec.metrics_every is not None:
        kw["metrics_every"] = spec.metrics_every
    # the travel asked for (a smoke run's 6 cm), whatever the measuring schedule: under --metrics-every alone this was
    # set, and `--max-travel 0.05` ran the world's own 1.5 m
    travel = asked_travel(spec)
    if travel is None and budget is not None:
        travel = SMOKE_TRAVEL if spec.smoke else budget
    if travel is not None:
        kw["max_travel"] = travel
    if spec.max_steps is not None:
        kw["max_steps"] = spec.max_steps
    elif spec.smoke:
        kw["max_steps"] = 12 if budget is None else 40
    if kw["mode"] == "visual-tactile":
        kw["interval_every"] = 1000 if spec.smoke else 10
    if spec.estimator:                   # every change to the world's estimator, resolved in one place
        kw["settings"] = spec.estimator.apply(world.defaults.estimator)
    if spec.touch != "point":
        kw["touch"] = spec.touch
    if spec.outer_tol is not None and kw["mode"] == "visual-tactile" and "regions" not in kw:
        kw["outer_tol"] = spec.outer_tol
    if spec.device is not None:
        kw["device"] = spec.device
    return kw


def atomic_json(path: Path, data: dict) -> None:
    from ..io.outputs import atomic_write

    atomic_write(path, json.dumps(data, allow_nan=True))


class RunFileError(ValueError):
    """A run's result file (``runs/<key>.json``) is unreadable or invalid; the message names the file and field."""


_SERIES = ("travel", "hausdorff", "hausdorff_touched", "uncertainty", "similarity", "correlation", "correlation_lo",
           "correlation_hi")


def _number(v, *, allow_nan: bool = True) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and (allow_nan or math.isfinite(v))


def study_worlds() -> tuple:
    """The simulated worlds: those a study runs."""
    from ..exploration.registry import world_names

    return tuple(world_names(simulated=True))


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
    if run["world"] not in study_worlds():
        raise bad("world", f"must be one of {study_worlds()}, got {run['world']!r}")
    if run["mode"] not in sweep_modes():
        raise bad("mode", f"must be one of {sweep_modes()}, got {run['mode']!r}")
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
    from ..core.registry import load_plugins

    load_plugins()                  # a Ray worker's process: the plugins' worlds, kernels and policies by name
    from ..session import explore
    from ..core.threads import torch_threads

    out = Path(spec.out)
    result_path = out / "runs" / f"{spec.key}.json"
    if finished(result_path, spec):
        return read_run_file(result_path)
    for sub in ("runs", "logs", "running"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    marker = out / "running" / f"{spec.key}.pid"
    marker.write_text(str(os.getpid()))
    t0 = time.perf_counter()
    with torch_threads(spec.threads):
        try:
            world = make_world(spec.world, spec.object, spec.seed, spec.smoke, spec.scene, spec.settings, spec.views,
                               spec.set_object, spec.cover, spec.camera_error)
            scene_time = time.perf_counter() - t0
        except (ValueError, RuntimeError, OSError) as exc:
            # a scene that cannot be built (a cover that does not close, a mesh that will not load) is a failed
            # row with its cause; the study goes on and writes its tables
            record = scene_failure_record(spec, exc, time.perf_counter() - t0)
            atomic_json(result_path, record)
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
        # where the run's time went [s]: building its scene, then the exploration's parts (PartClock)
        record["time"] = {"scene": scene_time, **trace.time_split}
        record["ruler"] = world.ruler
        if kw["mode"] == "visual-tactile" and "regions" not in kw and hasattr(world, "inner_quadrature"):
            t1 = time.perf_counter()
            record["baselines"] = run_baselines(world, trace, out / "logs" / f"{spec.key}.gpioius")
            record["time"]["baselines"] = time.perf_counter() - t1
            record["wall_time"] = time.perf_counter() - t0           # the run's whole time, its baselines too
        record["n_outer"] = _n_outer(trace.model)
        record["n_vision_inside"] = _n_outer(trace.model, inside=True)
        # the outer task's prior mean at the end (1: the paper's; 1 - gap / ramp once the touches set it)
        record["outer_mean"] = float(getattr(trace.model, "outer_mean", math.nan))
    estimator = kw.get("settings", world.defaults.estimator)
    policy = estimator.labels
    record["voxel"] = policy.voxel or 0.0
    # the inside points' depths [m] (0: the paper's labels only)
    record["touch_inside"], record["vision_inside"] = policy.touch_inside or 0.0, policy.vision_inside or 0.0
    record["vision_inside_gap"] = policy.vision_inside_gap or 0.0      # 0: the camera's inside points always kept
    record["touch"] = spec.touch
    if getattr(world, "views", None):                 # the camera's views (force-field world)
        record["views"] = "+".join(world.views)
    error = getattr(world, "camera_error", None)
    if error:                                         # the simulated camera error: what each view applied
        record["camera_error"] = {"asked": str(error), "views": world.camera_errors(),
                                  **({"sensing": error.as_record()} if error.sensing else {})}
    if spec.camera_bound is not None:
        record["camera_bound"] = spec.camera_bound
    if trace is not None and trace.camera_corrections is not None:   # what each view was moved by, and when
        record["camera_corrections"] = trace.camera_corrections
    if spec.settings is not None:
        record["settings"] = spec.settings
    preset = _asked_preset(spec, estimator)
    if preset is not None:           # the preset's content as run: a later release that changes it sets this run aside
        record["preset"] = {"name": preset, "digest": preset_digest(preset)}
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
    record["learn"] = estimator.learn
    if trace is not None:               # the estimator's settings the run used, as its log's header records them
        record["estimator"] = _logged_estimator(out / "logs" / f"{spec.key}.gpioius")
    record["kernel"] = estimator.kernel.kind
    if spec.estimator:                  # the changes asked for, beside the settings they made (``estimator``)
        record["overrides"] = spec.estimator.to_dict()
    if trace is not None and getattr(trace.model, "regions", None) and len(trace.region_correlation):
        # the local model's regions: the seen surface coloured by its correlation, and each region over the run
        from .figures import figure_regions

        record["region_correlation"] = np.asarray(trace.region_correlation)[-1].tolist()
        figure_regions(trace, out / "figures" / f"regions_{spec.key}.png",
                       f"{spec.world} {spec.object}, {spec.mode}, seed {spec.seed}")
    atomic_json(result_path, record)
    try:
        marker.unlink()
    except OSError:
        pass
    return record


def run_baselines(world, trace, log: Path) -> dict:
    """The simple baselines (:mod:`torch_gpioius.baselines`) of a visual-tactile run, scored by the converged ruler:
    from the camera's observations as its log's first record holds them (before any retraction of their inside
    points; and as the paper labels them, where the run smoothed them: ``trace.vision_plain``), the run's contacts in
    order and its kernel and sigma^2."""
    import torch

    from ..baselines import BASELINE_EDGE, BaselineData, score_baselines
    from ..io.datasets import replay
    from ..sim.ruler import METRICS_GRID

    first = None
    for _, ds in replay(log):
        first = ds
        if (ds.task == 1).any():
            break
    if first is None:
        return {}
    outer = first.task == 1
    model = trace.model
    # facets of 5 mm, as they are: a shrunk surface has no field of its own to correct its chords by
    data = BaselineData(first.x[outer], first.y[outer], np.asarray(trace.contacts, dtype=float), model.kernel,
                        float(model.noise), world.bounds(METRICS_GRID), METRICS_GRID, BASELINE_EDGE, world.range,
                        plain=trace.vision_plain)
    with torch.no_grad():
        surface = model.train_targets.cpu().numpy() == 0
    return score_baselines(world, data, model.train_inputs[0].detach().cpu().numpy()[surface])


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


def finished(path: Path, spec: RunSpec | None = None) -> bool:
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
    changed = _preset_changed(run) if spec is not None else None
    if changed is not None:
        _set_aside(path, "stale", changed)
        return False
    ruler = _current_ruler(spec.world) if spec is not None else None
    measured = any(_number(v) and math.isfinite(v) for v in run["series"].get("hausdorff", []))
    if ruler is not None and run.get("ruler") != ruler and measured:
        # measured by another ruler (the 2 cm marching cubes of earlier releases moved a Chamfer by -15 to +89 %):
        # its figures are not comparable with this folder's others
        _set_aside(path, "stale", f"measured by another ruler ({run.get('ruler') or 'marching cubes on a 2 cm grid'}"
                                  f"; now {ruler})")
        return False
    travel = asked_travel(spec) if spec is not None else None
    if travel is not None and not _same_travel(run.get("budget"), travel):
        # a run of another travel budget, or one of the releases that ran the world's own 1.5 m whatever was asked
        # (budget null): its figures answer another question
        _set_aside(path, "stale", f"a run of another travel budget ({run.get('budget')} m, asked {travel:g} m)")
        return False
    return True


def preset_digest(name: str) -> str:
    """A digest of the named estimator preset's settings as this release defines them (16 hex digits of the SHA-256
    of :meth:`~torch_gpioius.models.estimator.EstimatorSettings.to_dict`): a run record keeps it, so that a run made
    before a release changed the preset (the default's labels, its kernel) is done again, not mixed with runs of the
    new one."""
    import hashlib

    from ..models.estimator import PRESETS
    from ..models.labels import ObservationPolicy

    data = PRESETS[name]().to_dict()
    # the labels that differ from ObservationPolicy's own: a field a later release adds (off unless a preset sets
    # it) leaves the digest as it was
    plain = dataclasses.asdict(ObservationPolicy())
    data["labels"] = {k: v for k, v in data["labels"].items() if k not in plain or plain[k] != v}
    text = json.dumps(data, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _asked_preset(spec: RunSpec, estimator) -> str | None:
    """The preset a run's settings start from: the one asked for (``--settings``; a set object's "default"), else
    the name of the settings the run used where that is a preset (a world's or scene file's own), else None."""
    from ..models.estimator import PRESETS

    name = spec.settings or ("default" if spec.set_object is not None else None) or estimator.name
    return name if name in PRESETS else None


def _preset_changed(run: dict) -> str | None:
    """Why a run record's preset is not this release's (None: it is, or the record cannot tell): its digest differs
    (:func:`preset_digest`); for records written before the digest, the preset's on/off labels and ``cover_even``
    differ from the ones the record's settings hold, where nothing else could have set them (no ``--estimator``
    changes, no scene file)."""
    from ..models.estimator import PRESETS
    from ..models.labels import ObservationPolicy

    recorded = run.get("preset")
    if isinstance(recorded, dict) and recorded.get("name") in PRESETS:
        now = preset_digest(recorded["name"])
        if recorded.get("digest") != now:
            return (f"a run of the {recorded['name']!r} settings as an earlier release defined them (digest "
                    f"{recorded.get('digest')}, now {now})")
        return None
    estimator = run.get("estimator")
    scene_file = not str(run.get("scene_hash") or "set:").startswith("set:")    # (a set object's: no file)
    if (recorded is not None or run.get("overrides") or scene_file
            or not isinstance(estimator, dict) or not isinstance(estimator.get("labels"), dict)):
        return None
    name = run.get("settings") or estimator.get("name")        # (a preset's name only while nothing changed it)
    if name not in PRESETS:
        return None
    labels = PRESETS[name]().labels
    default = ObservationPolicy()
    keys = [f.name for f in dataclasses.fields(default) if isinstance(getattr(default, f.name), bool)] + ["cover_even"]
    was = {key: estimator["labels"].get(key, getattr(default, key)) for key in keys}    # (absent: the class's own)
    differ = [f"{key}: {was[key]!r}, now {getattr(labels, key)!r}" for key in keys if was[key] != getattr(labels, key)]
    if not differ:
        return None
    return f"a run of the {name!r} settings as an earlier release defined them ({'; '.join(differ)})"


def _current_ruler(world: str) -> str | None:
    """The ruler a world's runs are measured with now (:attr:`World.ruler` of its registered class), or None."""
    from ..exploration.registry import world_entry

    try:
        return getattr(world_entry(world).obj, "ruler", None)
    except (ValueError, ImportError):
        return None


def asked_travel(spec: RunSpec) -> float | None:
    """The travel budget [m] a run was asked for (``--max-travel``), or None: the world's own (a smoke run's 6 cm in a
    world with a budget)."""
    return None if spec.max_travel is None else float(spec.max_travel)


def _same_travel(recorded, asked: float) -> bool:
    return _number(recorded, allow_nan=False) and abs(float(recorded) - asked) <= 1e-9 * max(1.0, asked)

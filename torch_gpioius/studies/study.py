"""Studies as statistics: objects x modes x seeds (x worlds), one task per run, on Ray when installed.

``gpioius study --world planar|forcefield|mujoco --objects A,D --modes visual-tactile,tactile --seeds N --out DIR``
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

**Modules.** This one runs a study (:func:`run_sweep`: the folder's claim and lock, the runs on Ray or in-process);
:mod:`.study_plan` checks its arguments against the registries, :mod:`.study_runs` runs one (object, mode, seed)
and reads and writes its result file, :mod:`.study_aggregate` turns the result files into ``runs.csv``, the summary,
the claims and ``summary.md``, and :mod:`.study_figures` draws them. Their public names are importable from here.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path


from .study_aggregate import (METRICS, MIN_SEEDS_TO_JUDGE, NOT_APPLICABLE_METRICS, aggregate, failure,  # noqa: F401
                              failures_text, no_harm_margin)
from .study_runs import (BASE_MODES, CONTACT_WITHIN, FRACTIONS, RunFileError, RunSpec, atomic_json,  # noqa: F401
                         finished, make_world, read_run_file, run_one, scene_failure_record, sweep_modes)
from .study_plan import with_loose, MAX_SEEDS, StudyPlan  # noqa: F401
from . import study_plan, study_runs


def __getattr__(name):
    # WORLDS, DEFAULT_OBJECTS and MODES from the registries (study_runs), SweepSettings (0.2's StudyPlan) from the plan
    return study_plan.__getattr__(name) if name == "SweepSettings" else study_runs.__getattr__(name)


__all__ = ["run_sweep", "StudyPlan", "RunSpec", "run_one", "aggregate", "read_run_file", "RunFileError",  # noqa
           "MODES", "WORLDS", "FRACTIONS", "MAX_SEEDS", "BASE_MODES", "sweep_modes"]  # noqa: F822

# ---------------------------------------------------------------------------------------------- execution
def _ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def run_sweep(world: str = "planar", objects=None, modes=("visual-tactile", "tactile"), seeds: int = 10,
              out: str | Path = "outputs/study", workers: int | None = None, address: str | None = None,
              max_travel: float | None = None, max_steps: int | None = None, smoke: bool = False,
              progress: bool = True, threads: int = 1, backend: str = "auto", force: bool = False,
              scenes=(), touch: str = "point", outer_tol: float | None = None, device: str | None = None,
              settings: str | None = None, views=None, cover: str | None = None, metrics_every=None,
              camera_error=None, camera_bound=None, estimator=None, **deprecated) -> dict:
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
        views: the 3-D worlds' simulated camera views in place of the settings' (names from
            ``torch_gpioius.sim.forcefield.VIEWS``, a count or "paper": the fixed camera alone; ``with_views``);
            None: each world's own. A study folder holds one setting.
        cover: the cover of the object sets' objects (:data:`~torch_gpioius.sim.objectsets.COVERS`): "tight"
            (8 mm), "wide" (4 cm), "uneven" (5 mm to 5 cm) or "hanging" (to the table); default tight; one per
            folder.
        metrics_every: the estimate measured every k steps, or "schedule": at 10, 25 and 50 % of the travel, a stop
            and the end only (worlds with a travel budget; the fractions the summary reports, at a fraction of the
            cost: docs/performance.md); None: every 5 steps under a travel budget, every step elsewhere. One per
            folder.
        camera_error: the simulated cameras' errors, a :class:`~torch_gpioius.sensors.simulated.CameraError` or its
            text ("6mm,1deg"; "2x,20%holes"): each view of each run draws a rigid error of the extrinsic sizes from
            its seed, its depth noise scaled and pixels lost as the sensing terms say, and the run's record says
            what it applied (``camera_error``); None: none. The 3-D worlds; one per folder.
        camera_bound: the visual-tactile runs correct each view's capture from their contacts within this bound (a
            :class:`~torch_gpioius.sensors.simulated.CameraError` or its text, "12mm,2deg";
            ``ObservationPolicy.camera_bound``; each record's ``camera_corrections`` says what each view was moved by);
            None: the captures as the calibration places them. One per folder.
        estimator: changes to each world's estimator settings: an
            :class:`~torch_gpioius.models.overrides.EstimatorOverrides`, its plain dict (``{"voxel": 0.01,
            "labels": {"ray_smoothing": None}}``) or ``KEY=VALUE`` texts (the command line's ``--estimator``): the
            camera's voxel [m] (0: every point; compare settings across folders, docs/results-resolution.md), the
            kernel (a name or a :class:`~torch_gpioius.kernels.KernelChoice`; where ``learn`` learns the length,
            where it starts), sigma^2, what is learned, any label. The runs and the folder record them (the voxel,
            kernel, sigma^2 and ``learn`` among the folder's identity keys, as before). None: each world's own. One
            per folder.
        **deprecated: ``voxel``, ``learn``, ``kernel`` and ``noise`` of earlier releases, for one release: give
            ``estimator=EstimatorOverrides(voxel=..., ...)``.

    Why this many parameters: a study's plan is many independent choices (what runs, where, how it is measured);
    the estimator's settings, the part that grows, are one object (``estimator``). :class:`StudyPlan` holds them.

    Returns:
        ``{"runs", "skipped", "seconds", "backend", "rows", "summary", "claims"}``.

    Raises:
        ValueError: a bad argument (names it).
        FileExistsError: ``out`` holds something else and ``force`` is False.
        RuntimeError: another sweep is writing to ``out``.
        TypeError: a keyword it does not take.
    """
    from ..models.overrides import loose_keywords, warn_loose

    loose = {k: v for k, v in loose_keywords("run_sweep", deprecated, ("voxel", "learn", "kernel", "noise")).items()
             if v is not None}
    warn_loose("run_sweep", 2, **loose)
    sweep = StudyPlan.checked(
        world=world, objects=objects, modes=modes, seeds=seeds, out=out, workers=workers, address=address,
        max_travel=max_travel, max_steps=max_steps, smoke=smoke, progress=progress, threads=threads, backend=backend,
        force=force, scenes=scenes, touch=touch, outer_tol=outer_tol, device=device, settings=settings, views=views,
        cover=cover, metrics_every=metrics_every, camera_error=camera_error, camera_bound=camera_bound,
        estimator=with_loose(estimator, loose))
    return _run(sweep)


def _run(sweep: StudyPlan) -> dict:
    """Claim and lock the folder, run what is not done yet, aggregate (see :func:`run_sweep`)."""
    from ..io.outputs import FolderLock

    out = _claim(sweep)
    with FolderLock(out, "gpioius study"):
        running = _prepare(out)
        specs = sweep._specs(out)
        todo = [s for s in specs if not finished(out / "runs" / f"{s.key}.json", s)]
        skipped = len(specs) - len(todo)
        t0 = time.perf_counter()
        try:
            used = _execute(sweep, _built_first(sweep, todo))
        finally:
            if running.exists() and not any(running.iterdir()):
                running.rmdir()
        seconds = time.perf_counter() - t0
        result = aggregate(out, None, sweep.smoke, world=sweep.world, max_travel=sweep.max_travel)
    result.update(runs=len(specs), skipped=skipped, seconds=seconds, backend=used)
    return result


def _claim(sweep: StudyPlan) -> Path:
    from ..io.outputs import claim_folder

    # every setting, None where it is the world's own: a folder of one setting refuses runs of another either
    # way (a key left out of the call would not be compared); older folders lack the newer keys, which reads as
    # None, the setting they ran with
    identity = {"outer_tol": sweep.outer_tol, "settings": sweep.settings, "learn": sweep.learn,
                "views": None if sweep.views is None else "+".join(sweep.views), "noise": sweep.noise,
                "cover": sweep.cover, "metrics_every": sweep.metrics_every, "camera_error": sweep.camera_error,
                "camera_bound": sweep.camera_bound,
                # a folder's kernel as the command line names it (the earlier folders' keys)
                "kernel": sweep.kernel.name if sweep.kernel else None,
                "theta": sweep.kernel.lengthscale if sweep.kernel else None,
                # the other changes to the estimator (--estimator), as their plain dict; older folders: none
                "estimator": sweep.estimator.to_dict() if sweep.estimator else None}
    return claim_folder(sweep.out, "study", sweep.force, world=sweep.world, voxel=sweep.voxel,
                        touch=None if sweep.touch == "point" else sweep.touch, **identity)   # older: point runs


def _prepare(out: Path) -> Path:
    """The folder's ``runs/`` and a ``running/`` without stale markers (the lock is held: nobody else runs)."""
    (out / "runs").mkdir(parents=True, exist_ok=True)
    running = out / "running"
    for stale in running.glob("*.pid") if running.exists() else []:
        stale.unlink(missing_ok=True)
    return running


def _built_first(sweep: StudyPlan, todo: list[RunSpec]) -> list[RunSpec]:
    """Build each scene file that has runs to do once, before the first run: a scene that cannot be built (a
    cover that does not close, a mesh that will not load) gets a failed row for each of its runs, with the cause,
    and the other runs go ahead (a 30-run study used to die at such a scene after 29 minutes of runs)."""
    broken: dict[str, BaseException] = {}
    for name in dict.fromkeys(s.object for s in todo if s.scene is not None):
        spec = next(s for s in todo if s.object == name)
        try:
            make_world(sweep.world, name, 0, sweep.smoke, spec.scene, sweep.settings, sweep.views)
        except (ValueError, RuntimeError, OSError) as exc:
            broken[name] = exc
    for spec in todo:
        if spec.object in broken:
            out = Path(spec.out) / "runs"
            out.mkdir(parents=True, exist_ok=True)
            atomic_json(out / f"{spec.key}.json", scene_failure_record(spec, broken[spec.object]))
    if broken and sweep.progress:
        for name, exc in broken.items():
            print(f"study: scene {name!r} cannot be built, its runs are failed rows: {exc}", file=sys.stderr)
    return [s for s in todo if s.object not in broken]


def _execute(sweep: StudyPlan, todo: list[RunSpec]) -> str:
    """Run ``todo`` on Ray or in-process; returns how (for the report)."""
    from ..core.progress import progress as reporter

    use_ray = sweep.backend == "ray" or (sweep.backend == "auto" and _ray_available()
                                        and (len(todo) > 1 or sweep.address))
    bar = reporter(len(todo), f"study ({sweep.world})", sweep.progress)
    try:
        if todo and use_ray:
            try:
                _run_on_ray(todo, sweep.workers, sweep.address, bar)
                where = (f" at {sweep.address}" if sweep.address
                         else f" (local, {sweep.workers or os.cpu_count()} workers)")
                return "Ray" + where
            except RayStartError as exc:
                if sweep.address:               # a cluster the user named: its failure is theirs to see
                    raise ValueError(f"address: {exc}") from None
                print(f"study: {exc}; running the runs in this process, one after another", file=sys.stderr,
                      flush=True)
                todo = [s for s in todo if not finished(Path(s.out) / "runs" / f"{s.key}.json", s)]
        for spec in todo:
            bar.set_postfix_str(spec.key)
            run_one(spec)
            bar.update(1)
        return "in-process (sequential)"
    finally:
        bar.close()


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

    from ._reaper import RayReaper

    if ray.is_initialized():
        return _run_tasks(specs, bar, started_here=False)
    # a study killed with SIGKILL cannot shut Ray down: its watcher ends the processes Ray left (its agents)
    with RayReaper():
        _run_tasks(specs, bar, started_here=True, workers=workers, address=address)


def _run_tasks(specs: list[RunSpec], bar, *, started_here: bool, workers: int | None = None,
               address: str | None = None) -> None:
    """The runs as Ray tasks, on a Ray started here (and shut down at the end) or on the one already running."""
    import ray

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

"""A study's settings (:mod:`.sweep`): every argument of ``gpioius study`` checked against the registries before
anything runs (:class:`StudyPlan`)."""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import Any
from pathlib import Path

from ..core.moved import renamed
from ..core.validation import as_device, as_float, as_noise
from ..kernels import KernelChoice
from .study_runs import RunSpec, study_worlds, sweep_modes

__all__ = ["StudyPlan", "MAX_SEEDS", "checked_metrics_every"]


__getattr__ = renamed(__name__, {"SweepSettings": (__name__, "StudyPlan", "settings are the estimator's")})

#: Most seeds a sweep accepts per object and mode (a study over more is a mistake, not a request).
MAX_SEEDS = 10_000

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
    from ..core.tolerances import tol

    if kernel.lengthscale is not None:
        as_float(kernel.lengthscale, "lengthscale", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True,
                 unit="m")
    return kernel or None


@dataclass(frozen=True)
class StudyPlan:
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
    metrics_every: Any = None                           # k steps or "schedule"; None: the sweep's own
    camera_error: str | None = None                     # the simulated cameras' extrinsic error ("6mm,1deg")
    camera_bound: str | None = None                     # the captures corrected within it ("12mm,2deg")
    estimator: Any = None                               # the other changes (EstimatorOverrides), or None

    @property
    def overrides(self):
        """Every change this study makes to each world's estimator settings, as one
        :class:`~torch_gpioius.models.overrides.EstimatorOverrides` (the voxel, kernel, sigma^2, what is learned, the
        camera bound, then ``estimator``'s other changes), or None for none."""
        from ..models.overrides import EstimatorOverrides
        from ..sensors.simulated.camera import CameraError

        labels = {}
        if self.camera_bound is not None:
            bound = CameraError.parse(self.camera_bound)
            labels["camera_bound"] = (bound.translation, bound.rotation)
        own = EstimatorOverrides(kernel=self.kernel, noise=self.noise, voxel=self.voxel, learn=self.learn,
                                 labels=labels)
        merged = own.merged(self.estimator) if self.estimator else own
        return merged or None

    @classmethod
    def checked(cls, *, world, objects, modes, seeds, out, workers, address, max_travel, max_steps, smoke, progress,
                threads, backend, force, scenes, touch, outer_tol, device, settings=None, views=None, cover=None,
                metrics_every=None, camera_error=None, camera_bound=None, estimator=None) -> "StudyPlan":
        """The settings, each checked before anything runs (raises ValueError naming the argument): those of
        :func:`~torch_gpioius.studies.study.run_sweep`, whose parameters these are (the estimator's voxel, kernel,
        sigma^2 and ``learn`` read from ``estimator`` into the plan's fields, the folder's identity keys). Why this
        many parameters: run_sweep's, one each, checked together."""
        from ..exploration.registry import canonical_world_name, world_entry, world_names

        world = canonical_world_name(world, warn=True)
        if world not in study_worlds():
            raise ValueError(f"world: must be one of {study_worlds()}, got {world!r}")
        entry = world_entry(world)
        # the estimator's changes: those that are the folder's identity keys since before the resolver (the plan's
        # own fields) taken out of ``estimator``, the rest kept there
        estimator, loose = _overrides(estimator), {"voxel": None, "learn": None, "noise": None, "kernel": None}
        if estimator is not None:
            for key in loose:
                value = getattr(estimator, key)
                if value is None or (key == "kernel" and not isinstance(value, KernelChoice)):
                    continue
                loose[key] = value
            estimator = dataclasses.replace(estimator, voxel=None, learn=None, noise=None, kernel=(
                estimator.kernel if not isinstance(estimator.kernel, KernelChoice) else None)) or None
        voxel, learn, noise, kernel = loose["voxel"], loose["learn"], loose["noise"], loose["kernel"]
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
            if entry.dimension != 3:
                raise ValueError(f"voxel: the {world} world's camera view is sampled at its spacing, not "
                                 "voxel-averaged; --voxel applies to the 3-D worlds")
        from ..exploration.touch import TOUCH_MODELS

        if touch not in TOUCH_MODELS:
            raise ValueError(f"touch: must be one of {TOUCH_MODELS.choices()}, got {touch!r}")
        touch = TOUCH_MODELS.resolve(touch)
        if outer_tol is not None:
            outer_tol = as_float(outer_tol, "outer_tol", positive=True)
            if touch == "patch":
                raise ValueError("outer_tol: patch runs use the batched engine, which has no truncated outer basis")
        if device is not None:
            device = str(as_device(device))      # fails here, before any run, on a device this machine lacks
        if settings is not None:
            from ..sim.presets import SETTINGS

            if settings not in SETTINGS:
                raise ValueError(f"settings: must be one of {SETTINGS}, got {settings!r}")
            if not entry.presets:
                raise ValueError(f"settings: applies to the worlds that take presets ("
                                 f"{', '.join(world_names(presets=True))}: their scene files and objects), not {world}")
        if learn is not None:
            from ..exploration.config import as_learn

            as_learn(learn)
            if any(m == "local" for m in modes):
                raise ValueError(f"learn: the local mode has a similarity per region; learn={learn!r} does not apply")
        if views is not None:
            from ..sim.presets import as_views

            views = as_views(views)
            if not entry.presets:
                raise ValueError(f"views: the simulated camera views are those of "
                                 f"{', '.join(world_names(presets=True))}, not {world}'s")
        kernel = _kernel_choice(kernel)
        metrics_every = checked_metrics_every(metrics_every)
        if camera_error is not None:
            from ..sensors.simulated.camera import CameraError

            error = CameraError.parse(camera_error)
            if not hasattr(entry.cls, "with_camera_error"):
                raise ValueError(f"camera_error: the {world} world's cameras take no simulated camera error")
            camera_error = str(error) if error else None
        if camera_bound is not None:
            from ..sensors.simulated.camera import CameraError

            bound = CameraError.parse(camera_bound).check_bound()
            if not entry.presets or entry.dimension != 3:
                raise ValueError(f"camera_bound: corrects the captures of the 3-D worlds' cameras, not {world}'s")
            camera_bound = str(bound)
        if noise is not None:
            noise = as_noise(noise)
        from ..sim.scenefile import scene_fingerprint

        hashes = {name: scene_fingerprint(path) for name, path in scene_files.items()}
        return cls(world, objects, modes, seeds, Path(out), workers, address, max_travel, max_steps, smoke, progress,
                   threads, backend, force, scene_files, voxel, touch, outer_tol, device, settings, learn, views,
                   kernel, noise, hashes, set_objects, (cover or "tight") if set_objects else None, metrics_every,
                   camera_error, camera_bound, estimator)

    def _specs(self, out: Path) -> list[RunSpec]:
        # (name, scene file, identity, set object) of every object: a set's object is identified by its source,
        # size and cover, a scene file's by its content
        objects = [(o, None, None, None) for o in self.objects]
        objects += [(o, path, self.scene_hashes.get(o), None) for o, path in self.scene_files.items()]
        objects += [(o, None, f"set:{obj.source}:{obj.size!r}:{self.cover}", obj)
                    for o, obj in self.set_objects.items()]
        estimator = self.overrides
        return [RunSpec(self.world, o, m, s, str(out), self.smoke, self.max_travel, self.max_steps, self.threads,
                        scene, touch=self.touch, outer_tol=self.outer_tol, device=self.device,
                        settings=self.settings, views=self.views, scene_hash=identity, set_object=obj,
                        cover=self.cover if obj is not None else None, metrics_every=self.metrics_every,
                        camera_error=self.camera_error, camera_bound=self.camera_bound, estimator=estimator)
                for o, scene, identity, obj in objects for m in self.modes for s in range(self.seeds)]


def with_loose(estimator, loose: dict):
    """A study's ``estimator`` (:func:`_overrides`' forms) with the deprecated loose ``voxel``, ``learn``, ``kernel``
    and ``noise`` of :func:`~torch_gpioius.studies.study.run_sweep` (``loose``: those given) on top, as one
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides`; ``estimator`` itself when none is given.

    Raises:
        ValueError: a setting given both ways, or a bad value (named).
    """
    if not loose:
        return estimator
    from ..models.overrides import EstimatorOverrides

    given = _overrides(estimator) or EstimatorOverrides()
    for key in loose:
        if getattr(given, key) is not None:
            raise ValueError(f"estimator: {key} given beside the {key} argument; give it once")
    return given.merged(EstimatorOverrides(**loose))


def _overrides(estimator):
    """A study's changes to the estimator as an :class:`~torch_gpioius.models.overrides.EstimatorOverrides` (None
    for none): one, its plain dict or ``KEY=VALUE`` texts (:func:`~torch_gpioius.models.overrides.resolved_changes`).

    Raises:
        ValueError: anything else, or a bad key or value (named).
    """
    from ..models.overrides import resolved_changes

    return resolved_changes(estimator) or None


def checked_metrics_every(value):
    """``metrics_every`` of a study: None (the sweep's own), a number of steps >= 1, or "schedule" (10, 25 and 50 %
    of the travel, a stop and the end: the runs' cost set by the method, docs/performance.md)."""
    if value is None or (isinstance(value, str) and value == "schedule"):
        return value
    if isinstance(value, str) and value.isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"metrics_every: must be a number of steps >= 1 or 'schedule', got {value!r}")
    return value


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
    bad = [m for m in modes if m not in sweep_modes()]
    if bad:
        raise ValueError(f"modes: unknown {bad}; choose among {sweep_modes()}")
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
    from ..sim.scenefile import read_scene, scene_worlds

    if isinstance(scenes, (str, Path)):
        scenes = [scenes]
    out: dict[str, str] = {}
    for path in scenes or ():
        if world not in scene_worlds():
            raise ValueError(f"scenes: the {world} world does not build scene files; use one of {scene_worlds()}")
        spec = read_scene(path)
        if spec.name in out:
            raise ValueError(f"scenes: two scene files are named {spec.name!r} ({out[spec.name]}, {path})")
        out[spec.name] = str(Path(path).resolve())
    return out

"""Scene files: a user's object, its cover, the approach and the exploration range in one TOML file, buildable in
every world registered with a :class:`~torch_gpioius.exploration.registry.SceneSupport` (``forcefield``, ``mujoco``,
and a world registered from outside the package), for ``gpioius simulate3d --scene`` and ``gpioius study --scenes``.

A scene file, every length in metres in the UR5's base frame (z up)::

    name = "bottle"                   # default: the file's stem
    world = "forcefield"              # the world simulate3d uses (a study's --world overrides it)

    [object]
    mesh = "bottle.stl"               # relative to this file; "pybullet:duck.obj" is a mesh of pybullet's data
    scale = 0.001                     # to metres (this file is in millimetres)
    pose = { rpy_deg = [90, 0, 0] }   # or { quat = [w, x, y, z] }, and position = [x, y, z]
    at = [0.5, 0.0, 0.1]              # where the bottom centre of its bounding box goes
    repair = true                     # close holes (with a warning stating the change) or refuse

    [cover]
    kind = "tight"                    # "tight", "loose"; "uneven", "hanging" (force field); "foam" (MuJoCo)
    gap = 0.008                       # tight: the cover's distance from the body

    [approach]                        # optional: by default straight down onto the middle of the top
    start = [0.5, 0.0, 0.4]
    direction = [0, 0, -1]

    [range]                           # optional: by default the cover's box from a quarter of the height up
    min = [0.4, -0.1, 0.12]
    max = [0.6, 0.1, 0.35]

    [forcefield]                      # optional: settings and cover options of one world
    cover_stiffness = 5.0             # (Scene3D.from_mesh, cover_around)
    bridge = 0.03                     # a loose (or hanging) cover's bridging radius
    gap_far = 0.05                    # an uneven cover's gap on its thick side (gap: on its thin side)
    thick_side = [0, 1, 0]            # and that side's horizontal direction
    settings = "default"              # or "paper": one fixed camera, 5 cm voxels, the inverse multiquadric
    views = ["fixed", "mirrored", "wrist"]   # the simulated camera's views (or a count, or "paper")
    kernel = "matern52"               # or "imq"; lengthscale (theta): its length [m]; noise: sigma^2; voxel [m]
    lengthscale = 0.1                 # (default: a fifth of the body, 4-10 cm; a length given fixes it)
    noise = 0.08
    voxel = 0.02
    touch_inside = 0.02               # an inside point this deep behind each contact [m] (0: none)
    vision_inside = 0.01              # and behind each seen point [m] (0: none)
    vision_inside_gap = 0.03          # the camera's retracted once touches show the cover this far off [m] (0: never)
    cover_offset = false              # true: the outer task's prior mean then stands for the gap they measure
    learn = "task"                    # "length": the kernel's length learned with K_t; "all": the noise too
    camera_error = "6mm,1deg"         # the simulated cameras' calibration error (each view its own draw; "0": none);
                                      # and worse sensing: "2x" depth noise, "20%" pixels, "20%holes" blocks lost
    [estimator]                       # optional: the estimator's settings in every world, on the world's own
    noise = 0.05                      # (EstimatorOverrides.from_dict: kernel, lengthscale, noise, voxel, learn,
    labels = { ray_smoothing = 24 }   #  restart_every, and labels = a table of ObservationPolicy fields)
    [mujoco]                          # (MujocoScene.from_mesh, make_cover)
    spacing = 0.02
    slack = 0.03                      # a loose cloth's distance from the body before it settles
    vision_inside = 0                 # as in [forcefield]: e.g. none behind a cloth that hangs 3 cm off

``[cover]`` holds what every world reads (``kind``, ``gap``); an option only one world knows goes in that world's
section (its name), so one file builds several. The keys each world takes are its registry entry's (``scene``).
Every key is checked: a misspelt one, or a ``[cover]`` option the chosen world
does not use, is an error that names the file and the key, never ignored.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.validation import KERNEL_LENGTH, NOISE_RANGE

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["SceneSpec", "read_scene", "load_scene", "resolve_mesh", "scene_fingerprint", "truth_of_scene_file",
           "scene_worlds"]

#: The keys of a scene file besides the sections of the worlds that build scene files (``[forcefield]``).
_TOP = {"name", "world", "object", "cover", "approach", "range", "estimator"}
_OBJECT = {"mesh", "scale", "pose", "at", "repair", "resolution"}


def scene_worlds() -> list[str]:
    """The registered worlds that build scene files (``forcefield``, ``mujoco`` where it is installed, and those
    registered with a :class:`~torch_gpioius.exploration.registry.SceneSupport`)."""
    from ..exploration.registry import world_names

    return world_names(builds_scenes=True)


def _support(world: str):
    """The scene support of ``world``, or None: no such world, or one that builds no scene files (or whose optional
    extra is not installed)."""
    from ..exploration.registry import world_entry

    try:
        return world_entry(world).scene
    except (ValueError, ImportError):
        return None


def _section_keys(support) -> set:
    """What a world's own section may hold: its scene settings and its cover options (a loose cover's ``bridge`` in
    the force-field world, its ``slack`` in MuJoCo), so that one file serves several worlds."""
    return set(support.settings_keys) | set(support.cover_keys)


@dataclass
class SceneSpec:
    """A parsed scene file (see the module docstring)."""

    path: Path
    name: str
    world: str
    object: dict
    cover: dict
    approach: dict | None = None
    range: np.ndarray | None = None
    settings: dict = field(default_factory=dict)      # world name -> that world's settings
    estimator: dict | None = None                     # [estimator]: changes to every world's estimator settings


def resolve_mesh(ref: str, base: Path) -> Path:
    """The file a scene's ``object.mesh`` names: a path relative to the scene file, or ``pybullet:<name>`` for a mesh
    that ships inside the ``pybullet`` wheel (bunny, duck, teddy, mug; ``pip install 'torch_gpioius[shapes]'``).

    Raises:
        ValueError: pybullet is not installed, or the file does not exist.
    """
    if ref.startswith("pybullet:"):
        try:
            import pybullet_data
        except ImportError:
            from ..core.extras import install_hint

            raise ValueError(f"object.mesh: {ref!r} needs pybullet's data: {install_hint('shapes')}") from None
        path = Path(pybullet_data.getDataPath()) / ref[len("pybullet:"):]
    else:
        path = Path(ref)
        path = path if path.is_absolute() else base / path
    if not path.is_file():
        raise ValueError(f"object.mesh: no such file {str(path)!r}")
    return path


def scene_fingerprint(path) -> str:
    """What a scene is made of, as one hash: the scene file's bytes (every setting) and its mesh file's bytes.

    A study keys its finished runs by the scene's name; this tells a run of an edited scene file (another mesh,
    another gap) from one of the file as it was, so that a stale result is never reported for the new scene.

    Returns:
        a hex digest (sha256, 16 characters).

    Raises:
        ValueError: the scene file or its mesh cannot be read (names the file).
    """
    import hashlib

    spec = read_scene(path)
    digest = hashlib.sha256()
    for p in (spec.path, resolve_mesh(spec.object["mesh"], spec.path.parent)):
        try:
            digest.update(Path(p).read_bytes())
        except OSError as exc:
            raise ValueError(f"{p}: cannot read ({exc.strerror or exc})") from None
        digest.update(b"\0")
    return digest.hexdigest()[:16]


def _vector(v, label: str, path: Path) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64) if isinstance(v, list) and all(
        isinstance(e, (int, float)) and not isinstance(e, bool) for e in v) else None
    if a is None or a.shape != (3,) or not np.isfinite(a).all():
        raise ValueError(f"{path}: {label}: expected 3 finite numbers, got {v!r}")
    return a


def read_scene(path) -> SceneSpec:
    """Parse and check a scene file (the mesh is not loaded yet).

    Raises:
        ValueError: an unreadable file, TOML errors, unknown keys or sections, missing ``[object]`` or ``[cover]``,
            values of the wrong type (each names the file and the key).
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the scene file ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a valid TOML scene file ({exc})") from None
    except RecursionError:
        raise ValueError(f"{path}: not a scene file: its values are nested too deeply to read") from None
    _check_finite(data, path, "")

    def bad(key: str, why: str) -> ValueError:
        return ValueError(f"{path}: {key}: {why}")

    sections = {k: _support(k) for k in set(data) - _TOP}
    unknown = sorted(k for k, v in sections.items() if v is None)
    if unknown:
        raise bad(", ".join(unknown), f"unknown key(s); a scene file has {sorted(_TOP)} and a section per world that "
                                      f"builds scene files {scene_worlds()}")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "-_." for c in name):
        raise bad("name", f"must be letters, digits, '-', '_' or '.', got {name!r}")
    world = data.get("world", "forcefield")
    if not isinstance(world, str) or _support(world) is None:
        raise bad("world", f"must be one of {scene_worlds()}, got {world!r}")
    obj, cover = data.get("object"), data.get("cover")
    if not isinstance(obj, dict) or "mesh" not in obj:
        raise bad("[object]", "missing, or without mesh = \"<file>\"")
    if set(obj) - _OBJECT:
        raise bad("object", f"unknown key(s) {sorted(set(obj) - _OBJECT)}; allowed {sorted(_OBJECT)}")
    if not isinstance(obj["mesh"], str):
        raise bad("object.mesh", f"must be a file name, got {obj['mesh']!r}")
    _check_cover(cover, world, bad)
    for key, value in cover.items():
        problem = _setting_problem(key, value)
        if problem:
            raise bad(f"[cover] {key}", problem)
    if "pose" in obj:
        from .meshes import as_pose

        try:
            as_pose(obj["pose"])
        except (ValueError, TypeError) as exc:
            raise bad("object.pose", str(exc).removeprefix("pose").lstrip(".:").strip() or "malformed") from None
    if "at" in obj:
        obj = dict(obj, at=_vector(obj["at"], "object.at", path))
    approach = data.get("approach")
    if approach is not None:
        if not isinstance(approach, dict) or set(approach) != {"start", "direction"}:
            raise bad("[approach]", "must give both start and direction (and nothing else)")
        approach = {"start": _vector(approach["start"], "approach.start", path),
                    "direction": _vector(approach["direction"], "approach.direction", path)}
    bounds = data.get("range")
    if bounds is not None:
        if not isinstance(bounds, dict) or set(bounds) != {"min", "max"}:
            raise bad("[range]", "must give min and max (and nothing else)")
        bounds = np.stack([_vector(bounds["min"], "range.min", path), _vector(bounds["max"], "range.max", path)])
        if not (bounds[0] < bounds[1]).all():
            raise bad("range", "min must be below max on every axis")
    settings = {}
    for w, support in sections.items():
        s, allowed = data[w], _section_keys(support)
        if not isinstance(s, dict) or set(s) - allowed:
            raise bad(f"[{w}]", f"unknown key(s) {sorted(set(s) - allowed) if isinstance(s, dict) else s!r}; "
                                f"allowed {sorted(allowed)}")
        settings[w] = dict(s)
        for key, value in s.items():
            problem = _setting_problem(key, value)
            if problem:
                raise bad(f"[{w}] {key}", problem)
    estimator = data.get("estimator")
    if estimator is not None:              # checked as every door checks the estimator's changes
        from ..models.overrides import EstimatorOverrides

        estimator = EstimatorOverrides.from_dict(estimator, f"{path}: [estimator]").to_dict()
    return SceneSpec(path, name, world, dict(obj), dict(cover), approach, bounds, settings, estimator)


def _check_cover(cover, world: str, bad) -> None:
    """Refuse a ``[cover]`` that is missing, or whose kind or keys no world that builds scene files takes (a file
    serves several worlds: an option of another world's cover is kept for that world). The file's own world is asked
    first; the others (MuJoCo's module takes a second to import) only for a kind or key it does not take."""
    own = _support(world)
    if isinstance(cover, dict) and cover.get("kind") in own.cover_kinds and set(cover) - {"kind"} <= own.cover_keys:
        return
    supports = {w: _support(w) for w in dict.fromkeys([*scene_worlds(), world])}
    kinds = sorted({k for sup in supports.values() for k in sup.cover_kinds})
    if not isinstance(cover, dict) or cover.get("kind") not in kinds:
        raise bad("[cover]", f"missing, or its kind is not one of {kinds}")
    every_cover = set().union(*(sup.cover_keys for sup in supports.values())) | {"kind"}
    if set(cover) - every_cover:
        both = sorted(set.intersection(*(set(sup.cover_keys) for sup in supports.values())) | {"kind"})
        others = "; ".join(f"{w}: {sorted(set(sup.cover_keys) - set(both))}" for w, sup in supports.items())
        raise bad("cover", f"unknown key(s) {sorted(set(cover) - every_cover)}; [cover] takes {both} in every world, "
                           f"and a world's own options ({others})")


def _check_finite(value, path: Path, key: str) -> None:
    """Refuse inf and nan anywhere in a scene file (TOML has them), naming the key (``cover_stiffness = inf`` was
    accepted, then stopped the robot)."""
    if isinstance(value, float) and not np.isfinite(value):
        raise ValueError(f"{path}: {key or 'a value'}: must be a finite number, got {value!r}")
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finite(v, path, f"{key}.{k}" if key else str(k))
    elif isinstance(value, list):
        for v in value:
            _check_finite(v, path, key)


#: The scene settings whose values are checked when the file is read, not when the world is built: key ->
#: (lowest, highest, whether the lowest is allowed) for lengths and numbers [SI units].
_RANGES = {"cover_stiffness": (0.0, 1e7, False), "sensor_noise": (0.0, 10.0, True), "theta": (*KERNEL_LENGTH, False),
           "lengthscale": (*KERNEL_LENGTH, False),
           "noise": (*NOISE_RANGE, False),
           "bridge": (0.0, 0.2, False), "gap": (0.0, 0.2, False), "gap_far": (0.0, 0.2, False),
           "resolution": (0.0, 0.05, False), "spacing": (0.0, 0.2, False), "timestep": (0.0, 0.1, False),
           "settle_time": (0.0, 60.0, True)}


def _setting_problem(key: str, value) -> str | None:
    """Why a world section's ``key = value`` cannot be used, or None (the world checks the rest when it builds)."""
    if key == "voxel":
        from ..exploration.observations import check_voxel

        try:
            check_voxel(value)
        except ValueError as exc:
            return str(exc).removeprefix("voxel: ")
        return None
    from .presets import INSIDE_SETTINGS, inside_labels

    if key in INSIDE_SETTINGS:       # the labels' own ranges (0 for a depth: none)
        try:
            inside_labels(**{key: value})
        except ValueError as exc:
            return str(exc).removeprefix(f"ObservationPolicy.{key}: ")
        return None
    if key == "camera_error":
        from ..sensors.simulated.camera import CameraError

        try:
            CameraError.parse(value)
        except ValueError as exc:
            return str(exc).removeprefix("camera error: ")
        return None
    if key in _RANGES:
        lo, hi, closed = _RANGES[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"must be a number, got {value!r}"
        if not (value <= hi and (value >= lo if closed else value > lo)):
            return f"must be in {'[' if closed else '('}{lo:g}, {hi:g}], got {value!r}"
    return None


def _kernel_choice(settings: dict) -> dict:
    """A world section's settings with ``kernel`` and its length (``lengthscale``, or ``theta``, the paper's name)
    as one :class:`~torch_gpioius.kernels.KernelChoice`.

    Raises:
        ValueError: both ``lengthscale`` and ``theta`` given, or an unknown kernel name.
    """
    from ..kernels import KernelChoice

    settings = dict(settings)
    if "lengthscale" in settings and "theta" in settings:
        raise ValueError("lengthscale, theta: the same length under two names; give lengthscale")
    length = settings.pop("lengthscale", settings.pop("theta", None))
    name = settings.pop("kernel", None)
    if name is not None and not isinstance(name, str):
        raise ValueError(f"kernel: expected a name such as \"matern52\" or \"imq\", got {name!r}")
    choice = KernelChoice(name, length)
    if choice:
        settings["kernel"] = choice
    return settings


def _check_reach(scene, spec: SceneSpec) -> None:
    """Refuse a scene whose approach start the UR5 cannot reach, naming the file and the key that placed it (an
    object placed in millimetres, or beyond the arm's 0.85 m, failed later inside the inverse kinematics, naming
    neither)."""
    from kinematics.ur5 import UnreachablePoseError

    from .forcefield import simulated_ur5

    try:
        simulated_ur5(scene.start, scene.direction, scene.range[0], scene.range[1])
    except UnreachablePoseError:
        key = "approach.start" if spec.approach is not None else "object.at (the approach starts above the object)"
        where = np.round(scene.start, 3).tolist()
        raise ValueError(f"{spec.path}: {key}: the fingertip's start {where} m is out of the UR5's reach (its base at "
                         f"the origin, {np.linalg.norm(scene.start):.3g} m away; the arm reaches about 0.85 m); place "
                         "the object closer, in metres (scale = 0.001 converts a mesh in millimetres; positions are "
                         "metres)") from None


def load_scene(path, world: str | None = None, seed: int = 0, smoke: bool = False,
               settings: str | None = None):
    """Build the world a scene file describes.

    Args:
        path: the TOML file.
        world: a world that builds scene files (:func:`scene_worlds`; default: the file's ``world``).
        seed: the seeded perturbation of the approach and the noise (0: as written; ``World.perturbed``).
        smoke: a coarse MuJoCo cover (4 cm spacing) for quick checks; the force-field world ignores it.
        settings: "default" or "paper" in place of the file's ``settings`` (force-field world; see
            :meth:`~torch_gpioius.sim.forcefield.Scene3D.from_mesh`) or the MuJoCo world's own (its defaults and
            views: :meth:`~torch_gpioius.sim.mujoco.MujocoScene.with_settings`); the file's other settings still apply.

    Returns:
        The world its :class:`~torch_gpioius.exploration.registry.SceneSupport` builds (a
        :class:`~torch_gpioius.sim.forcefield.Scene3D`, a :class:`~torch_gpioius.sim.mujoco.MujocoScene`).

    Raises:
        ValueError: everything :func:`read_scene`, :func:`torch_gpioius.sim.meshes.load_mesh` and the world's
            constructor refuse, each prefixed with the file's name.
    """
    from .forcefield import place
    from .meshes import load_mesh

    spec, preset = read_scene(path), settings
    world = spec.world if world is None else world
    support = _support(world) if isinstance(world, str) else None
    if support is None:
        raise ValueError(f"world: a scene file builds {scene_worlds()}, got {world!r}")
    try:
        o = spec.object
        mesh = load_mesh(resolve_mesh(o["mesh"], spec.path.parent), scale=o.get("scale", 1.0), pose=o.get("pose"),
                         repair=o.get("repair", True), resolution=o.get("resolution"), name=spec.name)
        mesh = place(mesh, o.get("at"))
        cover = dict(spec.cover)
        kind = cover.pop("kind")
        if kind not in support.cover_kinds:
            raise ValueError(f"cover: the {world} world builds {list(support.cover_kinds)} covers, not {kind!r}")
        unused = set(cover) - support.cover_keys
        if unused:
            others = [w for w in spec.settings if w != world] or [w for w in scene_worlds() if w != world]
            raise ValueError(f"cover: {sorted(unused)} do not apply in the {world} world (it takes "
                             f"{sorted(support.cover_keys)}); options of one world go in its own section"
                             f"{', ' if others else ''}{', '.join(f'[{w}]' for w in others)}")
        own = spec.settings.get(world, {})
        cover.update({k: v for k, v in own.items() if k in support.cover_keys})
        settings = _kernel_choice({k: v for k, v in own.items() if k not in support.cover_keys})
        where = {}
        if spec.approach is not None:
            where.update(start=spec.approach["start"], direction=spec.approach["direction"])
        if spec.range is not None:
            where["bounds"] = spec.range
        scene = support.build(mesh, kind, name=spec.name, where=where, cover=cover, settings=settings,
                              preset=preset, smoke=smoke)
        if spec.estimator:                  # [estimator]: on the world's (or the preset's) own
            if not hasattr(scene, "with_estimator"):
                raise ValueError(f"[estimator]: the {world} world's scenes take no estimator settings "
                                 "(with_estimator)")
            scene = scene.with_estimator(spec.estimator)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{spec.path}: {exc}") from None
    if support.ur5:
        _check_reach(scene, spec)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
    made = scene.perturbed(seed)
    made.scene_file = {"path": str(spec.path.resolve()), "hash": scene_fingerprint(spec.path)}
    return made


def truth_of_scene_file(meta: dict) -> dict | None:
    """The true shapes (``World.truth()``) of the scene file a log's header names (``scene_file``), rebuilt in the
    header's world, or None: no scene file named, the file is gone, or it changed since the run (its content's
    digest differs: another body's shapes would be drawn as this run's truth)."""
    info = meta.get("scene_file")
    if not isinstance(info, dict) or not isinstance(info.get("path"), str):
        return None
    path = Path(info["path"])
    try:
        if not path.is_file() or scene_fingerprint(path) != info.get("hash"):
            return None
        world = meta.get("world")
        return load_scene(path, world=world if isinstance(world, str) and _support(world) else None).truth()
    except (ValueError, ImportError, OSError):
        return None

"""Worlds by name: one :class:`~torch_gpioius.core.registry.Registry` that the command line, the scene files, the
sweeps, the studies and the readers of logs use.

A world registers itself once, beside its class (``register_world("mujoco", MujocoScene, objects=..., dimension=3,
scene=SceneSupport(...))``), with its capabilities; nothing else matches world names in an if-chain. The built-in
worlds live in modules that are imported when their name is first asked for (MuJoCo is an optional extra), like entry
points:

| name | class | dimension | simulated | objects | scene files | world |
|---|---|---|---|---|---|---|
| ``planar`` | ``Scene2D`` | 2 | yes | A-D | no | the paper's 2-D study (Sec. V): polygons, a point fingertip |
| ``forcefield`` | ``Scene3D`` | 3 | yes | E-H | yes | Sec. VI in 3-D: a kinematic UR5, a static force-field cover |
| ``mujoco`` | ``MujocoScene`` | 3 | yes | E-H | yes | Sec. VI on MuJoCo: a simulated UR5, cloth and foam covers |
| ``robot`` | ``RobotWorld`` | 3 | no | - | no | a real UR5, force sensor and camera |

Older names are read where they appear in files (``2d``, ``3d``, ``penalty``, and the class names logs wrote).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from ..core.registry import Entry, Registry

__all__ = ["WorldEntry", "SceneSupport", "WORLDS", "register_world", "world_entry", "world_names", "make_world",
           "canonical_world_name", "registered_tables"]


@dataclass(frozen=True)
class SceneSupport:
    """What a world reads from a scene file (:mod:`torch_gpioius.sim.scenefile`) and how it builds one.

    Attributes:
        cover_keys: the ``[cover]`` keys it takes besides ``kind`` (``gap``, a loose cover's ``bridge``).
        cover_kinds: the cover kinds it builds ("tight", "loose", ...).
        settings_keys: the keys of its own section (``[forcefield]``) besides its cover keys.
        build: ``build(mesh, kind, *, name, where, cover, settings, preset, smoke) -> World``: the world around the
            placed body ``mesh`` (a trimesh in metres) under a cover of ``kind``, ``where`` the approach and range
            the file gives (``start``, ``direction``, ``bounds``), ``cover`` and ``settings`` its own section's
            values (a ``kernel`` and its length already one :class:`~torch_gpioius.kernels.KernelChoice`),
            ``preset`` "default", "paper" or None (the file's), ``smoke`` a quick coarse build.
        ur5: the world's robot is the UR5: the approach's start is checked against its reach when the file is loaded.
    """

    cover_keys: frozenset
    cover_kinds: tuple
    settings_keys: frozenset
    build: Callable
    ur5: bool = True


@dataclass
class WorldEntry(Entry):
    """One registered world and its capabilities.

    Attributes:
        name: its one name (CLI, API, studies, logs).
        obj: the :class:`~torch_gpioius.exploration.world.World` subclass (also :attr:`cls`).
        objects: ``objects(names, smoke) -> {name: World}``, the world's built-in objects (None: it has none).
        object_names: the names ``objects`` knows, in order.
        description: one line for help texts.
        dimension: 2 or 3.
        simulated: False for a world of real hardware (studies and simulate commands leave it out).
        scene: what it reads from scene files and how it builds one, or None: it builds none.
        presets: its worlds take the estimator's presets and the camera's views (``with_settings("paper")``,
            ``with_views(...)``): a study's ``--settings`` and ``--views`` apply to it.
    """

    objects: Callable | None = None
    object_names: tuple = ()
    dimension: int = 3
    simulated: bool = True
    scene: SceneSupport | None = None
    presets: bool = False
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def cls(self) -> type:
        """The world's class."""
        return self.obj

    @property
    def builds_scenes(self) -> bool:
        """Whether scene files can be built in this world."""
        return self.scene is not None

    def build(self, name: str, smoke: bool = False):
        """The built-in object ``name`` (built once per process; seeds perturb it, :meth:`World.perturbed`).

        Raises:
            ValueError: the world has no object of that name (lists them).
        """
        if self.objects is None or name not in self.object_names:
            raise ValueError(f"objects: unknown {name!r} in the {self.name} world; choose among "
                             f"{tuple(self.object_names)}")
        key = (name, bool(smoke))
        if key not in self._cache:
            self._cache[key] = self.objects([name], smoke)[name]
        return self._cache[key]


#: Names older releases used, in files and on the command line.
_OLD_NAMES = {"2d": "planar", "3d": "forcefield", "penalty": "forcefield", "Scene2D": "planar",
              "Scene3D": "forcefield", "MujocoScene": "mujoco", "RobotWorld": "robot"}
#: Every world by name; the built-in ones register when their module is imported.
WORLDS: Registry = Registry("world", entry_type=WorldEntry, old_names=_OLD_NAMES, builtin={
    "planar": "torch_gpioius.sim.plane", "forcefield": "torch_gpioius.sim.forcefield",
    "mujoco": "torch_gpioius.sim.mujoco", "robot": "torch_gpioius.exploration.world"})


def register_world(name: str, cls: type, *, objects: Callable | None = None, object_names=(),
                   description: str = "", dimension: int = 3, simulated: bool = True,
                   scene: SceneSupport | None = None, presets: bool = False) -> type:
    """Register ``cls`` under ``name`` (and set ``cls.kind = name``); returns ``cls``. The world is then a choice of
    ``gpioius study --world`` (when simulated), of scene files' ``world`` (with ``scene``), and of logs.

    Args:
        name: the world's one name.
        cls: its :class:`~torch_gpioius.exploration.world.World` subclass.
        objects: ``objects(names, smoke) -> {name: World}`` building its built-in objects, or None.
        object_names: the names ``objects`` knows.
        description: one line for help texts.
        dimension: 2 or 3.
        simulated: False for real hardware.
        scene: its scene-file support, or None.
        presets: its worlds have ``with_settings`` and ``with_views`` (:class:`WorldEntry`).

    Raises:
        ValueError: the name is taken by another class, is an old name of a built-in world, or a capability is out of
            its range.
    """
    if dimension not in (2, 3):
        raise ValueError(f"register_world: dimension must be 2 or 3, got {dimension!r}")
    if scene is not None and not isinstance(scene, SceneSupport):
        raise ValueError(f"register_world: scene must be a SceneSupport, got {type(scene).__name__}")
    WORLDS.register(name, cls, objects=objects, object_names=tuple(object_names), description=description,
                    dimension=dimension, simulated=bool(simulated), scene=scene, presets=bool(presets))
    cls.kind = name
    return cls


def canonical_world_name(name: str, *, warn: bool = False) -> str:
    """The current name of a world given by any name it has had (``"3d"`` -> ``"forcefield"``)."""
    return WORLDS.current_name(name, warn=warn, stacklevel=4)


def world_entry(name: str) -> WorldEntry:
    """The registered world ``name`` (an old name is accepted), importing a built-in world's module on first use.

    Raises:
        ValueError: no world of that name (lists the names).
    """
    return WORLDS.entry(name)


def world_names(**capabilities) -> list[str]:
    """Every world's name, the built-in ones first, then those registered since; with capabilities, only the worlds
    that have them (``world_names(simulated=True)``, ``world_names(builds_scenes=True)``)."""
    return WORLDS.names(**capabilities)


def make_world(world: str, name: str, seed: int = 0, smoke: bool = False):
    """The built-in object ``name`` of ``world``, perturbed by ``seed`` (seed 0: the object itself)."""
    return world_entry(world).build(name, smoke).perturbed(seed)


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def registered_tables(builtin_only: bool = False) -> dict[str, str]:
    """Every registry as a Markdown table, by kind: ``kernels``, ``worlds``, ``touch``, ``evidence``, ``sensors``
    (``gpioius registered`` prints them; docs/architecture.md holds the built-in ones: ``builtin_only``, the entries
    whose class is the package's)."""
    from ..kernels import KERNELS
    from ..sensors.registry import SENSORS
    from .policies import EVIDENCE_POLICIES
    from .touch import TOUCH_MODELS

    def ours(e) -> bool:
        return not builtin_only or getattr(e.obj, "__module__", "").startswith("torch_gpioius.")

    return {
        "kernels": KERNELS.markdown({"class": lambda e: f"`{e.obj.__name__}`"}, ours),
        "worlds": WORLDS.markdown({
            "class": lambda e: f"`{e.obj.__name__}`", "dimension": lambda e: e.dimension,
            "simulated": lambda e: _yes(e.simulated), "objects": lambda e: ", ".join(e.object_names) or "-",
            "scene files": lambda e: _yes(e.builds_scenes), "presets": lambda e: _yes(e.presets)}, ours),
        "touch": TOUCH_MODELS.markdown({"class": lambda e: f"`{e.obj.__name__}`"}, ours),
        "evidence": EVIDENCE_POLICIES.markdown({"class": lambda e: f"`{e.obj.__name__}`",
                                                "modes": lambda e: ", ".join(e.modes)}, ours),
        "sensors": SENSORS.markdown({"class": lambda e: f"`{e.obj.__name__}`", "measures": lambda e: e.measures,
                                     "hardware": lambda e: _yes(e.hardware)}, ours),
    }

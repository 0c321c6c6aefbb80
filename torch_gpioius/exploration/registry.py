"""Worlds by name: one registry that the command line, the sweeps, the studies and the readers of logs use.

A world registers itself once, beside its class (``register_world("mujoco", MujocoScene, objects=...)``); nothing
else matches world names in an if-chain. The built-in worlds live in modules that are imported when their name is
first asked for (MuJoCo is an optional extra), like entry points:

| name | class | objects | world |
|---|---|---|---|
| ``planar`` | ``Scene2D`` | A-D | the paper's 2-D study (Sec. V): polygons, a point fingertip |
| ``forcefield`` | ``Scene3D`` | E-H | Sec. VI in 3-D: a kinematic UR5, a static force-field cover |
| ``mujoco`` | ``MujocoScene`` | E-H | Sec. VI on MuJoCo: a simulated UR5, cloth and foam covers |
| ``robot`` | ``RobotWorld`` | - | a real UR5, force sensor and camera |

Older names are read where they appear in files (``2d``, ``3d``, ``penalty``, and the class names logs wrote).
"""

from __future__ import annotations

import importlib
import warnings
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["WorldEntry", "register_world", "world_entry", "world_names", "make_world", "canonical_world_name"]


@dataclass
class WorldEntry:
    """One registered world.

    Attributes:
        name: its one name (CLI, API, studies, logs).
        cls: the :class:`~torch_gpioius.exploration.world.World` subclass.
        objects: ``objects(names, smoke) -> {name: World}``, the world's built-in objects (None: it has none).
        object_names: the names ``objects`` knows, in order.
        description: one line for help texts.
    """

    name: str
    cls: type
    objects: Callable | None = None
    object_names: tuple = ()
    description: str = ""
    _cache: dict = field(default_factory=dict, repr=False)

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


_REGISTRY: dict[str, WorldEntry] = {}
#: Built-in worlds and the modules that register them on import.
_BUILTIN = {"planar": "torch_gpioius.sim.plane", "forcefield": "torch_gpioius.sim.forcefield",
            "mujoco": "torch_gpioius.sim.mujoco", "robot": "torch_gpioius.exploration.world"}
#: Names older releases used, in files and on the command line.
_OLD_NAMES = {"2d": "planar", "3d": "forcefield", "penalty": "forcefield", "Scene2D": "planar",
              "Scene3D": "forcefield", "MujocoScene": "mujoco", "RobotWorld": "robot"}


def register_world(name: str, cls: type, *, objects: Callable | None = None, object_names=(),
                   description: str = "") -> type:
    """Register ``cls`` under ``name`` (and set ``cls.kind = name``); returns ``cls``.

    Args:
        name: the world's one name.
        cls: its :class:`~torch_gpioius.exploration.world.World` subclass.
        objects: ``objects(names, smoke) -> {name: World}`` building its built-in objects, or None.
        object_names: the names ``objects`` knows.
        description: one line for help texts.

    Raises:
        ValueError: the name is taken by another class, or is an old name of a built-in world.
    """
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"register_world: the name must be an identifier, got {name!r}")
    if name in _OLD_NAMES:
        raise ValueError(f"register_world: {name!r} is an old name of a built-in world")
    taken = _REGISTRY.get(name)
    if taken is not None and taken.cls is not cls:
        raise ValueError(f"register_world: {name!r} is already {taken.cls.__name__}")
    cls.kind = name
    _REGISTRY[name] = WorldEntry(name, cls, objects, tuple(object_names), description)
    return cls


def canonical_world_name(name: str, *, warn: bool = False) -> str:
    """The current name of a world given by any name it has had (``"3d"`` -> ``"forcefield"``)."""
    if name in _OLD_NAMES:
        if warn:
            warnings.warn(f"world {name!r} is called {_OLD_NAMES[name]!r} now", DeprecationWarning, stacklevel=3)
        return _OLD_NAMES[name]
    return name


def world_entry(name: str) -> WorldEntry:
    """The registered world ``name`` (an old name is accepted), importing a built-in world's module on first use.

    Raises:
        ValueError: no world of that name (lists the names).
    """
    name = canonical_world_name(name)
    if name not in _REGISTRY and name in _BUILTIN:
        importlib.import_module(_BUILTIN[name])
    if name not in _REGISTRY:
        raise ValueError(f"world: unknown {name!r}; choose among {world_names()}")
    return _REGISTRY[name]


def world_names() -> list[str]:
    """Every world's name: the built-in ones first, then those registered since."""
    return list(_BUILTIN) + [n for n in _REGISTRY if n not in _BUILTIN]


def make_world(world: str, name: str, seed: int = 0, smoke: bool = False):
    """The built-in object ``name`` of ``world``, perturbed by ``seed`` (seed 0: the object itself)."""
    return world_entry(world).build(name, smoke).perturbed(seed)

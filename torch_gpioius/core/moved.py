"""Where the modules and names of earlier releases live now: one finder for every moved module, one forward for every
renamed name. Each says where its thing went with a DeprecationWarning, from the user's import or attribute, for one
release; the old path then gives the new module or object itself (``is``, not a copy), so pickles and checkpoints that
name an old path still load.

A moved module is found by :class:`MovedModules` (a :data:`sys.meta_path` finder placed after Python's own, so it is
asked only for names no file answers) instead of a file of re-exports left at each old place: the package's folders
hold only what lives there, and the list of what moved is this one table.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings
from typing import Callable

__all__ = ["MODULES", "MovedModules", "install", "renamed"]

#: old module -> (its module now, why it moved). Kept one release after the move.
MODULES: dict[str, tuple[str, str]] = {
    # the foundation every layer stands on
    "torch_gpioius.tolerances": ("torch_gpioius.core.tolerances", "the foundation's modules are gathered in core"),
    "torch_gpioius.exact": ("torch_gpioius.core.exact", "the foundation's modules are gathered in core"),
    "torch_gpioius.threads": ("torch_gpioius.core.threads", "the foundation's modules are gathered in core"),
    "torch_gpioius.registry": ("torch_gpioius.core.registry", "the foundation's modules are gathered in core"),
    "torch_gpioius.settings": ("torch_gpioius.core.exact", "settings are the estimator's"),
    # points, curves and surfaces
    "torch_gpioius.voxels": ("torch_gpioius.geometry.voxels", "geometry's modules are gathered in geometry"),
    "torch_gpioius.polylines": ("torch_gpioius.geometry.polylines", "geometry's modules are gathered in geometry"),
    "torch_gpioius.surfaces": ("torch_gpioius.geometry.surfaces", "geometry's modules are gathered in geometry"),
    "torch_gpioius.metrics": ("torch_gpioius.geometry.metrics", "geometry's modules are gathered in geometry"),
    # the exploration's planner and contact controller, beside the loop that uses them
    "torch_gpioius.planning": ("torch_gpioius.exploration.planning", "the planner is the exploration's"),
    "torch_gpioius.contact": ("torch_gpioius.exploration.contact", "the contact controller is the exploration's"),
    # fitting and replay apart from the file formats
    "torch_gpioius.io.offline": ("torch_gpioius.fitting", "fitting and plotting apart from the file formats"),
    # the studies' modules, named for the commands they serve
    "torch_gpioius.studies.study2d": ("torch_gpioius.studies.simulate", "named for gpioius simulate"),
    "torch_gpioius.studies.study3d": ("torch_gpioius.studies.simulate3d", "named for gpioius simulate3d"),
    "torch_gpioius.studies.sweep": ("torch_gpioius.studies.study", "named for gpioius study"),
    "torch_gpioius.studies.sweep_settings": ("torch_gpioius.studies.study_plan", "named for gpioius study"),
    "torch_gpioius.studies.sweep_runs": ("torch_gpioius.studies.study_runs", "named for gpioius study"),
    "torch_gpioius.studies.sweep_aggregate": ("torch_gpioius.studies.study_aggregate", "named for gpioius study"),
    "torch_gpioius.studies.sweep_figures": ("torch_gpioius.studies.study_figures", "named for gpioius study"),
    # simulated sensors in one place
    "torch_gpioius.sim.tactile": ("torch_gpioius.sensors.simulated.gelpad", "simulated sensors live in one place"),
}


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """A :data:`sys.meta_path` finder that answers an old module path with the module that lives at its new one.

    Args:
        moves: old dotted module name -> (new dotted module name, why it moved).
    """

    def __init__(self, moves: dict[str, tuple[str, str]]):
        self.moves = dict(moves)
        self._specs = {}

    def find_spec(self, fullname, path=None, target=None):
        if fullname not in self.moves:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec):
        new, why = self.moves[spec.name]
        module = importlib.import_module(new)
        self._specs[spec.name] = module.__spec__
        # stacklevel 2: the frame past this one outside the import machinery (warnings skips importlib's frames)
        warnings.warn(f"{spec.name} is {new} now ({why})", DeprecationWarning, stacklevel=2)
        return module

    def exec_module(self, module):
        # the new module ran when it was imported; the import machinery gave it the old name's spec: give its own back
        module.__spec__ = self._specs.pop(module.__spec__.name)


def install() -> None:
    """Put the finder for :data:`MODULES` on :data:`sys.meta_path` (once; after Python's own finders)."""
    if not any(isinstance(finder, MovedModules) for finder in sys.meta_path):
        sys.meta_path.append(MovedModules(MODULES))


def renamed(module: str, names: dict[str, tuple[str, str, str]]) -> Callable[[str], object]:
    """A module ``__getattr__`` that gives renamed or moved names from their new place, with a DeprecationWarning.

    Args:
        module: the module's own dotted name (``__name__``), for the message and the AttributeError.
        names: old name -> (the dotted module it lives in now, its name there, why it moved).

    Returns:
        ``__getattr__(name)``: the new object for an old name; AttributeError for any other.
    """
    def __getattr__(name):
        if name not in names:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        new_module, new_name, why = names[name]
        warnings.warn(f"{module}.{name} is {new_module}.{new_name} now ({why})", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(new_module), new_name)

    return __getattr__

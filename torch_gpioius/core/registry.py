"""One way to register an extension by name: kernels, worlds, touch models, evidence policies and force sensors.

Each extension point is one :class:`Registry`. An entry has one name, the aliases users type (``"imq"`` for
``InverseMultiquadricKernel``), a one-line description and its capabilities (a world's dimension, whether it is
simulated, its objects, what its scene files hold). The command line's choices, the scene files' keys, the studies'
settings and the docs' tables are read from the registries, so a kernel, world or policy registered from outside the
package is usable by name everywhere without a file of the package edited::

    from torch_gpioius.kernels import register_kernel
    register_kernel(MyKernel, aliases=("mine",))        # then: gpioius study --kernel mine, kernel = "mine"

Built-in entries whose modules are heavy or optional (MuJoCo) are imported when their name is first asked for, as
entry points are. A plugin (a module of one's own that registers) reaches the command line and a study's workers by
:func:`load_plugins`: an installed package names it as an entry point of the group ``torch_gpioius.plugins``, or the
environment variable ``GPIOIUS_PLUGINS`` lists it (``GPIOIUS_PLUGINS=my_lab.gpioius_kernels gpioius registered``).
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import warnings
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

__all__ = ["Registry", "Entry", "load_plugins", "PLUGIN_GROUP", "PLUGIN_ENV"]

#: The entry-point group of plugins (``[project.entry-points."torch_gpioius.plugins"] mine = "my_pkg.plugin"``).
PLUGIN_GROUP = "torch_gpioius.plugins"
#: The environment variable that lists plugin modules, comma-separated.
PLUGIN_ENV = "GPIOIUS_PLUGINS"
_LOADED: set[str] = set()

T = TypeVar("T")


@dataclass
class Entry:
    """One registered extension.

    Attributes:
        name: its one name (the command line's, the API's, the files').
        obj: what is registered (a class, usually).
        aliases: further names users type for it.
        description: one line for help texts and the docs' tables.
    """

    name: str
    obj: Any
    aliases: tuple = ()
    description: str = ""


class Registry(Mapping, Generic[T]):
    """Extensions of one kind by name: a read-only mapping from each entry's name to what it registers.

    Args:
        what: the kind, for messages ("kernel", "world").
        entry_type: the :class:`Entry` subclass that carries this kind's capabilities.
        builtin: ``{name: module}`` of built-in entries registered when their module is imported; their names come
            first, in this order.
        old_names: names of earlier releases, read with a DeprecationWarning where asked (files keep them).
        case_sensitive: False: names match in any case (``"Matern52"``, ``"matern52"``).
    """

    def __init__(self, what: str, *, entry_type: type = Entry, builtin: Mapping[str, str] | None = None,
                 old_names: Mapping[str, str] | None = None, case_sensitive: bool = True):
        self.what = what
        self.entry_type = entry_type
        self._builtin = dict(builtin or {})
        self._old = dict(old_names or {})
        self._case = case_sensitive
        self._entries: dict[str, Entry] = {}

    # ------------------------------------------------------------------------------------------ registering
    def register(self, name: str, obj: Any, *, aliases=(), replace: bool = False, **capabilities) -> Entry:
        """Register ``obj`` under ``name`` (and ``aliases``); returns its entry.

        Args:
            name: an identifier (letters, digits, ``_``).
            obj: what is registered.
            aliases: further names for it.
            replace: allow ``name`` to be taken by another object (a module reloaded).
            **capabilities: the fields of this registry's entry type (``description`` too).

        Raises:
            ValueError: a name that is no identifier, an old name of a built-in entry, a name or alias taken by
                another object, or a capability this kind of entry does not have (names it).
        """
        aliases = tuple(aliases)
        for n in (name, *aliases):
            if not isinstance(n, str) or not n.replace("-", "_").isidentifier():
                raise ValueError(f"register {self.what}: a name must be an identifier, got {n!r}")
            if n in self._old:
                raise ValueError(f"register {self.what}: {n!r} is an old name of {self._old[n]!r}")
            owner = self._owner(n)
            if owner is not None and owner.obj is not obj and not (replace and owner.name == name):
                raise ValueError(f"register {self.what}: {n!r} is already {_label(owner.obj)}")
        fields = {f.name for f in dataclasses.fields(self.entry_type)} - {"name", "obj", "aliases"}
        unknown = set(capabilities) - fields
        if unknown:
            raise ValueError(f"register {self.what}: unknown capabilities {sorted(unknown)}; a {self.what} has "
                             f"{sorted(fields)}")
        entry = self.entry_type(name, obj, aliases, **capabilities)
        self._entries[name] = entry
        return entry

    def owner(self, name: str) -> Entry | None:
        """The registered entry that has ``name`` as its name or an alias (any case where names match so), or None;
        a built-in entry not imported yet is not looked up."""
        return self._owner(name)

    def _owner(self, name: str) -> Entry | None:
        key = self._key(name)
        for e in self._entries.values():
            if key in (self._key(n) for n in (e.name, *e.aliases)):
                return e
        return None

    def _key(self, name: str) -> str:
        return name if self._case else name.lower()

    # ------------------------------------------------------------------------------------------ looking up
    def resolve(self, name: str, *, warn: bool = False) -> str:
        """The registered name that ``name`` (a name, an alias or an old name) stands for.

        Raises:
            ValueError: nothing of that name (lists the names users can type).
        """
        if not isinstance(name, str):
            raise ValueError(f"{self.what}: expected a name, got {name!r}")
        name = self.current_name(name, warn=warn, stacklevel=4)
        entry = self._owner(name)
        if entry is None and name in self._builtin:
            importlib.import_module(self._builtin[name])
            entry = self._owner(name)
        if entry is None:
            raise ValueError(f"{self.what}: unknown {name!r}; choose among {self.choices()}")
        return entry.name

    def current_name(self, name: str, *, warn: bool = False, stacklevel: int = 3) -> str:
        """``name`` itself, or the current name of an old one (``"3d"`` -> ``"forcefield"``), with a
        DeprecationWarning when ``warn`` (``stacklevel`` as :func:`warnings.warn`'s, from this call); not checked to
        be registered (:meth:`resolve` does)."""
        if name in self._old:
            if warn:
                warnings.warn(f"{self.what} {name!r} is called {self._old[name]!r} now", DeprecationWarning,
                              stacklevel=stacklevel)
            return self._old[name]
        return name

    def entry(self, name: str) -> Entry:
        """The entry ``name`` (or an alias, or an old name) stands for; see :meth:`resolve`."""
        return self._entries[self.resolve(name)]

    def __getitem__(self, name: str) -> T:
        try:
            return self.entry(name).obj
        except ValueError:
            raise KeyError(name) from None

    def __contains__(self, name) -> bool:
        try:
            self.resolve(name)
        except ValueError:
            return False
        return True

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self.names())

    def names(self, **capabilities) -> list[str]:
        """The registered names, built-in ones first (whether their module is imported yet or not), then in the order
        of registration; with ``capabilities``, only the entries whose fields equal them
        (``worlds.names(simulated=True)``; a built-in entry is then imported to be asked)."""
        out = list(self._builtin) + [n for n in self._entries if n not in self._builtin]
        if not capabilities:
            return out
        return [n for n in out if self._matches(n, capabilities)]

    def _matches(self, name: str, capabilities: dict) -> bool:
        try:
            entry = self.entry(name)
        except (ValueError, ImportError):
            return False
        return all(getattr(entry, k) == v for k, v in capabilities.items())

    def choices(self, **capabilities) -> list[str]:
        """What users can type: each name (filtered as :meth:`names` filters) followed by its aliases."""
        out = []
        for name in self.names(**capabilities):
            entry = self._entries.get(name)
            out += [name, *(entry.aliases if entry is not None else ())]
        return out

    def entries(self, **capabilities) -> list[Entry]:
        """The entries, in the order of :meth:`names` (built-in modules imported; one whose optional extra is not
        installed is left out)."""
        out = []
        for name in self.names(**capabilities):
            try:
                out.append(self.entry(name))
            except (ValueError, ImportError):
                continue
        return out

    def old_names(self) -> dict[str, str]:
        """``{old name: current name}``."""
        return dict(self._old)

    def make(self, name: str, *args, **kwargs):
        """``self[name](*args, **kwargs)``: an instance of the registered class."""
        return self.entry(name).obj(*args, **kwargs)

    def __repr__(self) -> str:
        return f"Registry({self.what!r}, {self.names()})"

    def markdown(self, columns: dict | None = None, where=None) -> str:
        """The entries (those for which ``where(entry)`` holds, if given) as a Markdown table: name, aliases,
        ``columns`` (``{heading: entry -> text}``) and the description (the docs' tables and ``gpioius registered``
        print it)."""
        columns = dict(columns or {})
        head = ["name", "aliases", *columns, "description"]
        rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for e in self.entries():
            if where is not None and not where(e):
                continue
            cells = [f"`{e.name}`", ", ".join(f"`{a}`" for a in e.aliases) or "-",
                     *(str(f(e)) for f in columns.values()), e.description or "-"]
            rows.append("| " + " | ".join(cells) + " |")
        return "\n".join(rows)


def _label(obj) -> str:
    return getattr(obj, "__qualname__", None) or type(obj).__name__


def load_plugins() -> list[str]:
    """Import every plugin module once: the entry points of :data:`PLUGIN_GROUP` and the modules named in
    :data:`PLUGIN_ENV`. A plugin registers what it brings when imported (``register_kernel``, ``register_world``,
    ...). The command line calls this before it reads its choices, and each study run before it builds its world.

    Returns:
        the modules imported by this call (none on later calls).

    Raises:
        ImportError: a plugin that cannot be imported (names it and where it was listed).
    """
    from importlib.metadata import entry_points

    wanted = [(ep.value.split(":")[0], f"entry point {ep.name!r} of {PLUGIN_GROUP}")
              for ep in entry_points(group=PLUGIN_GROUP)]
    wanted += [(m.strip(), PLUGIN_ENV) for m in os.environ.get(PLUGIN_ENV, "").split(",") if m.strip()]
    done = []
    for module, where in wanted:
        if module in _LOADED:
            continue
        try:
            importlib.import_module(module)
        except SystemExit as exc:               # sys.exit(3) at import ended gpioius with status 3 and no word
            raise ImportError(f"plugin {module!r} ({where}) called sys.exit({exc.code!r}) while being imported; a "
                              "plugin registers what it brings and returns") from None
        except Exception as exc:                # a plugin's own error, whatever it is, is named with the plugin
            raise ImportError(f"plugin {module!r} ({where}) cannot be imported: {type(exc).__name__}: {exc}") from exc
        _LOADED.add(module)
        done.append(module)
    return done

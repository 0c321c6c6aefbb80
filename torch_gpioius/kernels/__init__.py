"""Kernels of the GP models: the contract the exact engines rely on (:class:`ExactKernel`), the inverse
multiquadric of the paper (eq. 5, the default) and a Matérn-5/2.

A new kernel is one file: subclass :class:`ExactKernel`, implement its five methods (and, for its length to be
learned, :attr:`ExactKernel.length` and :meth:`ExactKernel.value_at` with ``learnable_length = True``), decorate the
class with :func:`register_kernel` (so logs and checkpoints can name it), and subclass the contract tests in
:class:`torch_gpioius.testing.KernelContract` for its test file.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from ..core.validation import as_float, as_kernel_length
from ..core.registry import Registry
from .base import ExactKernel, check_kernel
from .inverse_multiquadric import InverseMultiquadricKernel, imq
from .matern import Matern52

__all__ = ["ExactKernel", "InverseMultiquadricKernel", "Matern52", "imq", "register_kernel", "check_kernel",
           "from_description",
           "as_kernel", "KERNELS", "kernel_kind", "kernel_named", "kernel_of_record", "KernelChoice"]

#: Registered kernels by the name their ``describe()`` gives (its ``kind``), with the short names users type
#: (``"imq"``, ``"matern52"``); names match in any case.
KERNELS: Registry[type] = Registry("kernel", case_sensitive=False)


def register_kernel(cls: type | None = None, *, aliases=(), description: str = ""):
    """Make ``cls`` (an :class:`ExactKernel` with a ``kind`` name) rebuildable from its description, and usable by
    its kind or an alias from the command line (``--kernel``), scene files (``kernel = ...``) and studies. A class
    decorator, bare or with arguments (``@register_kernel(aliases=("m32",))``); returns ``cls``.

    The contract's cheap checks (:func:`~torch_gpioius.kernels.base.check_kernel`: finite, symmetric, positive
    definite) run on ``cls()`` here, or, for a class that needs arguments, on its first instance built by name.

    Raises:
        TypeError: ``cls`` is not an :class:`ExactKernel` subclass.
        ValueError: its kind or an alias is taken by another kernel (a built-in's above all: a plugin never replaces
            ``Matern52``), or the kernel fails the contract's cheap checks (names the check).
    """
    if cls is None:
        return lambda c: register_kernel(c, aliases=aliases, description=description)
    if not (isinstance(cls, type) and issubclass(cls, ExactKernel)):
        raise TypeError(f"register_kernel: {cls!r} is not an ExactKernel subclass")
    for name in (cls.kind, *aliases):
        owner = KERNELS.owner(name)
        if owner is not None and not _same_definition(owner.obj, cls):
            raise ValueError(f"register_kernel: {name!r} is already the kernel {_where(owner.obj)}; a kernel of its "
                             f"own needs a kind of its own (class {cls.__name__}: kind = {cls.kind!r})")
    try:
        instance = cls()
    except TypeError:                       # arguments required: checked on its first instance built by name
        instance = None
    if instance is not None:
        try:
            check_kernel(instance)
        except ValueError as exc:
            raise ValueError(f"register_kernel: {exc}") from None
        _CHECKED.add(cls)
    doc = (cls.__doc__ or "").strip().splitlines()
    KERNELS.register(cls.kind, cls, aliases=aliases, description=description or (doc[0] if doc else ""),
                     replace=True)          # the same definition again (a module reloaded): its entry renewed
    return cls


#: Kernel classes whose cheap contract checks have passed.
_CHECKED: set = set()


def _same_definition(a, b) -> bool:
    """Whether two classes are one definition: the same object, or a module's class reloaded."""
    return a is b or (getattr(a, "__module__", None), getattr(a, "__qualname__", None)) == \
        (getattr(b, "__module__", None), getattr(b, "__qualname__", None))


def _where(cls) -> str:
    return f"{getattr(cls, '__module__', '?')}.{getattr(cls, '__qualname__', cls)}"


def _built(cls: type, **params) -> ExactKernel:
    """``cls(**params)``, the contract's cheap checks run on the first instance of a class not checked when it was
    registered."""
    kernel = cls(**params)
    if cls not in _CHECKED:
        check_kernel(kernel)
        _CHECKED.add(cls)
    return kernel


register_kernel(InverseMultiquadricKernel, aliases=("imq",), description="the paper's inverse multiquadric (eq. 5)")
register_kernel(Matern52, aliases=("matern52",), description="Matérn-5/2 (the default settings')")


def from_description(description: dict) -> ExactKernel:
    """The kernel a ``describe()`` dict names (``{"kernel": "Matern52", "lengthscale": 0.1, ...}``).

    Raises:
        ValueError: an unknown kernel name or bad parameters (names them).
    """
    if not isinstance(description, dict) or "kernel" not in description:
        raise ValueError(f"kernel description: expected a dict with a 'kernel' name, got {description!r}")
    params = {k: v for k, v in description.items() if k != "kernel"}
    if description["kernel"] == InverseMultiquadricKernel.kind and "theta" in params:
        params["lengthscale"] = params.pop("theta")          # descriptions written before lengthscale was its name
    cls = KERNELS[kernel_kind(description["kernel"])]
    try:
        return _built(cls, **params)
    except TypeError as exc:
        raise ValueError(f"kernel {description['kernel']}: bad parameters {params} ({exc})") from None


def as_kernel(kernel) -> ExactKernel:
    """``kernel`` if given (an :class:`ExactKernel`), else the paper's inverse multiquadric of length scale 0.1 m.

    Raises:
        TypeError: ``kernel`` is not an :class:`ExactKernel`.
    """
    if kernel is None:
        return InverseMultiquadricKernel(0.1)
    if not isinstance(kernel, ExactKernel):
        raise TypeError(f"kernel: expected a torch_gpioius.kernels.ExactKernel (e.g. Matern52(0.1)), got "
                        f"{type(kernel).__name__}")
    return kernel


def kernel_kind(name: str) -> str:
    """The registered kind a name users type stands for ("imq", "matern52", or a kind itself, any case).

    Raises:
        ValueError: a name no registered kernel has (lists the names).
    """
    return KERNELS.resolve(name)


def _checked_length(lengthscale) -> float:
    return as_kernel_length(lengthscale, "lengthscale")


def _recorded_length(lengthscale) -> float:
    """A length a file records (read as it was written, within the kernels' numerical support)."""
    return as_float(lengthscale, "lengthscale", positive=True, unit="m")


def kernel_named(name: str, lengthscale: float | None = None) -> ExactKernel:
    """A registered kernel by a name users type, at length scale ``lengthscale`` [m] (None: the kernel's own default).

    Raises:
        ValueError: an unknown name or a length that is not a finite positive number.
    """
    cls = KERNELS[kernel_kind(name)]
    return _built(cls) if lengthscale is None else _built(cls, lengthscale=_checked_length(lengthscale))


def kernel_of_record(meta: dict, default: ExactKernel | None = None) -> ExactKernel:
    """The kernel a record names: its ``kernel`` description, else (records written before kernels described
    themselves) the inverse multiquadric of its ``theta``, else ``default`` (the paper's inverse multiquadric at
    0.1 m when None). Logs, datasets, checkpoints and run folders all read their kernel here.

    Raises:
        ValueError: a description of an unknown kernel, or a ``theta`` that is not a positive length.
    """
    if isinstance(meta.get("kernel"), dict):
        return from_description(meta["kernel"])
    if meta.get("theta") is not None:
        return InverseMultiquadricKernel(lengthscale=_recorded_length(meta["theta"]))
    return copy.deepcopy(default) if default is not None else InverseMultiquadricKernel(0.1)


@dataclass(frozen=True)
class KernelChoice:
    """A kernel asked for by the names users type (the command line's ``--kernel`` and ``--lengthscale``, a scene
    file's ``kernel`` and ``theta``, a study's settings), applied to the kernel settings already hold.

    Attributes:
        name: "imq", "matern52" or a registered kind; None: the kind the settings hold.
        lengthscale: the length scale [m]; None: the held kernel's when of the same kind, else the kind's default.

    Raises:
        ValueError: an unknown name or a length that is not a finite positive number.
    """

    name: str | None = None
    lengthscale: float | None = None

    def __post_init__(self) -> None:
        if self.name is not None:
            kernel_kind(self.name)
        if self.lengthscale is not None:
            object.__setattr__(self, "lengthscale", _checked_length(self.lengthscale))

    def __bool__(self) -> bool:
        return self.name is not None or self.lengthscale is not None

    def apply(self, current: ExactKernel | None) -> ExactKernel:
        """The kernel chosen, on top of ``current`` (None: the paper's inverse multiquadric); a new object."""
        current = as_kernel(current)
        kind = current.kind if self.name is None else kernel_kind(self.name)
        if kind == current.kind:
            chosen = copy.deepcopy(current)
        else:
            chosen = KERNELS[kind]()
        if self.lengthscale is not None:
            if not chosen.learnable_length:
                raise ValueError(f"lengthscale: the {kind} kernel has no length to set")
            chosen.length = self.lengthscale
        return chosen

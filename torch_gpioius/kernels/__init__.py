"""Kernels of the GP models: the contract the exact engines rely on (:class:`ExactKernel`), the inverse
multiquadric of the paper (eq. 5, the default) and a Matérn-5/2.

A new kernel is one file: subclass :class:`ExactKernel`, implement its five methods (and, for its length to be
learned, :attr:`ExactKernel.length` and :meth:`ExactKernel.value_at` with ``learnable_length = True``), decorate the
class with :func:`register_kernel` (so logs and checkpoints can name it), and subclass the contract tests in
``tests/kernels/contract.py`` for its test file.
"""

from __future__ import annotations

from .base import ExactKernel
from .inverse_multiquadric import InverseMultiquadricKernel, imq
from .matern import Matern52

__all__ = ["ExactKernel", "InverseMultiquadricKernel", "Matern52", "imq", "register_kernel", "from_description",
           "as_kernel", "KERNELS"]

#: Registered kernels by the name their ``describe()`` gives.
KERNELS: dict[str, type] = {}


def register_kernel(cls: type) -> type:
    """Class decorator: make ``cls`` (an :class:`ExactKernel` with a ``kind`` name) rebuildable from its description."""
    if not (isinstance(cls, type) and issubclass(cls, ExactKernel)):
        raise TypeError(f"register_kernel: {cls!r} is not an ExactKernel subclass")
    KERNELS[cls.kind] = cls
    return cls


register_kernel(InverseMultiquadricKernel)
register_kernel(Matern52)


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
    cls = KERNELS.get(description["kernel"])
    if cls is None:
        raise ValueError(f"kernel: unknown {description['kernel']!r}; registered: {sorted(KERNELS)}")
    try:
        return cls(**params)
    except TypeError as exc:
        raise ValueError(f"kernel {description['kernel']}: bad parameters {params} ({exc})") from None


def as_kernel(kernel, theta: float | None) -> ExactKernel:
    """``kernel`` if given (an :class:`ExactKernel`), else the paper's inverse multiquadric with length scale
    ``theta`` [m] (the paper's name; 0.1 when None).

    Raises:
        TypeError: ``kernel`` is not an :class:`ExactKernel`.
    """
    if kernel is None:
        return InverseMultiquadricKernel(0.1 if theta is None else theta)
    if not isinstance(kernel, ExactKernel):
        raise TypeError(f"kernel: expected a torch_gpioius.kernels.ExactKernel (e.g. Matern52(0.1)), got "
                        f"{type(kernel).__name__}")
    return kernel

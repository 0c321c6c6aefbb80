"""What the exact engines need of a kernel: the contract a new kernel implements (:class:`ExactKernel`).

The models keep their kernel as ``covar_module`` (the GPyTorch idiom); the exact engines (dense, structured, local),
the metrics and the planner's closed-form gradients read it through four methods, all with the kernel's parameters
taken as constants:

* :meth:`ExactKernel.value` -- ``k(x1_i, x2_j)``, `(n, m)`, differentiable in the points;
* :meth:`ExactKernel.gradient` -- ``dk(x1_i, x2_j) / dx1_i``, `(d, n, m)`, in closed form (the planner queries it
  for every step; autograd would need a backward pass per output);
* :meth:`ExactKernel.prior_variance` -- ``k(x, x)`` times an amplitude (the prior variance of a task);
* :meth:`ExactKernel.second_derivative_at_zero` -- ``kappa''(0)`` of the radial profile ``k = kappa(|a - b|)``:
  the variance of a directional derivative of the process, ``-kappa''(0)`` per unit direction (for gradient or
  normal observations and for checks of smoothness).

For hyper-parameter learning (``GPIOIS.learn_hyperparameters``) a kernel also names its length, optionally:

* :attr:`ExactKernel.length` -- the length [m] that sets how far correlation reaches (the inverse multiquadric's
  theta, the Matérn length scale), read and set as a float and stored as a constrained torch parameter (the
  GPyTorch idiom: ``raw_theta``, ``raw_lengthscale``), so that it is in ``state_dict`` and checkpoints;
* :meth:`ExactKernel.value_at` -- the values at a given length, differentiable in that length (a tensor).

A kernel without them stays usable everywhere with its length fixed; learning it then raises a ``TypeError``.

Stationarity is part of the contract: ``k(a, b)`` depends on ``a - b`` only (isotropic kernels on ``|a - b|``).
:meth:`ExactKernel.describe` names the kernel and its parameters for logs, checkpoints and resume, and
:func:`torch_gpioius.kernels.from_description` rebuilds it. :class:`torch_gpioius.testing.KernelContract` holds the
checks every kernel must pass (values against ``forward``, gradients against autograd, the second derivative against
finite differences, positive definite Gram matrices); a new kernel's test file subclasses it.
"""

from __future__ import annotations

import abc

from gpytorch.kernels import Kernel
from torch import Tensor

__all__ = ["ExactKernel", "check_kernel"]


class ExactKernel(Kernel, abc.ABC):
    """A stationary ``gpytorch.kernels.Kernel`` that the exact engines can use (see the module docstring).

    Subclasses implement :meth:`value`, :meth:`gradient`, :meth:`prior_variance`,
    :meth:`second_derivative_at_zero` and :meth:`describe`; :meth:`forward` (GPyTorch's entry point) defaults to
    :meth:`value`, so a subclass whose parameters are fixed need not write it. Registered kernels (the
    ``@register_kernel`` decorator of :mod:`torch_gpioius.kernels`) can be rebuilt from :meth:`describe`.
    """

    is_stationary = True
    has_lengthscale = False

    @abc.abstractmethod
    def value(self, x1: Tensor, x2: Tensor) -> Tensor:
        """`(n, m)` kernel values between `(n, d)` and `(m, d)` points [m], parameters as constants."""

    @abc.abstractmethod
    def gradient(self, x1: Tensor, x2: Tensor, value: Tensor | None = None) -> Tensor:
        """`(d, n, m)` derivatives ``dk(x1_i, x2_j) / dx1_i`` in closed form; ``value`` (`(n, m)`, from :meth:`value`)
        may be passed to save its recomputation."""

    @abc.abstractmethod
    def prior_variance(self, scale: float | Tensor = 1.0):
        """``k(x, x) * scale``: the prior variance of a process with amplitude ``scale`` (e.g. ``K_t[t, t]``)."""

    @abc.abstractmethod
    def second_derivative_at_zero(self) -> float:
        """``kappa''(0)`` of the radial profile ``k(a, b) = kappa(|a - b|)`` [1 / m^2 in the kernel's units]."""

    @abc.abstractmethod
    def describe(self) -> dict:
        """JSON-able ``{"kernel": name, **parameters}`` (logs, checkpoints, resume)."""

    #: Whether the kernel implements :attr:`length` and :meth:`value_at` (hyper-parameter learning).
    learnable_length: bool = False

    @property
    def length(self) -> float:
        """The kernel's length [m] (theta, the length scale), where :attr:`learnable_length` says it has one."""
        raise TypeError(f"{type(self).__name__}: no learnable length (implement length and value_at)")

    @length.setter
    def length(self, value: float) -> None:
        raise TypeError(f"{type(self).__name__}: no learnable length (implement length and value_at)")

    def value_at(self, x1: Tensor, x2: Tensor, length: Tensor) -> Tensor:
        """`(n, m)` values at the length ``length`` (a 0-d tensor [m]), differentiable in it and in the points."""
        raise TypeError(f"{type(self).__name__}: no learnable length (implement length and value_at)")

    def forward(self, x1: Tensor, x2: Tensor, diag: bool = False, last_dim_is_batch: bool = False, **params) -> Tensor:
        """GPyTorch's entry point: the kernel matrix `(..., n, m)` (or its diagonal with ``diag=True``)."""
        if last_dim_is_batch:
            raise NotImplementedError(f"{type(self).__name__}: last_dim_is_batch is not supported")
        if diag:
            return self.prior_variance(1.0) * x1.new_ones(x1.shape[:-1])
        return self.value(x1, x2)


def check_kernel(kernel: ExactKernel, dim: int = 3, points: int = 40, scale: float = 0.2) -> None:
    """The contract's cheap checks on one kernel object, run when a kernel is registered or first built by name (a
    kernel that fails them made every run of a study fail with a Cholesky error, and the study exit 0).

    Values are checked on ``points`` seeded points in a cube of half-edge ``scale`` [m]: their shape and dtype,
    finiteness, symmetry, the diagonal against :meth:`ExactKernel.prior_variance`, a positive semi-definite Gram
    matrix (smallest eigenvalue above ``-1e-9`` of the largest) and the gradient's shape. The full contract (gradients
    against autograd, the second derivative) is :class:`torch_gpioius.testing.KernelContract`'s, for a test file.

    Raises:
        ValueError: naming the kernel and the first check it fails.
    """
    import torch

    name = type(kernel).__name__
    gen = torch.Generator().manual_seed(0)
    a = (torch.rand(points, dim, generator=gen, dtype=torch.float64) * 2 - 1) * scale
    try:
        with torch.no_grad():
            v = kernel.value(a, a)
            g = kernel.gradient(a[:3], a[:5])
            prior = float(kernel.prior_variance(1.0))
    except Exception as exc:                  # a kernel's own error, whatever it is, is named with the kernel
        raise ValueError(f"kernel {name}: its value, gradient or prior variance fails on {points} points "
                         f"({type(exc).__name__}: {exc})") from exc
    if tuple(v.shape) != (points, points) or v.dtype != torch.float64:
        raise ValueError(f"kernel {name}: value(x, x) of {points} points must be a ({points}, {points}) float64 "
                         f"tensor, got {tuple(v.shape)} {v.dtype}")
    if not torch.isfinite(v).all() or not (prior > 0 and prior < float("inf")):
        raise ValueError(f"kernel {name}: values must be finite and the prior variance positive (got "
                         f"{prior!r})")
    if not torch.allclose(v, v.T, rtol=1e-12, atol=1e-14 * prior):
        raise ValueError(f"kernel {name}: value(x, x) is not symmetric")
    if not torch.allclose(torch.diagonal(v), torch.full((points,), prior, dtype=v.dtype), rtol=1e-10, atol=0.0):
        raise ValueError(f"kernel {name}: the diagonal of value(x, x) is not prior_variance(1) = {prior:g}")
    eig = torch.linalg.eigvalsh(v)
    if float(eig.min()) < -1e-9 * float(eig.max()):
        raise ValueError(f"kernel {name}: not positive definite: the Gram matrix of {points} points has the "
                         f"eigenvalue {float(eig.min()):.3g} (largest {float(eig.max()):.3g}); a GP needs a "
                         "positive definite kernel")
    if tuple(g.shape) != (dim, 3, 5):
        raise ValueError(f"kernel {name}: gradient(x1, x2) of (3, {dim}) and (5, {dim}) points must be "
                         f"({dim}, 3, 5), got {tuple(g.shape)}")

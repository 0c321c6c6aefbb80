r"""Matérn kernel with smoothness 5/2: the second kernel, and the proof that a kernel is one file.

.. math::
    k(\mathbf a, \mathbf b) = \sigma^2 \left(1 + \frac{\sqrt5\, r}{\ell} + \frac{5 r^2}{3 \ell^2}\right)
    e^{-\sqrt5\, r / \ell}, \qquad r = \|\mathbf a - \mathbf b\|

Twice differentiable (the inverse multiquadric is infinitely so): level sets of a GPIS under it are smooth, but less
rounded between sparse contacts. The length scale is a constrained torch parameter (GPyTorch's ``raw_lengthscale``,
``kernel.lengthscale``); it is fixed during exploration, as the paper fixes theta, unless the exploration learns it
(``learn="length"`` or ``"all"``, :meth:`torch_gpioius.GPIOIS.learn_hyperparameters`).
"""

from __future__ import annotations

import math

import torch
from gpytorch.constraints import GreaterThan
from torch import Tensor

from ..core.validation import as_float
from ..core.tolerances import tol
from .base import ExactKernel

__all__ = ["Matern52"]

_SQRT5 = math.sqrt(5.0)


class Matern52(ExactKernel):
    """Matérn-5/2 kernel with a length scale and a fixed amplitude (see the module docstring).

    Args:
        lengthscale: ``ell`` [m], in the range of ``tol.theta_range``.
        outputscale: ``sigma^2``, the prior variance ``k(x, x)`` (positive).

    Example:
        >>> model = tg.GPIOIS(x, y, task, kernel=tg.kernels.Matern52(0.1), noise=0.006).fit()
    """

    kind = "Matern52"
    has_lengthscale = True          # GPyTorch registers raw_lengthscale (Positive) and its lengthscale property
    learnable_length = True

    def __init__(self, lengthscale: float = 0.1, outputscale: float = 1.0, **kwargs) -> None:
        # the raw parameter is the length scale itself (no softplus: 0.1 stays 0.1 to the bit, as the describe/rebuild
        # round trip and resumed runs need); its range is checked where it is set and by the models' check_state
        kwargs.setdefault("lengthscale_constraint", GreaterThan(tol.theta_range[0], transform=None))
        super().__init__(**kwargs)
        ell = as_float(lengthscale, "lengthscale", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True,
                       unit="m")
        # float64 from the start (GPyTorch makes it in the default dtype): a float32 0.1 is 1.5e-9 off
        self.raw_lengthscale = torch.nn.Parameter(torch.zeros(*self.batch_shape, 1, 1, dtype=torch.float64),
                                                  requires_grad=False)
        self.length = ell
        self.sigma2 = as_float(outputscale, "outputscale", lo=1e-12, hi=1e12, positive=True)

    @property
    def ell(self) -> float:
        """The length scale [m] as a float (the exact engines take the parameters as constants)."""
        return float(self.lengthscale.detach().reshape(-1)[0])

    @property
    def length(self) -> float:
        """The length scale [m] (the contract's learnable length)."""
        return self.ell

    @length.setter
    def length(self, value: float) -> None:
        value = as_float(value, "lengthscale", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True, unit="m")
        self.initialize(raw_lengthscale=self.raw_lengthscale_constraint.inverse_transform(
            torch.full_like(self.raw_lengthscale, value)))

    def _radius(self, x1: Tensor, x2: Tensor) -> Tensor:
        # direct differences (no |a|^2 + |b|^2 - 2ab cancellation), as for the inverse multiquadric
        return torch.cdist(x1, x2, compute_mode="donot_use_mm_for_euclid_dist")

    def value(self, x1: Tensor, x2: Tensor) -> Tensor:
        return self.value_at(x1, x2, self.ell)

    def value_at(self, x1: Tensor, x2: Tensor, length: Tensor | float) -> Tensor:
        """`(n, m)` values at the length scale ``length`` (0-d tensor [m]), differentiable in it."""
        scalar = not isinstance(length, Tensor) or length.dim() == 0
        needs_graph = torch.is_grad_enabled() and (x1.requires_grad or x2.requires_grad
                                                   or (isinstance(length, Tensor) and length.requires_grad))
        if scalar and not needs_graph and x1.dim() == 2 and x2.dim() == 2:
            return self._value_in_place(x1, x2, length)
        s = _SQRT5 * self._radius(x1, x2) / length
        return self.sigma2 * (1.0 + s + s * s / 3.0) * torch.exp(-s)

    #: rows of a block of :meth:`_value_in_place` (its temporaries stay a few MB, in cache, for any number of points)
    _BLOCK = 512

    def _value_in_place(self, x1: Tensor, x2: Tensor, length: Tensor | float) -> Tensor:
        """The values of :meth:`value_at` without a graph, to the bit: the same operations in the same order, done in
        place on row blocks. Meshing and measuring an estimate evaluates the kernel between a grid and every
        observation; the expression above allocates five `(n, m)` temporaries, and this runs 2-3x faster."""
        out = torch.empty(x1.shape[0], x2.shape[0], dtype=torch.result_type(x1, x2), device=x1.device)
        for i in range(0, x1.shape[0], self._BLOCK):
            s = self._radius(x1[i:i + self._BLOCK], x2).mul_(_SQRT5).div_(length)
            t = (s * s).div_(3.0)
            p = out[i:i + self._BLOCK]
            torch.add(s, 1.0, out=p)
            p.add_(t).mul_(self.sigma2).mul_(s.neg_().exp_())
        return out

    def forward(self, x1: Tensor, x2: Tensor, diag: bool = False, last_dim_is_batch: bool = False, **params) -> Tensor:
        """GPyTorch's entry point, differentiable in ``raw_lengthscale`` (for a user's own training loop)."""
        if last_dim_is_batch:
            raise NotImplementedError(f"{type(self).__name__}: last_dim_is_batch is not supported")
        if diag:
            return self.prior_variance(1.0) * x1.new_ones(torch.broadcast_shapes(self.batch_shape, x1.shape[:-2])
                                                          + x1.shape[-2:-1])
        # a batch of kernels (GPyTorch's batch_shape) has a length per batch member, `(*batch, 1, 1)`
        length = self.lengthscale if len(self.batch_shape) else self.lengthscale.reshape(())
        return self.value_at(x1, x2, length)

    def gradient(self, x1: Tensor, x2: Tensor, value: Tensor | None = None) -> Tensor:
        """``dk/da = -sigma^2 (5 / (3 ell^2)) (1 + s) e^(-s) (a - b)``, ``s = sqrt(5) r / ell``: smooth at r = 0."""
        s = _SQRT5 * self._radius(x1, x2) / self.ell
        coef = -self.sigma2 * 5.0 / (3.0 * self.ell ** 2) * (1.0 + s) * torch.exp(-s)      # (n, m)
        diff = x1.unsqueeze(1) - x2.unsqueeze(0)                                         # (n, m, d)
        return (diff * coef.unsqueeze(-1)).permute(2, 0, 1)

    def prior_variance(self, scale: float | Tensor = 1.0):
        return scale * self.sigma2

    def second_derivative_at_zero(self) -> float:
        """``kappa''(0) = -sigma^2 5 / (3 ell^2)``."""
        return -self.sigma2 * 5.0 / (3.0 * self.ell ** 2)

    def describe(self) -> dict:
        return {"kernel": self.kind, "lengthscale": self.ell, "outputscale": self.sigma2}

    def __repr__(self) -> str:
        return f"Matern52(lengthscale={self.ell:g}, outputscale={self.sigma2:g})"

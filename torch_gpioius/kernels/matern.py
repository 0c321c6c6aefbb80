r"""Matérn kernel with smoothness 5/2: the second kernel, and the proof that a kernel is one file.

.. math::
    k(\mathbf a, \mathbf b) = \sigma^2 \left(1 + \frac{\sqrt5\, r}{\ell} + \frac{5 r^2}{3 \ell^2}\right)
    e^{-\sqrt5\, r / \ell}, \qquad r = \|\mathbf a - \mathbf b\|

Twice differentiable (the inverse multiquadric is infinitely so): level sets of a GPIS under it are smooth, but less
rounded between sparse contacts. Its parameters are fixed during exploration, as the paper fixes theta.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from .._validation import as_float
from ..tolerances import tol
from .base import ExactKernel

__all__ = ["Matern52"]

_SQRT5 = math.sqrt(5.0)


class Matern52(ExactKernel):
    """Matérn-5/2 kernel with a fixed length scale and amplitude (see the module docstring).

    Args:
        lengthscale: ``ell`` [m], in the range of ``tol.theta_range``.
        outputscale: ``sigma^2``, the prior variance ``k(x, x)`` (positive).

    Example:
        >>> model = tg.GPIOIS(x, y, task, kernel=tg.kernels.Matern52(0.1), noise=0.006).fit()
    """

    kind = "Matern52"

    def __init__(self, lengthscale: float = 0.1, outputscale: float = 1.0, **kwargs) -> None:
        super().__init__(**kwargs)
        self.ell = as_float(lengthscale, "lengthscale", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True,
                            unit="m")
        self.sigma2 = as_float(outputscale, "outputscale", lo=1e-12, hi=1e12, positive=True)

    def _radius(self, x1: Tensor, x2: Tensor) -> Tensor:
        # direct differences (no |a|^2 + |b|^2 - 2ab cancellation), as for the inverse multiquadric
        return torch.cdist(x1, x2, compute_mode="donot_use_mm_for_euclid_dist")

    def value(self, x1: Tensor, x2: Tensor) -> Tensor:
        s = _SQRT5 * self._radius(x1, x2) / self.ell
        return self.sigma2 * (1.0 + s + s * s / 3.0) * torch.exp(-s)

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

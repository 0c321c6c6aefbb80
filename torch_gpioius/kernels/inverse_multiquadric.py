"""Inverse multiquadric kernel, eq. (5) of the paper: the default kernel of every model."""

from __future__ import annotations

import torch
from gpytorch.constraints import Interval, Positive
from torch import Tensor

from .._validation import as_float
from ..tolerances import tol
from .base import ExactKernel

__all__ = ["InverseMultiquadricKernel", "imq"]


def imq(x1: Tensor, x2: Tensor, theta: Tensor | float, diag: bool = False) -> Tensor:
    r"""Inverse multiquadric kernel values, eq. (5): :math:`k(a, b) = (\|a - b\|^2 + \theta^2)^{-1/2}`.

    A small pure function shared by the GPyTorch kernel and the library's exact inference engine, so both
    evaluate the same arithmetic.

    Args:
        x1: `(..., n, d)` points [m].
        x2: `(..., m, d)` points [m].
        theta: kernel parameter theta_x [m]: a float, or a tensor broadcastable to the result.
        diag: if True, return the `(..., n)` values k(x1[i], x2[i]) (requires n == m).

    Returns:
        `(..., n, m)` kernel matrix [1/m], or `(..., n)` with ``diag=True``.
    """
    if diag:
        return ((x1 - x2).pow(2).sum(-1) + theta**2).rsqrt()
    # Distances by direct differences (cdist without its matmul shortcut): exact to rounding, no
    # ||a||^2 + ||b||^2 - 2ab cancellation, which matters for posterior variances near data (~1e-6 against a
    # prior of ~10); 4x faster than broadcasting, and its gradient at zero distance is 0, not NaN.
    dist = torch.cdist(x1, x2, compute_mode="donot_use_mm_for_euclid_dist")
    return (dist.pow(2) + theta**2).rsqrt()


class InverseMultiquadricKernel(ExactKernel):
    r"""Inverse multiquadric (IMQ) kernel of eq. (5), a ``gpytorch.kernels.Kernel``.

    .. math::
        k_x(\mathbf a, \mathbf b) = \left(\|\mathbf a - \mathbf b\|_2^2 + \theta_x^2\right)^{-1/2}

    The prior variance is ``k(x, x) = 1 / theta``. ``theta`` is stored as ``raw_theta`` with a positive
    constraint (GPyTorch style, see ``IndexKernel.var``). It is fixed by default, as during exploration
    (Sec. IV-A: "the other kernel parameters are fixed"); pass ``learn_theta=True`` to make it trainable in the
    GPyTorch idiom (``ExactMarginalLogLikelihood`` + a torch optimiser).

    Args:
        theta: kernel parameter theta_x [m], > 0.
        learn_theta: make ``raw_theta`` require gradients.
        theta_constraint: constraint on theta (default ``Positive()``).
        **kwargs: forwarded to ``gpytorch.kernels.Kernel`` (e.g. ``batch_shape``, ``active_dims``).

    Example:
        >>> k = InverseMultiquadricKernel(theta=0.1)
        >>> K = k(torch.zeros(3, 2, dtype=torch.float64)).to_dense()   # (3, 3), all 10.0
    """

    has_lengthscale = False
    is_stationary = True
    #: The name :meth:`describe` gives (and :func:`torch_gpioius.kernels.from_description` reads).
    kind = "InverseMultiquadric"
    learnable_length = True

    def __init__(self, theta: float = 0.1, learn_theta: bool = False, theta_constraint: Interval | None = None,
                 **kwargs):
        super().__init__(**kwargs)
        theta = as_float(theta, "theta", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True, unit="m")
        if theta_constraint is None:
            theta_constraint = Positive()
        self.register_parameter("raw_theta", torch.nn.Parameter(torch.zeros(*self.batch_shape, 1, 1,
                                                                            dtype=torch.float64)))
        self.register_constraint("raw_theta", theta_constraint)
        self.theta = theta
        self.raw_theta.requires_grad_(learn_theta)

    @property
    def theta(self) -> Tensor:
        """`(*batch_shape, 1, 1)` kernel parameter theta_x [m]."""
        return self.raw_theta_constraint.transform(self.raw_theta)

    @theta.setter
    def theta(self, value: float | Tensor) -> None:
        value = torch.as_tensor(value, dtype=self.raw_theta.dtype, device=self.raw_theta.device)
        lo, hi = tol.theta_range
        if not bool(torch.isfinite(value).all()) or not bool(((value >= lo) & (value <= hi)).all()):
            raise ValueError(f"theta: must be finite within [{lo:g}, {hi:g}] m, got {value.flatten()[:4].tolist()}")
        self.initialize(raw_theta=self.raw_theta_constraint.inverse_transform(value.expand_as(self.raw_theta)))

    def _theta(self) -> float:
        """theta as a Python float (the exact engines take the parameters as constants)."""
        return float(self.theta.detach().reshape(-1)[0])

    @property
    def length(self) -> float:
        """theta [m] (the contract's learnable length)."""
        return self._theta()

    @length.setter
    def length(self, value: float) -> None:
        self.theta = as_float(value, "theta", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True, unit="m")

    def value(self, x1: Tensor, x2: Tensor) -> Tensor:
        """`(n, m)` values ``(|a - b|^2 + theta^2)^(-1/2)`` [1/m], differentiable in the points."""
        return imq(x1, x2, self._theta())

    def value_at(self, x1: Tensor, x2: Tensor, length: Tensor) -> Tensor:
        """`(n, m)` values at ``theta = length`` (0-d tensor [m]), differentiable in it."""
        return imq(x1, x2, length)

    def gradient(self, x1: Tensor, x2: Tensor, value: Tensor | None = None) -> Tensor:
        """`(d, n, m)`: ``dk/da = -(a - b) k^3``."""
        k = self.value(x1, x2) if value is None else value
        diff = x1.unsqueeze(1) - x2.unsqueeze(0)                                       # (n, m, d)
        return -(diff * (k * k * k).unsqueeze(-1)).permute(2, 0, 1)

    def prior_variance(self, scale: float | Tensor = 1.0):
        """``k(x, x) * scale = scale / theta``."""
        return scale / self._theta()

    def second_derivative_at_zero(self) -> float:
        """``kappa''(0) = -1 / theta^3`` for ``kappa(r) = (r^2 + theta^2)^(-1/2)``."""
        return -1.0 / self._theta() ** 3

    def describe(self) -> dict:
        return {"kernel": self.kind, "theta": self._theta()}

    def forward(self, x1: Tensor, x2: Tensor, diag: bool = False, last_dim_is_batch: bool = False,
                **params) -> Tensor:
        """Kernel matrix `(..., n, m)` (or its diagonal `(..., n)` with ``diag=True``)."""
        if last_dim_is_batch:
            x1 = x1.transpose(-1, -2).unsqueeze(-1)
            x2 = x2.transpose(-1, -2).unsqueeze(-1)
        theta = self.theta.to(x1.dtype)
        if last_dim_is_batch:
            theta = theta.unsqueeze(-3)
        if diag:
            return imq(x1, x2, theta.squeeze(-1), diag=True)
        return imq(x1, x2, theta)

"""Inverse multiquadric kernel, eq. (5) of the paper: the default kernel of every model."""

from __future__ import annotations

import torch
from gpytorch.constraints import Interval, Positive
from torch import Tensor

from ..core.validation import as_float
from ..core.tolerances import tol
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

    The prior variance is ``k(x, x) = 1 / theta``. The paper's ``theta`` is this kernel's length scale: in code it
    is ``lengthscale`` (GPyTorch's name, the one every kernel of the library uses), stored as ``raw_theta`` with a
    positive constraint (GPyTorch style, see ``IndexKernel.var``; the storage name stays, so that checkpoints and
    logs of earlier versions load). It is fixed by default, as during exploration (Sec. IV-A: "the other kernel
    parameters are fixed"); pass ``learn_lengthscale=True`` to make it trainable in the GPyTorch idiom
    (``ExactMarginalLogLikelihood`` + a torch optimiser).

    Args:
        lengthscale: theta_x [m], > 0.
        learn_lengthscale: make ``raw_theta`` require gradients.
        theta_constraint: constraint on theta (default ``Positive()``).
        theta: the paper's name for ``lengthscale`` (deprecated alias).
        learn_theta: the earlier name of ``learn_lengthscale`` (deprecated alias).
        **kwargs: forwarded to ``gpytorch.kernels.Kernel`` (e.g. ``batch_shape``, ``active_dims``).

    Example:
        >>> k = InverseMultiquadricKernel(lengthscale=0.1)
        >>> K = k(torch.zeros(3, 2, dtype=torch.float64)).to_dense()   # (3, 3), all 10.0
    """

    has_lengthscale = False         # GPyTorch's own raw_lengthscale is not registered: raw_theta holds it
    is_stationary = True
    #: The name :meth:`describe` gives (and :func:`torch_gpioius.kernels.from_description` reads).
    kind = "InverseMultiquadric"
    learnable_length = True

    def __init__(self, lengthscale: float | None = None, learn_lengthscale: bool = False,
                 theta_constraint: Interval | None = None, *, theta: float | None = None,
                 learn_theta: bool | None = None, **kwargs):
        super().__init__(**kwargs)
        if theta is not None:
            if lengthscale is not None:
                raise ValueError("lengthscale and theta: give one (theta is the paper's name for the lengthscale)")
            import warnings

            warnings.warn("InverseMultiquadricKernel(theta=...) is InverseMultiquadricKernel(lengthscale=...) now",
                          DeprecationWarning, stacklevel=2)
            lengthscale = theta
        if learn_theta is not None:
            learn_lengthscale = learn_theta
        length = as_float(0.1 if lengthscale is None else lengthscale, "lengthscale", lo=tol.theta_range[0],
                          hi=tol.theta_range[1], positive=True, unit="m")
        if theta_constraint is None:
            theta_constraint = Positive()
        self.register_parameter("raw_theta", torch.nn.Parameter(torch.zeros(*self.batch_shape, 1, 1,
                                                                            dtype=torch.float64)))
        self.register_constraint("raw_theta", theta_constraint)
        self.theta = length
        self.raw_theta.requires_grad_(bool(learn_lengthscale))

    @property
    def theta(self) -> Tensor:
        """`(*batch_shape, 1, 1)` the paper's theta_x [m]: :attr:`lengthscale`."""
        return self.raw_theta_constraint.transform(self.raw_theta)

    @theta.setter
    def theta(self, value: float | Tensor) -> None:
        value = torch.as_tensor(value, dtype=self.raw_theta.dtype, device=self.raw_theta.device)
        lo, hi = tol.theta_range
        if not bool(torch.isfinite(value).all()) or not bool(((value >= lo) & (value <= hi)).all()):
            raise ValueError(f"lengthscale: must be finite within [{lo:g}, {hi:g}] m, got "
                             f"{value.flatten()[:4].tolist()}")
        self.initialize(raw_theta=self.raw_theta_constraint.inverse_transform(value.expand_as(self.raw_theta)))
        # the length as given, while the raw parameter holds it (softplus and back can move the last bit, and a
        # run that restarts its learning from the configured length must start from the same bits)
        self._given = float(value.reshape(-1)[0]) if value.numel() == 1 or bool((value == value.flatten()[0]).all()) \
            else None
        self._given_raw = self.raw_theta.detach().cpu().clone()

    @property
    def lengthscale(self) -> Tensor:
        """`(*batch_shape, 1, 1)` the length scale [m] (the paper's theta_x), GPyTorch's name."""
        return self.theta

    @lengthscale.setter
    def lengthscale(self, value: float | Tensor) -> None:
        self.theta = value

    def _theta(self) -> float:
        """theta as a Python float (the exact engines take the parameters as constants)."""
        return float(self.theta.detach().reshape(-1)[0])

    @property
    def length(self) -> float:
        """The length scale [m] as a float (the contract's learnable length; the paper's theta): the value it was
        set to, while its raw parameter is unchanged since."""
        given = getattr(self, "_given", None)
        raw = self.raw_theta.detach().cpu()
        if given is not None and raw.dtype == self._given_raw.dtype and torch.equal(self._given_raw, raw):
            return given
        return self._theta()

    @length.setter
    def length(self, value: float) -> None:
        self.theta = as_float(value, "lengthscale", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True,
                              unit="m")

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
        return {"kernel": self.kind, "lengthscale": self.length}

    def __repr__(self) -> str:
        return f"InverseMultiquadricKernel(lengthscale={self.length:g})"

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

"""The contract of the exact engines (:class:`ExactEngine`): what the models and K_t's fitter ask of an engine,
declared rather than probed.

An engine holds the training data and answers, for a task covariance ``b`` (K_t, `(2, 2)`; a local model's loadings
for :mod:`.local`), the exact log marginal likelihood (eq. 16) with its derivatives, and the posterior (eq. 12-13).
The engines are :class:`~torch_gpioius.inference.DenseExactInference` (one dense Cholesky factor),
:class:`~torch_gpioius.inference.StructuredExactInference` (outer block rotated, inner Schur complement) and its
batched and direct variants, and the local engines of :mod:`.local`.
"""

from __future__ import annotations

import abc
from typing import Callable

from torch import Tensor

__all__ = ["ExactEngine"]


class ExactEngine(abc.ABC):
    """An exact GP engine (see the module docstring).

    Subclasses implement :meth:`append`, :meth:`mll`, :meth:`mll_derivatives`, :meth:`predict` and
    :meth:`predict_mean`; the rest has defaults they override where they have something cheaper or more.

    Attributes:
        value_alone: :meth:`mll_value` costs less than :meth:`mll_derivatives`, so K_t's fit judges its trial points
            by the value alone (``optim.maximize_mll(level=...)``); False: by the derivatives, as the dense engine
            always has (its trial points cost a factorisation either way).
        closed_form_gradients: :meth:`predict_with_gradients` gives the x-gradients of the mean and variance in
            closed form; False: the model differentiates :meth:`predict` by autograd.
    """

    value_alone: bool = False
    closed_form_gradients: bool = False

    @abc.abstractmethod
    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        """Append observations `(k, d)`, `(k,)`, `(k,)`, reusing what is cached."""

    @abc.abstractmethod
    def mll(self, b: Tensor) -> Tensor:
        """The exact log marginal likelihood at ``b`` (a 0-d tensor)."""

    @abc.abstractmethod
    def mll_derivatives(self, b: Tensor) -> tuple[float, Tensor, Tensor]:
        """The log marginal likelihood at ``b`` with its gradient and Hessian in ``b``'s free entries."""

    @abc.abstractmethod
    def predict(self, xq: Tensor, task: int, b: Tensor, chunk: int = 4096) -> tuple[Tensor, Tensor]:
        """Posterior mean and variance `(m,)`, `(m,)` of task ``task`` at ``xq`` `(m, d)` [m]."""

    @abc.abstractmethod
    def predict_mean(self, xq: Tensor, task: int, b: Tensor, chunk: int = 4096) -> Tensor:
        """Posterior mean `(m,)` of task ``task`` at ``xq`` `(m, d)` [m]."""

    def mll_value(self, b: Tensor) -> float:
        """The log marginal likelihood at ``b`` alone."""
        return float(self.mll(b))

    def mll_gradient(self, b: Tensor) -> tuple[float, Tensor]:
        """The log marginal likelihood at ``b`` and its gradient (by default from :meth:`mll_derivatives`)."""
        value, grad, _ = self.mll_derivatives(b)
        return value, grad

    def predict_with_gradients(self, xq: Tensor, task: int, b: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Mean, variance and their x-gradients at ``xq``, where :attr:`closed_form_gradients` holds."""
        raise NotImplementedError(f"{type(self).__name__} has no closed-form gradients; differentiate predict()")

    def truncation(self, c: float) -> float:
        """Bound on a truncated outer basis' change of the Gram matrix relative to sigma^2 (0: exact)."""
        return 0.0

    def scout_engine(self) -> Callable[..., "ExactEngine"]:
        """The engine class (or factory, same arguments) for a thinned copy of this engine's data, which K_t's
        restarts run on (``GPIOIS.fit(scout=...)``): this engine's own class by default."""
        return type(self)

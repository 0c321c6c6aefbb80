"""Gaussian process implicit surface (GPIS), Sec. III-A, eq. (1)-(5): the tactile-only baseline."""

from __future__ import annotations

import torch
from gpytorch.distributions import MultivariateNormal
from torch import Tensor

from .base import ImplicitSurfaceGP, deprecated_theta
from ..core.validation import as_labels, as_points

__all__ = ["GPIS"]


class GPIS(ImplicitSurfaceGP):
    r"""Single-task GPIS: an ``ExactGP`` regressing the implicit function F of one shape.

    Prior ``F ~ GP(m, k_x)`` with ``m = 1`` (almost all space is outside the object) and the IMQ kernel of
    eq. (5); labels ``y = 0`` on the surface and ``y = 1`` in free space; the estimated shape is
    ``{x : mu(x) = 0}`` with ``mu < 0`` inside (eq. 4). Noise ``sigma^2`` and ``theta`` are fixed unless
    ``learn_hyperparameters`` learns them.

    Args:
        train_x: `(n, d)` observed points [m], base frame.
        train_y: `(n,)` labels in {0, 1}.
        theta: IMQ kernel parameter theta_x [m] (eq. 5; ignored when ``kernel`` is given).
        noise: noise variance sigma^2.
        learn_theta: make theta trainable in a user's own GPyTorch training loop (``fit`` never changes it;
            ``learn_hyperparameters`` learns it by the exact marginal likelihood).
        kernel: any :class:`~torch_gpioius.kernels.ExactKernel` in place of the inverse multiquadric.
        device: where the data and the exact arithmetic live ("cpu", "cuda", a ``torch.device``; default: where
            ``train_x`` is). Always float64.

    Raises:
        ValueError: NaN/inf coordinates, empty data, wrong shapes, labels outside {0, 1}.
    """

    num_tasks = 1

    def __init__(self, train_x, train_y, theta: float | None = None, noise: float = 0.006, learn_theta: bool = False,
                 kernel=None, device=None):
        deprecated_theta(theta, "GPIS")
        x = as_points(train_x, "train_x")
        y = as_labels(train_y, x.shape[0], "train_y")
        super().__init__((x,), y, theta, noise, learn_theta, kernel)
        self.to_device(device)

    def forward(self, x: Tensor) -> MultivariateNormal:
        """GPyTorch prior of F at `(n, d)` points."""
        return MultivariateNormal(self.mean_module(x), self.covar_module(x))

    def _task_matrix(self) -> Tensor:
        return torch.ones(1, 1, dtype=self.train_inputs[0].dtype, device=self.train_inputs[0].device)

    def _train_task(self) -> Tensor:
        return torch.zeros(self.train_inputs[0].shape[0], dtype=torch.long, device=self.train_inputs[0].device)

    def fit(self, multi_start: bool | None = None) -> "GPIS":
        """Nothing is learned in GPIS (theta, sigma^2 and m are fixed, eq. 1-5); refreshes the exact factors.

        Present so that GPIS and GPIOIS follow the same protocol during exploration (``multi_start`` is accepted for
        that and has nothing to start).

        Returns:
            self
        """
        self._inference().factor(self._task_matrix())
        return self

    def predict(self, x, task: int | str = 0) -> tuple[Tensor, Tensor]:
        """Posterior mean and variance of F, eq. (2)-(3). Differentiable with respect to ``x``.

        Args:
            x: `(m, d)` query points [m], base frame.
            task: the inner shape (0 or "inner"), the only one a GPIS has; accepted so that GPIS and GPIOIS answer
                the same call (a tactile-only fit is a GPIS).

        Returns:
            `(m,)` mean (``< 0`` inside, ``0`` on the surface) and `(m,)` variance.

        Raises:
            ValueError: ``task`` is the outer shape, which a GPIS does not model.
        """
        return self._predict(x, _inner_only(task))

    def predict_mean(self, x, task: int | str = 0) -> Tensor:
        """Posterior mean of F, eq. (2), without the variance: ``O(m n)`` where :meth:`predict` costs ``O(m n^2)``
        (meshing the estimate on a grid). Differentiable with respect to ``x``.

        Args:
            x: `(m, d)` query points [m], base frame.
            task: 0 / "inner" (see :meth:`predict`).

        Returns:
            `(m,)` mean, equal to ``predict(x)[0]``.
        """
        return self._predict_mean(x, _inner_only(task))


def _inner_only(task) -> int:
    """0 for the inner task (a GPIS models that one only); the outer one refused by name."""
    from ..core.validation import task_id

    t = task_id(task, "task")
    if t != 0:
        raise ValueError("task: a GPIS models the inner shape only (task 0, \"inner\"); the outer shape needs a "
                         "GPIOIS")
    return 0

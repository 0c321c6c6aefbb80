"""The kernel's length, the noise and K_t learned together by the exact log marginal likelihood, with autograd.

``GPIOIS.fit`` learns K_t alone with an exact Newton method on the structured engine, whose eigenbasis of the outer
block holds for one kernel length. Learning the length as well changes that basis at every evaluation, so this
module evaluates the likelihood by one dense Cholesky of the (possibly thinned) Gram matrix instead, takes its
gradient by the trace form (:func:`exact_mll_fast`) through the kernel contract's
:meth:`~torch_gpioius.kernels.ExactKernel.value_at`, and maximises it with L-BFGS over bounded parameters. The model
then takes the values and is exact again at them (the caller re-learns K_t on all the data with the structured
engine).

Written by hand because GPyTorch's ``ExactMarginalLogLikelihood`` holds the parameters in the model (a thinned copy
would need a second model) and has no bounds on the noise other than a lower one; the arithmetic is GPyTorch's own
(a Cholesky of ``k_x * K_t[t, t'] + sigma^2 I``), and the tests compare the two.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["HyperparameterResult", "LENGTH_BOUNDS", "NOISE_BOUNDS", "exact_mll", "exact_mll_fast",
           "maximize_hyperparameters"]

#: Default bounds of the learned length [m]: below 2 cm the estimate interpolates each fingertip contact alone, above
#: 50 cm it is smoother than any body the library explores (docs/method-notes.md section 12 measured the choices).
LENGTH_BOUNDS = (0.02, 0.5)
#: Default bounds of the learned noise variance sigma^2 (labels are 0, 1 and about -0.4).
NOISE_BOUNDS = (1e-4, 0.5)


@dataclass(frozen=True)
class HyperparameterResult:
    """What one learning of the length, the noise and K_t found (``GPIOIS.hyper_result``).

    Attributes:
        length: the learned kernel length [m] (theta, the Matérn length scale).
        noise: the learned noise variance sigma^2.
        task_covariance: `(2, 2)` K_t at the optimum of the data used (the model re-learns it on all data); None for
            one task (GPIS).
        mll: the exact log marginal likelihood at the optimum, on the data used [nats].
        mll_start: the same at the starting values [nats].
        points: how many observations the learning used (fewer than the model's when thinned).
        evaluations: likelihood evaluations (each one dense Cholesky and inverse of ``points`` rows).
        seconds: wall time of the learning [s].
        at_bound: names of the parameters ("length", "noise") that ended within 0.1 % of their log range from a
            bound.
        kept: whether the model kept the values (their full-data MLL after re-learning K_t was at least the
            previous one); set by the model.
        mll_full: the full data's exact MLL with the values kept [nats] (set by the model).
        mll_full_before: the full data's exact MLL before the learning [nats] (set by the model).
    """

    length: float
    noise: float
    task_covariance: Tensor | None
    mll: float
    mll_start: float
    points: int
    evaluations: int
    seconds: float
    at_bound: tuple[str, ...] = ()
    kept: bool = True
    mll_full: float = math.nan
    mll_full_before: float = math.nan


def _squash(u: Tensor, bounds: tuple[float, float]) -> Tensor:
    """A value in ``bounds`` from an unconstrained ``u``: log-uniform through a sigmoid (GPyTorch's Interval, in log
    space), so the optimiser never steps outside and the gradient never vanishes at a clamp."""
    lo, hi = math.log(bounds[0]), math.log(bounds[1])
    return torch.exp(lo + (hi - lo) * torch.sigmoid(u))


def _unsquash(value: float, bounds: tuple[float, float]) -> float:
    lo, hi = math.log(bounds[0]), math.log(bounds[1])
    p = (math.log(min(max(value, bounds[0]), bounds[1])) - lo) / (hi - lo)
    p = min(max(p, 1e-6), 1.0 - 1e-6)
    return math.log(p / (1.0 - p))


def _gram(kernel, x: Tensor, task: Tensor, length: Tensor, noise: Tensor, task_covariance: Tensor) -> Tensor:
    """`(n, n)` ``G = k_x(length) * K_t[t, t'] + sigma^2 I``, differentiable in the parameters."""
    eye = torch.eye(len(x), dtype=x.dtype, device=x.device)
    return kernel.value_at(x, x, length) * task_covariance[task][:, task] + noise * eye


def exact_mll(kernel, x: Tensor, y: Tensor, task: Tensor, length: Tensor, noise: Tensor, task_covariance: Tensor,
              prior_mean: float = 1.0) -> Tensor:
    """Exact log marginal likelihood [nats], eq. (16), differentiable in ``length``, ``noise`` and ``task_covariance``.

    Args:
        kernel: an :class:`~torch_gpioius.kernels.ExactKernel` with a learnable length (its :meth:`value_at`).
        x: `(n, d)` points [m].
        y: `(n,)` labels.
        task: `(n,)` task ids (all 0 for one task).
        length: 0-d tensor, the kernel length [m].
        noise: 0-d tensor, sigma^2.
        task_covariance: `(T, T)` K_t.
        prior_mean: the constant prior mean m.

    Returns:
        0-d tensor: ``-r^T G^-1 r / 2 - log|G| / 2 - n log(2 pi) / 2``, ``r = y - m``, ``G = k_x * K_t[t, t'] +
        sigma^2 I``.
    """
    chol = torch.linalg.cholesky(_gram(kernel, x, task, length, noise, task_covariance))
    r = (y - prior_mean).unsqueeze(-1)
    alpha = torch.cholesky_solve(r, chol)
    n = len(x)
    return -0.5 * (r * alpha).sum() - chol.diagonal().log().sum() - 0.5 * n * math.log(2.0 * math.pi)


def exact_mll_fast(kernel, x: Tensor, y: Tensor, task: Tensor, length: Tensor, noise: Tensor,
                   task_covariance: Tensor, prior_mean: float = 1.0) -> Tensor:
    """:func:`exact_mll`'s value, with the same gradient by the closed form ``dL = tr(W dG) / 2``,
    ``W = alpha alpha^T - G^-1`` (Rasmussen & Williams eq. 5.9), instead of autograd through the Cholesky factor.

    The factorisation and ``G^-1`` are computed once, outside autograd; the returned tensor is ``L + S - S.detach()``
    with the surrogate ``S = tr(W G) / 2``, where only ``G``'s elementwise construction from ``length``, ``noise`` and
    ``task_covariance`` is differentiated (O(n^2)). Autograd through the Cholesky costs two more O(n^3) triangular
    solves and a product: 130 against about 45 ms an evaluation at 768 points (one thread). Why by hand: torch has no
    fused log-determinant-and-solve with this backward, and GPyTorch's exact path is the autograd one.
    """
    n = len(x)
    gram = _gram(kernel, x, task, length, noise, task_covariance)
    with torch.no_grad():
        chol = torch.linalg.cholesky(gram)
        r = (y - prior_mean).unsqueeze(-1)
        alpha = torch.cholesky_solve(r, chol)
        value = -0.5 * (r * alpha).sum() - chol.diagonal().log().sum() - 0.5 * n * math.log(2.0 * math.pi)
        weight = alpha @ alpha.T - torch.cholesky_inverse(chol)
    surrogate = 0.5 * (weight * gram).sum()
    return value + surrogate - surrogate.detach()


def maximize_hyperparameters(kernel, x: Tensor, y: Tensor, task: Tensor, noise: float, task_covariance: Tensor | None,
                             prior_mean: float = 1.0, length_bounds: tuple[float, float] = LENGTH_BOUNDS,
                             noise_bounds: tuple[float, float] = NOISE_BOUNDS, max_iter: int = 60,
                             learn_noise: bool = True) -> HyperparameterResult:
    """Maximise :func:`exact_mll` over the kernel length, sigma^2 and the Cholesky factor of K_t (L-BFGS with a strong
    Wolfe line search), starting from the kernel's length, ``noise`` and ``task_covariance``.

    The length and sigma^2 are kept inside their bounds by a log-space sigmoid; K_t is ``L L^T`` with a positive
    diagonal (its log) as in ``GPIOIS.fit``. Deterministic for the same data.

    Why this many parameters: the data (``x``, ``y``, ``task``), the point the search starts from (``kernel``,
    ``noise``, ``task_covariance``, ``prior_mean``) and the search's box and budget are each one of the engine's inputs;
    the models call it with their own, users call the models.

    Args:
        kernel: the model's kernel (its ``length`` is the start; it is not changed here).
        x: `(n, d)` points [m].
        y: `(n,)` labels.
        task: `(n,)` task ids, 0 and 1 (all 0 for one task).
        noise: starting sigma^2.
        task_covariance: `(2, 2)` starting K_t, or None for one task of unit amplitude (GPIS: length and noise only).
        prior_mean: m.
        length_bounds: `(lo, hi)` of the length [m].
        noise_bounds: `(lo, hi)` of sigma^2.
        max_iter: cap on L-BFGS iterations.
        learn_noise: False holds sigma^2 at ``noise`` (then ``noise_bounds`` is not used): the length and K_t only.

    Returns:
        The :class:`HyperparameterResult` (``kept`` and the full-data fields are the model's to fill).
    """
    t0 = time.perf_counter()
    dt = dict(dtype=x.dtype, device=x.device)
    fixed_noise = None if learn_noise else torch.tensor(float(noise), **dt)
    start_q = [_unsquash(kernel.length, length_bounds), _unsquash(noise, noise_bounds) if learn_noise else 0.0]
    if task_covariance is not None:       # K_t = L L^T with log-diagonal parameters, as GPIOIS.fit
        kt0 = task_covariance.to(**dt)
        chol0 = torch.linalg.cholesky(kt0 + 1e-12 * kt0.diagonal().max() * torch.eye(len(kt0), **dt))
        l11 = max(float(chol0[1, 1]), 1e-4 * float(chol0[0, 0]))    # off a correlation of exactly 1
        start_q += [math.log(float(chol0[0, 0])), float(chol0[1, 0]), math.log(l11)]
    start_q = torch.tensor(start_q, **dt)
    p = start_q.clone().requires_grad_(True)
    zero, one = torch.zeros((), **dt), torch.ones(1, 1, **dt)

    def unpack(q: Tensor):
        if task_covariance is None:
            kt = one
        else:
            chol = torch.stack([torch.stack([q[2].exp(), zero]), torch.stack([q[3], q[4].exp()])])
            kt = chol @ chol.T
        sigma2 = _squash(q[1], noise_bounds) if fixed_noise is None else fixed_noise   # q[1]: no gradient then
        return _squash(q[0], length_bounds), sigma2, kt

    def objective(q: Tensor) -> Tensor:
        return exact_mll_fast(kernel, x, y, task, *unpack(q), prior_mean=prior_mean)

    with torch.no_grad():
        start = float(objective(p))
    count = [0]
    opt = torch.optim.LBFGS([p], lr=1.0, max_iter=max_iter, max_eval=2 * max_iter, tolerance_grad=1e-6,
                            tolerance_change=1e-10, history_size=10, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        count[0] += 1
        loss = -objective(p)
        loss.backward()
        return loss

    opt.step(closure)
    q = p.detach()
    with torch.no_grad():
        best = float(objective(q))
    if not best >= start:              # a failed line search (or a NaN) can end below the start: keep the start then
        q, best = start_q, start
    length, sigma2, kt = unpack(q)
    at_bound = tuple(name for name, u in (("length", q[0]), ("noise", q[1])) if abs(float(u)) > 6.9
                     and (learn_noise or name == "length"))
    return HyperparameterResult(length=float(length), noise=float(sigma2),
                                task_covariance=None if task_covariance is None else kt.detach().cpu(), mll=best,
                                mll_start=start, points=len(x), evaluations=count[0],
                                seconds=time.perf_counter() - t0, at_bound=at_bound)

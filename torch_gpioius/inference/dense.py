"""Exact GP arithmetic for GPIS / GPIOIS: one Cholesky factorisation of the full Gram matrix.

This is the dense reference engine behind ``GPIS`` and ``GPIOIS`` (``predict``, ``log_marginal_likelihood``,
``fit``). It never approximates: no CG, no Lanczos, no low-rank root. A faster exact engine can replace it behind
the same interface (``factor`` / ``predict`` / ``mll`` / ``mll_derivatives`` / ``append``).

Notation (paper eq. 9-16): the Gram matrix of the data is

    G = K_x ∘ B[t_i, t_j] + sigma^2 I,

with ``K_x`` the kernel matrix (the inverse multiquadric of eq. 5 by default; any
:class:`~torch_gpioius.kernels.ExactKernel`), ``B = K_t`` the 2x2 task covariance (eq. 10; ``B = [[1]]`` for the
single-task GPIS), and residuals ``r = y - m`` with prior mean ``m = 1`` (eq. 2).
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from ..kernels import ExactKernel
from .engine import ExactEngine
from ..core.tolerances import tol

__all__ = ["DenseExactInference", "JitterWarning", "NotPositiveDefiniteError", "robust_cholesky", "bordered",
           "engine_kernel"]


class JitterWarning(RuntimeWarning):
    """Kept for compatibility: no longer emitted. A matrix that is not positive definite to within rounding now
    raises :class:`NotPositiveDefiniteError` instead of being factorised with visible jitter."""


class NotPositiveDefiniteError(torch.linalg.LinAlgError):
    """A Gram matrix (or Schur complement) is not positive definite to within rounding: exact GP arithmetic cannot
    proceed. Causes: duplicate or near-duplicate points with a tiny noise, or an extreme task covariance."""


def robust_cholesky(a: Tensor, what: str = "Gram matrix") -> tuple[Tensor, float]:
    """Lower Cholesky factor of a symmetric positive-definite matrix, exact to rounding.

    If the factorisation fails, it is retried once with ``tol.jitter_rounding * n * eps * max(diag)`` on the
    diagonal: the backward error of any Cholesky factorisation is of that order, so this changes nothing the
    rounding had not changed already. A matrix that still fails is not positive definite in any meaningful sense
    and raises; nothing larger is ever added (that would be a different model, not exact arithmetic).

    Args:
        a: `(n, n)` symmetric matrix.
        what: name used in errors.

    Returns:
        `(n, n)` lower factor ``L`` with ``L L^T = a + jitter I``, and the absolute jitter added (0 or rounding level).

    Raises:
        NotPositiveDefiniteError: non-finite entries, or not positive definite to within rounding.
    """
    factor, info = torch.linalg.cholesky_ex(a)
    # NaN or inf anywhere in the lower triangle (the part a lower Cholesky reads) reaches the factor's diagonal, so
    # checking the n diagonal entries is enough on the fast path; the full check only runs when something failed
    if int(info) == 0 and bool(torch.isfinite(factor.diagonal(dim1=-2, dim2=-1)).all()):
        return factor, 0.0
    if not bool(torch.isfinite(a).all()):
        raise NotPositiveDefiniteError(
            f"{what} has NaN or inf entries (overflow: check the kernel's length scale, the noise and K_t)"
        )
    n = a.shape[-1]
    jitter = tol.jitter_rounding * n * torch.finfo(a.dtype).eps * float(a.diagonal().abs().max())
    factor, info2 = torch.linalg.cholesky_ex(a + jitter * torch.eye(n, dtype=a.dtype, device=a.device))
    if int(info2) == 0 and bool(torch.isfinite(factor.diagonal(dim1=-2, dim2=-1)).all()):
        return factor, jitter
    raise NotPositiveDefiniteError(
        f"{what} ({n} x {n}) is not positive definite to within rounding (leading minor {int(info)} failed, also "
        f"with {jitter:.3g} on the diagonal): duplicate or near-duplicate points with a tiny noise, or an extreme "
        "task covariance")


def engine_kernel(kernel) -> ExactKernel:
    """The kernel object of an engine (an :class:`ExactKernel`; the length travels inside it, never beside it).

    Raises:
        TypeError: anything else (a bare length included: wrap it, ``InverseMultiquadricKernel(0.1)``).
    """
    if isinstance(kernel, ExactKernel):
        return kernel
    raise TypeError(f"kernel: expected an ExactKernel (e.g. InverseMultiquadricKernel(0.1)), got "
                    f"{type(kernel).__name__}")


def bordered(k: Tensor, k_new_old: Tensor, k_new_new: Tensor) -> Tensor:
    """Symmetric kernel matrix `(n + k, n + k)` grown by new rows `(k, n)` and the new block `(k, k)`."""
    return torch.cat([torch.cat([k, k_new_old.T], dim=1), torch.cat([k_new_old, k_new_new], dim=1)], dim=0)


class DenseExactInference(ExactEngine):
    """Exact posterior, marginal likelihood and its K_t derivatives from one dense Cholesky factor.

    Args:
        x: `(n, d)` training points [m].
        y: `(n,)` labels, 0 on a surface, 1 in free space.
        task: `(n,)` long task ids (0 inner, 1 outer; all 0 for GPIS).
        kernel: the :class:`~torch_gpioius.kernels.ExactKernel`.
        noise: noise variance sigma^2 on the whole diagonal (eq. 12).
        mean: constant prior mean m (eq. 2).
    """

    def __init__(self, x: Tensor, y: Tensor, task: Tensor, kernel: ExactKernel, noise: float = 0.006,
                 mean: float = 1.0):
        self.kernel = engine_kernel(kernel)
        self.noise = float(noise)
        self.mean = float(mean)
        self.x = x.detach()
        self.y = y.detach()
        self.task = task.detach()
        self.kx = self.kernel.value(self.x, self.x)
        self._invalidate()

    # ------------------------------------------------------------------ data
    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        """Append observations, extending the cached kernel matrix by the new rows only (O(n k))."""
        x, y, task = x.detach(), y.detach(), task.detach()
        k_new_old = self.kernel.value(x, self.x)
        k_new_new = self.kernel.value(x, x)
        self.kx = bordered(self.kx, k_new_old, k_new_new)
        self.x = torch.cat([self.x, x])
        self.y = torch.cat([self.y, y])
        self.task = torch.cat([self.task, task])
        self._invalidate()

    def remove(self, drop: Tensor, task: Tensor) -> bool:
        """Drop observations (`(n,)` bool mask in data order) from the cached kernel matrix; always possible."""
        keep = ~drop
        self.kx = self.kx[keep][:, keep]
        self.x, self.y, self.task = self.x[keep], self.y[keep], self.task[keep]
        self._invalidate()
        return True

    @property
    def n(self) -> int:
        return self.x.shape[0]

    def _invalidate(self) -> None:
        self._key = None
        self._chol = None
        self._alpha = None
        self._gram_inv = None
        self.jitter = 0.0

    # ------------------------------------------------------------------ factorisation
    def gram(self, b: Tensor) -> Tensor:
        """`(n, n)` Gram matrix ``K_x ∘ B[t_i, t_j] + sigma^2 I`` (eq. 12)."""
        bt = b[self.task][:, self.task]
        g = self.kx * bt
        g.diagonal().add_(self.noise)
        return g

    def factor(self, b: Tensor) -> tuple[Tensor, Tensor]:
        """Cholesky factor `(n, n)` and weights ``alpha = G^{-1} (y - m)`` `(n,)`, cached per task covariance."""
        b = b.detach()
        key = tuple(b.flatten().tolist())
        if self._key != key:
            chol, self.jitter = robust_cholesky(self.gram(b))
            r = (self.y - self.mean).unsqueeze(-1)
            self._alpha = torch.cholesky_solve(r, chol).squeeze(-1)
            self._chol = chol
            self._gram_inv = None
            self._key = key
        return self._chol, self._alpha

    def gram_inverse(self, b: Tensor) -> Tensor:
        """`(n, n)` inverse of the Gram matrix from its Cholesky factor (cached)."""
        chol, _ = self.factor(b)
        if self._gram_inv is None:
            self._gram_inv = torch.cholesky_inverse(chol)
        return self._gram_inv

    # ------------------------------------------------------------------ posterior
    def predict(self, xq: Tensor, task: int, b: Tensor, chunk: int = 8192) -> tuple[Tensor, Tensor]:
        """Latent posterior mean and variance of F_task at query points, eq. (12)-(13).

        Differentiable with respect to ``xq`` (the cached factors are constants).

        Args:
            xq: `(m, d)` query points [m].
            task: 0 (inner) or 1 (outer).
            b: `(T, T)` task covariance.
            chunk: rows per block when ``xq`` does not require gradients (bounds memory to chunk x n).

        Returns:
            `(m,)` mean and `(m,)` variance.
        """
        _, alpha = self.factor(b)
        b = b.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            parts = [self.predict(xq[i:i + chunk], task, b, chunk) for i in range(0, xq.shape[0], chunk)]
            return torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])
        gi = self.gram_inverse(b)
        kq = self.kernel.value(xq, self.x) * b[task][self.task]
        mean = self.mean + kq @ alpha
        prior = self.kernel.prior_variance(b[task, task])
        var = prior - ((kq @ gi) * kq).sum(-1)
        return mean, var.clamp_min(0.0)

    def predict_mean(self, xq: Tensor, task: int, b: Tensor, chunk: int = 8192) -> Tensor:
        """Posterior mean of F_task at `(m, d)` query points, eq. (12), without the variance (no ``K^-1``:
        ``O(m n)``); differentiable with respect to ``xq``."""
        _, alpha = self.factor(b)
        b = b.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            return torch.cat([self.predict_mean(xq[i:i + chunk], task, b, chunk) for i in range(0, xq.shape[0], chunk)])
        return self.mean + (self.kernel.value(xq, self.x) * b[task][self.task]) @ alpha

    # ------------------------------------------------------------------ marginal likelihood
    def mll(self, b: Tensor) -> Tensor:
        """Log marginal likelihood, eq. (16) with C = -n/2 log(2 pi): a scalar tensor."""
        chol, alpha = self.factor(b)
        r = self.y - self.mean
        return (-chol.diagonal().log().sum() - 0.5 * (r @ alpha) - 0.5 * self.n * math.log(2 * math.pi))

    def mll_derivatives(self, b: Tensor) -> tuple[float, Tensor, Tensor]:
        r"""MLL with its exact gradient and Hessian in ``p = (K_t[0,0], K_t[0,1], K_t[1,1])``.

        With ``D_j = dG/dp_j`` (the kernel matrix masked to the inner-inner, inner-outer and outer-outer blocks)
        and ``alpha = G^{-1} r``:

            g_j    = 1/2 alpha^T D_j alpha - 1/2 tr(G^{-1} D_j)
            H_{jk} = 1/2 tr(G^{-1} D_j G^{-1} D_k) - (D_j alpha)^T G^{-1} (D_k alpha)

        (G is linear in p, so there is no second-derivative term.) Cost: one inverse and one n^3 product split
        over the three blocks.

        Returns:
            ``(mll, grad (3,), hess (3, 3))``.
        """
        _, alpha = self.factor(b)
        gi = self.gram_inverse(b)
        inner = (self.task == 0).nonzero().flatten()
        outer = (self.task == 1).nonzero().flatten()
        kx = self.kx
        n = self.n
        m = [torch.zeros(n, n, dtype=kx.dtype, device=kx.device) for _ in range(3)]
        d_alpha = [torch.zeros(n, dtype=kx.dtype, device=kx.device) for _ in range(3)]
        blocks = (((inner, inner),), ((inner, outer), (outer, inner)), ((outer, outer),))
        for j, pairs in enumerate(blocks):
            for rows, cols in pairs:
                if len(rows) == 0 or len(cols) == 0:
                    continue
                k_rc = kx[rows][:, cols]
                # (G^{-1} D_j)[:, cols] += G^{-1}[:, rows] K[rows, cols]
                m[j][:, cols] += gi[:, rows] @ k_rc
                d_alpha[j][rows] += k_rc @ alpha[cols]
        grad = torch.stack([0.5 * (alpha @ d_alpha[j]) - 0.5 * m[j].diagonal().sum() for j in range(3)])
        m_alpha = [mj @ alpha for mj in m]  # G^{-1} D_k alpha
        hess = torch.empty(3, 3, dtype=kx.dtype, device=kx.device)
        for j in range(3):
            for k in range(j, 3):
                h = 0.5 * (m[j] * m[k].T).sum() - d_alpha[j] @ m_alpha[k]
                hess[j, k] = hess[k, j] = h
        return float(self.mll(b)), grad, hess

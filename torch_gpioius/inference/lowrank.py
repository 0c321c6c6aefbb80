r"""A truncated eigenbasis of the outer kernel matrix with a bound on what it drops (issue 26's approximation).

The structured engine diagonalises ``K_oo`` once. A full eigendecomposition is O(N_o^3) at a fraction of GEMM
speed (273 s at N_o = 10,000 on one thread) and every step reads its N_o^2 eigenvectors. The inverse multiquadric's
spectrum decays exponentially, so most of ``K_oo`` lies in a few thousand directions; this module finds them
without forming ``K_oo``:

1. a greedy, blocked **pivoted Cholesky** ``K_oo ~ L L^T`` (``L``: `(N_o, r)`) that stops when the trace of the
   residual ``E = K_oo - L L^T`` is at most ``trace_tol``. ``E`` is a Schur complement of ``K_oo``, so it is
   positive semi-definite and ``||E||_2 <= tr(E)``: the trace is a rigorous bound on the dropped spectrum (up to
   rounding, ~``eps k(0)`` per point). It costs ``N_o r`` kernel values and O(N_o r^2) flops in GEMMs.
2. the eigenbasis of ``L L^T = U diag(lam) U^T`` from the ``r x r`` Gram matrix ``L^T L = V diag(lam) V^T``:
   ``U = L V diag(lam)^-1/2`` (O(N_o r^2 + r^3), a third of a thin QR's time). ``L L^T = U diag(lam) U^T`` holds
   to rounding whatever the conditioning; ``U``'s columns are orthonormal only to ``~eps lam_max / lam_k``, so the
   engine uses ``U`` only in forms that do not need their orthogonality (``(c K' + s I)^-1 = U (D - I/s) U^T +
   I/s``, where the weak modes' ``D_k - 1/s ~ -c lam_k / s^2`` is tiny). Modes below ``1e-12 lam_max`` are
   dropped and their eigenvalues added to the dropped trace.

The engine then works exactly with ``K' = U diag(lam) U^T`` in place of ``K_oo``: the Gram matrix it factors
differs from the true one by ``c E`` in the outer block, at most ``c tr(E)`` in spectral norm, against a Gram
matrix ``>= sigma^2 I``.

Hand-written because neither torch nor gpytorch offers a pivoted Cholesky with a residual-trace stop that
reads kernel columns lazily (gpytorch's ``pivoted_cholesky`` takes a formed matrix and a fixed rank).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

__all__ = ["OuterBasis", "pivoted_cholesky", "truncated_basis"]

#: Candidate pivots examined per block (one GEMM of ``(N_o, r) x (r, BLOCK)`` per block), at most; blocks start at
#: MIN_BLOCK and grow with the rank (r / 4), so a loose tolerance is not overshot by a whole block.
BLOCK = 128
MIN_BLOCK = 16
#: A candidate joins a block's pivots while its residual is at least this fraction of the largest residual left
#: outside the block (the greedy order, kept to within a factor that costs no extra rank in practice).
ACCEPT = 0.1
#: Modes of ``L L^T`` below this fraction of the largest are dropped (their ``U`` columns would be rounding).
WEAKEST = 1e-12


@dataclass(frozen=True)
class OuterBasis:
    """A truncated eigenbasis of ``K_oo``.

    Attributes:
        lam: `(r,)` eigenvalues of ``L L^T`` (>= 0).
        u: `(N_o, r)` eigenvectors (orthonormal to ``~eps lam_max / lam_k``, see the module docstring).
        dropped_trace: ``tr(K_oo - L L^T)``, a bound on the spectral norm of what the basis drops [kernel units].
        pivots: `(r,)` indices of the outer points the pivoted Cholesky chose.
    """

    lam: Tensor
    u: Tensor
    dropped_trace: float
    pivots: Tensor

    @property
    def rank(self) -> int:
        return int(self.lam.shape[0])


def pivoted_cholesky(kernel, x: Tensor, trace_tol: float, max_rank: int | None = None) -> tuple[Tensor, Tensor, Tensor]:
    """Greedy blocked pivoted Cholesky of ``K = k(x, x)`` until ``tr(K - L L^T) <= trace_tol``.

    Args:
        kernel: a stationary :class:`~torch_gpioius.kernels.ExactKernel` (``value`` and ``prior_variance``).
        x: `(n, d)` points [m].
        trace_tol: stop when the residual's trace is at most this [kernel units]; >= 0.
        max_rank: stop at this rank at the latest (default n).

    Returns:
        `(n, r)` factor L, `(n,)` residual diagonal ``diag(K - L L^T)`` (>= 0, recomputed from L at the end),
        `(r,)` pivot indices.
    """
    if not math.isfinite(trace_tol) or trace_tol < 0:
        raise ValueError(f"trace_tol: must be finite and >= 0, got {trace_tol}")
    n = x.shape[0]
    max_rank = n if max_rank is None else min(int(max_rank), n)
    k0 = float(kernel.prior_variance(1.0))
    d = torch.full((n,), k0, dtype=x.dtype, device=x.device)
    # Ties (all residuals equal at the start) are broken in a fixed pseudo-random order, so the first block's
    # candidates are spread over the cloud instead of being the first BLOCK points of a spatially sorted grid.
    gen = torch.Generator().manual_seed(0)
    tie = torch.rand(n, generator=gen, dtype=torch.float64).to(x.device) * (1e-12 * k0)
    factor = x.new_zeros((n, min(max_rank, 2 * BLOCK)))
    pivots: list[Tensor] = []
    r = 0
    while r < max_rank and float(d.sum()) > trace_tol:
        b = min(BLOCK, max(MIN_BLOCK, r // 4), max_rank - r, n - r)   # small first blocks: little overshoot
        cand = torch.topk(d + tie * (d > 0), b).indices
        cand = cand[d[cand] > 0]
        if not len(cand):
            break
        outside = d.clone()
        outside[cand] = 0.0
        floor = ACCEPT * float(outside.max())
        cols = kernel.value(x, x[cand]) - factor[:, :r] @ factor[cand, :r].T        # (n, b) residual columns
        block = cols[cand]                                                          # (b, b)
        # sequential pivoted Cholesky on the small block; the big update is one triangular solve below
        f = torch.zeros_like(block)
        res = block.diagonal().clone()
        accepted: list[int] = []
        for t in range(len(cand)):
            j = int(torch.argmax(res))
            if float(res[j]) <= max(floor, 0.0) or (t and float(res[j]) <= 1e-14 * k0):
                break
            col = (block[:, j] - f[:, :t] @ f[j, :t]) / math.sqrt(float(res[j]))
            f[:, t] = col
            res = res - col * col
            res[j] = -math.inf
            accepted.append(j)
        if not accepted:
            break
        acc = torch.tensor(accepted, device=x.device)
        lc = f[acc, :len(accepted)]                                                 # lower triangular
        new = torch.linalg.solve_triangular(lc, cols[:, acc].T, upper=False).T       # (n, t)
        if r + new.shape[1] > factor.shape[1]:
            grown = x.new_zeros((n, min(max_rank, max(2 * factor.shape[1], r + new.shape[1]))))
            grown[:, :r] = factor[:, :r]
            factor = grown
        factor[:, r:r + new.shape[1]] = new
        r += new.shape[1]
        pivots.append(cand[acc])
        d = (d - (new * new).sum(1)).clamp_min(0.0)
        d[cand[acc]] = 0.0
    factor = factor[:, :r]
    d = (k0 - (factor * factor).sum(1)).clamp_min(0.0)
    piv = torch.cat(pivots) if pivots else torch.zeros(0, dtype=torch.long, device=x.device)
    d[piv] = 0.0
    return factor, d, piv


def truncated_basis(kernel, x: Tensor, trace_tol: float, max_rank: int | None = None) -> OuterBasis:
    """Eigenbasis of a pivoted-Cholesky approximation of ``k(x, x)`` (see the module docstring).

    Args:
        kernel: stationary :class:`~torch_gpioius.kernels.ExactKernel`.
        x: `(N_o, d)` outer points [m].
        trace_tol: largest dropped trace ``tr(K_oo - U diag(lam) U^T)`` [kernel units].
        max_rank: cap on the rank (the trace may then exceed ``trace_tol``; ``dropped_trace`` says by how much).

    Returns:
        :class:`OuterBasis`.
    """
    factor, resid, piv = pivoted_cholesky(kernel, x, trace_tol, max_rank)
    if factor.shape[1] == 0:
        return OuterBasis(x.new_zeros(0), x.new_zeros((x.shape[0], 0)), float(resid.sum()), piv)
    lam, v = torch.linalg.eigh(factor.T @ factor)
    keep = lam > WEAKEST * float(lam.max())
    dropped = float(resid.sum()) + float(lam[~keep].clamp_min(0.0).sum())
    lam = lam[keep]
    # U = L V lam^-1/2, stored column-major (as eigh returns the exact engine's U): each step multiplies a few
    # kernel rows by U, and MKL's small-M double GEMM reads a column-major U faster (benchmarks/small_gemm.py)
    u = ((v[:, keep] / lam.sqrt()).T @ factor.T).T
    return OuterBasis(lam, u, dropped, piv)

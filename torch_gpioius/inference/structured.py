r"""Fast exact GPIOIS arithmetic for a fixed outer (visual) set and a growing inner (tactile) set.

During exploration the outer points are fixed, only inner points arrive, and only the three numbers of K_t change
(theta and sigma^2 are fixed). With ``K_t = [[a, b], [b, c]]`` the Gram matrix is

    G = [[a K_ii + s I, b K_io], [b K_oi, c K_oo + s I]],   s = sigma^2.

**Rotation.** One eigendecomposition ``K_oo = U diag(lam) U^T`` (O(N_o^3), once) makes the outer block diagonal
in the rotated coordinates: ``c K_oo + s I -> diag(c lam + s)``, so ``D = diag(1 / (c lam + s))`` is free for
any c. Inner rows enter through ``P = K_io U`` (one O(N_o^2) row per new inner point).

**Schur complement.** Eliminating the outer block leaves the N_i x N_i matrix

    S = a K_ii + s I - b^2 T(c),   T(c) = P D(c) P^T = sum_k f_k(c) p_k p_k^T,   f_k(c) = 1 / (c lam_k + s),

with ``log|G| = sum_k log(c lam_k + s) + log|S|`` and ``r^T G^-1 r = sum_k rt_k^2 D_k + v^T S^-1 v``
(``rt = U^T r_o``, ``v = r_i - b P D rt``). S is symmetric positive definite with S >= s I (a Schur complement
of G >= s I).

**T(c) without O(N_i^2 N_o) work per K_t.** In ``u = ln c`` each ``f_k`` is analytic in the strip
``|Im u| < pi`` whatever ``lam_k`` is (its poles sit at ``Im u = +-pi``), so on a window ``c in [c0 / 2, 2 c0]``
every mode has a rapidly converging Chebyshev expansion ``f_k(c) = sum_j a_kj T_j(x)``, ``x = (u - u0) / h``.
Then ``T(c) = sum_j T_j(x) M_j`` with c-independent ``M_j = P diag(a_:j) P^T`` built once per window, and T' and
T'' follow from the derivatives of ``T_j``. Mode k keeps ``J_k`` terms; ``J_k`` comes from a rigorous bound on
the truncation error of f_k, f_k' and f_k'' over the whole window (Bernstein ellipses and Cauchy estimates, see
``_unit_error_bounds``), allocated over the modes so that ``b^2 sum_k err_k |p_k|^2``, a bound on the spectral
norm of the perturbation of S, stays below ``tol.structured_series * s``. That keeps every result within
``tol.structured_series`` (relative) of the untruncated arithmetic. Rounding comes on top, as in any float64
computation: the computed coefficients carry ~1e-16 relative error, which the derivatives of ``T_j`` amplify, so
T, T' and T'' agree with the direct sum to ~1e-13, ~1e-12 and ~1e-10 of ``||T||`` (tests hold them to that).
``M_j`` are stored packed (lower triangle, row-major), so the rows of new inner points append at the end of
each and an evaluation of T, T', T'' reads each stored number once. The window is rebuilt around the current c
when c leaves it or when the data have grown past the bound.

**Derivatives.** With S, dS/dp and d^2S/dp^2 as explicit N_i x N_i matrices, the exact gradient and Hessian of
the log marginal likelihood in ``p = (a, b, c)`` cost O(N_i^2 J + N_i^3) per Newton iteration, never O(N_o^2).

**Queries.** Posterior mean: O(N) per point from cached weights. Posterior variance:
``b1^2 w^T D w + z^T S^-1 z`` with ``w = U^T k_o``, ``z = b0 k_i - b b1 P D w``: one O(N_o^2) rotation per point
(a quadratic form in N unknowns cannot be cheaper exactly); grids use matrix products.
"""

from __future__ import annotations

import functools
import math

import torch
from torch import Tensor

from ..kernels import ExactKernel
from .dense import bordered, engine_kernel, robust_cholesky
from .engine import ExactEngine
from .lowrank import truncated_basis
from ..core.tolerances import tol

__all__ = ["StructuredExactInference", "DirectStructuredInference"]

#: Highest Chebyshev order kept for any mode.
J_MAX = 48
#: Window of the expansion: c in [c0 / WINDOW, c0 * WINDOW] (u = ln c within ln WINDOW of the centre).
WINDOW = 2.0
#: Chebyshev-Lobatto interpolation degree used to compute the coefficients (aliasing is bounded, ~R^-(2n-J)).
N_NODES = 128


def _unit_error_bounds(lam: Tensor, noise: float, u0: float, h: float) -> Tensor:
    r"""Rigorous bounds on the truncation error of each ``f_k(c) = 1 / (c lam_k + s)`` over the window.

    Returns ``err[k, J]``: for mode k truncated after order J (interpolated coefficients, ``N_NODES``), a bound on
    ``max(|e|, |c de/dc|, |c^2 d^2e/dc^2|)`` over ``u = ln c in [u0 - h, u0 + h]``.

    Derivation, per Bernstein ellipse ``E_R`` in ``x = (u - u0) / h`` (semi-axes ``(R +- 1/R) / 2``):

    * on ``E_R``, ``r = lam e^{Re u}`` lies in ``[r_lo, r_hi]`` and ``|Im u| <= v = h (R - 1/R) / 2``, and
      ``|lam e^u + s| >= L = min_r max(m_v max(r, s), |r - s|)`` with ``m_v = 1`` (v <= pi/2),
      ``sqrt(1 - |cos v|)`` (v < pi), 0 otherwise (from ``|r e^{i phi} + s|^2 >= (r^2 + s^2)(1 - |cos v|)``);
    * so ``|f_k - kappa| <= M = min(1, r_hi / s) / L`` there (kappa = 1/s or 0), and for j >= 1
      ``|a_kj| <= 2 M R^-j``: the tail after J is at most ``2 M R^-(J+1) / (1 - 1/R)`` on [-1, 1];
    * on a smaller ellipse ``E_R'`` the tail is at most ``E' = 2 M (R'/R)^(J+1) / (1 - R'/R)``, and every
      disc of radius ``delta = (R' + 1/R') / 2 - 1`` around a point of [-1, 1] lies inside ``E_R'``, so Cauchy's
      estimates give ``|e_x| <= E' / delta``, ``|e_xx| <= 2 E' / delta^2``; with ``c d/dc = (1/h) d/dx``:
      ``|c e_c| <= |e_x| / h`` and ``|c^2 e_cc| <= |e_xx| / h^2 + |e_x| / h``;
    * interpolation at the ``n + 1`` Chebyshev-Lobatto points aliases ``|c_j - a_j| <= 4 M R^-(2n-j) / (1 - 1/R)``,
      added for every kept order with the Markov factors of its derivatives.

    The bound is the minimum over a grid of R (and R') of these expressions.
    """
    kind = dict(dtype=torch.float64, device=lam.device)
    lam = lam.to(**kind)
    j = torch.arange(J_MAX + 1, **kind)
    big_r = torch.logspace(math.log10(1.05), math.log10(min(1e4, 900.0 / h)), 72, **kind)   # e^(a_R h) finite
    a_r, b_r = (big_r + 1 / big_r) / 2, (big_r - 1 / big_r) / 2
    # per-unit-M tables (R, J): value tail, derivative tails (min over R' = R^t), aliasing
    rr = big_r.unsqueeze(1)
    value = 2 * rr ** (-(j + 1)) / (1 - 1 / rr)
    deriv = torch.full((len(big_r), J_MAX + 1), math.inf, **kind)
    for t in torch.linspace(0.02, 0.98, 49).tolist():
        rp = rr ** t
        q = rp / rr
        e_tail = 2 * q ** (j + 1) / (1 - q)
        delta = (rp + 1 / rp) / 2 - 1
        ex, exx = e_tail / delta, 2 * e_tail / delta ** 2
        deriv = torch.minimum(deriv, torch.maximum(ex / h, exx / h ** 2 + ex / h))
    alias = (j + 1) * 4 * rr ** (-(2 * N_NODES - j)) / (1 - 1 / rr) * (1 + 2 * j ** 2 / h + j ** 4 / (3 * h ** 2))
    unit = torch.maximum(value, deriv) + alias                                   # (nR, J+1)
    v = b_r * h
    m_v = torch.where(v <= math.pi / 2, torch.ones_like(v), (1 - torch.cos(v).abs()).clamp_min(0).sqrt())
    m_v = torch.where(v >= math.pi, torch.zeros_like(v), m_v)
    err = torch.full((len(lam), J_MAX + 1), math.inf, **kind)
    for i in range(len(big_r)):
        r_lo = lam * math.exp(u0 - float(a_r[i]) * h)
        r_hi = lam * math.exp(u0 + float(a_r[i]) * h)
        mv = float(m_v[i])
        low = torch.maximum(torch.full_like(r_hi, mv * noise), noise - r_hi)
        high = torch.maximum(mv * r_lo, r_lo - noise)
        bound_l = torch.where(r_hi <= noise, low, torch.where(r_lo >= noise, high, torch.full_like(r_lo, mv * noise)))
        m = torch.where(r_hi > 0, torch.minimum(torch.ones_like(r_hi), r_hi / noise) / bound_l,
                        torch.zeros_like(r_hi))                                 # M_k(R); 0 for lam = 0
        err = torch.minimum(err, m.unsqueeze(1) * unit[i].unsqueeze(0))
    return err


def _chebyshev_coefficients(lam: Tensor, noise: float, u0: float, h: float) -> Tensor:
    """`(N_o, J_MAX + 1)` coefficients of the degree-``N_NODES`` Chebyshev-Lobatto interpolant of each f_k."""
    kind = dict(dtype=torch.float64, device=lam.device)
    n = N_NODES
    k = torch.arange(n + 1, **kind)
    nodes = torch.cos(math.pi * k / n)
    f = 1.0 / (lam.to(**kind).unsqueeze(1) * torch.exp(u0 + h * nodes).unsqueeze(0) + noise)   # (N_o, n+1)
    weights = torch.ones(n + 1, **kind)
    weights[0] = weights[-1] = 0.5
    jj = torch.arange(J_MAX + 1, **kind)
    basis = torch.cos(math.pi * jj.unsqueeze(1) * k.unsqueeze(0) / n)              # (J+1, n+1)
    coef = (2.0 / n) * (f * weights) @ basis.T
    coef[:, 0] *= 0.5
    return coef


def _tril(n: int, device) -> tuple[Tensor, Tensor]:
    """Row-major lower-triangle indices of an n x n matrix (row i holds columns 0..i)."""
    idx = torch.tril_indices(n, n, device=device)
    return idx[0], idx[1]


def _kernel_rows(xq: Tensor, x_train: Tensor, kernel) -> Tensor:
    """`(1 + d, m, n)`: kernel values ``k(xq_i, x_j)`` and their derivatives in each coordinate of the query point."""
    k = kernel.value(xq, x_train)
    return torch.cat([k.unsqueeze(0), kernel.gradient(xq, x_train, k)])


class GrowingRows:
    """Rows appended in place into a buffer with spare capacity (``torch.cat`` would copy everything per append)."""

    def __init__(self, rows: Tensor):
        self.buf, self.n = rows.clone(), rows.shape[0]

    @property
    def data(self) -> Tensor:
        return self.buf[:self.n]

    def append(self, rows: Tensor) -> Tensor:
        n_new = self.n + rows.shape[0]
        if n_new > self.buf.shape[0]:
            buf = self.buf.new_empty((max(n_new, 2 * self.buf.shape[0] + 16),) + tuple(self.buf.shape[1:]))
            buf[:self.n] = self.data
            self.buf = buf
        self.buf[self.n:n_new] = rows
        self.n = n_new
        return self.data


class _ChebyshevStore:
    """``M_j = P diag(a_:j) P^T``, j = 0..max J_k, packed lower triangles in one ``(J + 1, capacity)`` block.

    Modes are permuted by decreasing order so that the modes kept at order j are a prefix of length ``n_j``.

    Args:
        lam: `(N_o,)` eigenvalues of K_oo.
        p: `(N_i, N_o)` rotated inner-outer kernel rows.
        noise: s.
        c0: centre of the window.
        beta2: b^2 the truncation is sized for (grown by ``headroom``).
        headroom: factor of growth (of b^2 and of the data's |p_k|^2) the truncation allows before a rebuild.
    """

    HEADROOM = 16.0
    GROUPS = 4

    def __init__(self, lam: Tensor, p: Tensor, noise: float, c0: float, beta2: float, headroom: float = HEADROOM):
        kind = dict(dtype=p.dtype, device=p.device)
        self.kind, self.noise = kind, noise
        self.u0, self.h = math.log(c0), math.log(WINDOW)
        coef = _chebyshev_coefficients(lam, noise, self.u0, self.h).to(**kind)
        err = _unit_error_bounds(lam, noise, self.u0, self.h)
        w = (p * p).sum(0).to(err)                                                   # |p_k|^2
        target = tol.structured_series * noise / (headroom * max(beta2, 1e-300))
        orders = self._allocate(err * w.unsqueeze(1), target)
        self.unit_err = err.gather(1, orders.unsqueeze(1)).squeeze(1).to(**kind)     # bound per unit |p_k|^2
        self.w = w.to(**kind)
        self.perm = torch.argsort(orders.to(p.device), descending=True, stable=True)
        counts = torch.bincount(orders, minlength=J_MAX + 1).flip(0).cumsum(0).flip(0)   # n_j = #{k: J_k >= j}
        self.n_j = [int(v) for v in counts.tolist() if v > 0]
        keep = torch.arange(len(self.n_j), device=orders.device).unsqueeze(0) <= orders[self.perm].unsqueeze(1)
        self.coef = coef[self.perm][:, :len(self.n_j)] * keep.to(**kind)             # (N_o, J + 1), permuted,
        #                                                                              zero beyond each J_k
        self.size = p.shape[0]
        self.capacity = 0
        self.block = torch.zeros(len(self.n_j), 0, **kind)
        self._reserve(self.size * (self.size + 1) // 2)
        self._pp = GrowingRows(p[:, self.perm[:self.n_j[0]]])                              # P, modes permuted
        self.pp = self._pp.data
        if self.size:
            r, c = _tril(self.size, p.device)
            for j, nj in enumerate(self.n_j):
                m = (self.pp[:, :nj] * self.coef[:nj, j]) @ self.pp[:, :nj].T
                self.block[j, :len(r)] = m[r, c]
        self._unpack = None                # gather index from packed to full; rebuilt when the size changes

    @staticmethod
    def _allocate(err: Tensor, target: float) -> Tensor:
        """Per-mode orders J_k minimising the work for ``sum_k err[k, J_k] <= target`` (bisection on a threshold)."""
        best = err[:, -1]
        if float(best.sum()) > target:
            raise FloatingPointError("structured engine: the Chebyshev window cannot meet tol.structured_series "
                                     f"with {J_MAX} orders")
        lo, hi = -320.0, math.log10(max(float(err.max()), 1e-300)) + 1
        orders = torch.full((err.shape[0],), J_MAX, dtype=torch.long, device=err.device)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            ok = err <= 10.0 ** mid
            ok[:, -1] = True
            trial = ok.to(torch.int8).argmax(1)
            if float(err.gather(1, trial.unsqueeze(1)).sum()) <= target:
                lo, orders = mid, trial
            else:
                hi = mid
        return orders

    def _reserve(self, packed: int) -> None:
        if packed <= self.capacity:
            return
        cap = max(packed, int(1.5 * self.capacity) + 1024)
        block = torch.zeros(self.block.shape[0], cap, **self.kind)
        block[:, :self.capacity] = self.block
        self.block, self.capacity = block, cap

    # ------------------------------------------------------------------ use
    def bound(self) -> float:
        """Bound on ``||T_rem||``, ``||c T'_rem||`` and ``||c^2 T''_rem||`` over the window (times b^2: on S)."""
        return float(self.unit_err @ self.w)

    def covers(self, c: float, beta2: float) -> bool:
        """Whether c lies in the window and ``b^2 bound()`` meets ``tol.structured_series * s`` (else rebuild)."""
        return abs(math.log(c) - self.u0) <= self.h and beta2 * self.bound() <= tol.structured_series * self.noise

    def append(self, p_new: Tensor) -> None:
        """Append the packed rows of new inner points, `(k, N_o)` rows of P (O(k N_i sum_j n_j))."""
        n_old = self.size
        n_new = n_old + p_new.shape[0]
        start, stop = n_old * (n_old + 1) // 2, n_new * (n_new + 1) // 2
        self._reserve(stop)
        r, c = _tril(n_new, p_new.device)
        r, c = r[start:] - n_old, c[start:]
        pn = p_new[:, self.perm[:self.n_j[0]]]
        self.pp = self._pp.append(pn)
        k, orders = pn.shape[0], len(self.n_j)
        rows = torch.zeros(orders, k, n_new, **self.kind)
        # Modes are grouped by order (the coefficients are zero beyond each mode's J_k): one GEMM per group reads
        # each column of P once; four groups balance wasted zeros against tiny, slow GEMMs.
        edges = [round(g * orders / self.GROUPS) for g in range(self.GROUPS + 1)]
        for jlo, jhi in zip(edges[:-1], edges[1:]):
            lo, hi = (self.n_j[jhi] if jhi < orders else 0), self.n_j[jlo]   # modes with jlo <= J_k < jhi
            if hi == lo:
                continue
            lhs = pn[:, lo:hi].unsqueeze(0) * self.coef[lo:hi, :jhi].T.unsqueeze(1)     # (jhi, k, m)
            rows[:jhi] += (lhs.reshape(-1, hi - lo) @ self.pp[:, lo:hi].T).view(jhi, k, n_new)
        self.block[:, start:stop] = rows[:, r, c]
        self.w = self.w + (p_new * p_new).sum(0)
        self.size = n_new

    def remove(self, keep: Tensor) -> None:
        """Keep only the stored rows where ``keep`` `(size,)` is True, in order: the packed entries of the kept pairs
        are gathered (O((J + 1) N_i^2) copies, no arithmetic), so a removal costs no rebuild. The truncation's
        bound keeps the removed rows' ``|p_k|^2`` in ``w``: a larger ``w`` only overstates the remainder, so the
        bound stays a bound."""
        idx = torch.nonzero(keep.to(self.block.device)).flatten()
        m = int(idx.numel())
        if m:
            r, c = _tril(m, idx.device)
            a, b = idx[r], idx[c]                       # idx is increasing: a >= b, the old pair's packed order
            self.block[:, :m * (m + 1) // 2] = self.block[:, a * (a + 1) // 2 + b].clone()
        self._pp = GrowingRows(self.pp[idx])
        self.pp = self._pp.data
        self.size = m
        self._unpack = None

    def t_matrices(self, c: float, derivatives: bool = True) -> tuple:
        """``T(c)`` and, with ``derivatives``, ``T'(c)``, ``T''(c)`` as `(N_i, N_i)` matrices (else None): one pass
        over the stored block."""
        x = (math.log(c) - self.u0) / self.h
        nj = len(self.n_j)
        t, dt, ddt = [1.0, x], [0.0, 1.0], [0.0, 0.0]                               # T_j(x), T_j'(x), T_j''(x)
        for j in range(2, nj):
            t.append(2 * x * t[-1] - t[-2])
            dt.append(2 * t[-2] + 2 * x * dt[-1] - dt[-2])
            ddt.append(4 * dt[-2] + 2 * x * ddt[-1] - ddt[-2])
        rows = [t[:nj]]
        if derivatives:                                            # d/dc = (1 / (h c)) d/dx
            hc = self.h * c
            rows += [[d / hc for d in dt[:nj]], [dd / hc ** 2 - d / (hc * c) for d, dd in zip(dt[:nj], ddt[:nj])]]
        coefs = torch.tensor(rows, dtype=torch.float64).to(**self.kind)
        n = self.size
        packed = coefs @ self.block[:, :n * (n + 1) // 2]                            # (1 or 3, n(n+1)/2)
        if self._unpack is None or self._unpack.numel() != n * n:
            i = torch.arange(n, device=self.block.device)
            hi, lo = torch.maximum(i.unsqueeze(1), i), torch.minimum(i.unsqueeze(1), i)
            self._unpack = (hi * (hi + 1) // 2 + lo).reshape(-1)                     # packed index of (i, j)
        out = [torch.take(row, self._unpack).view(n, n) for row in packed]
        return (out[0], out[1], out[2]) if derivatives else (out[0], None, None)


class StructuredExactInference(ExactEngine):
    """Exact GPIOIS engine: rotated outer block + inner Schur complement (see the module docstring).

    The :class:`~torch_gpioius.inference.engine.ExactEngine` contract, with the likelihood's value alone cheaper than
    its derivatives and the posterior's x-gradients in closed form.

    Args:
        x: `(n, d)` training points [m] (any order of tasks).
        y: `(n,)` labels.
        task: `(n,)` task ids; at least one outer (1) point.
        kernel: the :class:`~torch_gpioius.kernels.ExactKernel`.
        noise: sigma^2 > 0.
        mean: prior mean m.
    """

    def __init__(self, x: Tensor, y: Tensor, task: Tensor, kernel: ExactKernel, noise: float = 0.006,
                 mean: float = 1.0, *, outer_tol: float | None = None):
        self.kernel = engine_kernel(kernel)
        self.noise, self.mean = float(noise), float(mean)
        if outer_tol is not None and (not math.isfinite(outer_tol) or outer_tol <= 0):
            raise ValueError(f"outer_tol: must be a finite number > 0 (or None: exact), got {outer_tol}")
        self.outer_tol = outer_tol
        x, y, task = x.detach(), y.detach(), task.detach()
        inner, outer = task == 0, task == 1
        if not bool(outer.any()):
            raise ValueError("StructuredExactInference: needs at least one outer (task 1) point")
        self.xo, self.yo = x[outer], y[outer]
        self.xi, self.yi = x[inner], y[inner]
        kind = dict(dtype=x.dtype, device=x.device)
        self._kind = kind
        if outer_tol is None:
            lam, self.u = torch.linalg.eigh(self.kernel.value(self.xo, self.xo))
            self.lam = lam.clamp_min(0.0)  # K_oo is PSD; clamp rounding below zero
            self.dropped_trace = 0.0
        else:
            basis = truncated_basis(self.kernel, self.xo, outer_tol * self.noise)
            self.lam, self.u, self.dropped_trace = basis.lam, basis.u, basis.dropped_trace
        self.rt = self.u.T @ (self.yo - self.mean)
        self.kii = self.kernel.value(self.xi, self.xi)
        k_io = self.kernel.value(self.xi, self.xo) if len(self.xi) else torch.zeros(0, len(self.xo), **kind)
        self._p = GrowingRows(k_io @ self.u)
        # The truncated basis spans part of R^N_o: with K' = U diag(lam) U^T in place of K_oo,
        # (c K' + s I)^-1 = U D U^T + (I - U U^T) / s. The second term is c-independent; it enters T(c) as
        # C0 = (K_io K_oi - P P^T) / s, the weights as e = (K_io r_o - P rt) / s, the outer quadratic form as
        # (|r_o|^2 - |rt|^2) / s and queries through their raw kernel rows (forms that never need U^T U = I).
        self._raw = None
        if self.truncated:
            ro = self.yo - self.mean
            self._raw = {"kio": GrowingRows(k_io), "ro": ro,
                         "c0": (k_io @ k_io.T - self.p @ self.p.T) / self.noise,
                         "e": (k_io @ ro - self.p @ self.rt) / self.noise,
                         "quad_o": float(ro @ ro - self.rt @ self.rt) / self.noise}
        self._series = None  # _ChebyshevStore of the current window of K_t[1,1]
        # (contacts, (1 + d, k, r) rotated kernel rows and x-derivatives, their raw (1 + d, k, N_o) rows when
        # truncated, else None) of the last append
        self._rotated = None
        self._invalidate()

    # ------------------------------------------------------------------ data
    @property
    def p(self) -> Tensor:
        """`(N_i, N_o)` rotated inner-outer kernel rows ``P = K_io U``."""
        return self._p.data

    @property
    def n(self) -> int:
        return len(self.xi) + len(self.xo)

    @property
    def truncated(self) -> bool:
        """Whether the outer block uses a truncated basis (``outer_tol``) that drops part of ``K_oo``."""
        return self.outer_tol is not None and self.lam.shape[0] < len(self.xo)

    @property
    def rank(self) -> int:
        """Number of outer modes kept (N_o when exact)."""
        return int(self.lam.shape[0])

    value_alone = True
    closed_form_gradients = True

    def scout_engine(self):
        """A thinned copy of the data is factorised without a held factorisation or a Chebyshev store:
        :class:`DirectStructuredInference`, with this engine's ``outer_tol`` (its fixed starts spread K_t over more
        than one Chebyshev window: T(c) by direct products)."""
        return functools.partial(DirectStructuredInference, outer_tol=self.outer_tol)

    def truncation(self, c: float) -> float:
        """``c tr(E) / s``: bound on the truncated basis' perturbation of the Gram matrix ``G >= s I``, relative
        to s (0 when exact). ``E = K_oo - U diag(lam) U^T`` is positive semi-definite and ``||c E|| <= c tr(E)``."""
        return abs(c) * self.dropped_trace / self.noise

    @property
    def n_inner(self) -> int:
        return len(self.xi)

    def _invalidate(self) -> None:
        self._key = None
        self._cache = None
        self.jitter = 0.0

    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        """Append inner observations in O(k N_o^2 + k N_i sum_j n_j); outer ones rebuild the engine."""
        x, y, task = x.detach(), y.detach(), task.detach()
        if self._rebuild_with_outer(x, y, task):
            return
        p_new = self._ingest(x, y)
        if self._series is not None:
            self._series.append(p_new)
        self._invalidate()

    def _rebuild_with_outer(self, x: Tensor, y: Tensor, task: Tensor) -> bool:
        """Outer points change the eigendecomposition: rebuild the engine on all data (returns whether it did)."""
        if not bool((task == 1).any()):
            return False
        xs = torch.cat([self.xi, self.xo, x])
        ys = torch.cat([self.yi, self.yo, y])
        ts = torch.cat([torch.zeros(len(self.xi), dtype=torch.long, device=x.device),
                        torch.ones(len(self.xo), dtype=torch.long, device=x.device), task])
        self.__init__(xs, ys, ts, self.kernel, self.noise, self.mean, outer_tol=self.outer_tol)
        return True

    #: Growth of the data (and of b^2) the Chebyshev store's truncation allows before it is rebuilt.
    STORE_HEADROOM = _ChebyshevStore.HEADROOM

    #: False: T(c), T'(c), T''(c) by direct products ``P diag(f(c)) P^T`` at every factorisation, with no Chebyshev
    #: store (:class:`DirectStructuredInference`).
    SERIES = True

    #: Above this many surface contacts in one append (a tactile patch brings dozens), the planner's rotated
    #: x-derivative rows are computed at ingest for the first contact only (the one a patch step plans from).
    ROTATED_CONTACTS_MAX = 8

    def _ingest(self, x: Tensor, y: Tensor) -> Tensor:
        """Grow K_ii, P and the data by inner points `(k, d)`; returns the new rows of P, `(k, N_o)`."""
        self._grow_kii(self.kernel.value(x, self.xi), self.kernel.value(x, x))
        # The rows of P and, from the same pass over U, the rotated kernel x-derivatives at the new surface
        # contacts (y = 0): the planner plans from the contact just added, and U (N_o^2 doubles) is the largest
        # thing read per step. Free-space points get no derivative rows.
        dim, n_o = x.shape[1], len(self.xo)
        at = torch.nonzero(y == 0).squeeze(-1)
        if len(at) > 1:         # a contact in several rows in a row (ObservationPolicy.contact_repeats): its rows once
            at = at[torch.cat([at.new_ones(1, dtype=torch.bool), (x[at[1:]] != x[at[:-1]]).any(-1)])]
        if len(at) > self.ROTATED_CONTACTS_MAX:
            at = at[:1]
        contacts = x[at]
        rows = torch.cat([self.kernel.value(x, self.xo),
                          _kernel_rows(contacts, self.xo, self.kernel)[1:].reshape(-1, n_o)])
        rotated = rows @ self.u
        p_new = rotated[:len(x)]
        contact_rows = None if self._raw is None else torch.cat([rows[at].unsqueeze(0),
                                                                 rows[len(x):].view(dim, len(contacts), n_o)])
        self._rotated = (contacts, torch.cat([rotated[at].unsqueeze(0),
                                              rotated[len(x):].view(dim, len(contacts), self.rank)]), contact_rows)
        p_all = self._p.append(p_new)
        if self._raw is not None:
            raw, s, k_new = self._raw, self.noise, rows[:len(x)]
            k_io = raw["kio"].append(k_new)
            c0_rows = (k_new @ k_io.T - p_new @ p_all.T) / s                     # (k, N_i + k)
            raw["c0"] = bordered(raw["c0"], c0_rows[:, :-len(x)], c0_rows[:, -len(x):])
            raw["e"] = torch.cat([raw["e"], (k_new @ raw["ro"] - p_new @ self.rt) / s])
        self.xi = torch.cat([self.xi, x])
        self.yi = torch.cat([self.yi, y])
        return p_new

    def _grow_kii(self, k_new_old: Tensor, k_new_new: Tensor) -> None:
        self.kii = bordered(self.kii, k_new_old, k_new_new)

    def remove(self, drop: Tensor, task: Tensor) -> bool:
        """Drop inner observations in place, keeping the eigendecomposition of K_oo.

        Args:
            drop: `(n,)` bool mask over the model's observations (data order).
            task: `(n,)` their task ids.

        Returns:
            False (nothing changed) if outer points are to go: the caller then rebuilds the engine.
        """
        if bool((drop & (task == 1)).any()):
            return False
        keep = ~drop[task == 0]            # inner points keep their data order here (init and append)
        self.xi, self.yi = self.xi[keep], self.yi[keep]
        self.kii = self.kii[keep][:, keep]
        self._p = GrowingRows(self.p[keep])
        if self._raw is not None:
            raw = self._raw
            raw["kio"] = GrowingRows(raw["kio"].data[keep])
            raw["c0"], raw["e"] = raw["c0"][keep][:, keep], raw["e"][keep]
        if self._series is not None:           # the stored rows; rows deferred by a subclass follow later
            self._series.remove(keep[:self._series.size])
        self._rotated = None
        self._invalidate()
        return True

    # ------------------------------------------------------------------ T(c)
    @property
    def series(self) -> _ChebyshevStore | None:
        """The Chebyshev store of the current window (None before the first factorisation with inner points)."""
        return self._series

    def _t_matrices(self, c: float, beta: float, a: float, derivatives: bool, trial: bool = False) -> tuple:
        """T(c) = P D P^T `(N_i, N_i)`, with T'(c) and T''(c) if ``derivatives`` (else None); rebuilds the window
        if needed, except for a ``trial``'s value outside it."""
        c = max(c, 1e-300)
        if not self.SERIES:
            return self._direct_t_matrices(c, (0, 1, 2) if derivatives else (0,))
        if self._series is not None and self._series.size < self.n_inner:   # rows deferred by a subclass
            self._series.append(self.p[self._series.size:])
        if trial and self._series is not None and not self._series.covers(c, beta * beta):
            # a value alone outside the window (a Newton trial, often refused: a walk along w overshoots where the
            # likelihood turns) by direct products; a rebuild costs as much as the store's order of them (1.2 s at
            # 1,630 inner points), and three trials beyond it once cost three rebuilds in one re-learning
            return self._direct_t_matrices(c, (0,))
        if self._series is None or not self._series.covers(c, beta * beta):
            # size the truncation for the largest b^2 a PSD K_t allows at this a, c (b^2 <= a c)
            self._series = _ChebyshevStore(self.lam, self.p, self.noise, c, max(beta * beta, a * c),
                                           self.STORE_HEADROOM)
        return self._series.t_matrices(c, derivatives)

    def _direct_t_matrices(self, c: float, which: tuple[int, ...]) -> tuple:
        """``(T, T', T'')`` at ``c`` with those of ``which`` (0: ``T = P D P^T``, ``D = (c lam + s)^-1``; 1:
        ``T' = -P lam D^2 P^T``; 2: ``T'' = 2 P lam^2 D^3 P^T``) summed directly (one `(k N_i, r) x (r, N_i)` GEMM,
        exact, no truncation), each symmetrised (the Schur complement must be exactly symmetric, as from the store's
        unpacked T); the others None."""
        lam, p = self.lam, self.p
        d = 1.0 / (c * lam + self.noise)
        weights = {0: d, 1: -lam * d * d, 2: 2.0 * lam * lam * d ** 3}
        blocks = (torch.cat([p * weights[j] for j in which]) @ p.T).split(self.n_inner)
        out = dict(zip(which, (0.5 * (t + t.T) for t in blocks)))
        return tuple(out.get(j) for j in range(3))

    # ------------------------------------------------------------------ factorisation
    def factor(self, b: Tensor, derivatives: bool = False, trial: bool = False) -> dict:
        """Schur factor and posterior weights for task covariance ``b`` (cached).

        With ``derivatives`` the cache also holds T', T'' and the c-derivative vectors that ``mll_derivatives``
        needs; they come from the same pass over the stored expansion. ``trial``: a Newton trial's value
        (:meth:`mll_value`): outside the Chebyshev store's window T comes from direct products instead of a rebuild.
        """
        b = b.detach()
        key = tuple(b.flatten().tolist())
        if self._key == key and (not derivatives or self._cache.get("t1") is not None or not self.n_inner):
            return self._cache
        if self._key == key:
            return self._with_derivatives(self._cache)
        a, beta, c = float(b[0, 0]), float(b[0, 1]), float(b[1, 1])
        s = self.noise
        d_all = 1.0 / (c * self.lam + s)
        cache = {"a": a, "beta": beta, "c": c, "d": d_all, "alpha_rot": None}
        if self.n_inner:
            t = self._t_matrices(c, beta, a, derivatives, trial)
            pd = self.p @ self._weight_vectors(d_all, derivatives)  # P D rt (and its c-derivative companions)
            if self._raw is not None:                               # the truncated basis' complement
                t = (t[0] + self._raw["c0"],) + tuple(t[1:])
                pd[:, 0] += self._raw["e"]
            cache.update(t0=t[0], t1=t[1], t2=t[2], pd=pd, **self._schur(a, beta, t[0], pd))
        else:
            cache.update(alpha_i=torch.zeros(0, **self._kind))
            cache["alpha_rot"] = self._query_weights(cache) * self.rt
        self._cache, self._key = cache, key
        return cache

    def _with_derivatives(self, cache: dict) -> dict:
        """Add T', T'' and the c-derivative vectors to a factorisation made without them (a trial point judged by
        its value alone, then accepted), keeping its T, Schur factor and weights: the MLL and everything computed
        from them stay what they were."""
        c, beta = max(cache["c"], 1e-300), cache["beta"]
        if self.SERIES and self._series is not None and self._series.covers(c, beta * beta):
            _, t1, t2 = self._series.t_matrices(c, True)
        else:                # T came from direct products (outside the store's window): so do its derivatives
            _, t1, t2 = self._direct_t_matrices(c, (1, 2))
        derivative_pd = self.p @ self._weight_vectors(cache["d"], derivatives=True)[:, 1:]
        cache.update(t1=t1, t2=t2, pd=torch.cat([cache["pd"][:, :1], derivative_pd], dim=1))
        return cache

    def mll_value(self, b: Tensor) -> float:
        """The log marginal likelihood alone [nats], as :meth:`mll_derivatives` reports it at ``b`` (one
        factorisation; the derivatives added by a later :meth:`mll_derivatives` at the same ``b`` reuse it)."""
        self.factor(b, trial=True)
        return float(self.mll(b))

    def _schur(self, a: float, beta: float, t0: Tensor, pd: Tensor) -> dict:
        """The inner Schur complement ``S = a K_ii - b^2 T + s I`` factorised, with ``v``, ``alpha_i = S^-1 v`` and
        ``log det S`` (``chol``, ``v``, ``alpha_i``, ``logdet_s``); sets ``self.jitter``."""
        smat = a * self.kii - beta * beta * t0
        smat.diagonal().add_(self.noise)  # exactly symmetric: K_ii and the unpacked T are (Cholesky reads one half)
        chol, self.jitter = robust_cholesky(smat, "inner Schur complement")
        v = (self.yi - self.mean) - beta * pd[:, 0]
        alpha_i = torch.cholesky_solve(v.unsqueeze(-1), chol).squeeze(-1)
        return {"chol": chol, "v": v, "alpha_i": alpha_i, "logdet_s": 2 * chol.diagonal().log().sum()}

    @staticmethod
    def _solve_lower(f: dict, rhs: Tensor) -> Tensor:
        """``L^-1 rhs`` for the Schur factor ``L`` of a factorisation, `(N_i, m)` right-hand sides."""
        return torch.linalg.solve_triangular(f["chol"], rhs, upper=False)

    def _weight_vectors(self, d: Tensor, derivatives: bool) -> Tensor:
        """`(N_o, 1 or 3)`: ``D rt`` and, with ``derivatives``, ``lam D^2 rt`` and ``lam^2 D^3 rt`` (the rotated outer
        residual weighted for ``P D rt`` and its c-derivatives; ``d = 1 / (c lam + s)``)."""
        vecs = [d * self.rt]
        if derivatives:
            vecs += [self.lam * d * d * self.rt, self.lam * self.lam * d ** 3 * self.rt]
        return torch.stack(vecs, dim=1)

    def _query_weights(self, f: dict) -> Tensor:
        """`(r,)` weights of the rotated query rows: ``D``, or ``D - 1/s`` with a truncated basis, whose
        ``(c K' + s I)^-1 = U (D - I/s) U^T + I/s`` adds the raw rows' ``I/s`` part separately."""
        return f["d"] if self._raw is None else f["d"] - 1.0 / self.noise

    def _alpha_rot(self, f: dict) -> Tensor:
        """Outer weights in the rotated basis, ``U^T alpha_o`` (computed on the first query of a factor).

        With a truncated basis these are ``(D - 1/s) h`` and :meth:`_alpha_raw` holds ``g / s``
        (``h = rt - b P^T alpha_i``, ``g = r_o - b K_oi alpha_i``): ``k_o . alpha_o = w . alpha_rot + k_o . g / s``."""
        if f["alpha_rot"] is None:
            f["alpha_rot"] = self._query_weights(f) * (self.rt - f["beta"] * (self.p.T @ f["alpha_i"]))
        return f["alpha_rot"]

    def _alpha_raw(self, f: dict) -> Tensor:
        """`(N_o,)` ``g / s`` of a truncated basis (see :meth:`_alpha_rot`)."""
        if f.get("alpha_raw") is None:
            f["alpha_raw"] = (self._raw["ro"] - f["beta"] * (self._raw["kio"].data.T @ f["alpha_i"])) / self.noise
        return f["alpha_raw"]

    def _alpha_outer(self, f: dict) -> Tensor:
        """`(N_o,)` outer weights ``alpha_o`` in the original basis, ``U alpha_rot`` (plus ``g / s`` when truncated):
        the posterior mean is then ``m + b1 k_o . alpha_o + b0 k_i . alpha_i``, N_o per query instead of the
        ``N_o r`` of the rotated rows. Computed once per factor (``N_o r``); keyed on the weights it is built from,
        so a factor whose weights were reset (appends) recomputes it."""
        parts = (self._alpha_rot(f), None if self._raw is None else self._alpha_raw(f))
        held = f.get("alpha_o")
        if held is None or any(a is not b for a, b in zip(held[0], parts)):
            alpha_o = self.u @ parts[0]
            if parts[1] is not None:
                alpha_o = alpha_o + parts[1]
            f["alpha_o"] = held = (parts, alpha_o)
        return held[1]

    # ------------------------------------------------------------------ posterior
    def predict_mean(self, xq: Tensor, task: int, b: Tensor, chunk: int = 4096) -> Tensor:
        """Posterior mean of F_task at `(m, d)` points, eq. (12), without the variance; differentiable in ``xq``.

        The same mean as :meth:`predict` at ``O(m (N_i + N_o))`` instead of ``O(m N_o r)``: for meshing the
        estimate on a grid (a 1 cm camera keeps thousands of outer points, and the variance's rotated rows would
        cost a GEMM with U per grid block)."""
        f = self.factor(b)
        b = b.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            return torch.cat([self.predict_mean(xq[i:i + chunk], task, b, chunk) for i in range(0, xq.shape[0], chunk)])
        mean = self.mean + b[task, 1] * (self.kernel.value(xq, self.xo) @ self._alpha_outer(f))
        if self.n_inner:
            mean = mean + b[task, 0] * (self.kernel.value(xq, self.xi) @ f["alpha_i"])
        return mean

    def predict(self, xq: Tensor, task: int, b: Tensor, chunk: int = 4096) -> tuple[Tensor, Tensor]:
        """Posterior mean and variance of F_task at `(m, d)` points, eq. (12)-(13); differentiable in ``xq``."""
        f = self.factor(b)
        b = b.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            parts = [self.predict(xq[i:i + chunk], task, b, chunk) for i in range(0, xq.shape[0], chunk)]
            return torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])
        b0, b1, beta = b[task, 0], b[task, 1], f["beta"]
        k_o = self.kernel.value(xq, self.xo)
        w = k_o @ self.u                                  # (m, N_o) rotated outer kernel vectors
        dq = self._query_weights(f)
        mean = self.mean + b1 * (w @ self._alpha_rot(f))
        quad = b1 * b1 * (w * w * dq).sum(-1)
        if self._raw is not None:                                   # the truncated basis' I/s part
            mean = mean + b1 * (k_o @ self._alpha_raw(f))
            quad = quad + b1 * b1 * (k_o * k_o).sum(-1) / self.noise
        if self.n_inner:
            k_i = self.kernel.value(xq, self.xi)
            mean = mean + b0 * (k_i @ f["alpha_i"])
            z = b0 * k_i - beta * b1 * ((w * dq) @ self.p.T)       # (m, N_i)
            if self._raw is not None:
                z = z - beta * b1 * (k_o @ self._raw["kio"].data.T) / self.noise
            y = self._solve_lower(f, z.T)
            quad = quad + (y * y).sum(0)
        var = self.kernel.prior_variance(b[task, task]) - quad
        return mean, var.clamp_min(0.0)

    def predict_with_gradients(self, xq: Tensor, task: int, b: Tensor,
                               chunk: int = 256) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        r"""Posterior mean, variance and their x-gradients at `(m, d)` points, without autograd.

        Same arithmetic as ``predict`` differentiated by hand: with ``dk/dx = -(x - x') k^3`` (IMQ), the rotated
        vectors ``[w, dw/dx] = [k_o, dk_o/dx] U`` come from one pass over U (autograd needs one forward and one
        backward pass per output), and

            d mu/dx = b1 (dw/dx) alpha_rot + b0 (dk_i/dx) alpha_i,
            dV/dx   = -2 b1^2 (dw/dx) D w - 2 (dz/dx)^T S^-1 z,   z = b0 k_i - b b1 P D w.

        Returns:
            `(m,)` mean, `(m,)` variance, `(m, d)` mean gradient, `(m, d)` variance gradient (zero where the
            variance is clamped at 0, as autograd through ``predict`` gives).
        """
        f = self.factor(b)
        xq, b = xq.detach(), b.detach()
        if xq.shape[0] > chunk:
            parts = [self.predict_with_gradients(xq[i:i + chunk], task, b, chunk)
                     for i in range(0, xq.shape[0], chunk)]
            return tuple(torch.cat([p[k] for p in parts]) for k in range(4))
        m, dim = xq.shape
        b0, b1, beta = b[task, 0], b[task, 1], f["beta"]

        w_all = None
        if self._rotated is not None:                                        # queries at just-added points
            x_new, rotated, raw_rows = self._rotated
            hit = (xq.unsqueeze(1) == x_new.unsqueeze(0)).all(-1)            # (m, k)
            if bool(hit.any(1).all()):
                at = hit.to(torch.int8).argmax(1)
                w_all = rotated[:, at]
                k_rows = None if raw_rows is None else raw_rows[:, at]
        if w_all is None:
            k_rows = _kernel_rows(xq, self.xo, self.kernel)                  # (1 + d, m, N_o)
            w_all = (k_rows.reshape(-1, len(self.xo)) @ self.u).view(1 + dim, m, -1)
        w, dw = w_all[0], w_all[1:]
        d = self._query_weights(f)
        alpha_rot = self._alpha_rot(f)
        mean = self.mean + b1 * (w @ alpha_rot)
        g_mean = b1 * (dw @ alpha_rot)                                        # (d, m)
        quad = b1 * b1 * (w * w * d).sum(-1)
        g_quad = 2 * b1 * b1 * (dw * (w * d)).sum(-1)
        if self._raw is not None:                                            # the truncated basis' I/s part
            g_raw = k_rows @ self._alpha_raw(f)                              # (1 + d, m)
            mean, g_mean = mean + b1 * g_raw[0], g_mean + b1 * g_raw[1:]
            k0, s = k_rows[0], self.noise
            quad = quad + b1 * b1 * (k0 * k0).sum(-1) / s
            g_quad = g_quad + 2 * b1 * b1 * (k_rows[1:] * k0).sum(-1) / s
        if self.n_inner:
            k_all = _kernel_rows(xq, self.xi, self.kernel)                   # (1 + d, m, N_i)
            mean = mean + b0 * (k_all[0] @ f["alpha_i"])
            g_mean = g_mean + b0 * (k_all[1:] @ f["alpha_i"])
            z_all = b0 * k_all - beta * b1 * ((w_all * d) @ self.p.T)        # (1 + d, m, N_i)
            if self._raw is not None:
                z_all = z_all - beta * b1 * (k_rows @ self._raw["kio"].data.T) / self.noise
            y = self._solve_lower(f, z_all.reshape(-1, self.n_inner).T)
            y = y.T.reshape(1 + dim, m, -1)
            quad = quad + (y[0] * y[0]).sum(-1)
            g_quad = g_quad + 2 * (y[1:] * y[0]).sum(-1)
        var = self.kernel.prior_variance(b[task, task]) - quad
        g_var = torch.where(var > 0, -g_quad, torch.zeros_like(g_quad))
        return mean, var.clamp_min(0.0), g_mean.T.contiguous(), g_var.T.contiguous()

    # ------------------------------------------------------------------ marginal likelihood
    def mll(self, b: Tensor) -> Tensor:
        """Log marginal likelihood, eq. (16): a scalar tensor."""
        f = self.factor(b)
        d, c = f["d"], f["c"]
        logdet = torch.log(c * self.lam + self.noise).sum()
        quad = (self.rt * self.rt * d).sum()
        if self._raw is not None:              # the complement's modes: c * 0 + s each
            logdet = logdet + (len(self.xo) - self.rank) * math.log(self.noise)
            quad = quad + self._raw["quad_o"]
        if self.n_inner:
            logdet = logdet + f["logdet_s"]
            quad = quad + f["v"] @ f["alpha_i"]
        return -0.5 * logdet - 0.5 * quad - 0.5 * self.n * math.log(2 * math.pi)

    def mll_derivatives(self, b: Tensor) -> tuple[float, Tensor, Tensor]:
        r"""MLL with its exact gradient and Hessian in ``p = (K_t00, K_t01, K_t11)``.

        With ``S_j = dS/dp_j`` (``K_ii``, ``-2b T``, ``-b^2 T'``), ``S_jk`` (nonzero: ``S_bb = -2T``,
        ``S_bc = -2b T'``, ``S_cc = -b^2 T''``), ``v_j``, ``v_jk`` likewise, ``W = S^-1`` and ``u = W v``:

            g_j  = -1/2 [tr(W S_j) + 2 v_j.u - u.S_j u]
            H_jk = -1/2 [tr(W S_jk) - tr(W S_j W S_k) + 2 v_jk.u + 2 v_j.W v_k - 2 (W v_j).S_k u
                         - 2 (W v_k).S_j u + 2 (S_k u).W (S_j u) - u.S_jk u]

        plus the outer terms, which depend on c only. Cost: one inverse of S and one `(N_i, 2 N_i)` product.
        """
        f = self.factor(b, derivatives=True)
        mll = float(self.mll(b))
        lam, d, rt, beta = self.lam, f["d"], self.rt, f["beta"]
        g = torch.zeros(3, **self._kind)
        h = torch.zeros(3, 3, **self._kind)
        # outer scalar parts (depend on c only): -1/2 [sum log(c lam + s) + sum rt^2 D]
        g[2] += -0.5 * ((lam * d).sum() - (rt * rt * lam * d * d).sum())
        h[2, 2] += -0.5 * (-(lam * lam * d * d).sum() + 2 * (rt * rt * lam * lam * d ** 3).sum())
        if not self.n_inner:
            return mll, g, h
        t0, t1, t2, pd = f["t0"], f["t1"], f["t2"], f["pd"]
        a, n = f["a"], self.n_inner
        w = torch.cholesky_inverse(f["chol"])                                # W = S^-1
        u = f["alpha_i"]                                                    # W v
        wf = w.reshape(-1)
        tr_w_t = torch.stack([wf @ t0.reshape(-1), wf @ t1.reshape(-1), wf @ t2.reshape(-1)])   # tr(W T), ...(T', T'')
        scale = torch.tensor([1.0, -2 * beta, -beta * beta], **self._kind)   # S_j = scale_j A_j
        tr_ws = scale * torch.stack([wf @ self.kii.reshape(-1), tr_w_t[0], tr_w_t[1]])   # tr(W S_j)
        zero = torch.zeros_like(u)
        vj = torch.stack([zero, -pd[:, 0], beta * pd[:, 1]])                # dv/dp_j, (3, n)
        au = torch.stack([self.kii @ u, t0 @ u, t1 @ u, t2 @ u])            # K u, T u, T' u, T'' u
        su = scale.unsqueeze(1) * au[:3]                                    # S_j u
        g += -0.5 * (tr_ws + 2 * (vj @ u) - su @ u)
        if beta * beta >= 0.01 * a * f["c"]:
            # W T from S = a K + s' I - b^2 T (s' = s + jitter): W T = (a W K + s' W - I) / b^2, one product
            # fewer. Its relative rounding error is ~eps (1 + |b^2 W T|) / |b^2 W T|, small when the tasks are
            # correlated; only the Hessian uses it (the gradient takes tr(W T) directly), and Newton's fixed point
            # does not depend on the Hessian, only its speed does.
            wk_wt1 = (w @ torch.cat([self.kii, t1], dim=1)).view(n, 2, n).transpose(0, 1)
            wt0 = a * wk_wt1[0] + (self.noise + self.jitter) * w
            wt0.diagonal().sub_(1.0)
            ws = torch.stack([wk_wt1[0], wt0 / (beta * beta), wk_wt1[1]])
        else:
            ws = (w @ torch.cat([self.kii, t0, t1], dim=1)).view(n, 3, n).transpose(0, 1)   # W K, W T, W T'
        gram = ws.reshape(3, -1) @ ws.transpose(1, 2).reshape(3, -1).T      # tr(W A W B), A, B in {K, T, T'}
        tr_wsws = scale.unsqueeze(1) * scale.unsqueeze(0) * gram
        w_vs = torch.cat([vj, su]) @ w                                      # W v_j, W S_j u (W symmetric)
        wv, wsu = w_vs[:3], w_vs[3:]
        x = wv @ su.T                                                       # (W v_j).S_k u
        quad2 = 2 * (vj @ wv.T) - 2 * (x + x.T) + 2 * (su @ wsu.T)
        # second-derivative terms: tr(W S_jk) + 2 v_jk.u - u.S_jk u for (b, b), (b, c), (c, c)
        u_t = au[1:] @ u                                                    # u.T u, u.T' u, u.T'' u
        second = torch.zeros(3, 3, **self._kind)
        second[1, 1] = -2 * tr_w_t[0] + 2 * u_t[0]
        second[1, 2] = second[2, 1] = -2 * beta * tr_w_t[1] + 2 * (pd[:, 1] @ u) + 2 * beta * u_t[1]
        second[2, 2] = -beta * beta * tr_w_t[2] - 4 * beta * (pd[:, 2] @ u) + beta * beta * u_t[2]
        h += -0.5 * (second - tr_wsws + quad2)
        return mll, g, h


class DirectStructuredInference(StructuredExactInference):
    """:class:`StructuredExactInference` with T(c) by direct products at every factorisation instead of a Chebyshev
    store over a window of ``K_t[1, 1]``: exact (no series truncation), and cheaper where the likelihood is evaluated
    at K_t spread over more than a window's factor of 2 on few inner points, as the restarts' fixed starts on a
    thinned copy of the data are (GPIOIS.fit(scout=...)): a store costs about as much as its order (up to 48) such
    products to build, and on 256 inner points the fixed starts rebuilt it 12 times in 56 evaluations, more than
    half of a restart's time."""

    SERIES = False

r"""Fast exact GPIOIS arithmetic for a fixed outer (visual) set and a growing inner (tactile) set.

During exploration the outer points are fixed, only inner points arrive, and only the three numbers of K_t change
(theta and sigma^2 are fixed). With ``K_t = [[a, b], [b, c]]`` the Gram matrix is

    G = [[a K_ii + s I, b K_io], [b K_oi, c K_oo + s I]],   s = sigma^2.

**Rotation.** One eigendecomposition ``K_oo = U diag(lam) U^T`` (O(N_o^3), once) makes the outer block diagonal
in the rotated coordinates: ``c K_oo + s I -> diag(c lam + s)``, so ``D = diag(1 / (c lam + s))`` is free for
any c. Inner rows enter through ``P = K_io U`` (one O(N_o^2) row per new inner point).

**Schur complement.** Eliminating the outer block leaves the N_i x N_i matrix

    S = a K_ii + s I - b^2 T(c),   T(c) = P D(c) P^T,   log|G| = sum_k log(c lam_k + s) + log|S|,

and the quadratic form ``r^T G^-1 r = sum_k rt_k^2 D_k + v^T S^-1 v`` with ``rt = U^T r_o`` and
``v = r_i - b P D rt``. S is symmetric positive definite with S >= s I (a Schur complement of G >= s I).

**Three-way split.** Forming T(c) costs N_i^2 N_o. Modes are split at the c of the last split:

* low (``c lam < 0.15 s``): ``1/(c lam + s) = (1/s) sum_j (-c lam / s)^j``, with precomputed
  ``M_j = P_L lam_L^j P_L^T``;
* high (``c lam > s / 0.15``): ``1/(c lam + s) = sum_j (-s)^j / (c lam)^(j+1)``, with ``N_j = P_H lam_H^-(j+1) P_H^T``;
* middle: summed exactly, O(N_i^2 |middle|).

Each series is cut at the first J whose remainder bound, relative to S >= s I, is below ``tol.structured_series``:
``rho^(J+1) / (1 - rho) * tr(M_0) / s^2`` (low, ``rho = c max(lam_L) / s``) and
``rho^(J+1) / (1 - rho) * tr(N_0) / (c s)`` (high, ``rho = s / (c min(lam_H))``). When no J <= ``J_MAX`` meets a
bound (c moved far since the split), the split is rebuilt for the current c. Nothing else is approximated.

**Derivatives.** With S, dS/dp and d^2S/dp^2 as explicit N_i x N_i matrices (T, T', T'' from the head and the
series), the exact gradient and Hessian of the log marginal likelihood in ``p = (a, b, c)`` cost O(N_i^2 |head| +
N_i^3) per Newton iteration, never O(N_o^2).

**Queries.** Posterior mean: O(N) per point from cached weights. Posterior variance:
``b1^2 w^T D w + z^T S^-1 z`` with ``w = U^T k_o``, ``z = b0 k_i - b b1 P D w``: one O(N_o^2) rotation per point
(a quadratic form in N unknowns cannot be cheaper exactly); grids use matrix products.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from .inference import bordered, robust_cholesky
from .kernels import imq
from .tolerances import tol

__all__ = ["StructuredExactInference"]

J_MAX = 24


class _SeriesStore:
    """Series matrices of the low and high modes in one contiguous `(2 (J_MAX + 1), cap * cap)` block.

    Rows 0..J_MAX hold ``M_j = P_L diag(lam_L^j) P_L^T``, rows J_MAX+1.. hold ``N_j = P_H diag(lam_H^-(j+1)) P_H^T``,
    each an N_i x N_i matrix in the top-left of a cap x cap square. Any weighted sum of them is one small GEMM
    that reads the block once; rows for new inner points are written in place (capacity grows in chunks).
    """

    CHUNK = 24

    def __init__(self, low: Tensor, high: Tensor, lam: Tensor, p: Tensor, kind: dict):
        self.low, self.high, self.kind = low, high, kind
        j = torch.arange(J_MAX + 1, **kind).unsqueeze(1)
        one = torch.ones_like(lam)
        self.pows = torch.cat([torch.where(low, lam, one) ** j * low,                  # lam^j on low modes
                               torch.where(high, lam, one) ** (-(j + 1)) * high])     # lam^-(j+1) on high modes
        self.lam_low_max = float(lam[low].max()) if bool(low.any()) else 0.0
        self.lam_high_min = float(lam[high].min()) if bool(high.any()) else 0.0
        self.modes = low | high
        n = p.shape[0]
        self.cap = n + self.CHUNK
        self.block = torch.zeros(2 * (J_MAX + 1), self.cap * self.cap, **kind)
        self.size = 0
        self.trace_low = self.trace_high = 0.0
        if n:
            self._write(p, p, 0)
        self.size = n

    def _square(self) -> Tensor:
        return self.block.view(-1, self.cap, self.cap)

    def _write(self, p_new: Tensor, p_all: Tensor, n_old: int) -> None:
        pm_new, pm_all = p_new[:, self.modes], p_all[:, self.modes]
        rows = (pm_new.unsqueeze(0) * self.pows[:, self.modes].unsqueeze(1)) @ pm_all.T   # (2(J+1), k, n_all)
        sq = self._square()
        n_all = p_all.shape[0]
        sq[:, n_old:n_all, :n_all] = rows
        sq[:, :n_old, n_old:n_all] = rows[:, :, :n_old].transpose(1, 2)
        diag = rows[:, :, n_old:].diagonal(dim1=1, dim2=2).sum(-1)
        self.trace_low += float(diag[0])
        self.trace_high += float(diag[J_MAX + 1])

    def append(self, p_new: Tensor, p_all: Tensor) -> None:
        n_old, n_new = self.size, p_all.shape[0]
        if n_new > self.cap:
            cap = n_new + self.CHUNK
            block = torch.zeros(2 * (J_MAX + 1), cap * cap, **self.kind)
            block.view(-1, cap, cap)[:, :n_old, :n_old] = self._square()[:, :n_old, :n_old]
            self.block, self.cap = block, cap
        self._write(p_new, p_all, n_old)
        self.size = n_new

    def combine(self, coefs: Tensor, orders: tuple[int, int]) -> Tensor:
        """`(r, 2(J+1))` coefficients -> `(r, N_i, N_i)` weighted sums; reads only rows up to the orders used."""
        lo, hi = orders[0] + 1, J_MAX + 1 + orders[1] + 1
        out = coefs[:, :lo] @ self.block[:lo] + coefs[:, J_MAX + 1:hi] @ self.block[J_MAX + 1:hi]
        return out.view(-1, self.cap, self.cap)[:, :self.size, :self.size]

    def matrices(self) -> Tensor:
        return self._square()[: J_MAX + 1, :self.size, :self.size]


class StructuredExactInference:
    """Exact GPIOIS engine: rotated outer block + inner Schur complement (see the module docstring).

    Same interface as ``DenseExactInference`` (``append``, ``factor``, ``predict``, ``mll``, ``mll_derivatives``).

    Args:
        x: `(n, d)` training points [m] (any order of tasks).
        y: `(n,)` labels.
        task: `(n,)` task ids; at least one outer (1) point.
        theta: IMQ parameter [m].
        noise: sigma^2 > 0.
        mean: prior mean m.
    """

    def __init__(self, x: Tensor, y: Tensor, task: Tensor, theta: float, noise: float, mean: float = 1.0):
        self.theta, self.noise, self.mean = float(theta), float(noise), float(mean)
        x, y, task = x.detach(), y.detach(), task.detach()
        inner, outer = task == 0, task == 1
        if not bool(outer.any()):
            raise ValueError("StructuredExactInference: needs at least one outer (task 1) point")
        self.xo, self.yo = x[outer], y[outer]
        self.xi, self.yi = x[inner], y[inner]
        kind = dict(dtype=x.dtype, device=x.device)
        self._kind = kind
        lam, self.u = torch.linalg.eigh(imq(self.xo, self.xo, self.theta))
        self.lam = lam.clamp_min(0.0)  # K_oo is PSD; clamp rounding below zero
        self.rt = self.u.T @ (self.yo - self.mean)
        self.kii = imq(self.xi, self.xi, self.theta)
        self.p = imq(self.xi, self.xo, self.theta) @ self.u if len(self.xi) else torch.zeros(0, len(self.xo), **kind)
        self._middle = None  # bool mask of the modes summed exactly (the middle band)
        self._series = None  # _SeriesStore of the low and high modes
        self._invalidate()

    # ------------------------------------------------------------------ data
    @property
    def n(self) -> int:
        return len(self.xi) + len(self.xo)

    @property
    def n_inner(self) -> int:
        return len(self.xi)

    def _invalidate(self) -> None:
        self._key = None
        self._cache = None
        self.jitter = 0.0

    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        """Append inner observations in O(k N_o^2 + k N_i |series modes| J); outer ones rebuild the engine."""
        x, y, task = x.detach(), y.detach(), task.detach()
        if bool((task == 1).any()):
            xs = torch.cat([self.xi, self.xo, x])
            ys = torch.cat([self.yi, self.yo, y])
            ts = torch.cat([torch.zeros(len(self.xi), dtype=torch.long, device=x.device),
                            torch.ones(len(self.xo), dtype=torch.long, device=x.device), task])
            self.__init__(xs, ys, ts, self.theta, self.noise, self.mean)
            return
        self.kii = bordered(self.kii, imq(x, self.xi, self.theta), imq(x, x, self.theta))
        p_new = imq(x, self.xo, self.theta) @ self.u
        self.p = torch.cat([self.p, p_new])
        self.xi = torch.cat([self.xi, x])
        self.yi = torch.cat([self.yi, y])
        if self._series is not None:
            self._series.append(p_new, self.p)
        self._invalidate()

    # ------------------------------------------------------------------ mode split
    def _split(self, c: float) -> None:
        """Low (c lam < 0.15 s), high (c lam > s / 0.15) series and the exact middle band, at this c."""
        c = max(c, 1e-300)
        low = c * self.lam < 0.15 * self.noise
        high = c * self.lam > self.noise / 0.15
        self._middle = ~(low | high)
        self._series = _SeriesStore(low, high, self.lam, self.p, self._kind)

    @property
    def m_series(self) -> Tensor | None:
        """`(J_MAX + 1, N_i, N_i)` low-mode series matrices M_j = P_L diag(lam_L^j) P_L^T (None before a split)."""
        return None if self._series is None else self._series.matrices()

    @staticmethod
    def _order(rho: float, scale: float) -> int | None:
        """Smallest J with rho^(J+1) / (1 - rho) * scale <= tol, or None if above J_MAX / rho >= 0.5."""
        if scale == 0.0 or rho == 0.0:
            return 0
        if rho >= 0.5:
            return None
        target = tol.structured_series * (1 - rho) / scale
        j = max(0, math.ceil(math.log(target) / math.log(rho)) - 1) if target < 1 else 0
        return j if j <= J_MAX else None

    def _series_orders(self, c: float) -> tuple[int, int] | None:
        s, st = self.noise, self._series
        lo = self._order(c * st.lam_low_max / s, st.trace_low / s**2)
        hi = self._order(s / (c * st.lam_high_min), st.trace_high / (c * s)) if st.lam_high_min > 0 else 0
        return None if lo is None or hi is None else (lo, hi)

    def _t_matrices(self, c: float) -> tuple[Tensor, Tensor, Tensor]:
        """T(c) = P D P^T and its first two c-derivatives, `(N_i, N_i)` each."""
        orders = None if self._series is None else self._series_orders(c)
        if orders is None:
            self._split(c)
            orders = self._series_orders(c)
            if orders is None:
                raise FloatingPointError(f"structured engine: no series order <= {J_MAX} meets the bound at "
                                         f"K_t[1,1] = {c:.3g}")
        s = self.noise
        mid = self._middle
        lam_m = self.lam[mid]
        d = 1.0 / (c * lam_m + s)
        pm = self.p[:, mid]
        # coefficients of the truncated series: low T = (1/s) sum_j (-c/s)^j M_j, high T = sum_j (-s)^j c^-(j+1) N_j
        coefs = torch.zeros(3, 2 * (J_MAX + 1), dtype=torch.float64)
        st = self._series
        for j in range(orders[0] + 1 if bool(st.low.any()) else 0):
            sign = -1.0 if j % 2 else 1.0
            coefs[0, j] = sign * c**j / s ** (j + 1)
            coefs[1, j] = sign * j * c ** (j - 1) / s ** (j + 1) if j >= 1 else 0.0
            coefs[2, j] = sign * j * (j - 1) * c ** (j - 2) / s ** (j + 1) if j >= 2 else 0.0
        for j in range(orders[1] + 1 if bool(st.high.any()) else 0):   # empty series: no inf * 0 = NaN
            k, coef = J_MAX + 1 + j, (-s) ** j
            coefs[0, k] = coef * c ** (-(j + 1))
            coefs[1, k] = -coef * (j + 1) * c ** (-(j + 2))
            coefs[2, k] = coef * (j + 1) * (j + 2) * c ** (-(j + 3))
        t = self._series.combine(coefs.to(**self._kind), orders)
        t0 = t[0] + (pm * d) @ pm.T
        t1 = t[1] + (pm * (-lam_m * d * d)) @ pm.T
        t2 = t[2] + (pm * (2 * lam_m * lam_m * d * d * d)) @ pm.T
        return t0, t1, t2

    # ------------------------------------------------------------------ factorisation
    def factor(self, b: Tensor) -> dict:
        """Schur factor and posterior weights for task covariance ``b`` (cached)."""
        b = b.detach()
        key = tuple(b.flatten().tolist())
        if self._key == key:
            return self._cache
        a, beta, c = float(b[0, 0]), float(b[0, 1]), float(b[1, 1])
        s = self.noise
        d_all = 1.0 / (c * self.lam + s)
        t = self._t_matrices(c) if self.n_inner else None
        t0 = t[0] if t is not None else None
        cache = {"a": a, "beta": beta, "c": c, "d": d_all, "t": t}
        if self.n_inner:
            smat = a * self.kii - beta * beta * t0
            smat.diagonal().add_(s)
            smat = 0.5 * (smat + smat.T)
            chol, self.jitter = robust_cholesky(smat, "inner Schur complement")
            v = (self.yi - self.mean) - beta * (self.p @ (d_all * self.rt))
            alpha_i = torch.cholesky_solve(v.unsqueeze(-1), chol).squeeze(-1)
            cache.update(s=smat, chol=chol, v=v, alpha_i=alpha_i)
            alpha_rot = d_all * (self.rt - beta * (self.p.T @ alpha_i))
        else:
            cache.update(alpha_i=torch.zeros(0, **self._kind))
            alpha_rot = d_all * self.rt
        cache["alpha_rot"] = alpha_rot          # outer weights in the rotated basis (U^T alpha_o)
        self._cache, self._key = cache, key
        return cache

    # ------------------------------------------------------------------ posterior
    def predict(self, xq: Tensor, task: int, b: Tensor, chunk: int = 4096) -> tuple[Tensor, Tensor]:
        """Posterior mean and variance of F_task at `(m, d)` points, eq. (12)-(13); differentiable in ``xq``."""
        f = self.factor(b)
        b = b.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            parts = [self.predict(xq[i:i + chunk], task, b, chunk) for i in range(0, xq.shape[0], chunk)]
            return torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])
        b0, b1, beta = b[task, 0], b[task, 1], f["beta"]
        k_o = imq(xq, self.xo, self.theta)
        w = k_o @ self.u                                  # (m, N_o) rotated outer kernel vectors
        mean = self.mean + b1 * (w @ f["alpha_rot"])
        quad = b1 * b1 * (w * w * f["d"]).sum(-1)
        if self.n_inner:
            k_i = imq(xq, self.xi, self.theta)
            mean = mean + b0 * (k_i @ f["alpha_i"])
            z = b0 * k_i - beta * b1 * ((w * f["d"]) @ self.p.T)   # (m, N_i)
            y = torch.linalg.solve_triangular(f["chol"], z.T, upper=False)
            quad = quad + (y * y).sum(0)
        var = b[task, task] / self.theta - quad
        return mean, var.clamp_min(0.0)

    # ------------------------------------------------------------------ marginal likelihood
    def mll(self, b: Tensor) -> Tensor:
        """Log marginal likelihood, eq. (16): a scalar tensor."""
        f = self.factor(b)
        d, c = f["d"], f["c"]
        logdet = torch.log(c * self.lam + self.noise).sum()
        quad = (self.rt * self.rt * d).sum()
        if self.n_inner:
            logdet = logdet + 2 * f["chol"].diagonal().log().sum()
            quad = quad + f["v"] @ f["alpha_i"]
        return -0.5 * logdet - 0.5 * quad - 0.5 * self.n * math.log(2 * math.pi)

    def mll_derivatives(self, b: Tensor) -> tuple[float, Tensor, Tensor]:
        """MLL with its exact gradient and Hessian in ``p = (K_t00, K_t01, K_t11)`` (formulas: module docstring)."""
        f = self.factor(b)
        mll = float(self.mll(b))
        lam, d, rt, beta = self.lam, f["d"], self.rt, f["beta"]
        g = torch.zeros(3, **self._kind)
        h = torch.zeros(3, 3, **self._kind)
        # outer scalar parts (depend on c only): -1/2 [sum log(c lam + s) + sum rt^2 D]
        g[2] += -0.5 * ((lam * d).sum() - (rt * rt * lam * d * d).sum())
        h[2, 2] += -0.5 * (-(lam * lam * d * d).sum() + 2 * (rt * rt * lam * lam * d ** 3).sum())
        if not self.n_inner:
            return mll, g, h
        t0, t1, t2 = f["t"]
        zero = torch.zeros_like(t0)
        s_1 = [self.kii, -2 * beta * t0, -beta * beta * t1]               # dS/dp_j
        s_2 = [[zero, zero, zero], [zero, -2 * t0, -2 * beta * t1], [zero, -2 * beta * t1, -beta * beta * t2]]
        pd_rt = self.p @ (d * rt)
        pd_l = self.p @ (lam * d * d * rt)
        pd_ll = self.p @ (lam * lam * d ** 3 * rt)
        zv = torch.zeros_like(pd_rt)
        v_1 = [zv, -pd_rt, beta * pd_l]                                     # dv/dp_j
        v_2 = [[zv, zv, zv], [zv, zv, pd_l], [zv, pd_l, -2 * beta * pd_ll]]
        chol = f["chol"]
        w = torch.cholesky_inverse(chol)                                    # S^-1
        u = f["alpha_i"]                                                    # S^-1 v
        ws = [w @ sj for sj in s_1]                                         # S^-1 S_j
        w_v = [w @ vj for vj in v_1]                                        # S^-1 v_j
        s_u = [sj @ u for sj in s_1]                                        # S_j u
        for j in range(3):
            dlogdet = ws[j].diagonal().sum()
            dq = 2 * v_1[j] @ u - u @ s_u[j]
            g[j] += -0.5 * (dlogdet + dq)
            for k in range(j, 3):
                d2logdet = (w * s_2[j][k]).sum() - (ws[j] * ws[k].T).sum()
                d2q = (2 * v_2[j][k] @ u + 2 * v_1[j] @ w_v[k] - 2 * w_v[j] @ s_u[k] - 2 * w_v[k] @ s_u[j]
                       + 2 * s_u[k] @ (w @ s_u[j]) - u @ (s_2[j][k] @ u))
                h[j, k] += -0.5 * (d2logdet + d2q)
                if k != j:
                    h[k, j] = h[j, k]
        return mll, g, h

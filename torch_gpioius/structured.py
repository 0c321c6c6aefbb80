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

**Head / tail split.** Forming T(c) costs N_i^2 N_o. Modes with small ``c lam`` ("tail") are summed by the
convergent series ``1/(c lam + s) = (1/s) sum_j (-c lam / s)^j`` with precomputed ``M_j = P_T lam_T^j P_T^T``; the
rest ("head") is summed exactly. The series is cut at the first J with
``rho^(J+1) / (1 - rho) * tr(M_0) / s^2 <= tol.structured_series`` (``rho = c max(lam_T) / s``), a rigorous bound on
the relative perturbation of S (since S >= s I); when no J <= ``J_MAX`` meets it the split is rebuilt for the
current c. Nothing else is approximated.

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

from .inference import robust_cholesky
from .kernels import imq
from .tolerances import tol

__all__ = ["StructuredExactInference"]

J_MAX = 40


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
        self._head = None  # bool mask over modes
        self._split_c = None
        self._m_store = None  # (J_MAX + 1, capacity, capacity); M_j = _m_store[j, :N_i, :N_i]
        self._m_size = 0
        self.tr_m0 = 0.0
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
        """Append inner observations in O(k N_o^2 + k N_i (|tail| J)); outer ones rebuild the engine."""
        x, y, task = x.detach(), y.detach(), task.detach()
        if bool((task == 1).any()):
            xs = torch.cat([self.xi, self.xo, x])
            ys = torch.cat([self.yi, self.yo, y])
            ts = torch.cat([torch.zeros(len(self.xi), dtype=torch.long, device=x.device),
                            torch.ones(len(self.xo), dtype=torch.long, device=x.device), task])
            self.__init__(xs, ys, ts, self.theta, self.noise, self.mean)
            return
        k_new_old = imq(x, self.xi, self.theta)
        k_new_new = imq(x, x, self.theta)
        self.kii = torch.cat([torch.cat([self.kii, k_new_old.T], 1), torch.cat([k_new_old, k_new_new], 1)], 0)
        p_new = imq(x, self.xo, self.theta) @ self.u
        self.p = torch.cat([self.p, p_new])
        self.xi = torch.cat([self.xi, x])
        self.yi = torch.cat([self.yi, y])
        if self.m_series is not None:
            tail = ~self._head
            pows = self.lam[tail] ** torch.arange(J_MAX + 1, **self._kind).unsqueeze(1)      # (J+1, T)
            new_rows = (p_new[:, tail].unsqueeze(0) * pows.unsqueeze(1)) @ self.p[:, tail].T    # (J+1, k, N_i)
            n_old, n_new = self._m_size, self._m_size + len(x)
            if n_new > self._m_store.shape[1]:  # amortised growth: copy only when capacity doubles
                cap = max(2 * self._m_store.shape[1], n_new, 16)
                store = torch.zeros(J_MAX + 1, cap, cap, **self._kind)
                store[:, :n_old, :n_old] = self._m_store[:, :n_old, :n_old]
                self._m_store = store
            self._m_store[:, n_old:n_new, :n_new] = new_rows
            self._m_store[:, :n_old, n_old:n_new] = new_rows[:, :, :n_old].transpose(1, 2)
            self._m_size = n_new
            self.tr_m0 += float(new_rows[0, :, n_old:].diagonal().sum())
        self._invalidate()

    # ------------------------------------------------------------------ head / tail split
    def _split(self, c: float) -> None:
        """Head = modes with c lam > 0.15 s (summed exactly); tail series matrices M_j for the rest."""
        threshold = 0.15 * self.noise / max(c, 1e-300)
        self._head = self.lam > threshold
        self._split_c = c
        tail = ~self._head
        pt = self.p[:, tail]
        pows = self.lam[tail] ** torch.arange(J_MAX + 1, **self._kind).unsqueeze(1)   # (J+1, T)
        self._m_store = (pt.unsqueeze(0) * pows.unsqueeze(1)) @ pt.T if pt.shape[1] else \
            torch.zeros(J_MAX + 1, self.n_inner, self.n_inner, **self._kind)
        self._m_size = self.n_inner
        self.tr_m0 = float(self._m_store[0].diagonal().sum())

    @property
    def m_series(self) -> Tensor | None:
        """`(J_MAX + 1, N_i, N_i)` tail series matrices M_j = P_T diag(lam_T^j) P_T^T (None before the split)."""
        if self._m_store is None:
            return None
        return self._m_store[:, :self._m_size, :self._m_size]

    def _series_order(self, c: float) -> int | None:
        """Smallest J meeting the truncation bound at c, or None if the split must be rebuilt."""
        tail = ~self._head
        if not bool(tail.any()) or self.tr_m0 == 0.0:
            return 0
        rho = c * float(self.lam[tail].max()) / self.noise
        if rho >= 0.5:
            return None
        scale = self.tr_m0 / self.noise**2
        target = tol.structured_series
        if rho == 0.0:
            return 0
        j = math.ceil(math.log(target * (1 - rho) / scale) / math.log(rho)) - 1 if scale * rho / (1 - rho) > target \
            else 0
        return max(j, 0) if j <= J_MAX else None

    def _t_matrices(self, c: float) -> tuple[Tensor, Tensor, Tensor]:
        """T(c) = P D P^T and its first two c-derivatives, `(N_i, N_i)` each."""
        if self._head is None:
            self._split(c)
        order = self._series_order(c)
        if order is None:
            self._split(c)
            order = self._series_order(c)
            assert order is not None, "structured engine: series bound cannot be met"
        head = self._head
        s = self.noise
        lam_h = self.lam[head]
        d = 1.0 / (c * lam_h + s)
        ph = self.p[:, head]
        t0 = (ph * d) @ ph.T
        t1 = (ph * (-lam_h * d * d)) @ ph.T
        t2 = (ph * (2 * lam_h * lam_h * d * d * d)) @ ph.T
        if self.m_series is not None and order >= 0 and self.m_series.shape[1]:
            j = torch.arange(order + 1, **self._kind)
            sign = (-1.0) ** j
            w0 = sign * c**j / s ** (j + 1)
            w1 = sign * j * c ** (j - 1).clamp_min(0) / s ** (j + 1)
            w2 = sign * j * (j - 1) * c ** (j - 2).clamp_min(0) / s ** (j + 1)
            m = self.m_series[: order + 1]
            t0 = t0 + torch.einsum("j,jik->ik", w0, m)
            t1 = t1 + torch.einsum("j,jik->ik", w1, m)
            t2 = t2 + torch.einsum("j,jik->ik", w2, m)
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
        t0, t1, t2 = self._t_matrices(c) if self.n_inner else (None, None, None)
        cache = {"a": a, "beta": beta, "c": c, "d": d_all, "t": (t0, t1, t2)}
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
        cache["alpha_o"] = self.u @ alpha_rot
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
        mean = self.mean + b1 * (k_o @ f["alpha_o"])
        w = k_o @ self.u                                  # (m, N_o) rotated outer kernel vectors
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

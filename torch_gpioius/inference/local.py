r"""Exact engines of the local-similarity model (:class:`torch_gpioius.LocalGPIOIS`): dense reference and structured.

**Model** (the paper's Discussion: "local similarity"). One outer function and an inner function that follows it
by a coefficient that varies over space:

    F_out ~ GP(m, c k),     F_in(x) = m + beta(x) (F_out(x) - m) + H(x),     H ~ GP(0, a' k) independent,

    beta(x) = sum_r w_r(x) beta_r,   w(x) = softmax_r(-|x - m_r|^2 / (2 tau^2)),

with region centres ``m_r`` (k-means on the outer surface points) and a smoothing length ``tau``. Each region has
its own similarity: the correlation ``rho_r = beta_r sqrt(c) / sqrt(beta_r^2 c + a')`` and the paper's ratio
``beta_r c / (beta_r^2 c + a')``; within region r the task covariance is
``K_t^(r) = [[beta_r^2 c + a', beta_r c], [beta_r c, c]]``. With one region this is GPIOIS exactly: every PSD
``K_t`` with ``K11 > 0`` is ``c = K11, beta = K01 / K11, a' = K00 - K01^2 / K11``.

Every observation has loadings on the two latent functions: ``lambda_i = beta(x_i)`` and ``eta_i = 1`` for inner
points, ``lambda_i = 1`` and ``eta_i = 0`` for outer points, so the Gram matrix is

    G = K_x o (c lambda lambda^T + a' eta eta^T) + sigma^2 I.

Parameters ``p = (a', c, beta_1 .. beta_R)``.

**Structured engine.** The outer block stays ``c K_oo + sigma^2 I``, so the rotation ``K_oo = U diag(lam) U^T`` and
the Chebyshev store of ``T(c) = P D(c) P^T`` (``P = K_io U``) of :class:`StructuredExactInference` apply unchanged.
With ``Lambda = diag(beta(x_i))`` over the inner points and ``M(c) = c K_ii - c^2 T(c)``:

    S = a' K_ii + s I + Lambda M(c) Lambda,      v = r_i - c Lambda P D rt,

and the exact gradient and Hessian in ``p`` cost ``(R + 2)`` products of ``N_i x N_i`` matrices per Newton
iteration, never ``O(N_o^2)``. (Giving each outer region a task of its own with a free cross-region covariance
would make the outer block ``K_oo o C``, which has no fixed eigenbasis: every evaluation would factorise the
``N_o x N_o`` block, ~0.3 s at ``N_o = 2000``.)
"""

from __future__ import annotations

import functools
import math

import torch
from torch import Tensor

from .dense import engine_kernel, robust_cholesky
from .engine import ExactEngine
from .structured import StructuredExactInference

__all__ = ["region_weights", "loadings", "LocalDenseInference", "LocalStructuredInference"]


def region_weights(x: Tensor, centres: Tensor, tau: float) -> Tensor:
    """`(n, R)` soft region memberships ``softmax_r(-|x - m_r|^2 / (2 tau^2))`` of `(n, d)` points (differentiable)."""
    d2 = ((x.unsqueeze(1) - centres.unsqueeze(0)) ** 2).sum(-1)
    return torch.softmax(-d2 / (2.0 * tau * tau), dim=-1)


def loadings(task: Tensor, wts: Tensor, p: Tensor) -> tuple[Tensor, Tensor]:
    """`(n,)` loadings on F_out (lambda) and on H (eta) of observations with tasks ``task`` and weights ``wts``."""
    beta = wts @ p[2:]
    inner = task == 0
    lam = torch.where(inner, beta, torch.ones_like(beta))
    eta = inner.to(beta.dtype)
    return lam, eta


def query_loadings(xq: Tensor, task: int, p: Tensor, centres: Tensor, tau: float) -> tuple[Tensor, float]:
    """`(m,)` loadings on F_out of F_task at `(m, d)` queries (the region weights' beta for the inner task, 1 for the
    outer) and the query's loading on H (1 for the inner task, 0 for the outer)."""
    if task == 0:
        return region_weights(xq, centres, tau) @ p[2:], 1.0
    return torch.ones(xq.shape[0], dtype=xq.dtype, device=xq.device), 0.0


class LocalDenseInference(ExactEngine):
    """The dense reference engine of the local model: one Cholesky of the full Gram matrix (see the module docs).

    Args:
        x: `(n, d)` points; y: `(n,)` labels; task: `(n,)` ids; kernel, noise, mean: as GPIOIS (a float kernel is
            the inverse multiquadric's theta).
        centres: `(R, d)` region centres [m]; tau: smoothing length [m].
    """

    def __init__(self, x: Tensor, y: Tensor, task: Tensor, kernel, noise: float, mean: float,
                 centres: Tensor, tau: float) -> None:
        self.kernel = engine_kernel(kernel)
        self.noise, self.mean, self.tau = float(noise), float(mean), float(tau)
        self.x, self.y, self.task = x.detach(), y.detach(), task.detach()
        self.centres = centres.detach().to(self.x)
        self.kx = self.kernel.value(self.x, self.x)
        self.wts = region_weights(self.x, self.centres, self.tau)
        self._key = None

    @property
    def n(self) -> int:
        return self.x.shape[0]

    def scout_engine(self):
        """A copy of the data with the same regions."""
        return functools.partial(type(self), centres=self.centres, tau=self.tau)

    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        from .dense import bordered

        x, y, task = x.detach(), y.detach(), task.detach()
        self.kx = bordered(self.kx, self.kernel.value(x, self.x), self.kernel.value(x, x))
        self.x, self.y, self.task = torch.cat([self.x, x]), torch.cat([self.y, y]), torch.cat([self.task, task])
        self.wts = torch.cat([self.wts, region_weights(x, self.centres, self.tau)])
        self._key = None

    def remove(self, drop: Tensor, task: Tensor) -> bool:
        keep = ~drop
        self.kx = self.kx[keep][:, keep]
        self.x, self.y, self.task, self.wts = self.x[keep], self.y[keep], self.task[keep], self.wts[keep]
        self._key = None
        return True

    def gram(self, p: Tensor) -> Tensor:
        lam, eta = loadings(self.task, self.wts, p)
        g = self.kx * (p[1] * torch.outer(lam, lam) + p[0] * torch.outer(eta, eta))
        g.diagonal().add_(self.noise)
        return g

    def factor(self, p: Tensor):
        key = tuple(p.detach().tolist())
        if self._key != key:
            self._chol, self.jitter = robust_cholesky(self.gram(p.detach()))
            self._alpha = torch.cholesky_solve((self.y - self.mean).unsqueeze(-1), self._chol).squeeze(-1)
            self._gi = None
            self._key = key
        return self._chol, self._alpha

    def predict(self, xq: Tensor, task: int, p: Tensor, chunk: int = 8192) -> tuple[Tensor, Tensor]:
        _, alpha = self.factor(p)
        p = p.detach()
        if self._gi is None:
            self._gi = torch.cholesky_inverse(self._chol)
        kq, lq, eq = self._query_rows(xq, task, p)
        mean = self.mean + kq @ alpha
        prior = self.kernel.prior_variance(p[1] * lq * lq + p[0] * eq * eq)
        var = prior - ((kq @ self._gi) * kq).sum(-1)
        return mean, var.clamp_min(0.0)

    def predict_mean(self, xq: Tensor, task: int, p: Tensor, chunk: int = 8192) -> Tensor:
        _, alpha = self.factor(p)
        p = p.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            return torch.cat([self.predict_mean(xq[i:i + chunk], task, p, chunk) for i in range(0, xq.shape[0], chunk)])
        return self.mean + self._query_rows(xq, task, p)[0] @ alpha

    def _query_rows(self, xq: Tensor, task: int, p: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """`(m, n)` covariances of F_task at the queries with the training values at parameters ``p``, and the
        queries' loadings (:func:`query_loadings`)."""
        lam, eta = loadings(self.task, self.wts, p)
        lq, eq = query_loadings(xq, task, p, self.centres, self.tau)
        return self.kernel.value(xq, self.x) * (p[1] * lq.unsqueeze(1) * lam + p[0] * eq * eta), lq, eq

    def mll(self, p: Tensor) -> Tensor:
        chol, alpha = self.factor(p)
        r = self.y - self.mean
        return -chol.diagonal().log().sum() - 0.5 * (r @ alpha) - 0.5 * self.n * math.log(2 * math.pi)

    def mll_derivatives(self, p: Tensor) -> tuple[float, Tensor, Tensor]:
        """MLL with its exact gradient and Hessian in ``p = (a', c, beta_1..beta_R)`` (dense, by the trace
        formulas of :meth:`DenseExactInference.mll_derivatives` with the second derivatives of G)."""
        p = p.detach()
        _, alpha = self.factor(p)
        if self._gi is None:
            self._gi = torch.cholesky_inverse(self._chol)
        w = self._gi
        lam, eta = loadings(self.task, self.wts, p)
        inner = (self.task == 0).to(lam.dtype)
        dl = self.wts * inner.unsqueeze(1)                                    # d lambda / d beta_r, (n, R)
        kx, c = self.kx, float(p[1])
        k = len(p)
        d1 = [kx * torch.outer(eta, eta), kx * torch.outer(lam, lam)]
        d1 += [c * kx * (torch.outer(dl[:, r], lam) + torch.outer(lam, dl[:, r])) for r in range(k - 2)]
        d2 = {}
        for r in range(k - 2):
            d2[(1, 2 + r)] = kx * (torch.outer(dl[:, r], lam) + torch.outer(lam, dl[:, r]))
            for s in range(r, k - 2):
                d2[(2 + r, 2 + s)] = c * kx * (torch.outer(dl[:, r], dl[:, s]) + torch.outer(dl[:, s], dl[:, r]))
        wd = [w @ dj for dj in d1]
        da = [dj @ alpha for dj in d1]
        g = torch.stack([0.5 * (alpha @ da[j]) - 0.5 * wd[j].diagonal().sum() for j in range(k)])
        h = torch.zeros(k, k, dtype=kx.dtype, device=kx.device)
        for i in range(k):
            for j in range(i, k):
                v = 0.5 * (wd[i] * wd[j].T).sum() - da[i] @ (w @ da[j])
                if (i, j) in d2:
                    v = v + 0.5 * (alpha @ (d2[(i, j)] @ alpha)) - 0.5 * (w * d2[(i, j)]).sum()
                h[i, j] = h[j, i] = v
        return float(self.mll(p)), g, h


class LocalStructuredInference(StructuredExactInference):
    """The structured exact engine of the local model (see the module docstring): the rotation, the inner rows and
    the Chebyshev store of :class:`StructuredExactInference`, with the region loadings of the inner points."""

    def __init__(self, x: Tensor, y: Tensor, task: Tensor, kernel, noise: float, mean: float,
                 centres: Tensor, tau: float) -> None:
        super().__init__(x, y, task, kernel, noise, mean)
        self.centres, self.tau = centres.detach().to(self.xo), float(tau)
        self.wi = region_weights(self.xi, self.centres, self.tau)            # (N_i, R)

    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        if bool((task == 1).any()):
            xs = torch.cat([self.xi, self.xo, x.detach()])
            ys = torch.cat([self.yi, self.yo, y.detach()])
            ts = torch.cat([torch.zeros(len(self.xi), dtype=torch.long, device=x.device),
                            torch.ones(len(self.xo), dtype=torch.long, device=x.device), task.detach()])
            self.__init__(xs, ys, ts, self.kernel, self.noise, self.mean, self.centres, self.tau)
            return
        super().append(x, y, task)
        self.wi = torch.cat([self.wi, region_weights(x.detach(), self.centres, self.tau)])

    def remove(self, drop: Tensor, task: Tensor) -> bool:
        keep_i = ~drop[task == 0]
        done = super().remove(drop, task)
        if done:
            self.wi = self.wi[keep_i]
        return done

    #: the structured engine's closed form is the 2-task one: the local model differentiates predict() by autograd;
    #: its value alone is its factorisation's (no trial factorisation of the 2-task engine)
    closed_form_gradients = False
    value_alone = False

    def mll_value(self, p: Tensor) -> float:
        return float(self.mll(p))

    def scout_engine(self):
        """A copy of the data with the same regions (the store's window as the structured engine's)."""
        return functools.partial(type(self), centres=self.centres, tau=self.tau)

    def predict_with_gradients(self, *args, **kwargs):
        raise NotImplementedError("the local model differentiates predict() by autograd (LocalGPIOIS returns None "
                                  "from _predict_with_gradients)")

    # ------------------------------------------------------------------ factorisation
    def factor(self, p: Tensor, derivatives: bool = False) -> dict:
        p = p.detach()
        key = tuple(p.tolist())
        if self._key == key and (not derivatives or self._cache.get("t1") is not None or not self.n_inner):
            return self._cache
        a1, c = float(p[0]), float(p[1])
        s = self.noise
        d_all = 1.0 / (c * self.lam + s)
        cache = {"p": p, "c": c, "d": d_all, "alpha_rot": None}
        if self.n_inner:
            beta_i = self.wi @ p[2:]
            b2 = float((beta_i * beta_i).max()) * c * c
            t = self._t_matrices(c, math.sqrt(max(b2, 1e-300)), max(b2 / max(c, 1e-300), a1), derivatives)
            vecs = [d_all * self.rt]
            if derivatives:
                vecs += [self.lam * d_all * d_all * self.rt, self.lam * self.lam * d_all ** 3 * self.rt]
            pd = self.p @ torch.stack(vecs, dim=1)                 # P D rt, P D' rt (up to sign), ...
            mmat = c * self.kii - c * c * t[0]
            smat = a1 * self.kii + beta_i.unsqueeze(1) * mmat * beta_i.unsqueeze(0)
            smat.diagonal().add_(s)
            chol, self.jitter = robust_cholesky(smat, "inner Schur complement (local model)")
            v = (self.yi - self.mean) - c * beta_i * pd[:, 0]
            alpha_i = torch.cholesky_solve(v.unsqueeze(-1), chol).squeeze(-1)
            cache.update(t0=t[0], t1=t[1], t2=t[2], pd=pd, chol=chol, v=v, alpha_i=alpha_i, beta_i=beta_i, m=mmat)
        else:
            cache.update(alpha_i=torch.zeros(0, **self._kind), alpha_rot=d_all * self.rt,
                         beta_i=torch.zeros(0, **self._kind))
        self._cache, self._key = cache, key
        return cache

    def _alpha_rot(self, f: dict) -> Tensor:
        if f["alpha_rot"] is None:
            f["alpha_rot"] = f["d"] * (self.rt - f["c"] * (self.p.T @ (f["beta_i"] * f["alpha_i"])))
        return f["alpha_rot"]

    # ------------------------------------------------------------------ posterior
    def predict(self, xq: Tensor, task: int, p: Tensor, chunk: int = 4096) -> tuple[Tensor, Tensor]:
        f = self.factor(p)
        p = p.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            parts = [self.predict(xq[i:i + chunk], task, p, chunk) for i in range(0, xq.shape[0], chunk)]
            return torch.cat([q[0] for q in parts]), torch.cat([q[1] for q in parts])
        a1, c = p[0], f["c"]
        lq, eq = query_loadings(xq, task, p, self.centres, self.tau)
        k_o = self.kernel.value(xq, self.xo)
        w = k_o @ self.u                                       # (m, N_o)
        mean = self.mean + c * lq * (w @ self._alpha_rot(f))
        quad = (c * lq) ** 2 * (w * w * f["d"]).sum(-1)
        prior = self.kernel.prior_variance(c * lq * lq + a1 * eq)
        if self.n_inner:
            k_i = self.kernel.value(xq, self.xi)
            beta_i = f["beta_i"]
            cross = c * lq.unsqueeze(1) * beta_i + a1 * eq               # (m, N_i) kernel scales query-inner
            mean = mean + (cross * k_i) @ f["alpha_i"]
            z = c * lq.unsqueeze(1) * beta_i * (k_i - c * ((w * f["d"]) @ self.p.T)) + a1 * eq * k_i
            y = torch.linalg.solve_triangular(f["chol"], z.T, upper=False)
            quad = quad + (y * y).sum(0)
        var = prior - quad
        return mean, var.clamp_min(0.0)

    def predict_mean(self, xq: Tensor, task: int, p: Tensor, chunk: int = 4096) -> Tensor:
        """The mean of :meth:`predict` through the outer weights in the original basis (no GEMM with U per query)."""
        f = self.factor(p)
        p = p.detach()
        if not xq.requires_grad and xq.shape[0] > chunk:
            return torch.cat([self.predict_mean(xq[i:i + chunk], task, p, chunk) for i in range(0, xq.shape[0], chunk)])
        a1, c = p[0], f["c"]
        lq, eq = query_loadings(xq, task, p, self.centres, self.tau)
        mean = self.mean + c * lq * (self.kernel.value(xq, self.xo) @ self._alpha_outer(f))
        if self.n_inner:
            cross = c * lq.unsqueeze(1) * f["beta_i"] + a1 * eq
            mean = mean + (cross * self.kernel.value(xq, self.xi)) @ f["alpha_i"]
        return mean

    # ------------------------------------------------------------------ marginal likelihood
    def mll(self, p: Tensor) -> Tensor:
        f = self.factor(p)
        d, c = f["d"], f["c"]
        logdet = torch.log(c * self.lam + self.noise).sum()
        quad = (self.rt * self.rt * d).sum()
        if self.n_inner:
            logdet = logdet + 2 * f["chol"].diagonal().log().sum()
            quad = quad + f["v"] @ f["alpha_i"]
        return -0.5 * logdet - 0.5 * quad - 0.5 * self.n * math.log(2 * math.pi)

    def mll_derivatives(self, p: Tensor) -> tuple[float, Tensor, Tensor]:
        r"""MLL with its exact gradient and Hessian in ``p = (a', c, beta_1..beta_R)``.

        With ``S_j``, ``S_jk``, ``v_j``, ``v_jk`` the derivatives of the Schur complement and of ``v`` (module
        docstring; ``M' = K - 2c T - c^2 T'``, ``M'' = -2T - 4c T' - c^2 T''``, ``E_r = diag(w_r(x_i))``):

            S_a' = K,  S_c = Lambda M' Lambda,  S_r = E_r M Lambda + Lambda M E_r,
            S_cc = Lambda M'' Lambda,  S_cr = E_r M' Lambda + Lambda M' E_r,  S_rs = E_r M E_s + E_s M E_r,
            v_c = -Lambda P (D + c D') rt,  v_r = -c E_r P D rt,  v_cc = -Lambda P (2 D' + c D'') rt,
            v_cr = -E_r P (D + c D') rt,

        and the same trace formulas as :meth:`StructuredExactInference.mll_derivatives`, plus the outer terms in c.
        """
        f = self.factor(p, derivatives=True)
        p = p.detach()
        mll = float(self.mll(p))
        k = len(p)
        lam, d, rt, c = self.lam, f["d"], self.rt, f["c"]
        g = torch.zeros(k, **self._kind)
        h = torch.zeros(k, k, **self._kind)
        g[1] += -0.5 * ((lam * d).sum() - (rt * rt * lam * d * d).sum())
        h[1, 1] += -0.5 * (-(lam * lam * d * d).sum() + 2 * (rt * rt * lam * lam * d ** 3).sum())
        if not self.n_inner:
            return mll, g, h
        t0, t1, t2, pd, mmat = f["t0"], f["t1"], f["t2"], f["pd"], f["m"]
        beta, n = f["beta_i"], self.n_inner
        e = self.wi                                                        # (N_i, R)
        kii = self.kii
        m1 = kii - 2 * c * t0 - c * c * t1                                 # dM/dc
        m2 = -2 * t0 - 4 * c * t1 - c * c * t2                             # d2M/dc2
        # pd[:, 0] = P D rt, pd[:, 1] = P lam D^2 rt = -P D' rt, pd[:, 2] = P lam^2 D^3 rt = P D''/2 rt
        pdd = pd[:, 0] - c * pd[:, 1]                                      # P (D + c D') rt
        sj = [kii, beta.unsqueeze(1) * m1 * beta.unsqueeze(0)]
        vj = [torch.zeros(n, **self._kind), -beta * pdd]
        for r in range(k - 2):
            mb = mmat * beta.unsqueeze(0)                                  # M Lambda
            sj.append(e[:, r].unsqueeze(1) * mb + mb.T * e[:, r].unsqueeze(0))
            vj.append(-c * e[:, r] * pd[:, 0])
        w = torch.cholesky_inverse(f["chol"])
        u = f["alpha_i"]
        ws = [w @ sm for sm in sj]                                         # W S_j
        su = torch.stack([sm @ u for sm in sj])                            # S_j u
        vjs = torch.stack(vj)
        tr_ws = torch.stack([x.diagonal().sum() for x in ws])
        g += -0.5 * (tr_ws + 2 * (vjs @ u) - (su @ u))
        wv = vjs @ w                                                       # W v_j (W symmetric)
        wsu = su @ w                                                       # W S_j u
        # second derivatives of S and v (zero for every pair involving a')
        second_s, second_v = {}, {}
        second_s[(1, 1)] = beta.unsqueeze(1) * m2 * beta.unsqueeze(0)
        second_v[(1, 1)] = -beta * (-2 * pd[:, 1] + 2 * c * pd[:, 2])       # -Lambda P (2D' + c D'') rt
        for r in range(k - 2):
            mb1 = m1 * beta.unsqueeze(0)
            second_s[(1, 2 + r)] = e[:, r].unsqueeze(1) * mb1 + mb1.T * e[:, r].unsqueeze(0)
            second_v[(1, 2 + r)] = -e[:, r] * pdd
            for s_ in range(r, k - 2):
                em = e[:, r].unsqueeze(1) * mmat * e[:, s_].unsqueeze(0)
                second_s[(2 + r, 2 + s_)] = em + em.T
        for i in range(k):
            for j in range(i, k):
                val = -(ws[i] * ws[j].T).sum() + 2 * (vjs[i] @ wv[j]) - 2 * (wv[i] @ su[j]) - 2 * (wv[j] @ su[i]) \
                    + 2 * (su[j] @ wsu[i])
                if (i, j) in second_s:
                    sm = second_s[(i, j)]
                    val = val + (w * sm).sum() - u @ (sm @ u)
                if (i, j) in second_v:
                    val = val + 2 * (second_v[(i, j)] @ u)
                h[i, j] = h[i, j] - 0.5 * val
                if i != j:
                    h[j, i] = h[i, j]
        return mll, g, h

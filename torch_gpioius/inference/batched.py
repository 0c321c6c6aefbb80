r"""Exact GPIOIS engine for batches of inner points: rank-k updates of the factorisation at a held K_t.

A tactile patch brings k = 20-100 inner points per step, so N_i reaches thousands within one run. The structured
engine (:mod:`.structured`) refactorises the N_i x N_i Schur complement ``S = a K_ii + s I - b^2 T(c)`` at every
K_t it evaluates: O(N_i^3) per Newton evaluation. S depends on K_t = [[a, b], [b, c]] nonlinearly (through T(c)),
so no low-rank update carries a factorisation from one K_t to another. Given K_t, though, new inner points only
border S:

    S' = [[S, B], [B^T, C]],  B^T = a K_no - b^2 T_no,  C = a K_nn + s I - b^2 T_nn,

and everything the posterior and the *gradient* of the marginal likelihood need grows by a bordering step in
O(N_i^2 k + k N_o N_i + k N_o^2):

* the Cholesky factor ``L' = [[L, 0], [X^T, L_z]]``, ``X = L^-1 B``, ``L_z L_z^T = Z = C - X^T X`` (the
  posterior: exact given K_t, backward stable like any Cholesky factorisation in that order);
* ``W = S^-1`` by the block inverse ``W' = [[W + Y Y^T, -Y L_z^-1], [-L_z^-T Y^T, Z^-1]]``, ``Y = L^-T X L_z^-T``;
* ``T(c)`` and ``T'(c)`` at the held c, their new rows summed directly: ``P_new D P^T`` (no truncation).

With W, the exact gradient of the log marginal likelihood at the held K_t costs O(N_i^2) (three traces
``tr(W A)``, A in {K_ii, T, T'}, and matrix-vector products); the Hessian would cost O(N_i^3).

**When K_t is re-learned** (:meth:`torch_gpioius.GPIOIS.fit` with ``min_gain``): after each batch the exact
gradient g at the held K_t is computed, and the Newton decrement with the Hessian H of the last re-learning,
``g^T (-H)^-1 g / 2`` (in the Cholesky parameters, on the coordinates not held at a bound), predicts how many
nats a re-learning would gain. K_t is re-learned (Newton to convergence, O(N_i^3) per evaluation) when that
exceeds ``min_gain``, when the last Hessian is missing or not negative definite, or after ``max_hold`` batches;
otherwise it is held and the next batch is bordered in. Inference at the held K_t is exact (the tests hold it to
1e-9 of a dense solve after hundreds of batched appends); only K_t lags its optimum, by less than ``min_gain``
nats of marginal likelihood as predicted.

The square matrices live in zero-padded buffers with spare capacity, so a batch writes its rows in place, and a
trace ``tr(W A)`` is one dot product over the used rows of two buffers. Triangular solves with the factor go by
blocks (a strided view would otherwise be copied whole by LAPACK's wrapper at every solve).
"""

from __future__ import annotations


import torch
from torch import Tensor

from .dense import robust_cholesky
from .structured import StructuredExactInference, GrowingRows

__all__ = ["BatchedExactInference"]

#: Block size of the triangular solves on a buffer.
SOLVE_BLOCK = 512


class _Square:
    """An `(n, n)` matrix grown in place inside a zero-padded `(cap, cap)` buffer (row-major)."""

    def __init__(self, m: Tensor, cap: int | None = None, reuse: "_Square | None" = None):
        n = m.shape[0]
        cap = max(cap or 0, n + 64)
        if reuse is not None and reuse.buf.shape == (cap, cap) and reuse.buf.dtype == m.dtype \
                and reuse.buf.device == m.device:
            # a held state replaced by another of the same capacity: its buffer is refilled in place (a fresh
            # (cap, cap) allocation of tens of MB cost ~0.1 s in page faults, four of them per new K_t)
            self.buf = reuse.buf
            self.buf[:n, n:] = 0.0
            self.buf[n:] = 0.0
        else:
            self.buf = m.new_zeros(cap, cap)
        self.buf[:n, :n] = m
        self.n = n

    @property
    def view(self) -> Tensor:
        return self.buf[:self.n, :self.n]

    def rows(self) -> Tensor:
        """`(n * cap,)` the used rows, flat (columns beyond n are zero): ``rows() @ other.rows()`` is ``tr(A B^T)``."""
        return self.buf[:self.n].reshape(-1)

    def grow(self, k: int) -> None:
        """Make room for k more rows and columns (amortised: the capacity grows by half)."""
        need = self.n + k
        if need > self.buf.shape[0]:
            cap = max(need, int(1.5 * self.buf.shape[0]))
            buf = self.buf.new_zeros(cap, cap)
            buf[:self.n, :self.n] = self.view
            self.buf = buf
        self.n = need


class _LowerFactor:
    """A lower-triangular Cholesky factor grown by bordering, with blocked triangular solves.

    LAPACK's wrapper would copy a strided `(n, n)` view of the buffer whole at every solve; the blocks' GEMMs read
    it in place, and the contiguous diagonal blocks are kept (a border changes only the last one).
    """

    def __init__(self, chol: Tensor, cap: int, reuse: "_LowerFactor | None" = None):
        self.sq = _Square(chol, cap, None if reuse is None else reuse.sq)
        self._diag: dict[int, Tensor] = {}

    @property
    def n(self) -> int:
        return self.sq.n

    def border(self, x_t: Tensor, lz: Tensor) -> None:
        """Append rows ``[X^T, L_z]``: `(k, n)` and the `(k, k)` lower factor of the new block."""
        n, k = self.n, lz.shape[0]
        self.sq.grow(k)
        self.sq.buf[n:n + k, :n] = x_t
        self.sq.buf[n:n + k, n:n + k] = lz
        self._diag = {i0: b for i0, b in self._diag.items() if i0 + b.shape[0] < n}   # full blocks stay valid

    def _block(self, i0: int, i1: int) -> Tensor:
        blk = self._diag.get(i0)
        if blk is None or blk.shape[0] != i1 - i0:
            blk = self._diag[i0] = self.sq.buf[i0:i1, i0:i1].contiguous()
        return blk

    def solve(self, rhs: Tensor, transpose: bool = False) -> Tensor:
        """``L^-1 rhs`` (or ``L^-T rhs``), `(n, m)` right-hand sides."""
        n, lbuf = self.n, self.sq.buf
        x = rhs.clone()
        starts = list(range(0, n, SOLVE_BLOCK))
        if not transpose:
            for i0 in starts:
                i1 = min(n, i0 + SOLVE_BLOCK)
                if i0:
                    x[i0:i1] -= lbuf[i0:i1, :i0] @ x[:i0]
                x[i0:i1] = torch.linalg.solve_triangular(self._block(i0, i1), x[i0:i1], upper=False)
        else:
            for i0 in reversed(starts):
                i1 = min(n, i0 + SOLVE_BLOCK)
                if i1 < n:
                    x[i0:i1] -= lbuf[i1:n, i0:i1].T @ x[i1:n]
                x[i0:i1] = torch.linalg.solve_triangular(self._block(i0, i1).T, x[i0:i1], upper=True)
        return x


class BatchedExactInference(StructuredExactInference):
    """Exact GPIOIS engine with rank-k bordering of the factorisation at a held K_t (see the module docstring).

    Same interface and arithmetic as :class:`~torch_gpioius.inference.StructuredExactInference` (whose
    eigendecomposition of K_oo and Chebyshev store it inherits for re-learning K_t), plus
    :meth:`mll_gradient`. The first factorisation at a K_t also inverts S (O(N_i^3)); later inner batches
    border it in O(N_i^2 k). The Chebyshev store is only needed to re-learn K_t, so new rows reach it then.
    It takes the arguments of :class:`~torch_gpioius.inference.StructuredExactInference`.
    """

    #: Patches grow the data fast (tens of points per step): the store's truncation leaves room for 256x growth of
    #: ``b^2 |p_k|^2`` before a rebuild (one or two more Chebyshev orders per mode than the structured engine's 16x).
    STORE_HEADROOM = 256.0

    def __init__(self, *args, **kwargs):
        self._held: dict | None = None
        super().__init__(*args, **kwargs)
        #: Batches bordered in since the held factorisation was built.
        self.bordered_batches = 0

    # ------------------------------------------------------------------ data
    def append(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        """Append observations. Inner batches border the held factorisation (if any) in O(N_i^2 k + k N_o^2);
        outer points rebuild the engine."""
        x, y, task = x.detach(), y.detach(), task.detach()
        if self._rebuild_with_outer(x, y, task):
            return
        n_old = self.n_inner
        p_new = self._ingest(x, y)      # the Chebyshev store catches up when K_t is next re-learned
        self._invalidate()
        if self._held is not None:
            if self._held["n"] != n_old:
                self._held = None
            else:
                self._border(p_new, y)

    def _grow_kii(self, k_new_old: Tensor, k_new_new: Tensor) -> None:
        if not isinstance(self.__dict__.get("_kii"), _Square):
            super()._grow_kii(k_new_old, k_new_new)
            return
        sq, n = self._kii, self._kii.n
        sq.grow(k_new_new.shape[0])
        sq.buf[n:sq.n, :n] = k_new_old
        sq.buf[:n, n:sq.n] = k_new_old.T
        sq.buf[n:sq.n, n:sq.n] = k_new_new

    @property
    def kii(self) -> Tensor:
        """`(N_i, N_i)` inner kernel matrix (a view into a growing buffer)."""
        m = self.__dict__["_kii"]
        return m.view if isinstance(m, _Square) else m

    @kii.setter
    def kii(self, value: Tensor) -> None:
        self.__dict__["_kii"] = _Square(value)

    def remove(self, drop: Tensor, task: Tensor) -> bool:
        self._held = None
        return super().remove(drop, task)

    # ------------------------------------------------------------------ factorisation
    def factor(self, b: Tensor, derivatives: bool = False, trial: bool = False) -> dict:
        """As the structured engine; without ``derivatives``, at the held K_t the bordered factorisation is
        returned, and at a new K_t the factorisation is built once with S^-1 and held for later batches, except for
        a Newton ``trial``'s value (``mll_value``): the inverse of S that :meth:`_hold` adds costs more than the
        factorisation, and a refused trial never needs it."""
        key = tuple(b.detach().flatten().tolist())
        held = self._held
        if not derivatives and self.n_inner:
            if held is not None and held["key"] == key and held["n"] == self.n_inner:
                return held["cache"]
            if self._key == key:                 # a full factorisation at this K_t (a Newton trial's MLL)
                return self._cache
            if trial:
                return super().factor(b, trial=True)
            self._hold(b)
            return self._held["cache"]
        return super().factor(b, derivatives)

    def _hold(self, b: Tensor) -> None:
        """Build the held state at K_t = b from one full factorisation (with T') and the inverse of S."""
        f = self._direct_factor(b) if self._store_behind(b) else super().factor(b, derivatives=True)
        n = self.n_inner
        cap = max(self.__dict__["_kii"].buf.shape[0], n + 64)
        if cap != self.__dict__["_kii"].buf.shape[0]:
            self.__dict__["_kii"] = _Square(self.kii, cap)          # same capacity: traces are flat dot products
        a, beta, c = f["a"], f["beta"], f["c"]
        lam, d = self.lam, f["d"]
        cache = {k: f[k] for k in ("a", "beta", "c", "d")}
        cache.update(alpha_rot=None, lower_solve=None)
        old = self._held if self._held is not None else {}
        self._held = None                       # its buffers are refilled below: no half-replaced state survives
        self._held = {
            "key": tuple(b.detach().flatten().tolist()), "n": n, "a": a, "beta": beta, "c": c,
            "jitter": self.jitter, "d": d, "d1": -lam * d * d,
            "vecs": self._weight_vectors(d, derivatives=True),
            "chol": _LowerFactor(f["chol"], cap, old.get("chol")),
            "w": _Square(torch.cholesky_inverse(f["chol"]), cap, old.get("w")),
            "t0": _Square(f["t0"], cap, old.get("t0")), "t1": _Square(f["t1"], cap, old.get("t1")),
            "pd": GrowingRows(f["pd"]), "v": GrowingRows(f["v"]), "logdet_s": f["logdet_s"], "cache": cache,
        }
        self.bordered_batches = 0
        self._refresh()

    def _store_behind(self, b: Tensor) -> bool:
        """Whether the Chebyshev store would first have to catch up with rows bordered in since the last re-learning
        (or be rebuilt for this K_t): then T and T' are summed directly instead (:meth:`_direct_factor`)."""
        store = self._series
        if self._raw is not None or not self.n_inner:
            return False
        if store is None or store.size < self.n_inner:
            return True
        beta, c = float(b[0, 1]), max(float(b[1, 1]), 1e-300)
        return not store.covers(c, max(beta * beta, float(b[0, 0]) * c))

    def _direct_factor(self, b: Tensor) -> dict:
        """The factorisation ``_hold`` needs at K_t = b with T = P D P^T and T' = -P (lam D^2) P^T summed directly
        (one `(2 N_i, N_o) x (N_o, N_i)` GEMM, exact, no truncation) instead of from the Chebyshev store.

        Written for the held-Hessian tracking step (``GPIOIS.fit(track=True)``): between re-learnings the store
        lags behind the bordered rows, and catching it up cost a step 0.85 of 1.5 s at 1,600 inner points after 20
        held steps; the direct sum costs O(N_i^2 N_o) whatever the lag. Newton runs, which evaluate many K_t, keep
        the store."""
        b = b.detach()
        a, beta, c = float(b[0, 0]), float(b[0, 1]), float(b[1, 1])
        d = 1.0 / (c * self.lam + self.noise)
        t0, t1, _ = self._direct_t_matrices(c, (0, 1))
        pd = self.p @ self._weight_vectors(d, derivatives=True)
        return {"a": a, "beta": beta, "c": c, "d": d, "alpha_rot": None, "t0": t0, "t1": t1, "t2": None, "pd": pd,
                **self._schur(a, beta, t0, pd)}

    def _refresh(self) -> None:
        """Posterior weights of the held factorisation (two blocked triangular solves)."""
        h = self._held
        n, chol = h["n"], h["chol"]
        v = h["v"].data
        alpha_i = chol.solve(chol.solve(v.unsqueeze(1)), transpose=True)
        h["cache"].update(alpha_i=alpha_i.squeeze(1), v=v, pd=h["pd"].data, logdet_s=h["logdet_s"],
                          alpha_rot=None, n=n)

    def _border(self, p_new: Tensor, y_new: Tensor) -> None:
        """Border the held factorisation, S^-1, T and T' with k new inner points (rows of P: ``p_new``)."""
        h = self._held
        n, k = h["n"], p_new.shape[0]
        a, beta, s = h["a"], h["beta"], self.noise + h["jitter"]
        p_all = self.p                                              # (n + k, N_o), new rows last
        # (k, n + k) rows of T and T', summed directly (one GEMM)
        t0_rows, t1_rows = (torch.cat([p_new * h["d"], p_new * h["d1"]]) @ p_all.T).split(k)
        k_rows = self.kii[n:]                                       # K_ii is already grown
        s_rows = a * k_rows - beta * beta * t0_rows
        s_rows[:, n:].diagonal().add_(s)
        bt, cmat = s_rows[:, :n], s_rows[:, n:]
        cmat = 0.5 * (cmat + cmat.T)
        lsq, wsq = h["chol"], h["w"]
        x = lsq.solve(bt.T)                                         # (n, k) = L^-1 B
        lz, _ = robust_cholesky(cmat - x.T @ x, "bordered Schur complement")
        g = lsq.solve(x, transpose=True)                            # W B
        yt = torch.linalg.solve_triangular(lz, g.T, upper=False)    # (k, n) = L_z^-1 G^T = Y^T
        w_no = -torch.linalg.solve_triangular(lz.T, yt, upper=True)  # (k, n) = -Z^-1 G^T
        wsq.view.addmm_(yt.T, yt)
        lsq.border(x.T, lz)
        for sq in (wsq, h["t0"], h["t1"]):
            sq.grow(k)
        wsq.buf[n:n + k, :n] = w_no
        wsq.buf[:n, n:n + k] = w_no.T
        wsq.buf[n:n + k, n:n + k] = torch.cholesky_inverse(lz)
        for sq, rows in ((h["t0"], t0_rows), (h["t1"], t1_rows)):
            sq.buf[n:n + k, :n + k] = rows
            sq.buf[:n, n:n + k] = rows[:, :n].T
        pd_new = p_new @ h["vecs"]
        h["pd"].append(pd_new)
        h["v"].append((y_new - self.mean) - beta * pd_new[:, 0])
        h["logdet_s"] = h["logdet_s"] + 2 * lz.diagonal().log().sum()
        h["n"] = n + k
        self.bordered_batches += 1
        self._refresh()

    def _solve_lower(self, f: dict, rhs: Tensor) -> Tensor:
        if "lower_solve" in f:
            return self._held["chol"].solve(rhs)
        return super()._solve_lower(f, rhs)

    # ------------------------------------------------------------------ marginal likelihood
    def mll_gradient(self, b: Tensor) -> tuple[float, Tensor]:
        """Log marginal likelihood and its exact gradient in ``p = (K_t00, K_t01, K_t11)`` at ``b``.

        O(N_i^2) at the held K_t (three traces with the bordered S^-1); builds the held state first otherwise.

        Returns:
            ``(mll, grad (3,))``; the same numbers as :meth:`mll_derivatives` gives, without its Hessian.
        """
        f = self.factor(b)
        held = self._held
        if self.n_inner and (held is None or held["key"] != tuple(b.detach().flatten().tolist())
                             or held["n"] != self.n_inner):
            # factor() answered from a Newton run's cache at this K_t (a fit called again with no new data): the
            # traces need the held S^-1 of this K_t, not an older one
            self._hold(b)
            f = self._held["cache"]
        mll = float(self.mll(b))
        lam, d, rt = self.lam, f["d"], self.rt
        g = torch.zeros(3, **self._kind)
        g[2] += -0.5 * ((lam * d).sum() - (rt * rt * lam * d * d).sum())
        if not self.n_inner:
            return mll, g
        h = self._held
        beta = h["beta"]
        u, pd = f["alpha_i"], f["pd"]
        # K_ii and the held buffers share one capacity (set in _hold, grown by the same k each batch), so each trace
        # is one dot product over the used rows
        wr = h["w"].rows()
        tr = torch.stack([wr @ self.__dict__["_kii"].rows(), wr @ h["t0"].rows(), wr @ h["t1"].rows()])
        scale = torch.tensor([1.0, -2 * beta, -beta * beta], **self._kind)
        au = torch.stack([self.kii @ u, h["t0"].view @ u, h["t1"].view @ u])
        su = scale.unsqueeze(1) * au
        vj = torch.stack([torch.zeros_like(u), -pd[:, 0], beta * pd[:, 1]])
        g += -0.5 * (scale * tr + 2 * (vj @ u) - su @ u)
        return mll, g

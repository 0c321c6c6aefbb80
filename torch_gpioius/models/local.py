"""Local similarity (the paper's Discussion): GPIOIS whose inner-outer relation varies over regions of the object.

See :mod:`torch_gpioius.inference.local` for the model and its exact engines. In short: one outer function, and an
inner function that follows it by a coefficient ``beta(x)`` that blends per-region values ``beta_r`` (regions by
k-means on the outer surface points); each region gets its own correlation and its own 2x2 task covariance; one
region is GPIOIS exactly.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import torch
from gpytorch.distributions import MultivariateNormal
from torch import Tensor

from ..core.validation import as_labels, as_points, as_tasks, task_id
from ..inference.local import LocalDenseInference, LocalStructuredInference, region_weights
from ..inference.optim import FitResult, newton_maximize
from ..core.tolerances import tol
from .base import ImplicitSurfaceGP, deprecated_theta
from .gpiois import INNER, OUTER, UnidentifiedSimilarityWarning

__all__ = ["LocalGPIOIS", "kmeans_regions"]


def kmeans_regions(points: np.ndarray, regions: int, seed: int = 0) -> tuple[np.ndarray, float]:
    """Region centres `(R, d)` by k-means (k-means++ start, seeded) on `(n, d)` points, and a smoothing length
    ``tau`` [m]: half the median distance from each centre to its nearest neighbour (how far the memberships
    blend across a region border)."""
    from scipy.cluster.vq import kmeans2

    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < regions:
        raise ValueError(f"regions: {regions} regions need at least as many outer surface points, got {len(pts)}")
    if regions == 1:
        return pts.mean(axis=0, keepdims=True), 1.0
    distinct = len(np.unique(pts, axis=0))
    if distinct < regions:
        raise ValueError(f"regions: {regions} regions need at least {regions} distinct outer surface points, got "
                         f"{distinct} distinct among {len(pts)} (coincident points)")
    centres, _ = kmeans2(pts, regions, minit="++", seed=np.random.default_rng(seed))
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1) + np.diag(np.full(regions, np.inf))
    tau = float(0.5 * np.median(d.min(axis=1)))
    if not tau > 0:
        raise ValueError(f"regions: k-means placed several of the {regions} region centres at one point (the outer "
                         f"surface points take {distinct} distinct positions); use fewer regions")
    return centres, tau


class LocalGPIOIS(ImplicitSurfaceGP):
    r"""GPIOIS with a similarity per region of the outer shape (``tg.LocalGPIOIS``).

    ``F_in(x) = m + beta(x) (F_out(x) - m) + H(x)``, ``F_out ~ GP(m, c k)``, ``H ~ GP(0, a' k)``; region r has the
    task covariance ``[[beta_r^2 c + a', beta_r c], [beta_r c, c]]`` and the correlation
    ``beta_r sqrt(c) / sqrt(beta_r^2 c + a')``. ``fit()`` learns ``(a', c, beta_1..beta_R)`` by exact marginal
    likelihood (projected Newton with the exact gradient and Hessian). With ``regions=1`` it equals GPIOIS.

    Args:
        train_x: `(n, d)` positions [m], as :class:`torch_gpioius.GPIOIS`.
        train_y: `(n,)` labels (0 surface, 1 free space).
        train_task: `(n,)` task ids (0 inner, 1 outer).
        regions: number of regions R.
        theta: IMQ length scale [m], as GPIOIS.
        noise: observation noise variance sigma^2, as GPIOIS.
        centres: `(R, d)` region centres [m] (default: k-means on the outer surface points).
        tau: smoothing length of the memberships [m] (default: from the centres, :func:`kmeans_regions`).
        inference: "structured" (default when there are outer points) or "dense" (the reference).
        kernel: any :class:`~torch_gpioius.kernels.ExactKernel` in place of the inverse multiquadric.

    Raises:
        ValueError: bad data (as GPIOIS), fewer outer surface points than regions, a bad region count.
    """

    num_tasks = 2

    def __init__(self, train_x, train_y, train_task, regions: int = 4, theta: float | None = None, noise: float = 0.006,
                 centres=None, tau: float | None = None, inference: str = "auto", kernel=None):
        deprecated_theta(theta, "LocalGPIOIS")
        x = as_points(train_x, "train_x")
        y = as_labels(train_y, x.shape[0], "train_y")
        t = as_tasks(train_task, x.shape[0], "train_task")
        if isinstance(regions, bool) or not isinstance(regions, int) or not 1 <= regions <= 64:
            raise ValueError(f"regions: must be an integer in [1, 64], got {regions!r}")
        if inference not in ("auto", "dense", "structured"):
            raise ValueError(f"inference: must be 'auto', 'dense' or 'structured', got {inference!r}")
        super().__init__((x, t.unsqueeze(-1)), y, theta, noise, kernel=kernel)
        self.inference = inference
        if centres is None:
            seen = x[(t == OUTER) & (y == 0)].numpy()
            if len(seen) == 0:
                seen = x[t == OUTER].numpy()
            if len(seen) == 0:
                raise ValueError("LocalGPIOIS: needs outer (task 1) observations to define its regions")
            centres, auto_tau = kmeans_regions(seen, regions)
            tau = auto_tau if tau is None else tau
        centres = torch.as_tensor(np.asarray(centres, dtype=np.float64))
        if centres.shape != (regions, x.shape[1]) or not bool(torch.isfinite(centres).all()):
            raise ValueError(
                f"centres: expected a finite ({regions}, {x.shape[1]}) array [m], got {tuple(centres.shape)}"
            )
        tau = 1.0 if tau is None else float(tau)
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f"tau: must be a positive length [m], got {tau!r}")
        self.register_buffer("centres", centres)
        self.register_buffer("tau_", torch.tensor(tau, dtype=torch.float64))
        # p = (a', c, beta_1..beta_R): start as GPIOIS's identity K_t would have it (no relation: beta = 0)
        self.register_buffer("params", torch.cat([torch.tensor([1.0, 1.0], dtype=torch.float64),
                                                  torch.zeros(regions, dtype=torch.float64)]))
        self.fit_result: FitResult | None = None

    @property
    def regions(self) -> int:
        return int(self.centres.shape[0])

    @property
    def tau(self) -> float:
        return float(self.tau_)

    # ------------------------------------------------------------------ GPyTorch idiom
    def forward(self, x: Tensor, task: Tensor) -> MultivariateNormal:
        """Prior at `(n, d)` points with `(n, 1)` task ids (the loadings of the module docstring)."""
        from ..inference.local import loadings

        p = self.params
        lam, eta = loadings(task.reshape(-1), region_weights(x, self.centres.to(x), self.tau), p.to(x))
        k = self.covar_module(x).to_dense()
        cov = k * (p[1] * torch.outer(lam, lam) + p[0] * torch.outer(eta, eta))
        return MultivariateNormal(self.mean_module(x), cov)

    def __call__(self, x, task=None, **kwargs):
        if task is None:
            raise ValueError("task: LocalGPIOIS needs the task ids of the query points (0 inner, 1 outer)")
        if isinstance(task, str):
            task = task_id(task)
        if isinstance(task, int) or (torch.is_tensor(task) and task.dim() == 0):
            task = torch.full((x.shape[-2], 1), int(task), dtype=torch.long, device=x.device)
        elif task.dim() == x.dim() - 1:
            task = task.unsqueeze(-1)
        return super().__call__(x, task, **kwargs)

    # ------------------------------------------------------------------ engine
    def _train_task(self) -> Tensor:
        return self.train_inputs[1].squeeze(-1)

    @property
    def train_task(self) -> Tensor:
        return self._train_task()

    def _task_matrix(self) -> Tensor:
        return self.params

    def _engine_class(self):
        has_outer = bool((self._train_task() == OUTER).any())
        dense = self.inference == "dense" or not has_outer or self.noise < 1e-8
        cls = LocalDenseInference if dense else LocalStructuredInference
        centres, tau = self.centres, self.tau
        return lambda x, y, task, kernel, noise, mean: cls(x, y, task, kernel, noise, mean, centres, tau)

    def _key(self, n: int) -> tuple:
        return super()._key(n) + (tuple(self.centres.reshape(-1).tolist()), self.tau)

    def _predict_with_gradients(self, x, task: int):
        return None          # no closed form for this model: the geometry differentiates predict() by autograd

    # ------------------------------------------------------------------ similarity
    @property
    def identified(self) -> bool:
        task = self._train_task()
        return bool((task == INNER).any()) and bool((task == OUTER).any())

    def region_task_covariances(self) -> Tensor:
        """`(R, 2, 2)` the task covariance of each region."""
        a1, c, beta = self.params[0], self.params[1], self.params[2:]
        k00 = beta * beta * c + a1
        k01 = beta * c
        return torch.stack([torch.stack([k00, k01], -1), torch.stack([k01, c.expand_as(k01)], -1)], -2).detach()

    def region_correlations(self) -> Tensor:
        """`(R,)` the task correlation of each region (NaN when unidentified)."""
        if not self.identified:
            return torch.full((self.regions,), math.nan, dtype=torch.float64)
        kt = self.region_task_covariances()
        return (kt[:, 0, 1] / torch.sqrt(kt[:, 0, 0] * kt[:, 1, 1])).detach()

    def region_similarities(self) -> Tensor:
        """`(R,)` the paper's ratio ``K01 / K00`` of each region."""
        if not self.identified:
            return torch.full((self.regions,), math.nan, dtype=torch.float64)
        kt = self.region_task_covariances()
        return (kt[:, 0, 1] / kt[:, 0, 0]).detach()

    def _weights_outer(self) -> Tensor:
        xo = self.train_inputs[0][self._train_task() == OUTER]
        return region_weights(xo, self.centres.to(xo), self.tau).sum(0) if len(xo) else torch.ones(self.regions)

    @property
    def task_covariance(self) -> Tensor:
        """`(2, 2)` the task covariance of the outer-point-weighted mean coefficient (a summary; the model's own
        similarity is per region: :meth:`region_task_covariances`)."""
        w = self._weights_outer()
        beta = (w / w.sum()) @ self.params[2:]
        a1, c = self.params[0], self.params[1]
        return torch.tensor([[float(beta * beta * c + a1), float(beta * c)], [float(beta * c), float(c)]],
                            dtype=torch.float64)

    def step_summary(self) -> dict:
        """:meth:`ImplicitSurfaceGP.step_summary` with the weighted similarity, correlation and K_t, and each
        region's correlation."""
        out = super().step_summary()
        out.update(similarity=float(self.similarity), correlation=float(self.correlation),
                   task_covariance=self.task_covariance.detach().cpu().numpy(),
                   region_correlation=self.region_correlations().detach().cpu().numpy())
        return out

    @property
    def correlation(self) -> float:
        """Outer-point-weighted mean of the regions' correlations (NaN when unidentified)."""
        if not self.identified:
            return math.nan
        w = self._weights_outer()
        return float((w / w.sum()) @ self.region_correlations())

    @property
    def similarity(self) -> float:
        """Outer-point-weighted mean of the regions' paper ratios (NaN when unidentified)."""
        if not self.identified:
            return math.nan
        w = self._weights_outer()
        return float((w / w.sum()) @ self.region_similarities())

    def correlation_at(self, x) -> Tensor:
        """`(m,)` the local correlation ``beta(x) sqrt(c) / sqrt(beta(x)^2 c + a')`` at `(m, d)` points."""
        x0 = self.train_inputs[0]
        xq = as_points(x, "x", dim=self.dim, dtype=x0.dtype, device=x0.device)
        beta = region_weights(xq, self.centres.to(xq), self.tau) @ self.params[2:]
        a1, c = self.params[0], self.params[1]
        return (beta * torch.sqrt(c) / torch.sqrt(beta * beta * c + a1)).detach()

    def similarity_interval(self, level: float = 0.95, kind: str = "correlation"):
        raise NotImplementedError("similarity_interval: profile intervals are implemented for GPIOIS (one similarity); "
                                  "LocalGPIOIS reports region_correlations()")

    # ------------------------------------------------------------------ learning and prediction
    def fit(self, multi_start: bool | None = None) -> "LocalGPIOIS":
        """Learn ``(a', c, beta_1..beta_R)`` by maximising the exact log marginal likelihood (projected Newton on
        ``(log sqrt(a'), log sqrt(c), beta)`` with the engine's exact gradient and Hessian).

        Args:
            multi_start: also start from ``beta = 0.9`` everywhere with small a' (a strong relation); default: on the
                first fit only.
        """
        engine = self._inference()
        if multi_start is None:
            multi_start = self.fit_result is None
        lo, hi = tol.log_chol_bounds
        k = len(self.params)
        lower = np.r_[lo, lo, np.full(k - 2, -math.inf)]
        upper = np.r_[hi, hi, np.full(k - 2, math.inf)]
        x0 = self.train_inputs[0]

        def to_p(phi):
            return torch.tensor(np.r_[math.exp(2 * phi[0]), math.exp(2 * phi[1]), phi[2:]], dtype=x0.dtype,
                                device=x0.device)

        def value(phi):
            try:
                f, g, h = engine.mll_derivatives(to_p(phi))
            except (torch.linalg.LinAlgError, ArithmeticError):
                return -math.inf, None, None
            g64, h64 = g.detach().cpu().double().numpy(), h.detach().cpu().double().numpy()
            if not (math.isfinite(f) and np.isfinite(g64).all() and np.isfinite(h64).all()):
                return -math.inf, None, None
            jac = np.r_[2 * math.exp(2 * phi[0]), 2 * math.exp(2 * phi[1]), np.ones(k - 2)]
            grad = jac * g64
            hess = jac[:, None] * h64 * jac[None, :]
            hess[0, 0] += 4 * math.exp(2 * phi[0]) * g64[0]
            hess[1, 1] += 4 * math.exp(2 * phi[1]) * g64[1]
            return f, grad, hess

        p = self.params.double().cpu().numpy()
        starts = [np.r_[0.5 * math.log(max(p[0], 1e-24)), 0.5 * math.log(max(p[1], 1e-24)), p[2:]]]
        if multi_start:
            starts.append(np.r_[0.5 * math.log(0.01), 0.0, np.full(k - 2, 0.9)])
        best = None
        for phi0 in starts:
            phi, f, pg, it, ok = newton_maximize(value, np.clip(phi0, lower, upper), lower, upper)
            if best is None or f > best[1] + 1e-9 * max(1.0, abs(best[1])):
                best = (phi, f, pg, it, ok)
        phi, f, pg, it, ok = best
        if not self.identified:
            warnings.warn("LocalGPIOIS.fit: one task only: the similarities are unidentified (reported as NaN)",
                          UnidentifiedSimilarityWarning, stacklevel=2)
        if not ok:
            warnings.warn(f"LocalGPIOIS.fit: stopped after {it} iterations with projected gradient {pg:.3g}",
                          RuntimeWarning, stacklevel=2)
        self.params.copy_(to_p(phi).to(self.params))
        self.fit_result = FitResult(self.task_covariance, f, pg, it, ok)
        return self

    def set_params(self, params) -> "LocalGPIOIS":
        """Set ``(a', c, beta_1..beta_R)`` (e.g. the values a log recorded), as :meth:`fit` would have left them.

        Raises:
            ValueError: not ``R + 2`` finite numbers, or a non-positive ``a'`` or ``c``; the model is unchanged.
        """
        p = torch.as_tensor(params, dtype=torch.float64).reshape(-1)
        if p.shape != self.params.shape or not bool(torch.isfinite(p).all()) or not bool((p[:2] > 0).all()):
            raise ValueError(f"params: expected {self.params.numel()} finite numbers (a' > 0, c > 0, then one beta per "
                             f"region), got {p.tolist()}")
        with torch.no_grad():
            self.params.copy_(p.to(self.params))
        self._engine = None
        return self

    def predict(self, x, task: int | str = INNER) -> tuple[Tensor, Tensor]:
        """Posterior mean and variance of F_task (inner: eq. 12-13 with the local covariance); differentiable in x."""
        return self._predict(x, task_id(task))

    def predict_mean(self, x, task: int | str = INNER) -> Tensor:
        """Posterior mean of F_task alone (``predict(x, task)[0]`` without the variance's cost); differentiable in x."""
        return self._predict_mean(x, task_id(task))

    def log_marginal_likelihood(self) -> Tensor:
        return self._inference().mll(self.params)

    def check_state(self) -> None:
        super().check_state()
        p = self.params
        if not bool(torch.isfinite(p).all()) or float(p[0]) < 0 or float(p[1]) <= 0:
            raise ValueError(f"params: (a', c, beta...) must be finite with a' >= 0 and c > 0, got {p.tolist()}")

    def __repr__(self) -> str:
        rho = [round(v, 3) for v in self.region_correlations().tolist()]
        return f"LocalGPIOIS(regions={self.regions}, n={self.train_targets.numel()}, region correlations={rho})"

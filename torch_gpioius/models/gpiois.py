"""Gaussian process inner-outer implicit surface (GPIOIS), Sec. IV-A, eq. (9)-(16)."""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
import torch
from gpytorch.distributions import MultivariateNormal
from gpytorch.kernels import IndexKernel
from gpytorch.means import ConstantMean
from torch import Tensor

from .base import ImplicitSurfaceGP, deprecated_theta
from .gapfield import GapField
from ..core.validation import as_float, as_int, as_labels, as_points, as_tasks, task_id
from ..inference.dense import DenseExactInference
from ..inference.batched import BatchedExactInference
from ..inference.hyperparameters import HyperparameterResult
from ..inference.optim import FitResult
from ..inference.structured import StructuredExactInference
from ..inference.task_fit import TaskCovarianceFitter
from ..core.tolerances import tol

__all__ = ["fit_stop_reason", "GPIOIS", "INNER", "OUTER", "UnidentifiedSimilarityWarning"]

def _check_outer_mean(value) -> float:
    """``value`` as the outer task's prior mean: a finite number within ``1 +- tol.outer_mean_span``, else a
    ValueError naming ``outer_mean``."""
    return as_float(value, "outer_mean", lo=1.0 - tol.outer_mean_span, hi=1.0 + tol.outer_mean_span)


#: Task id of the inner (tactile) shape.
INNER = 0
#: Task id of the outer (visual) shape.
OUTER = 1

class FitNotConvergedWarning(RuntimeWarning):
    """``fit()`` stopped at its iteration cap before the projected gradient met its tolerance. The model keeps the
    best K_t found; on a flat likelihood (few contacts) that is within rounding of the optimum in the marginal
    likelihood, and ``fit_result`` says how far the gradient was from zero. Nothing for a user to do unless K_t
    itself is the result they report; an exploration counts these fits and says so once at the end."""


def fit_stop_reason(result) -> str:
    """Why K_t's fit stopped short of its gradient tolerance, in the one wording the warning, ``gpioius fit`` and
    ``fit.json`` use (``result``: a ``fit_result`` that did not converge)."""
    why = (f"at its cap of {result.iterations} iterations" if result.iterations >= tol.fit_max_iter else
           f"after {result.iterations} iterations, its last steps gaining less than the likelihood's rounding "
           "(tol.fit_ftol)")
    return (f"K_t's fit stopped {why}, short of the gradient tolerance (projected gradient {result.grad_norm:.3g}); "
            "the best K_t found is used, within rounding of the optimum where the likelihood is flat")


def _patches(points: np.ndarray, spacing: float) -> int:
    """How many points `(n, d)` a greedy pass keeps when each kept point removes those within ``spacing`` [m]."""
    if len(points) == 0:
        return 0
    from scipy.spatial import cKDTree

    tree, taken, kept = cKDTree(points), np.zeros(len(points), dtype=bool), 0
    for i in range(len(points)):
        if not taken[i]:
            kept += 1
            taken[tree.query_ball_point(points[i], spacing)] = True
    return kept


#: The fewest patches of surface observations of each task (:meth:`GPIOIS.similarity_support`) from which the
#: similarity is read out as a finding; below it the interval is reported with "too few observations to tell".
MIN_SIMILARITY_PATCHES = 4


class UnidentifiedSimilarityWarning(UserWarning):
    """The data observe only one task, so the similarity between the shapes cannot be learned from them."""


# softplus(-1000) == 0.0 exactly in float64: pins IndexKernel's diagonal term v at zero so K_t = W W^T.
_ZERO_VAR_RAW = -1000.0


class GPIOIS(ImplicitSurfaceGP):
    r"""Two-task GPIS over the inner (tactile, task 0) and outer (visual, task 1) shapes, eq. (9)-(16).

    Covariance ``k((x, t), (x', t')) = k_x(x, x') K_t[t, t']`` (eq. 9) with the IMQ kernel (eq. 5) and a
    free-form PSD task matrix ``K_t`` (eq. 10) held by ``gpytorch.kernels.IndexKernel(num_tasks=2, rank=2)``:
    ``K_t = W W^T`` with ``W`` the lower Cholesky factor (the paper's ``theta_t = L``); the IndexKernel's extra
    diagonal term is pinned at zero. Prior mean ``m = 1`` and noise ``sigma^2`` are fixed; ``fit()`` learns
    ``K_t`` and only ``K_t`` by exact marginal likelihood (eq. 15-16); ``learn_hyperparameters()`` learns the
    kernel's length and sigma^2 with it.

    The similarity of the paper is ``K_t[0,1] / K_t[0,0]`` (Sec. V-A-3): a regression coefficient of F_out on
    F_in scaled, not a correlation; it can exceed 1.

    Args:
        train_x: `(n, d)` observed points [m], base frame.
        train_y: `(n,)` labels, 0 on a surface (touched or seen), 1 in free space.
        train_task: `(n,)` task ids, 0 inner (tactile), 1 outer (visual).
        theta: IMQ kernel parameter theta_x [m] (eq. 5; ignored when ``kernel`` is given).
        noise: noise variance sigma^2.
        task_covariance: `(2, 2)` initial K_t (default identity: no assumed relation between the shapes).
        learn_theta: make theta trainable in a user's own GPyTorch training loop (``fit`` never changes it;
            ``learn_hyperparameters`` learns it by the exact marginal likelihood).
        inference: exact engine behind ``predict`` / ``fit`` / ``log_marginal_likelihood``: "dense" (one
            Cholesky of the full Gram matrix, the reference), "structured" (``StructuredExactInference``: fixed
            outer set, inner Schur complement; agrees with dense to ~1e-10, 100x faster at N_o = 2000), or
            "auto" (structured when there are outer points and sigma^2 >= 1e-8, else dense), or "batched"
            (``BatchedExactInference``: the structured engine with rank-k bordering of the factorisation at a
            held K_t, for tactile patches of tens of points per step; use it with ``fit(min_gain=...)``).
        kernel: any :class:`~torch_gpioius.kernels.ExactKernel` (e.g. ``tg.kernels.Matern52(0.1)``) in place of the
            inverse multiquadric; both engines stay exact for it.
        outer_tol: None (default: exact) or an **approximation beside the exact engine** for large outer sets
            (thousands of fine camera voxels): the structured engine then uses a truncated eigenbasis of K_oo from a
            pivoted Cholesky that drops a positive semi-definite part E of trace at most ``outer_tol * sigma^2``
            (``inference.lowrank``). The Gram matrix then differs from the exact one by at most
            ``K_t[1,1] tr(E)`` in spectral norm, ``truncation`` of the model's value relative to ``sigma^2``
            (docs/performance.md gives its measured effect). Only with ``inference`` "auto" or "structured".
        device: where the data and the exact arithmetic live ("cpu", "cuda", a ``torch.device``; default: where
            ``train_x`` is). Always float64; K_t's 3 x 3 Newton algebra runs on the host.

    Raises:
        ValueError: NaN/inf coordinates, empty data, mismatched lengths, labels or task ids outside {0, 1}.

    Why this many parameters: the constructor is the design card's public API (the training data and each of the
    paper's hyperparameters by name); ``EstimatorSettings.make_model`` builds it from one settings object.

    Example:
        >>> model = GPIOIS(x, y, task, kernel=Matern52(lengthscale=0.1), noise=0.006).fit()
        >>> mean, var = model.predict(grid, task=0)   # F_in posterior, eq. (12)-(13)
        >>> model.similarity                          # K_t[0,1] / K_t[0,0]
    """

    num_tasks = 2

    def __init__(self, train_x, train_y, train_task, theta: float | None = None, noise: float = 0.006,
                 task_covariance: Tensor | None = None, learn_theta: bool = False, inference: str = "auto",
                 kernel=None, device=None, outer_tol: float | None = None):
        deprecated_theta(theta, "GPIOIS")
        x = as_points(train_x, "train_x")
        y = as_labels(train_y, x.shape[0], "train_y")
        t = as_tasks(train_task, x.shape[0], "train_task")
        if inference not in ("auto", "dense", "structured", "batched"):
            raise ValueError(f"inference: must be 'auto', 'dense', 'structured' or 'batched', got {inference!r}")
        if outer_tol is not None:
            if inference not in ("auto", "structured"):
                raise ValueError(f"outer_tol: needs inference 'auto' or 'structured', got {inference!r}")
            outer_tol = as_float(outer_tol, "outer_tol", positive=True)
        super().__init__((x, t.unsqueeze(-1)), y, theta, noise, learn_theta, kernel)
        self.inference = inference
        #: Truncated outer basis: dropped trace at most ``outer_tol * sigma^2`` (None: exact).
        self.outer_tol = outer_tol
        self.task_covar_module = IndexKernel(num_tasks=2, rank=2).double()
        self.task_covar_module.raw_var.data.fill_(_ZERO_VAR_RAW)
        self.task_covar_module.raw_var.requires_grad_(False)
        self.task_covariance = torch.eye(2, dtype=torch.float64) if task_covariance is None else task_covariance
        #: The outer task's constant prior mean (``mean_module`` is the inner task's, m = 1): 1, the paper's, unless
        #: set by :meth:`set_outer_mean`.
        self.outer_mean_module = ConstantMean().double()
        self.outer_mean_module.constant.data.fill_(1.0)
        self.outer_mean_module.raw_constant.requires_grad_(False)
        #: The cover's gap over the body when the outer mean stands for it place by place (:meth:`set_outer_mean`
        #: with a :class:`GapField`); None: the constant ``outer_mean_module``.
        self._outer_field: GapField | None = None
        #: Outcome of the last ``fit()`` (None before the first).
        self.fit_result: FitResult | None = None
        self._held_fits = 0
        self.to_device(device)

    # ------------------------------------------------------------------ GPyTorch idiom
    def forward(self, x: Tensor, task: Tensor) -> MultivariateNormal:
        """GPyTorch prior at `(n, d)` points with `(n, 1)` task ids: mean m, covariance k_x ∘ K_t (eq. 9)."""
        covar = self.covar_module(x).mul(self.task_covar_module(task))
        outer = task.squeeze(-1) == OUTER
        outer_mean = self.outer_mean_module(x) if self._outer_field is None else self._outer_field.mean(x).to(x)
        return MultivariateNormal(torch.where(outer, outer_mean, self.mean_module(x)), covar)

    def __call__(self, x, task=None, **kwargs):
        """``model(x, task)``: GPyTorch prior (train mode) or posterior (eval mode) of F_task at x.

        ``task`` may be an int, an `(m,)` or an `(m, 1)` tensor of task ids.
        """
        if task is None:
            raise ValueError("task: GPIOIS needs the task ids of the query points (0 inner, 1 outer)")
        if isinstance(task, str):
            task = task_id(task)
        if isinstance(task, int) or (torch.is_tensor(task) and task.dim() == 0):
            task = torch.full((x.shape[-2], 1), int(task), dtype=torch.long, device=x.device)
        elif task.dim() == x.dim() - 1:
            task = task.unsqueeze(-1)
        return super().__call__(x, task, **kwargs)

    # ------------------------------------------------------------------ task covariance
    @property
    def task_covariance(self) -> Tensor:
        """`(2, 2)` task covariance K_t (eq. 10), detached. ``K_t[0, 0]`` is k_t(in, in)."""
        return self.task_covar_module._eval_covar_matrix().detach().clone()

    @task_covariance.setter
    def task_covariance(self, value) -> None:
        if value is None or isinstance(value, str):
            raise ValueError(f"task_covariance: expected a finite (2, 2) matrix, got {value!r}")
        try:
            kt = torch.as_tensor(value, dtype=torch.float64)
        except Exception as exc:
            raise ValueError(f"task_covariance: expected a finite (2, 2) matrix ({exc})") from None
        if kt.shape != (2, 2) or not torch.isfinite(kt).all():
            raise ValueError(f"task_covariance: expected a finite (2, 2) matrix, got shape {tuple(kt.shape)}")
        if float(kt.abs().max()) > tol.task_covariance_max:
            raise ValueError(f"task_covariance: entries above {tol.task_covariance_max:g} are outside the supported "
                             f"range (got {kt.tolist()})")
        if (kt - kt.T).abs().max() > 1e-12 * kt.abs().max().clamp_min(1.0):
            raise ValueError("task_covariance: must be symmetric")
        chol, info = torch.linalg.cholesky_ex(kt)
        if int(info) != 0:  # PSD but singular (e.g. perfectly correlated tasks): a square root by eigenvalues
            evals, evecs = torch.linalg.eigh(kt)
            if evals.min() < -1e-12 * evals.abs().max():
                raise ValueError(f"task_covariance: must be positive semi-definite (eigenvalues {evals.tolist()})")
            chol = evecs * evals.clamp_min(0).sqrt()
        cf = self.task_covar_module.covar_factor
        cf.data.copy_(chol.to(cf))

    @property
    def identified(self) -> bool:
        """Whether the data can identify the relation between the tasks: both tasks have observations.

        With one task only, ``K_t[0, 1]`` does not enter the likelihood at all (nor does the absent task's
        variance): any value fits the data equally well, so the similarity is *unidentified*, not zero.
        """
        task = self._train_task()
        return bool((task == INNER).any()) and bool((task == OUTER).any())

    @property
    def similarity(self) -> float:
        """The paper's similarity ``K_t[0,1] / K_t[0,0]`` (Sec. V-A-3): a ratio of amplitudes that can exceed 1.

        NaN when the data observe only one task (:attr:`identified` is False): the ratio is then unidentified,
        and a number such as 0 would read as "dissimilar".
        """
        if not self.identified:
            return float("nan")
        kt = self.task_covariance
        return float(kt[0, 1] / kt[0, 0])

    @property
    def correlation(self) -> float:
        """Task correlation ``K_t[0,1] / sqrt(K_t[0,0] K_t[1,1])`` in [-1, 1] (not the paper's similarity).

        NaN when unidentified (one task only, see :attr:`identified`).
        """
        if not self.identified:
            return float("nan")
        kt = self.task_covariance
        return float(kt[0, 1] / torch.sqrt(kt[0, 0] * kt[1, 1]))

    def similarity_support(self) -> dict:
        """How much the data can say about the similarity: the surface observations of each task counted as patches
        one kernel length apart (greedy thinning at the length: observations closer than that vary together, and
        the similarity is learned from how the two shapes vary together across patches).

        Returns:
            ``{"inner": patches, "outer": patches, "length": the spacing [m], "enough": bool, "reason": str}``;
            ``enough`` is False below :data:`MIN_SIMILARITY_PATCHES` patches of either task, and ``reason`` then
            says so in one sentence (empty otherwise). One contact and one cloud point reported a correlation of
            1.0000 [0.79, 1.00], and a 22-point cloud of a 22 cm bottle an interval of [1.00, 1.00].
        """
        try:
            length = float(self.kernel.length)
        except TypeError:                       # a kernel without a length: the paper's theta
            length = float(self.theta or 0.1)
        x = self.train_inputs[0].detach().cpu().numpy()
        y = self.train_targets.detach().cpu().numpy()
        task = self._train_task().cpu().numpy()
        counts = {}
        for name, t in (("inner", INNER), ("outer", OUTER)):
            pts = x[(task == t) & (y == 0)]
            counts[name] = _patches(pts, length)
        enough = min(counts.values()) >= MIN_SIMILARITY_PATCHES
        reason = "" if enough else (
            f"too few observations to tell: the contacts cover {counts['inner']} and the seen surface "
            f"{counts['outer']} patch(es) one kernel length ({length:g} m) apart; the similarity needs at least "
            f"{MIN_SIMILARITY_PATCHES} of each")
        return {**counts, "length": length, "enough": enough, "reason": reason}

    # ------------------------------------------------------------------ the outer task's prior mean
    @property
    def outer_mean(self) -> float:
        """The outer task's constant prior mean (the inner task's is m = 1, eq. 2): 1 unless set; with a gap field
        (:attr:`outer_field`) the mean its median gap stands for, ``1 - g0 / ramp``."""
        if self._outer_field is not None:
            return self._outer_field.constant_mean
        return float(self.outer_mean_module.constant.reshape(-1)[0])

    @property
    def outer_field(self) -> GapField | None:
        """The cover's gap over the body the outer mean stands for place by place (``1 - g(x) / ramp``), or None
        when the outer mean is one constant (:attr:`outer_mean`)."""
        return self._outer_field

    def set_outer_mean(self, value: "float | GapField") -> "GPIOIS":
        """Set the outer task's prior mean: a constant (1: the paper's model, one mean for both tasks), or the mean
        ``1 - g(x) / ramp`` of a :class:`GapField` ``g`` (a cover whose gap varies over the body).

        With a correlation near 1 the inner estimate away from the touches is ``1 + r (mu_out - m_out)`` (``r =
        K_t[0,1] / K_t[1,1]``): a cover that stands off the body by ``g`` everywhere is the body's field shifted by
        ``g / ramp`` label units (the labels rise from 0 on a surface to 1 a ramp out), and an outer mean of ``1 -
        g / ramp`` lets the transfer carry the cover's shape without its offset where ``r = 1`` (docs/method-notes.md
        section 15; ``1 - g / ramp + 1 / r - 1`` for the learned ``r``: ``ObservationPolicy.cover_carry``);
        a field ``g(x)`` does the same where the gap changes from place to place (section 18). The labels stay as
        they are (0, 1, negative inside); the engines see each task's residual from its own mean. The engine is
        rebuilt at the next use; K_t is kept (re-learn with :meth:`fit`).

        Args:
            value: the mean, in label units, within ``1 +- tol.outer_mean_span``; or a :class:`GapField` (its
                means at every place within that span).

        Raises:
            ValueError: not a finite number in that range, nor a gap field; the model is left unchanged.
        """
        if isinstance(value, GapField):
            _check_outer_mean(1.0 - 0.1 / value.ramp + value.carry)   # the deepest gap a field gives (0.1 m)
            _check_outer_mean(1.0 + value.carry)                       # and the shallowest
            if value != self._outer_field:
                self._outer_field = value
                self.outer_mean_module.constant.data.fill_(value.constant_mean)
                self._engine = None
            return self
        value = _check_outer_mean(value)
        if value != self.outer_mean or self._outer_field is not None:
            self._outer_field = None
            self.outer_mean_module.constant.data.fill_(value)
            self._engine = None          # not appended to: its labels were shifted for the old mean
        return self

    def _outer_shift(self, x: Tensor) -> Tensor | float:
        """How far the engines' labels of the outer task lie above the labels at `(n, d)` points ``x``
        (``1 - outer mean``): the engines subtract one mean, 1, from every label. A float for a constant mean,
        `(n,)` for a gap field."""
        if self._outer_field is not None:
            return (1.0 - self._outer_field.mean(x)).to(x)
        return 1.0 - self.outer_mean

    def _engine_targets(self, y: Tensor, task: Tensor, x: Tensor) -> Tensor:
        shift = self._outer_shift(x)
        if not torch.is_tensor(shift) and shift == 0.0:
            return y
        return y + shift * (task.reshape(-1) == OUTER).to(y.dtype)

    def _predict(self, x, task: int) -> tuple[Tensor, Tensor]:
        mean, var = super()._predict(x, task)
        return (mean - self._outer_shift(self._check_query(x)), var) if task_id(task) == OUTER else (mean, var)

    def _predict_mean(self, x, task: int) -> Tensor:
        mean = super()._predict_mean(x, task)
        return mean - self._outer_shift(self._check_query(x)) if task_id(task) == OUTER else mean

    def _predict_with_gradients(self, x, task: int):
        out = super()._predict_with_gradients(x, task)
        if out is None or task_id(task) != OUTER:
            return out
        if self._outer_field is None:
            return (out[0] - self._outer_shift(x),) + tuple(out[1:])
        q = self._check_query(x).detach().requires_grad_(True)     # the field's x-gradient, by autograd
        shift = self._outer_shift(q)
        (grad,) = torch.autograd.grad(shift.sum(), q)
        return (out[0] - shift.detach(), out[1], out[2] - grad) + tuple(out[3:])

    def check_state(self) -> None:
        super().check_state()
        _check_outer_mean(self.outer_mean)
        kt = self.task_covariance
        if float(kt.abs().max()) > tol.task_covariance_max:
            raise ValueError(
                f"task_covariance: entries above {tol.task_covariance_max:g} are outside the supported range"
            )

    def similarity_interval(self, level: float = 0.95, kind: str = "correlation") -> tuple[float, float]:
        """Profile-likelihood interval of the similarity between the shapes at ``level`` (docs/theory.md).

        The other two parameters of K_t are maximised out at every value of the similarity; the interval is where
        twice the drop of the log marginal likelihood stays below the chi-square quantile (at ``rho = +-1``, the
        boundary of the parameter space, below the quantile of the ``1/2 chi2_0 + 1/2 chi2_1`` mixture). Call
        :meth:`fit` first: the interval is built around the fitted K_t.

        Args:
            level: confidence level in (0, 1).
            kind: "correlation" (``K01 / sqrt(K00 K11)``, in [-1, 1], the similarity studies report first) or
                "ratio" (the paper's ``K01 / K00``, unbounded: an endpoint the data never rule out is ``+-inf``).

        Returns:
            ``(lo, hi)``. With one task only (unidentified, see :attr:`identified`) the whole range: ``(-1, 1)`` or
            ``(-inf, inf)``.
        """
        from ..inference.interval import correlation_interval, ratio_interval

        if kind not in ("correlation", "ratio"):
            raise ValueError(f"kind: must be 'correlation' or 'ratio', got {kind!r}")
        level = as_float(level, "level", lo=0.5, hi=0.9999)
        if not self.identified:
            return (-1.0, 1.0) if kind == "correlation" else (-math.inf, math.inf)
        engine = self._inference()
        x0 = self.train_inputs[0]

        def evaluate(kt: Tensor):
            return engine.mll_derivatives(kt.to(dtype=x0.dtype, device=x0.device))

        kt = self.task_covariance
        lo, hi, _ = (correlation_interval if kind == "correlation" else ratio_interval)(evaluate, kt, level)
        return float(lo), float(hi)

    def correlation_plausible(self, value: float = 1.0, level: float = 0.95) -> bool:
        """Whether the profile-likelihood interval of the correlation at ``level`` contains ``value``
        (:meth:`similarity_interval`), decided without computing the whole interval: one profile at ``value``.

        With one task only the correlation is unidentified and every value is plausible (True).
        """
        from ..inference.interval import plausible_correlation

        level = as_float(level, "level", lo=0.5, hi=0.9999)
        value = as_float(value, "value", lo=-1.0, hi=1.0)
        if not self.identified:
            return True
        engine = self._inference()
        x0 = self.train_inputs[0]
        return plausible_correlation(lambda kt: engine.mll_derivatives(kt.to(dtype=x0.dtype, device=x0.device)),
                                     self.task_covariance, value, level)

    def _engine_class(self):
        if self.inference == "dense":
            return DenseExactInference
        has_outer = bool((self._train_task() == OUTER).any())
        if self.outer_tol is not None:
            if not has_outer:
                raise ValueError("outer_tol: needs outer (task 1) observations")
            return functools.partial(StructuredExactInference, outer_tol=self.outer_tol)
        if self.inference in ("structured", "batched"):
            if not has_outer:
                raise ValueError(f"inference={self.inference!r} needs outer (task 1) observations")
            return StructuredExactInference if self.inference == "structured" else BatchedExactInference
        return StructuredExactInference if has_outer and self.noise >= 1e-8 else DenseExactInference

    def _key(self, n: int) -> tuple:
        return super()._key(n) + (self.outer_tol, self.outer_mean, id(self._outer_field))

    def step_summary(self) -> dict:
        """:meth:`ImplicitSurfaceGP.step_summary` with the similarity, the correlation, K_t, the truncation's bound
        and, for a held K_t, the Newton decrement that decided to hold it."""
        out = super().step_summary()
        fit = self.fit_result
        out.update(similarity=float(self.similarity), correlation=float(self.correlation),
                   task_covariance=self.task_covariance.detach().cpu().numpy(), truncation=float(self.truncation))
        if fit is not None and not fit.relearned and math.isfinite(fit.predicted_gain):
            out["fit_gap"] = float(fit.predicted_gain)
        return out

    @property
    def truncation(self) -> float:
        """Bound on the truncated outer basis' change of the Gram matrix, relative to sigma^2: ``K_t[1,1] tr(E) /
        sigma^2`` (0.0 with the exact engines; see ``outer_tol``)."""
        if self.outer_tol is None:
            return 0.0
        return float(self._inference().truncation(float(self.task_covariance[1, 1])))

    def _task_matrix(self) -> Tensor:
        x0 = self.train_inputs[0]
        return self.task_covariance.to(dtype=x0.dtype, device=x0.device)

    def _train_task(self) -> Tensor:
        return self.train_inputs[1].squeeze(-1)

    @property
    def train_task(self) -> Tensor:
        """`(n,)` task ids of the training points."""
        return self._train_task()

    # ------------------------------------------------------------------ learning and prediction
    FIT_OPTIONS = frozenset({"min_gain", "max_hold", "track", "scout"})

    def fit(self, multi_start: bool | None = None, min_gain: float | None = None,
            max_hold: int = 20, track: bool = False, scout: int | None = None) -> "GPIOIS":
        """Learn K_t (and only K_t) by maximising the exact log marginal likelihood, eq. (15)-(16).

        A projected, damped Newton method on the Cholesky parameters of K_t with the exact gradient and Hessian
        (``DenseExactInference.mll_derivatives``) runs to the tolerances of ``tol`` (see ``optim.maximize_mll``).
        Deterministic for the same data.

        With ``min_gain`` (the rule for batches of inner points, docs/performance.md): first the exact gradient g
        at the current K_t (O(N_i^2) with ``inference="batched"``); K_t is kept when the Newton decrement with
        the Hessian H of the last re-learning, ``g^T (-H)^-1 g / 2`` on the coordinates not held at a bound,
        predicts a gain below ``min_gain`` nats, and fewer than ``max_hold`` fits in a row have kept it.
        Otherwise K_t is re-learned as without ``min_gain``, or, with ``track``, moved by one Newton step with that
        held H (one factorisation at the new K_t instead of a Newton run's three or four evaluations with exact
        Hessians): the step is kept when the exact MLL rises and the decrement that remains at the new K_t (then
        ``fit_result.predicted_gain``) is below the one before; otherwise (H no longer describes the likelihood) K_t
        is re-learned in full. Inference at a kept or tracked K_t stays exact; only K_t's distance from the optimum
        is approximate, and it is reported.

        Args:
            multi_start: also start from fixed, data-independent K_t values (identity; 0.1 x a correlation of 0.9)
                and from the current variances with correlation 0, and keep the best. Default: on the first fit only;
                later fits warm-start from the current K_t (exploration adds a few points per step, and restarts
                every ``restart_every`` steps).
            min_gain: re-learn only when the predicted gain exceeds this [nats] (None: always re-learn). For
                scale: a 95 % profile interval spans 1.92 nats below the optimum.
            max_hold: re-learn in full after this many kept or tracked fits in a row, whatever the prediction.
            track: with ``min_gain``, replace a re-learning by one held-Hessian Newton step where that raises the MLL.
            scout: with ``multi_start`` and more inner points than this, run the fixed starts on a copy of the data
                whose inner points are thinned to ``scout`` (evenly along their order of arrival; every outer point
                kept), and re-learn on all the data from each optimum found there in another basin than the warm
                start's (not on a first fit, which has no warm start). With ``min_gain`` the warm start itself
                follows the rule above (held, tracked, or re-learned where the gradient predicts more), so a
                restart costs one gradient on all the data plus ``scout^3`` instead of ``N_i^3`` per evaluation of
                the fixed starts, plus one full re-learning per other basin; without it, the warm start's full
                re-learning too. The K_t kept is the best of those on the full likelihood (an optimum of it, or a
                held one within the rule's predicted gain). A basin that the thinned copy does not have is missed.
                Also, a re-learning from a K_t with a
                correlation of 1 (a restart's warm start too) first runs on the copy; where the copy's run leaves the
                bound, the full data's run starts where it ended (the walk from the bound, a dozen or more evaluations,
                then costs ``scout^3`` each) and is kept if it ends above the warm start's MLL; otherwise the full
                data's run starts from the warm K_t. On a first fit with more inner points than ``scout`` (a user's
                file of a thousand contacts), the first K_t and the fixed starts run on the copy, and the full data
                re-learn from each basin's optimum found there. None: everything runs on all the data.

        Returns:
            self, with ``fit_result`` describing the optimisation (``relearned``, ``predicted_gain``, ``tracked``,
            ``starts``, ``scout``).

        Raises:
            ValueError: ``min_gain`` negative or NaN, ``max_hold`` below 1, ``scout`` below 2.
        """
        if min_gain is not None and not min_gain >= 0:        # NaN fails this too
            raise ValueError(f"min_gain: must be a number of nats >= 0 (inf: hold for max_hold fits), got {min_gain!r}")
        if max_hold < 1:
            raise ValueError(f"max_hold: must be >= 1, got {max_hold!r}")
        scout = as_int(scout, "scout", 2, allow_none=True)
        if multi_start is None:
            multi_start = self.fit_result is None
        fitter = self._task_fitter()
        held = fitter.fit(multi_start, min_gain, max_hold, track, scout)
        self._held_fits = fitter.held_fits
        best = self.fit_result = fitter.result
        if held:
            return self
        if not self.identified:
            present = "outer" if bool((self._train_task() == OUTER).any()) else "inner"
            warnings.warn(f"GPIOIS.fit: only {present} (task {int(present == 'outer')}) observations: the similarity "
                          "K_t[0,1] is unidentified (reported as NaN); only the observed task's variance was learned",
                          UnidentifiedSimilarityWarning, stacklevel=2)
        if not best.converged:
            warnings.warn(f"GPIOIS.fit: {fit_stop_reason(best)}", FitNotConvergedWarning, stacklevel=2)
        return self

    def _task_fitter(self) -> TaskCovarianceFitter:
        """K_t's fitter on this model's engine, from its current K_t and the memory of its last fits."""
        return TaskCovarianceFitter(self._inference(), self.task_covariance, self.fit_result, self._held_fits,
                                    like=self.train_inputs[0], scout_engine=self._scout_engine,
                                    n_inner=int((self._train_task() == INNER).sum()), settle=self._settled)

    def _settled(self, kt: Tensor) -> Tensor:
        """Store ``kt`` as K_t and return it as stored (its Cholesky factor's product)."""
        self.task_covariance = kt
        return self.task_covariance

    def _scout_engine(self, size: int):
        """An engine on a copy of the data with ``size`` inner points (evenly spaced in arrival order, so a path's
        whole length is kept) and every outer point: the restarts' and the escapes' cheap likelihood."""
        task = self._train_task()
        keep = self._thinned(size)
        cls = self._inference().scout_engine()
        x = self.train_inputs[0]
        return cls(x[keep], self._engine_targets(self.train_targets, task, x)[keep], task[keep], self.covar_module,
                   self.noise, self.prior_mean)

    def _learned_task_covariance(self) -> Tensor | None:
        return self.task_covariance

    def _after_hyperparameters(self, result: HyperparameterResult) -> None:
        self.task_covariance = result.task_covariance
        self.fit(multi_start=False)

    def _hyper_state(self) -> tuple:
        return (self.task_covariance, self.fit_result, self._held_fits)

    def _restore_hyper_state(self, state: tuple) -> None:
        self.task_covariance, self.fit_result, self._held_fits = state

    def fit_state(self) -> tuple[np.ndarray, bool, int]:
        """What ``fit(min_gain=...)`` decides from, for logs and resume: the last re-learning's `(3, 3)` Hessian
        (NaN if none), whether the last fit re-learned, and the held fits in a row."""
        last = self.fit_result
        hess = np.full((3, 3), np.nan) if last is None or last.hessian is None else np.asarray(last.hessian)
        return hess, bool(last is None or last.relearned), int(self._held_fits)

    def restore_fit_state(self, hessian, relearned: bool, held_fits: int) -> None:
        """Restore :meth:`fit_state` on a model rebuilt from a log (its K_t already set)."""
        hess = np.asarray(hessian, dtype=np.float64)
        if hess.shape != (3, 3) or not np.isfinite(hess).all():
            return
        self.fit_result = FitResult(self.task_covariance, math.nan, math.nan, 0, True, hessian=hess,
                                    relearned=bool(relearned))
        self._held_fits = int(held_fits)

    def predict(self, x, task: int | str = INNER) -> tuple[Tensor, Tensor]:
        """Latent posterior mean and variance of F_task, eq. (12)-(13). Differentiable with respect to ``x``.

        Args:
            x: `(m, d)` query points [m], base frame.
            task: 0 or "inner" for F_in (tactile), 1 or "outer" for F_out (visual).

        Returns:
            `(m,)` posterior mean (``< 0`` inside, ``0`` on the estimated surface) and `(m,)` variance.
        """
        return self._predict(x, task_id(task))

    def predict_mean(self, x, task: int | str = INNER) -> Tensor:
        """Latent posterior mean of F_task, eq. (12), without the variance. Differentiable with respect to ``x``.

        Equal to ``predict(x, task)[0]`` at a fraction of the cost when the camera keeps thousands of outer points:
        the variance needs every query's kernel row rotated into the outer eigenbasis (``O(m N_o r)``), the mean
        only its dot product with the weights (``O(m (N_i + N_o))``). Use it to mesh the estimate on a grid.

        Args:
            x: `(m, d)` query points [m], base frame.
            task: 0 or "inner" for F_in (tactile), 1 or "outer" for F_out (visual).

        Returns:
            `(m,)` posterior mean (``< 0`` inside, ``0`` on the estimated surface).
        """
        return self._predict_mean(x, task_id(task))

    def __repr__(self) -> str:
        kt = self.task_covariance
        n_in = int((self._train_task() == INNER).sum())
        return (f"GPIOIS(n_inner={n_in}, n_outer={self._train_task().numel() - n_in}, kernel={self.kernel!r}, "
                f"noise={self.noise:g}, K_t={[[round(v, 6) for v in r] for r in kt.tolist()]}, "
                f"similarity={self.similarity:.4g})")

"""Shared machinery of GPIS and GPIOIS: fixed mean and noise, validation, the exact inference engine."""

from __future__ import annotations

import copy
import dataclasses
import math

import gpytorch
import numpy as np
import torch
from gpytorch.constraints import GreaterThan
from gpytorch.likelihoods import GaussianLikelihood
from gpytorch.means import ConstantMean
from torch import Tensor

from ..core.validation import as_device, as_float, as_int, as_labels, as_points, as_tasks, task_id
from ..inference.dense import DenseExactInference
from ..inference.hyperparameters import (LENGTH_BOUNDS, NOISE_BOUNDS, HyperparameterResult,
                                         maximize_hyperparameters)
from ..kernels import ExactKernel, InverseMultiquadricKernel, as_kernel
from ..core.exact import exact_arithmetic
from ..core.tolerances import tol

__all__ = ["ImplicitSurfaceGP"]


def _fixed_likelihood(noise: float) -> GaussianLikelihood:
    noise = as_float(noise, "noise", lo=tol.noise_range[0], hi=tol.noise_range[1], positive=True)
    lik = GaussianLikelihood(noise_constraint=GreaterThan(0.0))
    lik.double()
    lik.noise = torch.tensor(noise, dtype=torch.float64)  # a Python float would pass through float32
    lik.raw_noise.requires_grad_(False)
    return lik


class ImplicitSurfaceGP(gpytorch.models.ExactGP):
    """Base class: an ``ExactGP`` with constant prior mean fixed at ``m = 1`` and fixed noise (eq. 1-3).

    Subclasses define ``forward`` and the task structure; this class owns the exact inference engine
    (``DenseExactInference``), keeps it in step with the data and hyper-parameters, and validates input. The kernel
    is ``covar_module`` (an :class:`~torch_gpioius.kernels.ExactKernel`; the paper's inverse multiquadric with
    ``theta`` unless ``kernel`` is given).
    """

    #: Number of tasks of the model (1 for GPIS, 2 for GPIOIS).
    num_tasks: int = 1
    #: The options of K_t's fit that :meth:`fit` takes beyond ``multi_start`` (a touch model's ``fit_options`` pass
    #: only these): none for a model without K_t.
    FIT_OPTIONS: frozenset = frozenset()

    def __init__(self, train_inputs: tuple[Tensor, ...], train_y: Tensor, theta: float | None, noise: float,
                 learn_theta: bool = False, kernel: ExactKernel | None = None):
        likelihood = _fixed_likelihood(noise)
        if kernel is not None and theta is not None:
            raise ValueError("theta and kernel: give one (theta is the inverse multiquadric's lengthscale; a kernel "
                             "carries its own)")
        if kernel is None:
            kernel = InverseMultiquadricKernel(0.1 if theta is None else theta, learn_lengthscale=learn_theta)
        kernel = as_kernel(kernel)
        super().__init__(train_inputs, train_y, likelihood)
        self.mean_module = ConstantMean().double()
        self.mean_module.constant.data.fill_(1.0)
        self.mean_module.constant.requires_grad_(False)
        self.covar_module = kernel.double()
        self._engine: DenseExactInference | None = None
        self._engine_key: tuple | None = None
        #: Outcome of the last ``learn_hyperparameters()`` (None before the first).
        self.hyper_result: HyperparameterResult | None = None

    # ------------------------------------------------------------------ what an exploration step records
    def step_summary(self) -> dict:
        """What an exploration records of the model after a step (the loop reads this, and never asks what kind of
        model it holds): ``similarity``, ``correlation`` (NaN without two tasks), ``task_covariance`` (`(2, 2)`
        array, or None), ``truncation`` (a truncated outer basis's bound; 0 when exact), ``fit_gap`` (how far a held
        K_t was from its optimum [nats]; NaN when re-learned), ``noise``, ``length`` (the kernel's learnable
        length [m]; NaN without one) and ``region_correlation`` (`(R,)` array of a local model, or None)."""
        kernel = self.covar_module
        return {"similarity": math.nan, "correlation": math.nan, "task_covariance": None, "truncation": 0.0,
                "fit_gap": math.nan, "noise": float(self.noise),
                "length": float(kernel.length) if kernel.learnable_length else math.nan, "region_correlation": None}

    # ------------------------------------------------------------------ properties
    @property
    def kernel(self) -> ExactKernel:
        """The kernel (``covar_module``)."""
        return self.covar_module

    @property
    def lengthscale(self) -> float | None:
        """The kernel's length scale [m] (the inverse multiquadric's theta_x, eq. 5; a Matérn's length scale); None
        for a kernel without one."""
        try:
            return float(self.covar_module.length)
        except TypeError:
            return None

    @property
    def theta(self) -> float | None:
        """The paper's name of :attr:`lengthscale` [m] (eq. 5), for every kernel that has a length."""
        return self.lengthscale

    @property
    def noise(self) -> float:
        """Noise variance sigma^2 on the diagonal of the Gram matrix (eq. 12)."""
        return float(self.likelihood.noise.reshape(-1)[0])

    @property
    def prior_mean(self) -> float:
        """Constant prior mean m (eq. 2), 1 by default."""
        return float(self.mean_module.constant.reshape(-1)[0])

    @property
    def train_x(self) -> Tensor:
        """`(n, d)` training points [m]."""
        return self.train_inputs[0]

    @property
    def dim(self) -> int:
        """Spatial dimension d."""
        return self.train_inputs[0].shape[-1]

    def _thinned(self, size: int | None, outer_size: int | None = None) -> Tensor:
        """Indices of a copy of the data with at most ``size`` inner and ``outer_size`` outer points (None: all),
        each task's kept points evenly spaced in arrival order, so a path's whole length is kept."""
        task = self._train_task()
        keep = []
        for which, cap in ((0, size), (1, outer_size)):
            index = torch.nonzero(task == which).squeeze(-1)
            if cap is not None and len(index) > cap:
                index = index[torch.linspace(0, len(index) - 1, cap, device=index.device).round().long()]
            keep.append(index)
        return torch.cat(keep)

    def _set_hyperparameters(self, length: float, noise: float) -> None:
        """Set the kernel's length [m] and sigma^2, each validated before either changes; the engine follows."""
        noise = as_float(noise, "noise", lo=tol.noise_range[0], hi=tol.noise_range[1], positive=True)
        as_float(length, "length", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True, unit="m")
        self.covar_module.length = length
        self.likelihood.noise = torch.tensor(noise, dtype=torch.float64, device=self.likelihood.raw_noise.device)

    def hyperparameter_state(self) -> dict[str, list]:
        """The kernel's and the likelihood's raw parameters as JSON-able lists (``{"covar_module.raw_theta": ...}``):
        what a log records each step of a run that learns them, so that a resume restores them to the bit (a length
        set as a float passes through its constraint's transform and back, which is exact only to rounding)."""
        out = {}
        for prefix, module in (("covar_module", self.covar_module), ("likelihood", self.likelihood)):
            for name, value in module.state_dict().items():
                if "_constraint." not in name and torch.is_tensor(value) and value.is_floating_point():
                    out[f"{prefix}.{name}"] = value.detach().cpu().tolist()
        return out

    def load_hyperparameter_state(self, state: dict) -> None:
        """Restore :meth:`hyperparameter_state` (validated by :meth:`check_state`; on failure nothing changes).

        Raises:
            ValueError: a name this model does not have, a wrong shape, or values outside the supported ranges.
        """
        own = {f"{p}.{n}": v for p, m in (("covar_module", self.covar_module), ("likelihood", self.likelihood))
               for n, v in m.state_dict().items()}
        update = {}
        for name, value in state.items():
            if name not in own or "_constraint." in name:
                raise ValueError(f"hyperparameter state: {name!r} is not a parameter of this model's kernel or "
                                 "likelihood")
            tensor = torch.as_tensor(value, dtype=own[name].dtype, device=own[name].device)
            if tensor.shape != own[name].shape:
                raise ValueError(f"hyperparameter state: {name} has shape {tuple(tensor.shape)}, the model's "
                                 f"{tuple(own[name].shape)}")
            update[name] = tensor
        self.load_state_dict({**self.state_dict(), **update})

    def _task_matrix(self) -> Tensor:  # (T, T) task covariance used by the engine
        raise NotImplementedError

    def _train_task(self) -> Tensor:  # (n,) long
        raise NotImplementedError

    # ------------------------------------------------------------------ engine
    #: Which exact engine computes predict / fit: "dense" (the reference), "structured" or "auto".
    inference: str = "dense"

    def _engine_class(self):
        return DenseExactInference

    def _key(self, n: int) -> tuple:
        """What an engine built for n observations depends on: hyper-parameters, size, dtype and device."""
        x = self.train_inputs[0]
        return (tuple(self.covar_module.describe().items()), self.noise, self.prior_mean, n, x.dtype, x.device)

    def _inference(self):
        """The exact engine for the current data and hyper-parameters (rebuilt only when they change)."""
        x = self.train_inputs[0]
        key = self._key(x.shape[0])
        if self._engine is None or self._engine_key != key:
            self._engine = self._engine_class()(x, self._engine_targets(self.train_targets, self._train_task(), x),
                                                self._train_task(), self.covar_module, self.noise, self.prior_mean)
            self._engine_key = key
        return self._engine

    def _engine_targets(self, y: Tensor, task: Tensor, x: Tensor) -> Tensor:
        """The labels `(n,)` at points `(n, d)` ``x`` as the engines take them, which subtract the one prior mean
        :attr:`prior_mean` from every label: the labels themselves (GPIOIS shifts those of a task whose prior mean
        differs)."""
        return y

    def _append_to_engine(self, x: Tensor, y: Tensor, task: Tensor) -> None:
        if self._engine is not None:
            self._engine.append(x, self._engine_targets(y, task, x), task)
            n = self._engine.n
            self._engine_key = self._key(n)

    def to_device(self, device) -> "ImplicitSurfaceGP":
        """Move the data and the model to ``device`` (None: stay); the engine is rebuilt there, in float64.

        Raises:
            ValueError: an unknown device name, or one this torch build cannot use (names it).
        """
        dev = as_device(device)
        return self if dev is None else self.to(dev)

    def _apply(self, fn, *args, **kwargs):
        # .to(dtype) / .float() / .half() would run the GP arithmetic in that dtype: refuse before anything moves.
        # The probe is what fn makes of a float64 tensor (device moves keep float64 and pass).
        probe = fn(torch.zeros((), dtype=torch.float64))
        if torch.is_tensor(probe) and probe.dtype != torch.float64:
            raise TypeError(
                f"{type(self).__name__}: the GP arithmetic is float64 only (posterior variances near data are ~1e-6 "
                f"against a prior variance of ~10, which {probe.dtype} cancels away); the model was left unchanged. "
                "Move it with .to(device) and cast the results of predict() if you need another dtype.")
        self._engine = None  # device moves rebuild the engine
        return super()._apply(fn, *args, **kwargs)

    def check_state(self) -> None:
        """Validate hyper-parameters as the constructor would: theta and the noise in their supported ranges,
        the prior mean m = 1 (eq. 2), finite parameters, and (GPIOIS) a finite PSD ``K_t`` within range.

        Raises:
            ValueError: naming the first invalid field.
        """
        for name, value in self.state_dict().items():
            if "_constraint." in name:      # constraint bounds are legitimately infinite (GreaterThan, Positive)
                continue
            if torch.is_tensor(value) and value.is_floating_point() and not bool(torch.isfinite(value).all()):
                raise ValueError(f"{name}: contains NaN or inf")
        if self.theta is not None:
            as_float(self.theta, "theta", lo=tol.theta_range[0], hi=tol.theta_range[1], positive=True, unit="m")
        elif self.covar_module.learnable_length:      # e.g. the Matern length scale
            as_float(self.covar_module.length, "kernel length", lo=tol.theta_range[0], hi=tol.theta_range[1],
                     positive=True, unit="m")
        as_float(self.noise, "noise", lo=tol.noise_range[0], hi=tol.noise_range[1], positive=True)
        if self.prior_mean != 1.0:
            raise ValueError(f"prior mean: must be m = 1 (eq. 2; free space is labelled 1), got {self.prior_mean}")

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        """``torch.nn.Module.load_state_dict``, then :meth:`check_state`; on failure the previous state is restored.

        Raises:
            ValueError: the loaded state is invalid (the model keeps its previous state).
        """
        before = {k: v.detach().clone() for k, v in self.state_dict().items()}
        result = super().load_state_dict(state_dict, strict=strict, assign=assign)
        self._engine = None
        try:
            self.check_state()
        except ValueError:
            super().load_state_dict(before)
            self._engine = None
            raise
        return result

    def set_train_data(self, inputs=None, targets=None, strict=True):
        self._engine = None
        return super().set_train_data(inputs, targets, strict)

    def add_observations(self, x, y, task=None) -> "ImplicitSurfaceGP":
        """Append observations; the posterior updates exactly (the engine extends its factorisation by the new rows),
        the hyperparameters (K_t) are re-learned by ``fit()``.

        Args:
            x: `(k, d)` points [m].
            y: `(k,)` labels: 0 on a surface, 1 in free space, below 0 inside.
            task: `(k,)` task ids (0 inner, 1 outer), or one id or name ("inner" / "outer") for all; a one-task model
                (GPIS) takes None or zeros, the same signature, so that the exploration adds a batch to any model
                alike.

        Raises:
            ValueError: on bad input (an outer observation for a one-task model too); the model is left unchanged.
        """
        x0 = self.train_inputs[0]
        x = as_points(x, "x", dim=self.dim, dtype=x0.dtype, device=x0.device)
        y = as_labels(y, x.shape[0], "y", dtype=x0.dtype, device=x0.device)
        t = self._new_tasks(task, x.shape[0])
        inputs = (torch.cat([x0, x]),)
        if self.num_tasks > 1:
            inputs += (torch.cat([self.train_inputs[1], t.unsqueeze(-1)]),)
        engine = self._engine
        self.set_train_data(inputs, torch.cat([self.train_targets, y]), strict=False)
        self._engine = engine
        self._append_to_engine(x, y, t)
        return self

    def _new_tasks(self, task, k: int) -> Tensor:
        """The task ids `(k,)` of ``k`` new observations (see :meth:`add_observations`)."""
        device = self.train_inputs[0].device
        if self.num_tasks > 1:
            return as_tasks(task, k, "task", device=device)
        if task is not None:
            t = np.asarray(task.cpu() if isinstance(task, torch.Tensor) else task).reshape(-1)
            if t.shape != (k,) or (t != 0).any():
                raise ValueError(f"task: a GPIS models the inner task alone; expected {k} zeros, got "
                                 f"{t.tolist()[:8]}")
        return torch.zeros(k, dtype=torch.long, device=device)

    def __call__(self, *args, **kwargs):
        with exact_arithmetic():
            return super().__call__(*args, **kwargs)

    # ------------------------------------------------------------------ public API
    def _check_query(self, x, name: str = "x") -> Tensor:
        x0 = self.train_inputs[0]  # as_points keeps the autograd graph of x (planner, users' gradients)
        return as_points(x, name, dim=self.dim, dtype=x0.dtype, device=x0.device)

    def _predict(self, x, task: int) -> tuple[Tensor, Tensor]:
        xq = self._check_query(x)
        return self._inference().predict(xq, task, self._task_matrix())

    def _predict_mean(self, x, task: int) -> Tensor:
        return self._inference().predict_mean(self._check_query(x), task, self._task_matrix())

    def _predict_with_gradients(self, x, task: int) -> tuple[Tensor, Tensor, Tensor, Tensor] | None:
        """Mean, variance and their x-gradients by the engine's closed form, or None if it has none (autograd)."""
        task = task_id(task)
        if task not in range(self.num_tasks):
            raise ValueError(f"task: must be in 0..{self.num_tasks - 1}, got {task!r}")
        engine = self._inference()
        if not engine.closed_form_gradients:
            return None
        return engine.predict_with_gradients(self._check_query(x).detach(), task, self._task_matrix())

    def remove_observations(self, index) -> "ImplicitSurfaceGP":
        """Remove training observations (e.g. free-space samples a later contact showed to be too close).

        The exact engine drops the rows in place where it can (the structured engine keeps its eigendecomposition
        when only inner points go) and is rebuilt from the remaining data otherwise; hyper-parameters and K_t are
        kept.

        Args:
            index: `(k,)` integer indices or an `(n,)` boolean mask of the observations to remove.

        Raises:
            ValueError: indices out of range, or removing every observation; the model is left unchanged.
        """
        n = self.train_targets.shape[0]
        try:
            idx = torch.as_tensor(index)
        except Exception as exc:
            raise ValueError(f"index: expected integer indices or a boolean mask ({exc})") from None
        device = self.train_targets.device
        if idx.dtype == torch.bool:
            if idx.shape != (n,):
                raise ValueError(f"index: boolean mask must have shape ({n},), got {tuple(idx.shape)}")
            drop = idx.to(device)
        else:
            if idx.is_floating_point() or idx.is_complex():
                raise ValueError(f"index: expected integer indices or a boolean mask, got dtype {idx.dtype} "
                                 f"(e.g. {idx.flatten()[:3].tolist()}); a float index is never rounded")
            idx = idx.reshape(-1).long()
            if idx.numel() and (idx.min() < -n or idx.max() >= n):
                raise ValueError(f"index: out of range for {n} observations")
            idx = torch.where(idx < 0, idx + n, idx)
            if idx.unique().numel() != idx.numel():
                raise ValueError("index: duplicate indices; to remove by a 0/1 mask pass it as a boolean tensor "
                                 "(dtype=torch.bool)")
            drop = torch.zeros(n, dtype=torch.bool, device=device)
            drop[idx.to(device)] = True
        if bool(drop.all()):
            raise ValueError("index: cannot remove every observation (empty data)")
        if not bool(drop.any()):
            return self
        keep = ~drop
        current = self._engine is not None and self._engine_key == self._key(n)
        engine, task = self._engine, self._train_task()
        self.set_train_data(tuple(t[keep] for t in self.train_inputs), self.train_targets[keep], strict=False)
        if current and engine.remove(drop, task):   # an up-to-date engine drops the rows in place where it can
            self._engine = engine
            self._engine_key = self._key(n - int(drop.sum()))
        return self

    def _learned_task_covariance(self) -> Tensor | None:   # K_t learned with the length and noise (GPIOIS)
        return None

    def _after_hyperparameters(self, result: HyperparameterResult) -> None:   # GPIOIS re-learns K_t on all data
        return None

    def _hyper_state(self) -> tuple:
        return ()

    def _restore_hyper_state(self, state: tuple) -> None:
        return None

    def learn_hyperparameters(self, size: int | None = None, outer_size: int | None = None,
                              length_bounds: tuple[float, float] = LENGTH_BOUNDS,
                              noise_bounds: tuple[float, float] = NOISE_BOUNDS, max_iter: int = 60,
                              start: tuple[float, float] | None = None, learn_noise: bool = True
                              ) -> "ImplicitSurfaceGP":
        """Learn the kernel's length, the noise sigma^2 and K_t together by the exact log marginal likelihood.

        They live in the model as torch parameters (the kernel's ``raw_theta`` or ``raw_lengthscale``, the
        likelihood's ``raw_noise``, GPIOIS's IndexKernel factor), read back as ``kernel.length``, :attr:`noise` and
        ``task_covariance``. The likelihood is maximised with autograd through one dense
        Cholesky per evaluation (``inference.hyperparameters``), on all the data or on a copy thinned to ``size``
        inner and ``outer_size`` outer points (evenly in arrival order). Then K_t is re-learned on all the data with
        the model's exact engine at the new values (``fit()``), and the values are kept only if the full data's exact
        MLL is then at least what it was before; otherwise the model is put back as it was. Either way inference stays
        exact: only *which* length and noise is a choice.

        The criterion (measured in docs/method-notes.md, sections 12-13): with the paper's labels alone the marginal
        likelihood picks 2-5 cm lengths and almost no noise, and worse shapes than the fixed defaults; with points
        known to lie inside (``touch_inside``, ``vision_inside``) it gave better shapes on 8 of 9 datasets offline.

        Args:
            size: cap on the inner points the learning uses (None: all).
            outer_size: cap on the outer points it uses (None: all).
            length_bounds: `(lo, hi)` of the length [m].
            noise_bounds: `(lo, hi)` of sigma^2.
            max_iter: cap on L-BFGS iterations.
            start: `(length [m], sigma^2)` the optimiser starts from (None: the model's current values). The
                exploration starts every learning from the run's configured values, so that one learning's optimum
                does not hold the next in its basin.
            learn_noise: False holds sigma^2 (at ``start``'s, else the model's): the length and K_t only.

        Returns:
            self, with ``hyper_result`` (:class:`~torch_gpioius.inference.hyperparameters.HyperparameterResult`).

        Raises:
            TypeError: the kernel has no learnable length (``ExactKernel.learnable_length``).
            ValueError: bad sizes or bounds (the model is unchanged).
        """
        if not self.covar_module.learnable_length:
            raise TypeError(f"learn_hyperparameters: the {type(self.covar_module).__name__} kernel has no learnable "
                            "length (ExactKernel.length and value_at)")
        size = as_int(size, "size", 2, allow_none=True)
        outer_size = as_int(outer_size, "outer_size", 2, allow_none=True)
        max_iter = as_int(max_iter, "max_iter", 1, 10_000)
        bounds = {}
        for name, value, range_ in (("length_bounds", length_bounds, tol.theta_range),
                                    ("noise_bounds", noise_bounds, tol.noise_range)):
            try:
                lo, hi = (float(v) for v in value)
            except (TypeError, ValueError):
                raise ValueError(f"{name}: expected (lo, hi), got {value!r}") from None
            if not (range_[0] <= lo < hi <= range_[1]):
                raise ValueError(f"{name}: need {range_[0]:g} <= lo < hi <= {range_[1]:g}, got ({lo:g}, {hi:g})")
            bounds[name] = (lo, hi)
        if start is not None:
            try:
                start_length, start_noise = (float(v) for v in start)
            except (TypeError, ValueError):
                raise ValueError(f"start: expected (length, noise), got {start!r}") from None
            kernel = copy.deepcopy(self.covar_module)     # the start, on a copy: the model changes only when kept
            kernel.length = start_length
            start_noise = as_float(start_noise, "start noise", lo=tol.noise_range[0], hi=tol.noise_range[1],
                                   positive=True)
        else:
            kernel, start_noise = self.covar_module, self.noise
        keep = self._thinned(size, outer_size)
        task = self._train_task()
        y = self._engine_targets(self.train_targets, task, self.train_inputs[0])[keep]
        result = maximize_hyperparameters(kernel, self.train_inputs[0][keep], y, task[keep],
                                          start_noise, self._learned_task_covariance(), self.prior_mean,
                                          max_iter=max_iter, learn_noise=bool(learn_noise), **bounds)
        before = (self.hyperparameter_state(), self._hyper_state(), self._engine, self._engine_key)
        mll_before = float(self.log_marginal_likelihood())
        try:
            self._set_hyperparameters(result.length, result.noise)
            self._after_hyperparameters(result)
            mll_after = float(self.log_marginal_likelihood())
        except (torch.linalg.LinAlgError, ArithmeticError, ValueError):
            mll_after = -math.inf
        kept = mll_after >= mll_before
        if not kept:             # put the model back as it was, to the bit, engine included (no rebuild)
            raw, state, engine, key = before
            self.load_hyperparameter_state(raw)
            self._restore_hyper_state(state)
            self._engine, self._engine_key = engine, key
        self.hyper_result = dataclasses.replace(result, kept=kept, mll_full=max(mll_after, mll_before),
                                                mll_full_before=mll_before)
        return self

    def log_marginal_likelihood(self) -> Tensor:
        """Log marginal likelihood of the training labels, eq. (16) with ``C = -n/2 log(2 pi)``.

        Exact (Cholesky), not divided by n (GPyTorch's ``ExactMarginalLogLikelihood`` divides by n).

        Returns:
            Scalar tensor [nats].
        """
        return self._inference().mll(self._task_matrix())


def deprecated_theta(theta, owner: str) -> None:
    """Warn that ``theta=`` (the paper's symbol, where users typed it) is the inverse multiquadric's lengthscale now,
    carried by the kernel (``kernel=InverseMultiquadricKernel(lengthscale=...)``)."""
    if theta is not None:
        import warnings

        warnings.warn(f"{owner}(theta=...) is an alias of kernel=InverseMultiquadricKernel(lengthscale=...): the "
                      "kernel carries its length", DeprecationWarning, stacklevel=3)


def kernel_for_theta(theta, kernel, owner: str):
    """``kernel``, or for the deprecated ``theta=`` alias of an entry point users type (``explore``, the command
    line's ``--theta``) the inverse multiquadric of that length scale [m], in the users' range of kernel lengths, with a
    DeprecationWarning; None when neither is given.

    Raises:
        ValueError: both given, or a ``theta`` out of range (names it).
    """
    if theta is None:
        return kernel
    if kernel is not None:
        raise ValueError("theta and kernel: give one (theta is the inverse multiquadric's length scale; a kernel "
                         "carries its own)")
    from ..core.validation import as_kernel_length

    length = as_kernel_length(theta, "theta")
    deprecated_theta(theta, owner)
    return InverseMultiquadricKernel(lengthscale=length)

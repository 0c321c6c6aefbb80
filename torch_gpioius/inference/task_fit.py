"""K_t's fit (eq. 15-16) as one object the model asks: the Newton runs of ``optim.maximize_mll`` from a warm start
and, on restarts, from fixed ones; the min_gain rule that holds K_t or tracks it by one held-Hessian step; the scouts
that run the restarts on a thinned copy of the data; the escape from the ridge of a correlation of 1.

:class:`TaskCovarianceFitter` holds the machinery; the model (``GPIOIS.fit``) hands it the engine, the current K_t
and the memory of the last fits, and takes back the K_t and the :class:`~torch_gpioius.inference.optim.FitResult`.
See ``GPIOIS.fit`` for what each option does and docs/performance.md for the rule's measurements.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np
import torch
from torch import Tensor

from .engine import ExactEngine
from .optim import (FitResult, chain_to_cholesky, chol_params_to_task_covariance, cholesky_bounds, free_coordinates,
                    held_newton_step, maximize_mll, predicted_gain, task_covariance_to_chol_params)

__all__ = ["TaskCovarianceFitter", "on_ridge", "ridge", "held_gain"]


def on_ridge(kt: Tensor) -> bool:
    """Whether K_t's correlation is 1 to within ``1 - rho^2 <= 1e-6`` (the shapes' relation at its bound)."""
    a, b, c = float(kt[0, 0]), float(kt[0, 1]), float(kt[1, 1])
    return a > 0 and c > 0 and 1.0 - b * b / (a * c) <= 1e-6


def ridge(kt: Tensor, grad: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, float]:
    """On the ridge of a correlation of 1 (:func:`on_ridge`) with the gradient pushing ``w = log L[1,1]`` further
    down, hold ``w`` as if at its bound and bound its gain by ``|g_w| / 2``: the MLL depends on ``w`` through
    ``z = e^(2w)`` only, so all that ``w -> -inf`` can still bring is ``(dMLL/dz) z = g_w / 2`` to first order in the
    tiny ``z``, where the quadratic model's ``g_w^2 / (2 |H_ww|)`` grows without bound as ``H_ww -> 0`` (a correlation
    of 1 then asked for a re-learning at every step, each stalling on the flat ridge).

    With the gradient pointing off the ridge (``g_w > 0``) the gain is unbounded for the rule: the likelihood is
    convex in ``w`` there and a Hessian from any K_t says nothing of where it turns (24 nats off on
    tests/inference/test_batched.py's data), so the rule never holds K_t there: it re-learns, which steps off the
    ridge (``optim.newton_maximize``), or tracks where a held-Hessian step raises the MLL.

    Returns:
        the free coordinates with ``w`` held where that applies, and the gain bound for ``w`` [nats].
    """
    if not (free[2] and grad[2] != 0 and on_ridge(kt)):
        return free, 0.0
    if grad[2] > 0:
        return free, math.inf
    held = free.copy()
    held[2] = False
    return held, 0.5 * abs(float(grad[2]))


def held_gain(kt: Tensor, grad: np.ndarray, free: np.ndarray, hessian: np.ndarray) -> tuple[float, np.ndarray]:
    """The re-learning gain [nats] predicted at ``kt`` with a held Hessian (the Newton decrement, ``w`` treated by
    :func:`ridge`), and the coordinates it leaves free."""
    free, ridge_gain = ridge(kt, grad, free)
    return predicted_gain(grad, hessian, free) + ridge_gain, free


class TaskCovarianceFitter:
    """Learns K_t on one engine's data; after :meth:`fit`, :attr:`task_covariance`, :attr:`result` and
    :attr:`held_fits` are what the model keeps.

    Args:
        engine: the model's exact engine (its data and arithmetic).
        task_covariance: the current `(2, 2)` K_t (the warm start).
        last: the last fit's result (None: a first fit).
        held_fits: fits in a row that kept or tracked K_t.
        like: a tensor of the training points' dtype and device (K_t is evaluated in them).
        scout_engine: ``scout_engine(size) -> ExactEngine``, an engine on a copy of the data with ``size`` inner
            points (``fit(scout=...)``), or None (no scouting).
        n_inner: the inner points in the data.
        settle: ``settle(K_t) -> K_t`` as the model stores it (its Cholesky factor's product, the last bits
            rounded), applied to every K_t the fitter moves to, so that it continues from what the model holds.
    """

    def __init__(self, engine: ExactEngine, task_covariance: Tensor, last: FitResult | None, held_fits: int, *,
                 like: Tensor, scout_engine: Callable[[int], ExactEngine] | None = None, n_inner: int = 0,
                 settle: Callable[[Tensor], Tensor] | None = None):
        self.engine = engine
        self.task_covariance = task_covariance
        self.result = last
        self.held_fits = int(held_fits)
        self._like = like
        self._scout_engine = scout_engine
        self._n_inner = int(n_inner)
        self._settle = settle if settle is not None else (lambda kt: kt)

    def _matrix(self, kt: Tensor) -> Tensor:
        return kt.to(dtype=self._like.dtype, device=self._like.device)

    # ------------------------------------------------------------------ the fit
    def fit(self, multi_start: bool, min_gain: float | None, max_hold: int, track: bool,
            scout: int | None) -> bool:
        """Learn K_t as ``GPIOIS.fit`` describes. Returns True when the min_gain rule kept or tracked K_t without a
        re-learning (nothing else ran); False when K_t was learned (:attr:`result` then has ``starts`` and
        ``scout``)."""
        if min_gain is not None and not multi_start and self.hold(min_gain, max_hold, track):
            return True
        evaluate, level = self.likelihood(self.engine)
        # the thinned copy serves a later fit with more inner points than it keeps
        scouting = scout is not None and self.result is not None and self._n_inner > scout
        if scout is not None and self.result is None and multi_start and self._n_inner > scout:
            return self._first_scouted(evaluate, level, scout)
        best = None
        if scouting and multi_start and min_gain is not None and self.hold(min_gain, max_hold, track):
            # a restart's warm start by the min_gain rule too: held or tracked where the exact gradient allows (the
            # Hessian is refreshed by the next full re-learning, at the latest after max_hold fits), instead of a
            # Newton run on all the data at O(N_i^3) an evaluation on every restart
            best = self.result
        elif scouting:
            best = self.scouted_escape(evaluate, level, scout)
        if best is None:
            best = maximize_mll(evaluate, self.task_covariance, level=level)
        starts, scouted = 1, 0
        if multi_start:
            fixed = self.fixed_starts()
            # a restart's fixed starts on a thinned copy: scout^3, not N_i^3, per evaluation; the full data re-learn
            # once more per other basin found there
            candidates = self.scout_starts(fixed, scout, best.task_covariance) if scouting else fixed
            starts, scouted = 1 + len(fixed), (scout if scouting else 0)
            for kt0 in candidates:
                result = maximize_mll(evaluate, kt0, level=level)
                if result.mll > best.mll + 1e-9 * max(1.0, abs(best.mll)):
                    best = result
        self.task_covariance = self._settle(best.task_covariance)
        self.result = dataclasses.replace(best, starts=starts, scout=scouted)
        return False

    def fixed_starts(self) -> list[Tensor]:
        """The restarts' K_t: fixed, data-independent values, and the current variances with no relation (a warm
        start near a correlation of 1 can sit in a local optimum that these leave: tests/models/test_gpiois.py)."""
        return [torch.eye(2, dtype=torch.float64),
                0.1 * torch.tensor([[1.0, 0.9], [0.9, 1.0]], dtype=torch.float64),
                torch.diag(self.task_covariance.diagonal().clamp_min(1e-6))]

    def likelihood(self, engine: ExactEngine) -> tuple[Callable, Callable | None]:
        """``evaluate(K_t) -> (mll, grad, hess)`` and ``level(K_t) -> mll`` (None where the engine's value alone
        costs as much as its derivatives: ``ExactEngine.value_alone``) on ``engine``, for ``maximize_mll``."""

        def evaluate(kt: Tensor):
            return engine.mll_derivatives(self._matrix(kt))

        if not engine.value_alone:
            return evaluate, None

        def level(kt: Tensor) -> float:
            return engine.mll_value(self._matrix(kt))

        return evaluate, level

    # ------------------------------------------------------------------ scouts on a thinned copy
    def scouted_escape(self, evaluate, level, size: int) -> FitResult | None:
        """When the current K_t has a correlation of 1 (to within ``1 - rho^2 <= 1e-6``: the optimiser stops on that
        flat ridge before the bound of ``w``), the copy's Newton run from it; the full data's run starts where it
        ended and is kept when it ends above the current K_t's MLL. None otherwise (the caller runs the full data
        from the current K_t)."""
        if not on_ridge(self.task_covariance):
            return None
        # from the copy's result even where it stays at a correlation of 1: its u and v are close to the full data's
        # there, and from the warm K_t (the gradient pointing off the ridge) the full run made the copy's detour again,
        # up to w's trust-region edge and back down to its bound: 17 evaluations at 1,600 inner points (13.6 s)
        copy, copy_level = self.likelihood(self._scout_engine(size))
        guess = maximize_mll(copy, self.task_covariance, level=copy_level).task_covariance
        mll = float(self.engine.mll(self._matrix(self.task_covariance)))
        result = maximize_mll(evaluate, guess, level=level)
        return result if result.mll >= mll else None

    def _first_scouted(self, evaluate, level, size: int) -> bool:
        """A first fit's starts (the current K_t and :meth:`fixed_starts`) run on the thinned copy; the full data
        re-learn from each basin's optimum found there, and the best on the full likelihood is kept: one or two Newton
        runs on all the data instead of four (1,000 contacts of a user's file: four full runs were 177 of a fit's
        236 s). A basin that the thinned copy does not have is missed, as in a scouted restart."""
        fixed = self.fixed_starts()
        best = None
        for kt0 in self.scout_basins([self.task_covariance, *fixed], size):
            result = maximize_mll(evaluate, kt0, level=level)
            if best is None or result.mll > best.mll + 1e-9 * max(1.0, abs(best.mll)):
                best = result
        self.task_covariance = self._settle(best.task_covariance)
        self.result = dataclasses.replace(best, starts=1 + len(fixed), scout=size)
        return False

    def scout_basins(self, starts: list[Tensor], size: int) -> list[Tensor]:
        """Run ``starts`` on the thinned copy of ``size`` inner points; return the copy's optima, one per basin (K_t
        more than 1 % apart, relative to its largest entry), the first start's first. A later start's run ends as soon
        as it comes within 1 % of an optimum already found: it is heading into that basin, which is all the copy is
        asked (the runs that end on the ridge of a correlation of 1 creep along it for a dozen steps or more)."""
        evaluate, level = self.likelihood(self._scout_engine(size))
        found = [maximize_mll(evaluate, starts[0], level=level).task_covariance]

        def known(kt: Tensor) -> bool:
            return any(float((kt - other).abs().max()) <= 0.01 * float(other.abs().max()) for other in found)

        for kt0 in starts[1:]:
            kt = maximize_mll(evaluate, kt0, until=known, level=level).task_covariance
            if not known(kt):
                found.append(kt)
        return found

    def scout_starts(self, fixed: list[Tensor], size: int, warm: Tensor) -> list[Tensor]:
        """Run the warm and the fixed starts on the thinned copy; return the copy's optima that lie in other basins
        than the warm start's (K_t more than 1 % apart, relative to its largest entry), one per basin. Which of two
        near-equal optima is the higher can change with the thinning, so every other basin found is returned for
        the full data to judge, not only a better one (:meth:`scout_basins`)."""
        return self.scout_basins([warm, *fixed], size)[1:]

    # ------------------------------------------------------------------ the min_gain rule
    def hold(self, min_gain: float, max_hold: int, track: bool = False) -> bool:
        """Keep K_t if the exact gradient predicts a re-learning gain below ``min_gain``, or (``track``) move it by
        one held-Hessian Newton step that raises the MLL (see ``GPIOIS.fit``). False: re-learn in full."""
        last = self.result
        if last is None or last.hessian is None or (not last.relearned and self.held_fits >= max_hold):
            return False
        mll, grad, free = self.chol_gradient(self._matrix(self.task_covariance))
        gain, free = held_gain(self.task_covariance, grad, free, last.hessian)
        if gain > min_gain:
            return track and self.track(mll, grad, gain, free, last)
        self.held_fits = self.held_fits + 1 if not last.relearned else 1
        self.result = FitResult(self.task_covariance, mll, float(np.abs(np.where(free, grad, 0.0)).max()), 0,
                                last.converged, hessian=last.hessian, relearned=False, predicted_gain=gain)
        return True

    def chol_gradient(self, kt: Tensor) -> tuple[float, np.ndarray, np.ndarray]:
        """Exact MLL at ``kt`` with its gradient in the Cholesky parameters and the coordinates free to move
        (O(N_i^2) at the batched engine's held K_t, one factorisation at a new one)."""
        mll, g = self.engine.mll_gradient(kt)
        phi = task_covariance_to_chol_params(kt)
        grad, _ = chain_to_cholesky(phi, g, torch.zeros(3, 3, dtype=kt.dtype, device=kt.device))
        return mll, grad, free_coordinates(phi, grad, *cholesky_bounds())

    def track(self, mll: float, grad: np.ndarray, gain: float, free: np.ndarray, last: FitResult) -> bool:
        """One Newton step with the last re-learning's Hessian from the current K_t, kept if the exact MLL rises and
        the predicted gain that remains is below ``gain``, the one before the step (the held Hessian still contracts
        towards the optimum; near a bound of K_t it can stop doing so while the MLL still creeps up). Not taken
        where a coordinate at its bound is free to leave it: K_t at a correlation of 1 (``w`` at its lower bound)
        whose gradient now points inside, where the held Hessian, taken at the bound, says nothing of the
        interior (the optimum there can be nats away: tests/inference/test_batched.py)."""
        phi = task_covariance_to_chol_params(self.task_covariance)
        lower, upper = cholesky_bounds()
        if (((phi <= lower) | (phi >= upper)) & free).any():
            return False
        candidate = held_newton_step(phi, grad, last.hessian, free)
        if candidate is None:
            return False
        kt = chol_params_to_task_covariance(candidate)
        try:
            mll_new, grad_new, free = self.chol_gradient(self._matrix(kt))
        except (torch.linalg.LinAlgError, ArithmeticError):
            return False
        if not (math.isfinite(mll_new) and np.isfinite(grad_new).all()) or mll_new < mll:
            return False
        remaining, free = held_gain(kt, grad_new, free, last.hessian)
        if not remaining < gain:
            return False
        self.task_covariance = self._settle(kt)
        self.held_fits = self.held_fits + 1 if not last.relearned else 1
        self.result = FitResult(self.task_covariance, mll_new, float(np.abs(np.where(free, grad_new, 0.0)).max()), 1,
                                last.converged, hessian=last.hessian, relearned=False, predicted_gain=remaining,
                                tracked=True)
        return True

"""Second-order maximisation of the marginal likelihood over the task covariance K_t (eq. 15).

K_t is parametrised by its Cholesky factor, as in the paper (``K_t = L L^T``, ``theta_t = L``), with log
diagonals so that every parameter vector gives a PSD matrix and the parametrisation is unique:

    phi = (u, v, w),  L = [[e^u, 0], [v, e^w]],
    K_t[0,0] = e^{2u},  K_t[0,1] = v e^u,  K_t[1,1] = v^2 + e^{2w}.

Written by hand rather than with ``scipy.optimize``: on three parameters a projected, Levenberg-damped Newton
method converges quadratically in a handful of iterations, honours the bounds that keep a singular optimum
(perfectly correlated tasks) finite, warm-starts cheaply during exploration, and is deterministic; SciPy's bounded
methods are first order (L-BFGS-B, dozens of O(n^3) evaluations) or carry heavy per-iteration overhead
(trust-constr).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
from torch import Tensor

from ..core.tolerances import tol

__all__ = ["FitResult", "chol_params_to_task_covariance", "task_covariance_to_chol_params", "maximize_mll",
           "newton_maximize", "predicted_gain", "chain_to_cholesky", "cholesky_bounds",
           "free_coordinates", "held_newton_step"]


@dataclass
class FitResult:
    """Outcome of a K_t fit.

    Attributes:
        task_covariance: `(2, 2)` learned K_t.
        mll: log marginal likelihood at the last evaluated point [nats]; when the Newton-decrement stop took a
            final unevaluated step, the returned K_t is better than this by less than ``tol.fit_ftol * |mll|``.
        grad_norm: infinity norm of the projected gradient in the Cholesky parameters at the end.
        iterations: Newton iterations taken.
        converged: whether the tolerance was met before ``tol.fit_max_iter``.
        hessian: `(3, 3)` Hessian of the MLL in the Cholesky parameters at the last evaluated point (None where
            the fit evaluated none); ``GPIOIS.fit(min_gain=...)`` predicts later gains with it.
        relearned: False when ``GPIOIS.fit(min_gain=...)`` held K_t instead of re-learning it.
        predicted_gain: the Newton decrement [nats] that decided a held fit (NaN for a full fit).
        starts: how many starting points the fit tried (1: warm start only; more: ``multi_start``).
        tracked: True when ``GPIOIS.fit(track=True)`` moved K_t by one Newton step with the held Hessian instead of
            re-learning it to convergence (``predicted_gain`` is then what is predicted to remain).
        scout: inner points of the thinned copy of the data on which ``GPIOIS.fit(scout=...)`` ran the fixed
            starts (0: they ran on all the data, or there were none).
    """

    task_covariance: Tensor
    mll: float
    grad_norm: float
    iterations: int
    converged: bool
    hessian: np.ndarray | None = None
    relearned: bool = True
    predicted_gain: float = math.nan
    starts: int = 1
    tracked: bool = False
    scout: int = 0


def chol_params_to_task_covariance(phi) -> Tensor:
    """`(3,)` Cholesky parameters (u, v, w) -> `(2, 2)` K_t (float64)."""
    u, v, w = (float(x) for x in phi)
    eu = math.exp(u)
    return torch.tensor([[eu * eu, v * eu], [v * eu, v * v + math.exp(2 * w)]], dtype=torch.float64)


def task_covariance_to_chol_params(kt: Tensor) -> np.ndarray:
    """`(2, 2)` positive-definite K_t -> `(3,)` Cholesky parameters (u, v, w), clamped to the bounds."""
    lo, hi = tol.log_chol_bounds
    a, b, c = float(kt[0, 0]), float(kt[0, 1]), float(kt[1, 1])
    a = max(a, math.exp(2 * lo))
    l00 = math.sqrt(a)
    v = b / l00
    l11sq = max(c - v * v, math.exp(2 * lo))
    return np.array([min(max(math.log(l00), lo), hi), v, min(max(0.5 * math.log(l11sq), lo), hi)])


def chain_to_cholesky(phi: np.ndarray, g: Tensor, h: Tensor) -> tuple[np.ndarray, np.ndarray]:
    """Gradient and Hessian in phi from those in p = (a, b, c) by the chain rule (3x3 NumPy arithmetic: these
    small steps run once per Newton iteration, where torch's per-operation dispatch would dominate)."""
    u, v, w = phi.tolist()
    eu, e2u, e2w = math.exp(u), math.exp(2 * u), math.exp(2 * w)
    jac = np.array([[2 * e2u, 0.0, 0.0],
                    [v * eu, eu, 0.0],
                    [0.0, 2 * v, 2 * e2w]])  # d p_i / d phi_j
    g64 = g.detach().cpu().double().numpy()
    h64 = h.detach().cpu().double().numpy()
    # sum_i g_i d^2 p_i / d phi^2
    curvature = np.array([[4 * e2u * g64[0] + v * eu * g64[1], eu * g64[1], 0.0],
                          [eu * g64[1], 2.0 * g64[2], 0.0],
                          [0.0, 0.0, 4 * e2w * g64[2]]])
    return jac.T @ g64, jac.T @ h64 @ jac + curvature


def _evaluate_trial(evaluate, phi: np.ndarray):
    """Evaluate a trial point; a numerical failure there (an extreme K_t) counts as a rejected step."""
    try:
        f, g, h = evaluate(chol_params_to_task_covariance(phi))
    except (torch.linalg.LinAlgError, ArithmeticError):
        return -math.inf, None, None
    if not (math.isfinite(f) and bool(torch.isfinite(g).all()) and bool(torch.isfinite(h).all())):
        return -math.inf, None, None
    return f, g, h


def newton_maximize(value, phi0: np.ndarray, lower: np.ndarray, upper: np.ndarray, caps: Callable | None = None,
                    until: Callable | None = None, return_hessian: bool = False, level: Callable | None = None):
    """Maximise a smooth function of a few parameters within bounds by projected, Levenberg-damped Newton steps.

    Args:
        value: ``phi (k,) -> (f, grad (k,), hess (k, k))`` in NumPy, or ``(-inf, None, None)`` where the function
            cannot be evaluated (a rejected trial point).
        phi0: `(k,)` start (clamped to the bounds).
        lower: `(k,)` lower bounds (``-inf`` for none).
        upper: `(k,)` upper bounds (``+inf`` for none).
        caps: ``phi -> (k,)`` the largest change of each parameter in one step (a trust region: a longer step is
            shortened along its direction), or None.
        until: ``phi -> bool``, checked after each accepted step: True ends the run there, unconverged (a caller
            that only needs to know where a run is heading, e.g. into a known optimum's neighbourhood), or None.
        return_hessian: also return the Hessian at the last accepted point (the point returned, or the one the
            final Newton-decrement step left), not that of a trial point it evaluated and refused.
        level: ``phi -> f`` alone (``-inf`` where it cannot be evaluated), or None. With it a trial point is judged
            by its value first and ``value`` (the derivatives) is asked only where it is accepted, so refused trials
            cost the value alone (for the GP's likelihood one factorisation, against the Hessian's inverse and
            products, several times as much); the damped steps make the same decisions. An edge step walks on along
            its coordinate by values while they rise (:func:`_edge_walk`), the derivatives asked where it ends.

    Returns:
        ``(phi, f, projected_gradient_norm, iterations, converged)`` (and the `(k, k)` Hessian with
        ``return_hessian``); convergence as in :func:`maximize_mll`.
        Three accepted steps in a row that gain less than ``tol.fit_ftol`` (relative) end it unconverged: the
        function's rounding, not the optimum, stops progress there.

    Where the Hessian is not negative definite and a free coordinate has positive curvature (the function convex
    along it) and a gradient along it, with ``caps``: first a step along that coordinate alone, to the trust
    region's edge in the gradient's direction, kept if the function rises (:func:`_convex_rise`). Newton's model has
    no maximum along such a coordinate, and the damped step along it is as small as the gradient, which on a flat
    ridge (a correlation of 1, ``w = log L[1, 1]`` near its bound, where the likelihood depends on ``w`` through
    ``e^(2w)``) is below the gradient tolerance and the stall tolerance however much there is to gain (24 nats
    measured on tests/inference/test_batched.py's data; an analytic case in tests/models/test_gpiois.py). Such steps
    are not stalls. An edge step that fell (past where the function turns) is retried a quarter as long, and after
    three that fell the coordinate is left to the damped steps for the rest of the run, so rounding-level curvature
    at a flat maximum costs at most three evaluations per coordinate.
    """
    phi = np.minimum(np.maximum(np.asarray(phi0, dtype=np.float64), lower), upper)
    f, grad, hess = value(phi)
    if grad is None:
        raise torch.linalg.LinAlgError("newton_maximize: the starting point cannot be evaluated")
    k = len(phi)
    damping = 0.0
    converged = False
    it = 0
    pg_norm = math.inf
    stalls = 0
    reach: dict = {}                      # a coordinate's edge step, as a fraction of its cap, after steps that fell

    def judged(point: np.ndarray, floor: float):
        """``(f, grad, hess)`` at ``point`` where ``f >= floor``, else ``(f, None, None)`` (with ``level``, the
        derivatives are asked only where the point is accepted)."""
        if level is None:
            f_p, g_p, h_p = value(point)
            return (f_p, g_p, h_p) if math.isfinite(f_p) and f_p >= floor else (f_p, None, None)
        f_p = level(point)
        return value(point) if math.isfinite(f_p) and f_p >= floor else (f_p, None, None)

    refused_point = None                  # the last trial point refused: the same point again is not re-evaluated
    for it in range(1, tol.fit_max_iter + 1):
        free = free_coordinates(phi, grad, lower, upper)
        pg = np.where(free, grad, 0.0)
        pg_norm = float(np.abs(pg).max())
        idx = np.flatnonzero(free)
        neg_h = -hess[np.ix_(idx, idx)]
        min_eig = float(np.linalg.eigvalsh(neg_h).min()) if len(idx) else math.inf
        concave = min_eig > 1e-12 * max(1.0, abs(f))
        if not concave and caps is not None:
            rise = _convex_rise(phi, grad, hess, free, lower, upper, caps(phi), reach)
            if rise is not None:
                if level is not None:
                    rise, f_new, g_new, h_new = _edge_walk(rise, phi, f, level, value, lower, upper, caps, reach)
                else:
                    f_new, g_new, h_new = judged(rise, math.nextafter(f, math.inf))
                if g_new is not None:
                    phi, f, grad, hess, stalls = rise, f_new, g_new, h_new, 0
                    if until is not None and until(phi):
                        break
                    continue
                i = int(np.flatnonzero(rise != phi)[0])    # it went past where the function turns: a quarter next
                reach[i] = reach.get(i, 1.0) / 4.0
                refused_point = rise
        if pg_norm <= tol.fit_gtol:
            converged = True
            break
        shift = max(damping, 0.0 if concave else -min_eig + 1e-8 * max(1.0, abs(f)))
        while True:
            step = np.zeros(k)
            step[idx] = np.linalg.solve(neg_h + shift * np.eye(len(idx)), grad[idx])
            over = float(np.max(np.abs(step) / caps(phi))) if caps is not None else 0.0
            if over > 1.0:
                step /= over
            candidate = np.minimum(np.maximum(phi + step, lower), upper)
            decrement = float(grad @ (candidate - phi))
            if shift == 0.0 and over <= 1.0 and 0 <= decrement <= tol.fit_ftol * max(1.0, abs(f)):
                # Newton-decrement stop: the pure Newton step predicts a gain below tolerance; near a
                # non-degenerate maximum its error is quadratic in that gain, so take it without re-evaluating.
                return (candidate, f, pg_norm, it, True) + ((hess,) if return_hessian else ())
            if refused_point is not None and np.array_equal(candidate, refused_point):
                g_new = None
            else:
                f_new, g_new, h_new = judged(candidate, f - 1e-12 * max(1.0, abs(f)))
            if g_new is not None:
                break
            refused_point = candidate        # a larger shift whose step is still cut to the same edge: not re-evaluated
            shift = max(10.0 * shift, 1e-6 * max(1.0, abs(f)))
            if shift > 1e12 * max(1.0, abs(f)):
                return (phi, f, pg_norm, it, False) + ((hess,) if return_hessian else ())
        damping = shift / 10.0 if shift > 0 else 0.0
        # a stall: steps that gain nothing above the function's own rounding (an ill-conditioned K_t, where the
        # evaluations differ by more than the tolerance asks) end the fit instead of running to fit_max_iter
        stalls = stalls + 1 if f_new - f <= tol.fit_ftol * max(1.0, abs(f)) else 0
        phi, f, grad, hess = candidate, f_new, g_new, h_new
        if stalls >= 3 or (until is not None and until(phi)):
            break
    return (phi, f, pg_norm, it, converged) + ((hess,) if return_hessian else ())


def _edge_walk(rise: np.ndarray, phi: np.ndarray, f: float, level: Callable, value: Callable, lower: np.ndarray,
               upper: np.ndarray, caps: Callable, reach: dict):
    """The edge step of :func:`newton_maximize` judged by values alone: from ``phi`` to ``rise``, and on along the
    same coordinate by steps of the same reach while the value rises (the points a run with derivatives would try
    next while the function stays convex along it), the derivatives asked once, where the walk ends. On the ridge of
    a correlation of 1 the likelihood rises along ``w`` for several edge steps, each a Hessian otherwise. A walk that
    ends by a step that fell quarters the coordinate's reach, as a refused edge step does.

    Returns:
        ``(point, f, grad, hess)`` at the walk's last rising point, or ``(rise, f, None, None)`` where the first
        step already falls (the caller refuses it).
    """
    i = int(np.flatnonzero(rise != phi)[0])
    direction = math.copysign(1.0, rise[i] - phi[i])
    best, f_best, point = None, f, rise
    while True:
        f_point = level(point)
        if not (math.isfinite(f_point) and f_point > f_best):
            if best is None:
                return rise, f_point, None, None
            reach[i] = reach.get(i, 1.0) / 4.0                   # it went past where the function turns
            break
        best, f_best = point, f_point
        if best[i] in (lower[i], upper[i]):
            break
        point = best.copy()
        point[i] = min(max(best[i] + direction * reach.get(i, 1.0) * caps(best)[i], lower[i]), upper[i])
    f_new, g_new, h_new = value(best)
    return best, f_new, g_new, h_new


#: An edge step that fell is retried a quarter as long; below this fraction of the cap the coordinate is left to the
#: damped Newton steps for the rest of the run (at most three refused edge steps per coordinate and run).
_EDGE_MIN = 1.0 / 16.0


def _convex_rise(phi: np.ndarray, grad: np.ndarray, hess: np.ndarray, free: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, caps: np.ndarray, reach: dict) -> np.ndarray | None:
    """The step of :func:`newton_maximize` along a coordinate on which the function is convex and rising: among the
    free coordinates with positive curvature ``hess[i, i] > 0`` and a non-zero gradient, the one whose step to the
    trust region's edge (``reach.get(i, 1) * caps[i]`` in the gradient's direction, clamped to the bounds; ``reach``
    shrinks after steps that fell, and a coordinate whose reach is below :data:`_EDGE_MIN` is not tried) gains the
    most to first order (convexity along it makes that a lower bound of the gain while it holds). None: no such
    coordinate, or none that can move."""
    best, best_gain = None, 0.0
    for i in np.flatnonzero(free):
        if reach.get(i, 1.0) < _EDGE_MIN or not (hess[i, i] > 0 and grad[i] != 0):
            continue
        candidate = phi.copy()
        candidate[i] = min(max(phi[i] + math.copysign(reach.get(i, 1.0) * caps[i], grad[i]), lower[i]), upper[i])
        gain = float(grad[i] * (candidate[i] - phi[i]))
        if gain > best_gain:
            best, best_gain = candidate, gain
    return best


def maximize_mll(evaluate: Callable[[Tensor], tuple[float, Tensor, Tensor]], kt0: Tensor,
                 until: Callable[[Tensor], bool] | None = None,
                 level: Callable[[Tensor], float] | None = None) -> FitResult:
    """Maximise the marginal likelihood over K_t by projected, damped Newton steps (:func:`newton_maximize` in the
    Cholesky parameters ``phi``).

    Args:
        evaluate: maps a `(2, 2)` K_t to ``(mll, grad (3,), hess (3, 3))`` in ``p = (K_t00, K_t01, K_t11)``.
        kt0: `(2, 2)` starting K_t (positive definite; clamped to the parameter bounds).
        until: ``K_t -> bool`` after each accepted step; True ends the run there, unconverged (None: run to the
            tolerances).
        level: maps a `(2, 2)` K_t to the MLL alone, computed the way ``evaluate`` computes it (None: trial points
            are judged with ``evaluate``); see :func:`newton_maximize`.

    Returns:
        The ``FitResult``. Convergence: projected gradient infinity-norm <= ``tol.fit_gtol``, or a Newton
        decrement below ``tol.fit_ftol * max(1, |mll|)``.
    """
    lower, upper = cholesky_bounds()

    def value(phi):
        f, g, h = _evaluate_trial(evaluate, phi)
        if g is None:
            return f, None, None
        return (f, *chain_to_cholesky(phi, g, h))

    phi0 = task_covariance_to_chol_params(kt0)
    f0, g0, h0 = evaluate(chol_params_to_task_covariance(phi0))      # the start must evaluate (errors propagate)
    first = [(f0, *chain_to_cholesky(phi0, g0, h0))]

    def value_first(phi):
        if first:
            return first.pop()
        return value(phi)

    stop = None if until is None else (lambda phi: until(chol_params_to_task_covariance(phi)))

    def value_alone(phi) -> float:
        try:
            f = level(chol_params_to_task_covariance(phi))
        except (torch.linalg.LinAlgError, ArithmeticError):
            return -math.inf
        return f if math.isfinite(f) else -math.inf

    # the Hessian where the run ended, for the min_gain rule (GPIOIS.fit): not a refused trial point's
    phi, f, pg_norm, it, converged, hess = newton_maximize(value_first, phi0, lower, upper, step_caps, stop,
                                                           return_hessian=True,
                                                           level=None if level is None else value_alone)
    return FitResult(chol_params_to_task_covariance(phi), f, pg_norm, it, converged, hessian=hess)


def cholesky_bounds() -> tuple[np.ndarray, np.ndarray]:
    """`(3,)` lower and upper bounds of the Cholesky parameters (u, v, w): ``tol.log_chol_bounds`` on the log
    diagonals, ``e^hi`` on the off-diagonal's magnitude (so every entry of K_t stays below ``2 e^(2 hi)``; unbounded,
    one Newton step once took K_t[1, 1] past ``tol.task_covariance_max``)."""
    lo, hi = tol.log_chol_bounds
    return np.array([lo, -math.exp(hi), lo]), np.array([hi, math.exp(hi), hi])


def step_caps(phi: np.ndarray) -> np.ndarray:
    """`(3,)` the largest change of each Cholesky parameter (u, v, w) in one Newton step: ``tol.fit_max_step`` on
    the log diagonals, and on ``v`` the change that scaling K_t by ``e^(2 fit_max_step)`` would make
    (``v`` scales with ``sqrt`` of K_t)."""
    r = tol.fit_max_step
    u, v, w = (float(x) for x in phi)
    return np.array([r, math.expm1(r) * max(abs(v), math.exp(w), math.exp(u) * 1e-3), r])


def free_coordinates(phi: np.ndarray, grad: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """`(k,)` bool: the coordinates a projected ascent may move (not at a bound with the gradient pointing past it)."""
    return ~(((phi <= lower) & (grad < 0)) | ((phi >= upper) & (grad > 0)))


def predicted_gain(grad: np.ndarray, hess: np.ndarray, free: np.ndarray) -> float:
    """Newton decrement ``g^T (-H)^-1 g / 2`` of a maximisation on the free coordinates.

    Args:
        grad: `(k,)` gradient.
        hess: `(k, k)` Hessian (of a maximum: negative definite on the free coordinates).
        free: `(k,)` bool, the coordinates not held at a bound.

    Returns:
        The gain [units of the function] one Newton step predicts; inf where -H is not positive definite.
    """
    idx = np.flatnonzero(free)
    if not len(idx):
        return 0.0
    try:
        chol = np.linalg.cholesky(-np.asarray(hess, dtype=np.float64)[np.ix_(idx, idx)])
    except np.linalg.LinAlgError:
        return math.inf
    z = np.linalg.solve(chol, np.asarray(grad, dtype=np.float64)[idx])
    return 0.5 * float(z @ z)


def held_newton_step(phi: np.ndarray, grad: np.ndarray, hess: np.ndarray,
                     free: np.ndarray | None = None) -> np.ndarray | None:
    """One projected Newton step in the Cholesky parameters with a Hessian from an earlier K_t (``GPIOIS.fit``'s
    tracking step): ``phi + (-H)^-1 g`` on the free coordinates, shortened to :func:`step_caps` and clamped to
    :func:`cholesky_bounds`.

    Args:
        phi: `(3,)` current Cholesky parameters.
        grad: `(3,)` exact gradient of the MLL at ``phi``.
        hess: `(3, 3)` Hessian of the MLL from the last full re-learning.
        free: `(3,)` bool, the coordinates to move (default: those not held at a bound, :func:`free_coordinates`).

    Returns:
        `(3,)` the candidate parameters, or None where ``-H`` is not positive definite on the free coordinates (no
        ascent direction can be trusted from it).
    """
    lower, upper = cholesky_bounds()
    if free is None:
        free = free_coordinates(phi, grad, lower, upper)
    idx = np.flatnonzero(free)
    step = np.zeros(len(phi))
    if len(idx):
        neg_h = -np.asarray(hess, dtype=np.float64)[np.ix_(idx, idx)]
        try:
            chol = np.linalg.cholesky(neg_h)
        except np.linalg.LinAlgError:
            return None
        step[idx] = np.linalg.solve(chol.T, np.linalg.solve(chol, np.asarray(grad, dtype=np.float64)[idx]))
    over = float(np.max(np.abs(step) / step_caps(phi)))
    if over > 1.0:
        step /= over
    return np.minimum(np.maximum(phi + step, lower), upper)

r"""Profile-likelihood intervals of the similarity between the tasks: the correlation and the paper's ratio.

The task covariance ``K_t = [[a, b], [b, c]]`` is learned by maximum marginal likelihood (eq. 15-16); a point
estimate says nothing about how well the data pin it down. When the inner and outer observations are far apart, or
when only surface points are seen, the likelihood is flat in the correlation ``rho = b / sqrt(a c)`` and the
optimiser stops on a bound (``rho`` exactly 1) without any evidence for it.

**Profile likelihood.** For a fixed ``rho`` the other two parameters are maximised out,
``l_p(rho) = max_{a, c} log p(y | a, rho sqrt(a c), c)`` (a 2-parameter Newton method in ``(log sqrt(a),
log sqrt(c))`` with the engines' exact gradient and Hessian, warm-started along ``rho``). The 95 % interval is
``{rho : 2 (l_hat - l_p(rho)) <= q}`` with ``l_hat`` the maximum over the closed set ``|rho| <= 1``.

**The boundary.** ``rho = +-1`` is on the edge of the parameter space, where the likelihood-ratio statistic is
not chi-square with one degree of freedom: under ``rho = 1`` it is the mixture ``1/2 chi2_0 + 1/2 chi2_1`` (Self and
Liang, 1987). So ``q`` is the ``chi2_1`` quantile (3.84 at 95 %) inside and the mixture's (2.71) at ``rho = +-1``
itself: the interval reaches 1 exactly when the data cannot tell ``rho = 1`` from the best fit at that level.

**The paper's ratio** ``s = b / a`` is profiled the same way over ``(log sqrt(a), log l11)`` with ``b = s a`` and
``c = s^2 a + l11^2``; it is unbounded, so an endpoint the likelihood never rules out is reported as ``+-inf``.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import torch

__all__ = ["correlation_interval", "ratio_interval", "profile_correlation", "chi2_quantile", "plausible_correlation"]

Evaluate = Callable[[torch.Tensor], tuple[float, torch.Tensor, torch.Tensor]]


def chi2_quantile(level: float, boundary: bool = False) -> float:
    """The ``chi2_1`` quantile at ``level`` (inside), or that of ``1/2 chi2_0 + 1/2 chi2_1`` (at a boundary)."""
    from scipy.stats import chi2

    return float(chi2.ppf(2 * level - 1, 1)) if boundary else float(chi2.ppf(level, 1))


def _kt(a: float, b: float, c: float) -> torch.Tensor:
    return torch.tensor([[a, b], [b, c]], dtype=torch.float64)


def _newton2(evaluate: Evaluate, params: np.ndarray, to_p: Callable, max_iter: int = 60,
             lo: float = -12.0, hi: float = 12.0) -> tuple[float, np.ndarray]:
    """Maximise the MLL over two log-parameters with damped Newton steps; ``to_p(x) -> (p, J, second)`` maps them to
    ``p = (a, b, c)`` with Jacobian ``J (3, 2)`` and ``second[i]``, the Hessian of ``p_i`` (2, 2)."""
    x = np.clip(np.asarray(params, dtype=np.float64), lo, hi)

    def value(x):
        p, jac, sec = to_p(x)
        try:
            f, g, h = evaluate(_kt(*p))
        except (torch.linalg.LinAlgError, ArithmeticError):
            return -math.inf, None, None
        g64, h64 = g.detach().cpu().double().numpy(), h.detach().cpu().double().numpy()
        grad = jac.T @ g64
        hess = jac.T @ h64 @ jac + sum(g64[i] * sec[i] for i in range(3))
        return f, grad, hess

    f, grad, hess = value(x)
    if grad is None:
        return -math.inf, x
    shift = 0.0
    for _ in range(max_iter):
        free = ~(((x <= lo) & (grad < 0)) | ((x >= hi) & (grad > 0)))
        if np.abs(np.where(free, grad, 0.0)).max() < 1e-8 * max(1.0, abs(f)):
            break
        while True:
            neg = -hess + shift * np.eye(2)
            evals = np.linalg.eigvalsh(neg)
            if evals.min() <= 1e-12 * max(1.0, abs(f)):
                shift = max(shift * 10.0, 1e-8 * max(1.0, abs(f)), -evals.min() + 1e-8 * max(1.0, abs(f)))
                continue
            step = np.linalg.solve(neg, np.where(free, grad, 0.0))
            cand = np.clip(x + step, lo, hi)
            f_new, g_new, h_new = value(cand)
            if f_new >= f - 1e-12 * max(1.0, abs(f)):
                break
            shift = max(10.0 * shift, 1e-6 * max(1.0, abs(f)))
            if shift > 1e12 * max(1.0, abs(f)):
                return f, x
        gain = f_new - f
        x, f, grad, hess = cand, f_new, g_new, h_new
        shift /= 10.0
        if gain <= 1e-10 * max(1.0, abs(f)):
            break
    return f, x


def _correlation_map(rho: float):
    def to_p(x):
        u, w = x
        a, c = math.exp(2 * u), math.exp(2 * w)
        b = rho * math.exp(u + w)
        jac = np.array([[2 * a, 0.0], [b, b], [0.0, 2 * c]])
        sec = [np.array([[4 * a, 0.0], [0.0, 0.0]]), b * np.ones((2, 2)), np.array([[0.0, 0.0], [0.0, 4 * c]])]
        return (a, b, c), jac, sec

    return to_p


def profile_correlation(evaluate: Evaluate, rho: float, start: np.ndarray) -> tuple[float, np.ndarray]:
    """``l_p(rho)``: the MLL maximised over ``(log sqrt(a), log sqrt(c))`` with the correlation fixed at ``rho``."""
    return _newton2(evaluate, start, _correlation_map(float(np.clip(rho, -1.0, 1.0))))


def _search(profile: Callable[[float, np.ndarray], tuple[float, np.ndarray]], centre: float, edge: float,
            l_hat: float, q_inside: float, q_edge: float | None, start: np.ndarray, tol: float) -> float:
    """The endpoint between ``centre`` (inside) and ``edge``: ``edge`` itself when it is not ruled out (with the
    boundary quantile ``q_edge``), else the crossing of ``2 (l_hat - l_p) = q_inside`` by bisection."""
    f_edge, x_edge = profile(edge, start)
    if q_edge is not None and 2 * (l_hat - f_edge) <= q_edge:
        return edge
    lo, hi, x = centre, edge, start
    while abs(hi - lo) > tol:
        mid = 0.5 * (lo + hi)
        f_mid, x_mid = profile(mid, x)
        if 2 * (l_hat - f_mid) <= q_inside:
            lo, x = mid, x_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def correlation_interval(evaluate: Evaluate, kt_hat: torch.Tensor, level: float = 0.95,
                         tol: float = 1e-3) -> tuple[float, float, float]:
    """Profile-likelihood interval of the task correlation (see the module docstring).

    Args:
        evaluate: ``K_t -> (mll, grad, hess)`` in ``(K00, K01, K11)`` (an engine's ``mll_derivatives``).
        kt_hat: `(2, 2)` fitted K_t (the optimiser's maximum).
        level: confidence level.
        tol: width of the bisection's last bracket on rho.

    Returns:
        ``(lo, hi, rho_hat)`` with ``-1 <= lo <= rho_hat <= hi <= 1``.
    """
    a, b, c = float(kt_hat[0, 0]), float(kt_hat[0, 1]), float(kt_hat[1, 1])
    rho_hat = float(np.clip(b / math.sqrt(a * c), -1.0, 1.0))
    start = np.array([0.5 * math.log(a), 0.5 * math.log(c)])
    f_hat, _ = profile_correlation(evaluate, rho_hat, start)
    # the maximum over the closed set: the optimiser's bound keeps rho just inside +-1
    for edge in (-1.0, 1.0):
        if abs(edge - rho_hat) < 1e-3:
            f_edge, _ = profile_correlation(evaluate, edge, start)
            if f_edge > f_hat:
                f_hat, rho_hat = f_edge, edge
    q_in, q_edge = chi2_quantile(level), chi2_quantile(level, boundary=True)
    lo = _search(lambda r, x: profile_correlation(evaluate, r, x), rho_hat, -1.0, f_hat, q_in, q_edge, start, tol)
    hi = _search(lambda r, x: profile_correlation(evaluate, r, x), rho_hat, 1.0, f_hat, q_in, q_edge, start, tol)
    return min(lo, rho_hat), max(hi, rho_hat), rho_hat


def _ratio_map(s: float):
    def to_p(x):
        u, w = x
        a, l2 = math.exp(2 * u), math.exp(2 * w)
        p = (a, s * a, s * s * a + l2)
        jac = np.array([[2 * a, 0.0], [2 * s * a, 0.0], [2 * s * s * a, 2 * l2]])
        sec = [np.array([[4 * a, 0.0], [0.0, 0.0]]), np.array([[4 * s * a, 0.0], [0.0, 0.0]]),
               np.array([[4 * s * s * a, 0.0], [0.0, 4 * l2]])]
        return p, jac, sec

    return to_p


def ratio_interval(evaluate: Evaluate, kt_hat: torch.Tensor, level: float = 0.95, tol: float = 1e-3,
                   limit: float = 1e3) -> tuple[float, float, float]:
    """Profile-likelihood interval of the paper's ratio ``K01 / K00``; ``+-inf`` where the likelihood does not rule
    out ratios beyond ``+-limit``."""
    a, b, c = float(kt_hat[0, 0]), float(kt_hat[0, 1]), float(kt_hat[1, 1])
    s_hat = b / a
    start = np.array([0.5 * math.log(a), 0.5 * math.log(max(c - b * b / a, 1e-24))])

    def profile(s, x):
        return _newton2(evaluate, x, _ratio_map(s))

    f_hat, _ = profile(s_hat, start)
    q = chi2_quantile(level)
    ends = []
    for sign in (-1.0, 1.0):
        width, inside, x = max(1.0, abs(s_hat)) * 0.25, s_hat, start
        while True:
            probe = s_hat + sign * width
            f, x_p = profile(probe, x)
            if 2 * (f_hat - f) > q:
                break
            inside, x = probe, x_p
            width *= 2.0
            if width > limit:
                inside = sign * math.inf
                break
        if math.isinf(inside):
            ends.append(inside)
            continue
        lo_, hi_ = inside, probe
        while abs(hi_ - lo_) > tol * max(1.0, abs(s_hat)):
            mid = 0.5 * (lo_ + hi_)
            f_mid, x_mid = profile(mid, x)
            if 2 * (f_hat - f_mid) <= q:
                lo_, x = mid, x_mid
            else:
                hi_ = mid
        ends.append(0.5 * (lo_ + hi_))
    return min(ends[0], s_hat), max(ends[1], s_hat), s_hat


def plausible_correlation(evaluate: Evaluate, kt_hat: torch.Tensor, rho: float = 1.0, level: float = 0.95) -> bool:
    """Whether the correlation ``rho`` (default 1) lies in the ``level`` profile-likelihood interval: one profile
    evaluation instead of the whole interval (``rho = +-1`` with the boundary quantile)."""
    a, b, c = float(kt_hat[0, 0]), float(kt_hat[0, 1]), float(kt_hat[1, 1])
    rho_hat = float(np.clip(b / math.sqrt(a * c), -1.0, 1.0))
    start = np.array([0.5 * math.log(a), 0.5 * math.log(c)])
    f_hat, _ = profile_correlation(evaluate, rho_hat, start)
    f_rho, _ = profile_correlation(evaluate, rho, start)
    f_hat = max(f_hat, f_rho)
    return 2 * (f_hat - f_rho) <= chi2_quantile(level, boundary=abs(rho) == 1.0)

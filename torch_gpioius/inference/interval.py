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
    """The ``chi2_1`` quantile at ``level`` (inside), or that of ``1/2 chi2_0 + 1/2 chi2_1`` (at a boundary).

    A ``chi2_1`` variable is a squared standard normal, so its quantile at ``p`` is ``z^2`` with ``z`` the normal
    quantile at ``(1 + p) / 2`` (at a boundary ``p = 2 level - 1``: ``z`` at ``level``). The standard library's
    normal quantile gives it to rounding; scipy.stats, which gave it before, cost 1.9 s to import in every run's
    process, a fifth of a short run."""
    from statistics import NormalDist

    z = NormalDist().inv_cdf(level if boundary else (1.0 + level) / 2.0)
    return z * z


def _kt(a: float, b: float, c: float) -> torch.Tensor:
    return torch.tensor([[a, b], [b, c]], dtype=torch.float64)


def _newton2(evaluate: Evaluate, params: np.ndarray, to_p: Callable, max_iter: int = 60,
             lo: float = -12.0, hi: float = 12.0) -> tuple[float, np.ndarray, tuple | None]:
    """Maximise the MLL over two log-parameters with damped Newton steps; ``to_p(x) -> (p, J, second)`` maps them to
    ``p = (a, b, c)`` with Jacobian ``J (3, 2)`` and ``second[i]``, the Hessian of ``p_i`` (2, 2).

    Returns:
        The maximum, the `(2,)` parameters there, and ``(g, H, hess)`` there: the MLL's `(3,)` gradient and
        `(3, 3)` Hessian in ``p`` and its `(2, 2)` Hessian in the parameters (None if the start could not be
        evaluated).
    """
    x = np.clip(np.asarray(params, dtype=np.float64), lo, hi)

    def value(x):
        p, jac, sec = to_p(x)
        try:
            f, g, h = evaluate(_kt(*p))
        except (torch.linalg.LinAlgError, ArithmeticError):
            return -math.inf, None, None, None
        g64, h64 = g.detach().cpu().double().numpy(), h.detach().cpu().double().numpy()
        grad = jac.T @ g64
        hess = jac.T @ h64 @ jac + sum(g64[i] * sec[i] for i in range(3))
        return f, grad, (g64, h64), hess

    f, grad, gp, hess = value(x)
    if grad is None:
        return -math.inf, x, None
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
            f_new, g_new, gp_new, h_new = value(cand)
            if f_new >= f - 1e-12 * max(1.0, abs(f)):
                break
            shift = max(10.0 * shift, 1e-6 * max(1.0, abs(f)))
            if shift > 1e12 * max(1.0, abs(f)):
                return f, x, (*gp, hess)
        gain = f_new - f
        x, f, grad, gp, hess = cand, f_new, g_new, gp_new, h_new
        shift /= 10.0
        if gain <= 1e-10 * max(1.0, abs(f)):
            break
    return f, x, (*gp, hess)


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
    f, x, _, _ = _profile_slope(evaluate, rho, start)
    return f, x


def _profile_slope(evaluate: Evaluate, rho: float, start: np.ndarray) -> tuple[float, np.ndarray, float, float]:
    """``l_p(rho)``, its maximiser ``(u, w)``, and its slope and curvature in rho (NaN where the profile could not be
    evaluated).

    With ``b = rho e^(u + w)``: the slope is ``dl/db e^(u + w)`` (the envelope theorem: ``(u, w)`` sit at their
    maximum), the curvature the Schur complement ``H_rr - H_rv H_vv^-1 H_vr`` of the MLL's Hessian in
    ``(rho, u, w)``."""
    rho = float(np.clip(rho, -1.0, 1.0))
    f, x, derivs = _newton2(evaluate, start, _correlation_map(rho))
    if derivs is None:
        return f, x, math.nan, math.nan
    g, h, h_uw = derivs
    e = math.exp(x[0] + x[1])
    a, b, c = math.exp(2 * x[0]), rho * e, math.exp(2 * x[1])
    jr = np.array([0.0, e, 0.0])                             # dp / drho
    juw = np.array([[2 * a, 0.0], [b, b], [0.0, 2 * c]])     # dp / d(u, w)
    cross = juw.T @ h @ jr + g[1] * e                        # d2 l / drho d(u, w): d2 b / drho du = e, likewise w
    try:
        curvature = float(jr @ h @ jr - cross @ np.linalg.solve(h_uw, cross))
    except np.linalg.LinAlgError:
        curvature = math.nan
    return f, x, float(g[1]) * e, curvature


def _search(evaluate: Evaluate, centre: tuple[float, float, float, float, np.ndarray], edge: float,
            q_inside: float, q_edge: float | None, tol: float) -> float:
    """The endpoint between the ``centre`` (the maximum ``l_hat`` of the profile, inside; ``(rho, l_hat, slope,
    curvature, maximiser)`` as :func:`_profile_slope` gives them there) and ``edge``:
    ``edge`` itself when it is not ruled out (with the boundary quantile ``q_edge``), else the crossing of
    ``2 (l_hat - l_p(rho)) = q_inside``, returned as the middle of a bracket no wider than ``tol``.

    The crossing is sought on the signed root ``g(rho) = sqrt(2 (l_hat - l_p(rho))) - sqrt(q_inside)``, nearly linear
    where the profile is nearly quadratic: first where the centre's quadratic model (its slope and curvature) puts
    it, then by Newton steps with the profile's slope (``g' = -l_p' / sqrt(2 (l_hat - l_p))``) from the point nearest
    the crossing, each aimed ``tol / 4`` past its target so that the crossing ends up bracketed from both sides.
    A step that leaves the bracket or fails to halve ``|g|`` is followed by a bisection. Every profile is warm-started
    from the nearest profiled rho. About 4 profiles per endpoint instead of bisection's 11 (``tol`` 1e-3 over
    [-1, 1]); each profile is a few exact MLL evaluations, O(N_i^3) at thousands of inner points."""
    rho_c, l_hat, slope_c, curv_c, x_c = centre
    seen = [(rho_c, x_c)]

    def run(r: float) -> tuple[float, float, float, np.ndarray]:
        x0 = min(seen, key=lambda p: abs(p[0] - r))[1]
        f, x, slope, _ = _profile_slope(evaluate, r, x0)
        if math.isfinite(f):
            seen.append((r, x))
        d = 2.0 * max(l_hat - f, 0.0) if math.isfinite(f) else math.inf
        rt = math.sqrt(d)
        dg = -slope / rt if 0 < rt < math.inf else math.nan
        return f, rt - root_q, dg, x

    root_q = math.sqrt(q_inside)
    toward = math.copysign(1.0, edge - rho_c)
    f_edge, g_edge, dg_edge, _ = run(edge)
    if q_edge is not None and 2 * (l_hat - f_edge) <= q_edge:
        return edge
    inside, outside = rho_c, edge                   # g(inside) <= 0 < g(outside)
    best = (edge, g_edge, dg_edge)
    # the quadratic model's crossing: s d + k d^2 / 2 = -q / 2 along ``toward``
    s, k = toward * slope_c, curv_c
    guess = math.nan
    if math.isfinite(s) and math.isfinite(k):
        if k < 0:
            d = (-s - math.sqrt(s * s - k * q_inside)) / k if s * s - k * q_inside >= 0 else math.nan
        else:
            d = -0.5 * q_inside / s if s < 0 else math.nan
        guess = rho_c + toward * d
    bisect_next = False
    for i in range(200):
        if abs(outside - inside) <= tol:
            break
        lo_, hi_ = min(inside, outside), max(inside, outside)
        r, g, dg = best
        if i == 0:
            cand = guess
        else:
            cand = r - g / dg if math.isfinite(g) and math.isfinite(dg) and dg != 0.0 else math.nan
            if math.isfinite(cand):
                cand += math.copysign(0.25 * tol, cand - r)
        if bisect_next or not lo_ < cand < hi_:
            cand = 0.5 * (inside + outside)
        _, g_c, dg_c, _ = run(cand)
        if g_c <= 0:
            inside = cand
        else:
            outside = cand
        bisect_next = not bisect_next and i > 0 and not abs(g_c) <= 0.5 * abs(g)
        if math.isfinite(g_c) and not abs(g_c) > abs(best[1]):
            best = (cand, g_c, dg_c)
    return 0.5 * (inside + outside)


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
    f_hat, x_hat, slope, curv = _profile_slope(evaluate, rho_hat, start)
    # the maximum over the closed set: the optimiser's bound keeps rho just inside +-1
    for edge in (-1.0, 1.0):
        if abs(edge - rho_hat) < 1e-3:
            f_edge, x_edge, s_edge, c_edge = _profile_slope(evaluate, edge, start)
            if f_edge > f_hat:
                f_hat, rho_hat, x_hat, slope, curv = f_edge, edge, x_edge, s_edge, c_edge
    q_in, q_edge = chi2_quantile(level), chi2_quantile(level, boundary=True)
    centre = (rho_hat, f_hat, slope, curv, x_hat)
    lo = _search(evaluate, centre, -1.0, q_in, q_edge, tol)
    hi = _search(evaluate, centre, 1.0, q_in, q_edge, tol)
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
        f, x_s, _ = _newton2(evaluate, x, _ratio_map(s))
        return f, x_s

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

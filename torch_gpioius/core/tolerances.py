"""Numerical tolerances used across the library, in one place (trimesh ``constants.tol`` style).

All values are for float64 arithmetic.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Tolerances", "tol"]


@dataclass(frozen=True)
class Tolerances:
    """Library-wide numerical tolerances.

    Attributes:
        jitter_rounding: when a Cholesky factorisation fails, it is retried once with ``jitter_rounding * n * eps``
            times the largest diagonal entry added: the perturbation a backward-stable Cholesky makes anyway.
            Anything larger would change the model, not its rounding, so a matrix that still fails is an error
            (``NotPositiveDefiniteError``), never a silently regularised result.
        fit_gtol: absolute tolerance on the projected gradient of the log marginal likelihood with
            respect to the Cholesky parameters of ``K_t`` [nats per unit parameter].
        fit_ftol: relative tolerance on the predicted MLL gain of a pure Newton step (Newton decrement): below
            it the step is taken and the fit stops; the gradient after such a step is ~fit_gtol.
        fit_max_iter: iteration cap of the K_t optimiser.
        fit_max_step: trust radius of one Newton step of the K_t optimiser, in ``log sqrt`` of K_t's scale (2: at
            most a factor e^4 ~ 55 per step). A Newton step from far out on a flat ridge (a correlation near 1, or
            data that want a large signal variance) once leapt from K_t ~ 0.4 to 1e10 in one step, where the
            arithmetic of every engine loses the marginal likelihood to cancellation and reports a spurious gain.
        log_chol_bounds: bounds on ``log L[0, 0]`` and ``log L[1, 1]`` where ``K_t = L L^T`` (and ``e^hi`` on
            ``|L[1, 0]|``); they keep the optimiser finite when the likelihood prefers a singular ``K_t`` (e.g.
            perfectly correlated tasks).
        normal_eps: gradient norm below which a normal is considered undefined.
        theta_range: supported IMQ kernel parameter theta_x [m]; outside it the kernel over- or underflows
            (theta = 1e-170 made the Gram matrix infinite).
        noise_range: supported noise variance sigma^2.
        task_covariance_max: largest supported magnitude of a K_t entry (the optimiser's bounds keep K_t below
            2 e^24 ~ 5.3e10).
        outer_mean_span: how far the outer task's prior mean may lie from 1 (``GPIOIS.set_outer_mean``), in label
            units (10: a cover 10 ramps, 50 cm at the 5 cm ramp, off the body).
        structured_series: bound, relative to sigma^2, on the perturbation of the inner Schur complement (and
            of its c-derivatives, scaled by c and c^2) from truncating the Chebyshev expansion of the structured
            engine (``StructuredExactInference``).
    """

    jitter_rounding: float = 4.0
    fit_gtol: float = 1e-7
    fit_ftol: float = 1e-9
    fit_max_iter: int = 200
    fit_max_step: float = 2.0
    log_chol_bounds: tuple[float, float] = (-12.0, 12.0)
    normal_eps: float = 1e-12
    structured_series: float = 1e-13
    theta_range: tuple[float, float] = (1e-6, 1e3)
    noise_range: tuple[float, float] = (1e-12, 1e6)
    task_covariance_max: float = 1e12
    outer_mean_span: float = 10.0


tol = Tolerances()

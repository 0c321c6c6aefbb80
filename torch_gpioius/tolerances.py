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
        jitter_start: first relative jitter (times the mean Gram diagonal) tried when a Cholesky fails.
        jitter_max: largest relative jitter tried before giving up with an error.
        fit_gtol: absolute tolerance on the projected gradient of the log marginal likelihood with
            respect to the Cholesky parameters of ``K_t`` [nats per unit parameter].
        fit_ftol: relative tolerance on the predicted MLL gain of a pure Newton step (Newton decrement): below
            it the step is taken and the fit stops; the gradient after such a step is ~fit_gtol.
        fit_max_iter: iteration cap of the K_t optimiser.
        log_chol_bounds: bounds on ``log L[0, 0]`` and ``log L[1, 1]`` where ``K_t = L L^T``; they keep the
            optimiser finite when the likelihood prefers a singular ``K_t`` (e.g. perfectly correlated tasks).
        normal_eps: gradient norm below which a normal is considered undefined.
        structured_series: bound, relative to sigma^2, on the perturbation of the inner Schur complement (and
            of its c-derivatives, scaled by c and c^2) from truncating the Chebyshev expansion of the structured
            engine (``StructuredExactInference``).
    """

    jitter_start: float = 1e-10
    jitter_max: float = 1e-2
    fit_gtol: float = 1e-7
    fit_ftol: float = 1e-9
    fit_max_iter: int = 200
    log_chol_bounds: tuple[float, float] = (-12.0, 12.0)
    normal_eps: float = 1e-12
    structured_series: float = 1e-13


tol = Tolerances()

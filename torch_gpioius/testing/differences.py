"""Finite differences with an error estimate of their own: the references the kernel contract (and the project's
tests) check closed-form derivatives against.

A reference has an error of its own: a central difference errs by its step's truncation and by the rounding of
each evaluation divided by the step. :func:`richardson_derivative` estimates both, and
:func:`assert_close_to_reference` gives the tolerance a margin over that estimate.
"""

from __future__ import annotations

import numpy as np

__all__ = ["richardson_derivative", "assert_close_to_reference"]


def richardson_derivative(f, x, h, directions=None):
    """Derivatives of ``f`` at ``x`` by Richardson-extrapolated central differences, with an error estimate.

    A reference has an error of its own (docs/architecture.md, "Tests"): a central difference D(h) errs by ~h^2 f'''
    (truncation) plus ~r / h, where r is the rounding noise of one evaluation of f, which for a linear solve is
    cond * eps * |f|, not eps * |f|, and moves with the BLAS blocking (thread count, CPU). The estimate here is
    R(h/2) with R(h) = (4 D(h/2) - D(h)) / 3 (fourth order); its error is estimated as |R(h) - R(h/2)| (the
    truncation of R(h) is 16x that of R(h/2), and both carry rounding of the same size), plus a floor of
    eps * max|f| / h per evaluation.

    Args:
        f: maps an array shaped like ``x`` to an array (or a scalar).
        x: point; ``directions`` default to the unit vectors of ``x.ravel()``.
        h: base step.
        directions: `(k, x.size)` directions; the result has one derivative per direction.

    Returns:
        ``(derivative, error)``: arrays of shape ``(k,) + f(x).shape``.
    """
    x = np.asarray(x, dtype=np.float64)
    dirs = np.eye(x.size) if directions is None else np.asarray(directions, dtype=np.float64)
    est, err = [], []
    for d in dirs:
        d = d.reshape(x.shape)
        vals = {}

        def central(step):
            plus, minus = np.asarray(f(x + step * d), float), np.asarray(f(x - step * d), float)
            vals[step] = max(np.abs(plus).max(), np.abs(minus).max())
            return (plus - minus) / (2 * step)

        d1, d2, d4 = central(h), central(h / 2), central(h / 4)
        r1, r2 = (4 * d2 - d1) / 3, (4 * d4 - d2) / 3
        noise = max(8 * np.finfo(float).eps * max(vals.values()), _rounding_noise(f, x, d, h))
        floor = noise / (h / 4)
        est.append(r2)
        err.append(np.abs(r1 - r2) + floor)
    return np.array(est), np.array(err)


def _rounding_noise(f, x, d, h):
    """The rounding noise of one evaluation of ``f`` near ``x``, measured (after Moré and Wild's ECnoise): the
    fourth differences of ``f`` at seven points 1e-6 h apart along ``d`` hold no smooth part (it scales as
    (1e-6 h)^4) but the rounding, whose variance they multiply by 70. A linear solve's rounding is cond * eps * |f|,
    and cancellation (a variance: the prior minus a quadratic form) makes it larger than eps * |f| again: a floor of
    eps * |f| alone failed on a CPU whose kernels round otherwise (a 5e-9 difference against a 3e-10 estimate)."""
    step = 1e-6 * h
    values = np.array([np.asarray(f(x + j * step * d), float) for j in range(-3, 4)])
    fourth = np.diff(values, n=4, axis=0)
    return float(np.sqrt(np.mean(fourth ** 2) / 70.0)) * 3.0          # 3 sigma


def assert_close_to_reference(actual, reference, error, margin=10.0, what="value"):
    """Assert ``|actual - reference| <= margin * error`` elementwise, naming the worst element."""
    actual, reference, error = (np.asarray(a, dtype=np.float64) for a in (actual, reference, error))
    bad = np.abs(actual - reference) > margin * error
    if bad.any():
        i = np.unravel_index(np.argmax(np.abs(actual - reference) / np.maximum(error, 1e-300)), actual.shape)
        raise AssertionError(f"{what}: {actual[i]!r} vs reference {reference[i]!r} (difference "
                             f"{abs(actual[i] - reference[i]):.3g}, reference error estimate {error[i]:.3g}, "
                             f"margin {margin}); {int(bad.sum())} of {bad.size} elements out of tolerance")

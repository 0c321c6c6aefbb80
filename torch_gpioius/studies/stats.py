"""Statistics of studies over seeds: medians with distribution-free intervals, paired differences, Wilcoxon tests.

A sliding exploration is chaotic: 1e-12 differences in a planned direction grow into centimetres over 150 contacts,
so one run says little about a method. Every figure is a median over seeds with an interval that makes no
assumption about the distribution:

* the interval of a median is the order-statistic (binomial) interval ``[x_(k), x_(n+1-k)]`` with the largest ``k``
  whose coverage ``1 - 2 P(Bin(n, 1/2) < k)`` is at least the level; for small ``n`` (below 6 at 95 %) no such
  interval exists and the full range is reported with its actual coverage;
* paired differences (visual-tactile minus tactile, the same seed) get the same interval and a two-sided Wilcoxon
  signed-rank p-value (``scipy.stats.wilcoxon``, exact for small samples).

**Failures count.** A run that ends with no estimate (no estimated surface inside the range: its Hausdorff
distance is NaN) is a result, and the worst one. With ``failed="worst"`` (the default for distances and variances,
where lower is better) a non-finite value ranks above every finite one: it enters the median and its interval as
``+inf``, and a paired comparison counts it as a loss for the side that failed (both failing: a tie). Dropping it
instead would make a mode's summary look *better* the more often it fails. ``failed="drop"`` is for values a mode
does not have (a tactile run has no task correlation); the count of non-finite values is reported either way.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["median_interval", "paired_difference", "describe", "FAILED_POLICIES"]

#: How non-finite values enter: as the worst outcome (+inf), or not at all (a value the mode does not have).
FAILED_POLICIES = ("worst", "drop")


def _check_policy(failed: str) -> None:
    if failed not in FAILED_POLICIES:
        raise ValueError(f"failed: must be one of {FAILED_POLICIES}, got {failed!r}")


def median_interval(values, level: float = 0.95, *, failed: str = "worst") -> dict:
    """Median of ``values`` and its distribution-free interval.

    Args:
        values: numbers, NaN (or inf) where a run has no value.
        level: the interval's coverage.
        failed: ``"worst"``: non-finite values count as ``+inf`` (worse than any finite value); ``"drop"``: they are
            left out (see the module docstring).

    Returns:
        ``{"median", "lo", "hi", "n", "failed", "coverage"}``: ``n`` the values that entered, ``failed`` the
        non-finite ones among ``values``; median and ends may be ``inf``; NaNs and ``n = 0`` when nothing entered.
    """
    _check_policy(failed)
    v = np.asarray(values, dtype=float).ravel()
    bad = ~np.isfinite(v)
    out = _order_interval(np.where(bad, math.inf, v) if failed == "worst" else v[~bad], level)
    out["failed"] = int(bad.sum())
    return out


def _order_interval(x, level: float) -> dict:
    """Median and order-statistic interval of ``x`` (no NaN; +-inf rank at the ends)."""
    x = np.sort(np.asarray(x, dtype=float))
    n = len(x)
    if n == 0:
        return {"median": math.nan, "lo": math.nan, "hi": math.nan, "n": 0, "coverage": math.nan}
    from scipy.stats import binom

    best_k, coverage = 1, 1 - 2 * binom.cdf(0, n, 0.5)
    for k in range(1, n // 2 + 1):
        cov = 1 - 2 * binom.cdf(k - 1, n, 0.5)
        if cov >= level:
            best_k, coverage = k, cov
        else:
            break
    # the middle pair of an even count may hold an infinity: +inf and a finite value give +inf; -inf and +inf
    # (as many wins as losses by failure) give 0 rather than NaN
    lo_mid, hi_mid = x[(n - 1) // 2], x[n // 2]
    median = 0.0 if math.isinf(lo_mid) and math.isinf(hi_mid) and lo_mid != hi_mid else float((lo_mid + hi_mid) / 2)
    return {"median": median, "lo": float(x[best_k - 1]), "hi": float(x[n - best_k]), "n": int(n),
            "coverage": float(coverage)}


def paired_difference(a, b, level: float = 0.95, *, failed: str = "worst") -> dict:
    """Per-pair differences ``a - b``: their median and interval, and the two-sided Wilcoxon signed-rank p-value
    (NaN for fewer than 2 non-zero pairs).

    With ``failed="worst"`` every pair enters: a non-finite ``a`` against a finite ``b`` is a loss for ``a``
    (difference ``+inf``), the reverse a win (``-inf``), both non-finite a tie (0); the Wilcoxon test ranks the
    infinite differences above every finite one. With ``failed="drop"`` only pairs where both are finite enter.

    Returns:
        ``{"median", "lo", "hi", "n", "failed", "coverage", "p_wilcoxon", "wins", "losses"}`` (``wins``: pairs with
        ``a < b``; ``losses``: ``a > b``; ``failed``: pairs where either side is non-finite).
    """
    _check_policy(failed)
    a, b = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired_difference: a and b must pair up, got {len(a)} and {len(b)} values")
    fa, fb = ~np.isfinite(a), ~np.isfinite(b)
    if failed == "worst":
        with np.errstate(invalid="ignore"):          # inf - inf where both failed: replaced by 0 below
            diff = a - b
        d = np.where(fa & fb, 0.0, np.where(fa, math.inf, np.where(fb, -math.inf, diff)))
    else:
        d = (a - b)[~(fa | fb)]
    out = _order_interval(d, level)
    out["failed"] = int((fa | fb).sum())
    p = math.nan
    if np.count_nonzero(d) >= 2:
        from scipy.stats import wilcoxon

        # a rank test: an infinite difference only needs to rank above every finite one
        big = 2.0 * float(np.abs(d[np.isfinite(d)]).max(initial=0.0)) + 1.0
        p = float(wilcoxon(np.clip(d, -big, big), alternative="two-sided", zero_method="wilcox").pvalue)
    out.update(p_wilcoxon=p, wins=int((d < 0).sum()), losses=int((d > 0).sum()))
    return out


def describe(values) -> str:
    """``"median [lo, hi]"`` of a :func:`median_interval` dict (``inf`` where failures reach the median or an end)."""
    return f"{values['median']:.3g} [{values['lo']:.3g}, {values['hi']:.3g}]"

"""Statistics of studies over seeds: medians with distribution-free intervals, paired differences, Wilcoxon tests.

A sliding exploration is chaotic: 1e-12 differences in a planned direction grow into centimetres over 150 contacts,
so one run says little about a method. Every figure is a median over seeds with an interval that makes no
assumption about the distribution:

* the interval of a median is the order-statistic (binomial) interval ``[x_(k), x_(n+1-k)]`` with the largest ``k``
  whose coverage ``1 - 2 P(Bin(n, 1/2) < k)`` is at least the level; for small ``n`` (below 6 at 95 %) no such
  interval exists and the full range is reported with its actual coverage;
* paired differences (visual-tactile minus tactile, the same seed) get the same interval and a two-sided Wilcoxon
  signed-rank p-value (``scipy.stats.wilcoxon``, exact for small samples).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["median_interval", "paired_difference", "describe"]


def median_interval(values, level: float = 0.95) -> dict:
    """Median of the finite ``values`` and its distribution-free interval.

    Returns:
        ``{"median", "lo", "hi", "n", "coverage"}`` (NaNs and ``n = 0`` for no finite value).
    """
    x = np.sort(np.asarray([v for v in np.asarray(values, dtype=float).ravel() if math.isfinite(v)]))
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
    return {"median": float(np.median(x)), "lo": float(x[best_k - 1]), "hi": float(x[n - best_k]), "n": int(n),
            "coverage": float(coverage)}


def paired_difference(a, b, level: float = 0.95) -> dict:
    """Per-pair differences ``a - b`` (pairs where both are finite): their median and interval, and the two-sided
    Wilcoxon signed-rank p-value (NaN for fewer than 2 non-zero pairs).

    Returns:
        ``{"median", "lo", "hi", "n", "coverage", "p_wilcoxon", "wins"}`` (``wins``: pairs with ``a < b``).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    d = a[ok] - b[ok]
    out = median_interval(d, level)
    p = math.nan
    if np.count_nonzero(d) >= 2:
        from scipy.stats import wilcoxon

        p = float(wilcoxon(d, alternative="two-sided", zero_method="wilcox").pvalue)
    out.update(p_wilcoxon=p, wins=int((d < 0).sum()))
    return out


def describe(values) -> str:
    """``"median [lo, hi]"`` of a :func:`median_interval` dict, in centimetres when given metres (keys ``*_m``)."""
    return f"{values['median']:.3g} [{values['lo']:.3g}, {values['hi']:.3g}]"

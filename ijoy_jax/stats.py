"""Confidence intervals without SciPy: the two-sided 95 % Student-t quantile and a sample's mean with its
interval, shared by the sweep tables, the cue's study and the benchmarks."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["mean_ci", "t_quantile"]

_NORMAL_975 = 1.959963984540054


# t_{0.975, df} for df = 1..30 (scipy.stats.t.ppf, 6 decimals); the expansion below is used beyond.
_T975 = (12.706205, 4.302653, 3.182446, 2.776445, 2.570582, 2.446912, 2.364624, 2.306004, 2.262157, 2.228139,
         2.200985, 2.178813, 2.160369, 2.144787, 2.131450, 2.119905, 2.109816, 2.100922, 2.093024, 2.085963,
         2.079614, 2.073873, 2.068658, 2.063899, 2.059539, 2.055529, 2.051831, 2.048407, 2.045230, 2.042272)


def t_quantile(df: int) -> float:
    """Two-sided 95% Student-t quantile ``t_{0.975, df}`` (df >= 1; NaN below).

    A table for df <= 30 (6 decimals), a 4-term Cornish-Fisher expansion in
    1/df beyond (error < 1e-7 there), so no SciPy is needed.

    Example:
      >>> round(t_quantile(9), 3)
      2.262
    """
    if df < 1:
        return math.nan
    if df <= len(_T975):
        return _T975[df - 1]
    z, v = _NORMAL_975, float(df)
    return (z + (z**3 + z) / (4 * v) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * v**2)
            + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * v**3)
            + (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / (92160 * v**4))


def mean_ci(x) -> tuple[float, float]:
    """(mean, half-width of its two-sided 95% Student-t interval) of a sample (NaN half-width below 2).

    The t quantile is :func:`t_quantile` (no SciPy needed).

    Example:
      >>> from ijoy_jax import stats
      >>> [round(v, 3) for v in stats.mean_ci([1.0, 2.0, 3.0, 4.0])]
      [2.5, 2.054]
    """
    x = np.asarray(x, np.float64)
    n = x.size
    if n < 2:
        return float(np.mean(x)) if n else math.nan, math.nan
    return float(np.mean(x)), float(t_quantile(n - 1) * np.std(x, ddof=1) / math.sqrt(n))

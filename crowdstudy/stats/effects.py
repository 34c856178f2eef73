"""Intervals and standardised effect sizes of within-subject contrasts.

- :func:`critical_value`: the multiplier of a contrast's SE for a confidence interval,
  as emmeans' ``confint`` computes it: Tukey ``qtukey(level, k, df) / sqrt(2)`` (R's
  secant algorithm, :func:`crowdstudy.stats._tukey.studentized_range_ppf`; the t
  quantile when k = 2), Bonferroni
  ``qt(1 - (1 - level) / (2 m), df)`` (also for Holm, whose step-down has no interval;
  emmeans does the same), or the plain ``qt(1 - (1 - level) / 2, df)``.
- :func:`dz_interval`: Cohen's ``d_z = mean(d) / sd(d)`` of paired differences ``d`` and
  its exact interval under normality: the noncentral-t parameters ``ncp`` for which the
  observed ``t = d_z sqrt(n)`` is the upper / lower ``(1 - level) / 2`` quantile,
  divided by ``sqrt(n)`` (Cumming & Finch 2001; what effectsize's ``cohens_d(paired =
  TRUE)`` reports, here solved to 1e-12 instead of its optimiser's ~1e-6).
- :func:`hedges_j`: the exact small-sample correction ``J(df) = Gamma(df/2) /
  (sqrt(df/2) Gamma((df-1)/2))``.

``g_av`` (Lakens 2013, eq. 10) standardises a mean difference by the average SD of the two
levels, ``d_av = mean(d) / ((sd_A + sd_B) / 2)``, and ``g_av = J(n - 1) d_av``. Its interval
here is the ``d_z`` interval rescaled by ``J sd(d) / sd_av``, i.e. it treats the ratio of the
two standardisers as known (an approximation; ``d_z``'s interval is exact).
All effect sizes are unitless; estimates and intervals of contrasts are in the dv's units.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize as _opt
from scipy import stats as _st
from scipy.special import gammaln, nctdtr

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._tukey import studentized_range_ppf

__all__ = ["critical_value", "dz_interval", "hedges_j", "ncp_interval"]


def critical_value(adjust: str, *, level: float, df: float, n_means: int, n_contrasts: int) -> float:
    """SE multiplier of a ``level`` confidence interval for one contrast of a family.

    ``adjust``: the family's p-value adjustment (``"tukey"``, ``"bonferroni"``, ``"holm"``
    -> Bonferroni, ``"none"``); ``n_means``: levels compared (Tukey); ``n_contrasts``: the
    family's size (Bonferroni); ``df``: error degrees of freedom.
    """
    if not 0 < level < 1:
        raise InvalidInputError(f"level must be in (0, 1), got {level!r}")
    alpha = 1.0 - level
    if adjust == "tukey" and n_means == 2:  # the range of two means: the t quantile (emmeans too)
        return float(_st.t.ppf(1.0 - alpha / 2.0, df))
    if adjust == "tukey":
        if df >= 2:
            return studentized_range_ppf(level, n_means, df) / np.sqrt(2.0)
        return float(_st.studentized_range.ppf(level, n_means, df)) / np.sqrt(2.0)
    if adjust in ("bonferroni", "holm"):
        return float(_st.t.ppf(1.0 - alpha / (2.0 * n_contrasts), df))
    if adjust == "none":
        return float(_st.t.ppf(1.0 - alpha / 2.0, df))
    raise InvalidInputError(f"adjust must be tukey, bonferroni, holm or none, got {adjust!r}")


def hedges_j(df: float) -> float:
    """Exact small-sample bias correction of a standardised mean difference (df > 1)."""
    if df <= 1:
        return float("nan")
    return float(np.exp(gammaln(df / 2.0) - 0.5 * np.log(df / 2.0) - gammaln((df - 1.0) / 2.0)))


def _ncp_for(t: float, df: float, prob: float) -> float:
    """The noncentrality with ``P(T_{df, ncp} <= t) = prob`` (decreasing in ncp)."""

    def f(ncp: float) -> float:
        v = float(nctdtr(df, ncp, t))
        if np.isnan(v):  # far tails: use P(T <= t) = 1 - P(T <= -t | -ncp)
            v = 1.0 - float(nctdtr(df, -ncp, -t))
        if np.isnan(v):
            v = 1.0 if ncp < t else 0.0
        return v - prob

    width = 10.0 + abs(t)
    lo, hi = t - width, t + width
    while f(lo) < 0:
        lo -= width
    while f(hi) > 0:
        hi += width
    # scipy's stub does not tie the result to full_output (here off: the root alone)
    return float(_opt.brentq(f, lo, hi, xtol=1e-13, rtol=4 * np.finfo(float).eps, maxiter=500))  # pyright: ignore[reportArgumentType]


def ncp_interval(t: float, df: float, level: float = 0.95) -> tuple[float, float]:
    """Interval of a noncentral-t parameter from an observed ``t`` with ``df`` df."""
    if not np.isfinite(t):
        return float("nan"), float("nan")
    alpha = 1.0 - level
    return _ncp_for(t, df, 1.0 - alpha / 2.0), _ncp_for(t, df, alpha / 2.0)


def dz_interval(diffs: np.ndarray, level: float = 0.95) -> tuple[float, float, float]:
    """``(d_z, low, high)`` of paired differences ``diffs`` (1-D, n >= 2; NaN if sd = 0)."""
    d = np.asarray(diffs, dtype=float)
    n = d.size
    if n < 2:
        raise InvalidInputError(f"d_z needs at least 2 differences, got {n}")
    sd = float(d.std(ddof=1))
    if not sd > 0:
        return float("nan"), float("nan"), float("nan")
    dz = float(d.mean()) / sd
    lo, hi = ncp_interval(dz * np.sqrt(n), n - 1.0, level)
    return dz, lo / np.sqrt(n), hi / np.sqrt(n)

"""Post hoc pairwise comparisons for fully within-subject designs, as emmeans computes them
for an afex model with its default multivariate model.

For a compared factor ``A`` (optionally within each combination of ``by`` factors), each
subject's marginal mean of every level of ``A`` is the mean of its cell means over the
factors that are neither ``A`` nor ``by`` (equal weights). A contrast ``a_i - a_j`` then
has ``estimate = mean_s(d_s)``, ``SE = sd_s(d_s) / sqrt(n)``, ``df = n - 1``,
``t = estimate / SE``, where ``d_s`` is subject ``s``'s difference: the SE of the contrast
applied to the per-subject means, exactly emmeans' ``model = "multivariate"``.

Adjustments work within each ``by`` group (the family), as emmeans does:
``"tukey"``: ``P(Q > |t| sqrt(2))`` for the studentized range of ``k`` means (``k`` =
levels of ``A``) with ``df`` degrees of freedom (computed with R's ptukey algorithm, so
it agrees with emmeans to ~1e-12);
``"bonferroni"``: ``min(1, m p)`` with ``m`` the family's number of contrasts;
``"holm"``: Holm's step-down; ``"none"``.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix, cell_matrix
from crowdstudy.stats._tukey import studentized_range_sf
from crowdstudy.stats.effects import critical_value, dz_interval, hedges_j

__all__ = ["pairwise", "pairwise_from_cells", "adjust_pvalues", "tukey_p", "POSTHOC_COLUMNS"]

#: Columns of :func:`pairwise`'s table (plus one column per ``by`` factor, after ``by_level``).
POSTHOC_COLUMNS = (
    "factor",
    "by",
    "by_level",
    "A",
    "B",
    "contrast",
    "estimate",
    "SE",
    "df",
    "t",
    "p_unc",
    "p_adj",
    "adjust",
    "n_means",
    "n_contrasts",
    "lower_CL",
    "upper_CL",
    "ci_adjust",
    "dz",
    "dz_low",
    "dz_high",
    "g_av",
    "g_av_low",
    "g_av_high",
)

_ADJUST = ("tukey", "bonferroni", "holm", "none")


def tukey_p(t, n_means: int, df: float) -> np.ndarray:
    """Tukey-adjusted p of t ratios: ``P(Q_{n_means, df} > |t| sqrt(2))`` (R's ptukey
    algorithm, :mod:`crowdstudy.stats._tukey`; scipy's integrator when df < 2)."""
    t = np.abs(np.asarray(t, dtype=float))
    if n_means < 2:
        raise InvalidInputError(f"n_means must be >= 2 for the studentized range, got {n_means}")
    if n_means == 2:  # the range of two means is |difference|: exactly the two-sided t test
        out = 2.0 * _st.t.sf(t, df)
    elif df >= 2:
        out = studentized_range_sf(np.nan_to_num(t.ravel()) * np.sqrt(2.0), n_means, df).reshape(t.shape)
    else:
        out = np.empty_like(t)
        for i, val in np.ndenumerate(t):
            out[i] = 1.0 if val == 0 else float(_st.studentized_range.sf(val * np.sqrt(2.0), n_means, df))
    return np.where(np.isnan(t), np.nan, np.clip(out, 0.0, 1.0))  # an undefined t stays undefined


def adjust_pvalues(p, method: str, *, t=None, n_means: int | None = None, df: float | None = None) -> np.ndarray:
    """Adjust one family of p-values (``tukey`` needs ``t``, ``n_means`` and ``df``)."""
    p = np.asarray(p, dtype=float)
    m = p.size
    if method == "none":
        return p.copy()
    if method == "bonferroni":
        return np.minimum(1.0, p * m)
    if method == "holm":
        order = np.argsort(p, kind="stable")
        stepped = np.maximum.accumulate((m - np.arange(m)) * p[order])
        out = np.empty(m)
        out[order] = np.minimum(1.0, stepped)
        return out
    if method == "tukey":
        if t is None or n_means is None or df is None:
            raise InvalidInputError("adjust='tukey' needs the t ratios, the number of means and df")
        return tukey_p(t, n_means, df)
    raise InvalidInputError(f"adjust must be one of {', '.join(_ADJUST)}, got {method!r}")


def _as_names(value, name: str) -> list[str]:
    if value is None:
        return []
    if isinstance(value, str):
        return [value]
    if not all(isinstance(v, str) for v in value):
        raise InvalidInputError(f"{name} must be a column name or a list of column names, got {value!r}")
    return list(value)


def pairwise_from_cells(
    cm: CellMatrix, factor: str, by=None, *, adjust: str = "tukey", level: float = 0.95
) -> pd.DataFrame:
    """:func:`pairwise` on an already validated cell matrix."""
    by = _as_names(by, "by")
    if adjust not in _ADJUST:
        raise InvalidInputError(f"adjust must be one of {', '.join(_ADJUST)}, got {adjust!r}")
    if factor not in cm.factors:
        raise InvalidInputError(f"factor {factor!r} is not a within factor; within: {', '.join(cm.factors)}")
    for b in by:
        if b not in cm.factors:
            raise InvalidInputError(f"by factor {b!r} is not a within factor; within: {', '.join(cm.factors)}")
        if b == factor:
            raise InvalidInputError(f"by factor {b!r} is the compared factor itself")
    n = cm.values.shape[0]
    grid = cm.values.reshape(n, *cm.shape)
    fi = cm.factors.index(factor)
    bi = [cm.factors.index(b) for b in by]
    other = [i for i in range(len(cm.factors)) if i != fi and i not in bi]
    marg = grid.mean(axis=tuple(1 + i for i in other)) if other else grid
    kept = [i for i in range(len(cm.factors)) if i not in other]  # axis order of marg (after subjects)
    marg = np.moveaxis(
        marg, [1 + kept.index(i) for i in bi] + [1 + kept.index(fi)], list(range(1, len(bi) + 2))
    )  # (n, *by, factor)
    levels = cm.levels[fi]
    k = len(levels)
    df = float(n - 1)
    rows = []
    by_levels = list(itertools.product(*[cm.levels[i] for i in bi])) if bi else [()]
    pairs = list(itertools.combinations(range(k), 2))
    for blv in by_levels:
        means = marg[(slice(None), *[cm.levels[i].index(v) for i, v in zip(bi, blv, strict=True)])]  # (n, k)
        d = np.stack([means[:, i] - means[:, j] for i, j in pairs], axis=1)
        est = d.mean(axis=0)
        se = d.std(axis=0, ddof=1) / np.sqrt(n)
        with np.errstate(divide="ignore", invalid="ignore"):
            # a zero difference with zero spread is 0/0: t and p undefined (NaN), as in R
            t = np.where(se > 0, est / se, np.where(est == 0, np.nan, np.sign(est) * np.inf))
        p_unc = 2.0 * _st.t.sf(np.abs(t), df)
        p_adj = adjust_pvalues(p_unc, adjust, t=t, n_means=k, df=df)
        ci_adjust = "bonferroni" if adjust == "holm" else adjust
        crit = critical_value(ci_adjust, level=level, df=df, n_means=k, n_contrasts=len(pairs))
        sds = means.std(axis=0, ddof=1)
        j_corr = hedges_j(df)
        for c, (i, j) in enumerate(pairs):
            dz, dz_lo, dz_hi = dz_interval(d[:, c], level)
            sd_av = 0.5 * (sds[i] + sds[j])
            scale = j_corr * float(d[:, c].std(ddof=1)) / sd_av if sd_av > 0 else float("nan")
            row = {
                "factor": factor,
                "by": ",".join(by),
                "by_level": ",".join(map(str, blv)),
                **{b: v for b, v in zip(by, blv, strict=True)},
                "A": levels[i],
                "B": levels[j],
                "contrast": f"{levels[i]} - {levels[j]}",
                "estimate": float(est[c]),
                "SE": float(se[c]),
                "df": df,
                "t": float(t[c]),
                "p_unc": float(p_unc[c]),
                "p_adj": float(p_adj[c]),
                "adjust": adjust,
                "n_means": k,
                "n_contrasts": len(pairs),
                "lower_CL": float(est[c] - crit * se[c]),
                "upper_CL": float(est[c] + crit * se[c]),
                "ci_adjust": ci_adjust,
                "dz": dz,
                "dz_low": dz_lo,
                "dz_high": dz_hi,
                "g_av": dz * scale,
                "g_av_low": dz_lo * scale,
                "g_av_high": dz_hi * scale,
            }
            rows.append(row)
    cols = list(POSTHOC_COLUMNS[:3]) + by + list(POSTHOC_COLUMNS[3:])
    out = pd.DataFrame(rows, columns=cols)
    out.attrs.update(n_subjects=n, dropped_subjects=list(cm.dropped), level=float(level))
    return out


def pairwise(
    data: pd.DataFrame,
    dv: str | None,
    within,
    subject: str | None,
    *,
    factor: str | None = None,
    by=None,
    adjust: str = "tukey",
    missing: str = "raise",
    duplicates: str = "warn",
    level: float = 0.95,
) -> pd.DataFrame:
    """Pairwise comparisons of the levels of ``factor`` (within each ``by`` combination).

    Parameters
    ----------
    data, dv, within, subject, missing, duplicates: as :func:`crowdstudy.stats.anova.rm_anova`
        (``within`` lists every within factor of the design, so marginal means average
        over the ones not compared, and missing cells are detected).
    factor: the compared factor; default: the single factor of ``within`` not in ``by``.
    by: factor name(s): compare within each combination of their levels (emmeans'
        ``~ factor | by``), each combination being one adjustment family.
    adjust: ``"tukey"`` (default), ``"bonferroni"``, ``"holm"`` or ``"none"``.

    Returns
    -------
    DataFrame, one row per contrast, families in the order of the ``by`` levels:
    ``factor``; ``by`` (by factors joined by ","); ``by_level`` (their levels joined by
    ","); one column per by factor; ``A``, ``B``, ``contrast`` ("A - B", level order);
    ``estimate`` (mean of A - B, dv units); ``SE``; ``df`` (n_subjects - 1); ``t``;
    ``p_unc`` (two-sided, unadjusted); ``p_adj``; ``adjust``; ``n_means`` (levels of the
    factor); ``n_contrasts`` (contrasts in the family); ``lower_CL``, ``upper_CL``: the
    ``level`` confidence interval of the estimate, adjusted for the family as emmeans'
    ``confint`` adjusts it (``ci_adjust``: Tukey where the p is Tukey's; Bonferroni for
    Holm, which has no interval); ``dz`` (mean / SD of the per-subject differences) with
    its exact noncentral-t interval ``dz_low``, ``dz_high`` (unadjusted ``level``);
    ``g_av`` (difference / mean of the two levels' SDs, times Hedges' J) with
    ``g_av_low``, ``g_av_high`` (see :mod:`crowdstudy.stats.effects`).
    """
    names = _as_names(within, "within")
    by_names = _as_names(by, "by")
    if factor is None:
        rest = [w for w in names if w not in by_names]
        if len(rest) != 1:
            raise InvalidInputError(f"factor is ambiguous: within factors not in by: {rest}; pass factor=...")
        factor = rest[0]
    cm = cell_matrix(data, dv, names if names else within, subject, missing=missing, duplicates=duplicates)
    return pairwise_from_cells(cm, factor, by_names, adjust=adjust, level=level)

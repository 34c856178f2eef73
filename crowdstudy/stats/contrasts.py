"""Simple-effects tests and polynomial trend contrasts of a fully within-subject design, as
emmeans computes them on an afex model with its multivariate model (``model =
"multivariate"``).

The multivariate model's estimates are the cell means ``m`` (``c`` cells) with covariance
``S / n`` (``S`` the subjects' sample covariance of their cell values) and ``n - 1`` error
df. A set of ``r`` contrasts ``L`` (r x c) is tested with the Wald F of emmeans' ``test(...,
joint = TRUE)``: ``F = (L m)' (L S L' / n)^-1 (L m) / r`` on ``(r, n - 1)`` df, which is what
``joint_tests`` reports for each model term within each ``by`` cell. This is not the
univariate ANOVA's F (that pools the error over the effect's df); for a 1-df effect the two
coincide (``F = t^2`` of the paired comparison).

``polynomial_contrasts`` applies emmeans' ``"poly"`` contrasts (orthogonal polynomials over
equally spaced levels, scaled to integers: -2 -1 0 1 2 / 2 -1 -2 -1 2 / ... for five levels)
to the marginal means of a factor: estimate, SE = sd(per-subject contrast) / sqrt(n),
t on n - 1 df, unadjusted p (emmeans' default for "poly"), and a ``level`` interval.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix
from crowdstudy.stats.anova import effect_contrasts, effect_terms

__all__ = ["simple_effects", "polynomial_contrasts", "poly_coefficients", "wald_f", "SIMPLE_COLUMNS", "TREND_COLUMNS"]

#: Columns of :func:`simple_effects` (plus one column per ``by`` factor, after ``by_level``).
SIMPLE_COLUMNS = ("term", "by", "by_level", "df1", "df2", "F", "p")
#: Columns of :func:`polynomial_contrasts` (plus one column per ``by`` factor).
TREND_COLUMNS = (
    "factor",
    "by",
    "by_level",
    "contrast",
    "degree",
    "coefficients",
    "estimate",
    "SE",
    "df",
    "t",
    "p",
    "lower_CL",
    "upper_CL",
)

_DEGREE_NAMES = ("linear", "quadratic", "cubic", "quartic", "degree 5", "degree 6")


def _names(value, what: str, cm: CellMatrix) -> list[str]:
    out = [] if value is None else [value] if isinstance(value, str) else list(value)
    for name in out:
        if name not in cm.factors:
            raise InvalidInputError(f"{what} factor {name!r} is not a within factor; within: {', '.join(cm.factors)}")
    if len(set(out)) != len(out):
        raise InvalidInputError(f"{what} lists a factor twice: {out}")
    return out


def wald_f(z: np.ndarray) -> tuple[float, float, float, float]:
    """Joint Wald test that the mean of the per-subject contrast scores ``z`` (n x r) is 0
    with the multivariate model's covariance: ``(F, df1, df2, p)``; NaN where the scores'
    covariance is singular and the mean 0 (no variation), F inf where only the covariance is."""
    n, r = z.shape
    zbar = z.mean(axis=0)
    cov = np.cov(z, rowvar=False, ddof=1).reshape(r, r) / n
    # emmeans tests the estimable part: the rank of the covariance decides df1
    vals, vecs = np.linalg.eigh(cov)
    tol = 1e-10 * max(float(vals.max(initial=0.0)), float((z * z).mean()) / n)
    keep = vals > tol
    rank = int(keep.sum())
    if rank == 0:
        return (float("nan") if np.allclose(zbar, 0.0) else float("inf")), float(r), float(n - 1), float("nan")
    proj = vecs[:, keep].T @ zbar
    f = float(proj @ (proj / vals[keep])) / rank
    df2 = float(n - 1)
    return f, float(rank), df2, float(_st.f.sf(f, rank, df2))


def simple_effects(cm: CellMatrix, by) -> pd.DataFrame:
    """emmeans' ``joint_tests(fit, by = by)``: every effect of the factors not in ``by``
    (main effects, then interactions, R's order), tested within each combination of the
    ``by`` levels with the Wald F of the multivariate model (see the module docstring).

    Returns one row per (by combination, term): ``term`` (factors joined by ":"), ``by``,
    ``by_level`` (levels joined by ","), one column per by factor, ``df1``, ``df2`` (n - 1),
    ``F``, ``p`` (unadjusted, as joint_tests prints it).
    """
    by = _names(by, "by", cm)
    if not by:
        raise InvalidInputError("simple_effects needs at least one by factor (else it is the omnibus test)")
    rest = [f for f in cm.factors if f not in by]
    if not rest:
        raise InvalidInputError(f"by {by} leaves no factor to test")
    n = cm.values.shape[0]
    grid = cm.values.reshape(n, *cm.shape)
    bi = [cm.factors.index(b) for b in by]
    ri = [cm.factors.index(f) for f in rest]
    grid = np.moveaxis(grid, [1 + i for i in bi], list(range(1, len(bi) + 1)))  # (n, *by, *rest)
    rest_shape = tuple(cm.shape[i] for i in ri)
    rows = []
    for combo in itertools.product(*[range(cm.shape[i]) for i in bi]):
        block = grid[(slice(None), *combo)].reshape(n, -1)  # (n, cells of rest)
        labels = [cm.levels[i][j] for i, j in zip(bi, combo, strict=True)]
        for term in effect_terms(len(rest)):
            z = block @ effect_contrasts(rest_shape, term).T
            f, df1, df2, p = wald_f(z)
            rows.append(
                {
                    "term": ":".join(rest[t] for t in term),
                    "by": ",".join(by),
                    "by_level": ",".join(map(str, labels)),
                    **dict(zip(by, labels, strict=True)),
                    "df1": df1,
                    "df2": df2,
                    "F": f,
                    "p": p,
                }
            )
    cols = list(SIMPLE_COLUMNS[:3]) + by + list(SIMPLE_COLUMNS[3:])
    out = pd.DataFrame(rows, columns=cols)
    out.attrs.update(n_subjects=n, model="multivariate")
    return out


def poly_coefficients(k: int) -> np.ndarray:
    """Integer orthogonal-polynomial contrasts of ``k`` equally spaced levels, (k - 1, k),
    scaled as emmeans' ``poly.emmc`` scales them (degrees above 6 are not returned)."""
    if k < 2:
        raise InvalidInputError(f"polynomial contrasts need >= 2 levels, got {k}")
    x = np.arange(1, k + 1, dtype=float)
    q, _ = np.linalg.qr(np.vander(x - x.mean(), min(k, 7), increasing=True))
    out = []
    for j in range(1, q.shape[1]):
        con = q[:, j] * np.sign(q[-1, j])  # the last level positive, as R's poly()
        con = con / con[con > 0.01].min()
        z = np.abs(con - np.round(con)).max()
        while z > 0.05:
            con = con / z
            z = np.abs(con - np.round(con)).max()
        out.append(np.round(con))
    return np.array(out)


def polynomial_contrasts(cm: CellMatrix, factor: str, by=None, *, level: float = 0.95) -> pd.DataFrame:
    """emmeans' ``contrast(emmeans(fit, ~ factor | by), "poly")`` with confidence intervals.

    The levels of ``factor`` are taken as equally spaced in their order (the design's
    densities, 2.22 ... 6.66 characters/m^2, are). Marginal means average over the
    factors not in ``factor`` / ``by`` with equal weights. Returns one row per (by
    combination, degree): ``factor``, ``by``, ``by_level``, one column per by factor,
    ``contrast`` ("linear" ...), ``degree``, ``coefficients`` (space-separated),
    ``estimate`` (sum of coefficient x mean, dv units), ``SE``, ``df`` (n - 1), ``t``, ``p``
    (two-sided, unadjusted), ``lower_CL``, ``upper_CL`` (unadjusted ``level`` interval).
    """
    if not isinstance(factor, str):
        raise InvalidInputError(f"factor must be one factor name, got {factor!r}")
    _names(factor, "trend", cm)
    by = _names(by, "by", cm)
    if factor in by:
        raise InvalidInputError(f"by factor {factor!r} is the trend factor itself")
    n = cm.values.shape[0]
    grid = cm.values.reshape(n, *cm.shape)
    fi = cm.factors.index(factor)
    bi = [cm.factors.index(b) for b in by]
    other = tuple(1 + i for i in range(len(cm.factors)) if i != fi and i not in bi)
    marg = grid.mean(axis=other) if other else grid
    kept = [i for i in range(len(cm.factors)) if 1 + i not in other]
    marg = np.moveaxis(marg, [1 + kept.index(i) for i in bi] + [1 + kept.index(fi)], list(range(1, len(bi) + 2)))
    coef = poly_coefficients(cm.shape[fi])
    df = float(n - 1)
    crit = float(_st.t.ppf(0.5 + level / 2.0, df))
    rows = []
    for combo in itertools.product(*[range(cm.shape[i]) for i in bi]):
        means = marg[(slice(None), *combo)]  # (n, k)
        labels = [cm.levels[i][j] for i, j in zip(bi, combo, strict=True)]
        scores = means @ coef.T  # (n, degrees)
        est = scores.mean(axis=0)
        se = scores.std(axis=0, ddof=1) / np.sqrt(n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(se > 0, est / se, np.where(est == 0, np.nan, np.sign(est) * np.inf))
        p = 2.0 * _st.t.sf(np.abs(t), df)
        for d in range(coef.shape[0]):
            rows.append(
                {
                    "factor": factor,
                    "by": ",".join(by),
                    "by_level": ",".join(map(str, labels)),
                    **dict(zip(by, labels, strict=True)),
                    "contrast": _DEGREE_NAMES[d],
                    "degree": d + 1,
                    "coefficients": " ".join(str(int(c)) for c in coef[d]),
                    "estimate": float(est[d]),
                    "SE": float(se[d]),
                    "df": df,
                    "t": float(t[d]),
                    "p": float(p[d]),
                    "lower_CL": float(est[d] - crit * se[d]),
                    "upper_CL": float(est[d] + crit * se[d]),
                }
            )
    cols = list(TREND_COLUMNS[:3]) + by + list(TREND_COLUMNS[3:])
    out = pd.DataFrame(rows, columns=cols)
    out.attrs.update(n_subjects=n, level=float(level))
    return out

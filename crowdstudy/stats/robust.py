"""Robustness analyses of the Method effect, reported beside the repeated-measures ANOVA.

- :func:`mixed_model`: a linear mixed model that keeps incomplete participants (no listwise
  deletion): ``score ~ Density * Viewpoint * Method`` (sum-to-zero coding, as
  ``options(contrasts = c("contr.sum", "contr.poly"))`` in R) with a random intercept and a
  random Method slope per participant (``(1 + Method | participant)`` in lme4), fitted by
  REML: lme4's profiled criterion over the relative covariance factor (3 parameters),
  minimised with Powell's method (~0.1 s; statsmodels' MixedLM gives the same fit, slower,
  and is the tests' second reference). Fixed-effect
  standard errors are lme4's: ``s sqrt(diag((X' V^-1 X)^-1))``. Tests of single
  coefficients are Wald z tests (lmerTest's Satterthwaite t tests are in the R reference
  for comparison; with a dozen participants they give somewhat larger p).
- :func:`signed_rank_test`, :func:`sign_test`, :func:`ordinal_method_check`: checks that do
  not treat the Likert points as an interval scale: per participant the sign (and the rank
  of the size) of the Ours - Baseline difference, within every Density x Viewpoint cell and
  over all cells, with R's ``wilcox.test`` (exact when n < 50 without ties or zeros, else
  the normal approximation with continuity and tie correction; zeros dropped) and
  ``binom.test``.
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix

__all__ = ["mixed_model", "MixedModelResult", "signed_rank_test", "sign_test", "ordinal_method_check"]


@dataclasses.dataclass
class MixedModelResult:
    """``fixed``: one row per coefficient (``term`` as R names it under contr.sum:
    "(Intercept)", "Density1", "Density1:Method1" ...; ``estimate``, ``SE``, ``z``, ``p``);
    ``variances``: {"participant (Intercept)", "participant Method1", "covariance",
    "residual"} (dv units squared); ``loglik``: REML log-likelihood; ``n_obs``,
    ``n_participants``, ``n_incomplete`` (participants without every cell, kept);
    ``method``: the Method contrast (``contrast`` "A - B", ``estimate`` = 2 x the Method1
    coefficient for two methods, ``SE``, ``z``, ``p``, ``lower_CL``, ``upper_CL``: Wald 95 %)."""

    fixed: pd.DataFrame
    variances: dict
    loglik: float
    n_obs: int
    n_participants: int
    n_incomplete: int
    method: dict
    converged: bool


def _sum_coding(values: pd.Series, levels: list) -> np.ndarray:
    """(n, k - 1) contr.sum columns: level j < k-1 -> e_j, the last level -> -1."""
    k = len(levels)
    out = np.zeros((len(values), k - 1))
    idx = pd.Categorical(values, categories=levels).codes
    if (idx < 0).any():
        raise InvalidInputError(f"value {values.iloc[int(np.flatnonzero(idx < 0)[0])]!r} is not a level {levels}")
    for j in range(k - 1):
        out[idx == j, j] = 1.0
    out[idx == k - 1, :] = -1.0
    return out


def _design_matrix(long: pd.DataFrame, factors: list[str], levels: dict) -> tuple[np.ndarray, list[str]]:
    coded = {f: _sum_coding(long[f], levels[f]) for f in factors}
    cols, names = [np.ones(len(long))], ["(Intercept)"]
    for order in range(1, len(factors) + 1):
        for term in itertools.combinations(factors, order):
            for combo in itertools.product(*[range(len(levels[f]) - 1) for f in term]):
                col = np.ones(len(long))
                for f, j in zip(term, combo, strict=True):
                    col = col * coded[f][:, j]
                cols.append(col)
                names.append(":".join(f"{f}{j + 1}" for f, j in zip(term, combo, strict=True)))
    return np.column_stack(cols), names


class _Reml:
    """Profiled REML criterion of ``y = X b + Z u_g + e`` with ``u_g ~ N(0, s^2 L L')`` per
    group and ``e ~ N(0, s^2 I)`` (lme4's parametrisation, ``theta`` = the lower triangle of
    ``L``), from per-group cross products (Woodbury identities; q = 2 random effects)."""

    def __init__(self, y: np.ndarray, x: np.ndarray, z: np.ndarray, groups: np.ndarray):
        self.n, self.p = x.shape
        codes, self.uniq = pd.factorize(groups)
        g = len(self.uniq)
        q = z.shape[1]
        self.ztz = np.zeros((g, q, q))
        self.ztx = np.zeros((g, q, self.p))
        self.zty = np.zeros((g, q))
        np.add.at(self.ztz, codes, z[:, :, None] * z[:, None, :])
        np.add.at(self.ztx, codes, z[:, :, None] * x[:, None, :])
        np.add.at(self.zty, codes, z * y[:, None])
        self.xtx, self.xty, self.yty = x.T @ x, x.T @ y, float(y @ y)

    @staticmethod
    def lower(theta) -> np.ndarray:
        return np.array([[theta[0], 0.0], [theta[1], theta[2]]])

    def solve(self, theta):
        """(criterion, b, s^2, (X' V^-1 X)^-1) at ``theta`` (V relative to s^2)."""
        lam = self.lower(theta)
        m = np.eye(2)[None] + lam.T @ self.ztz @ lam  # I + L'Z'ZL
        minv = np.linalg.inv(m)
        a = lam.T @ self.ztx  # L'Z'X per group
        c = self.zty @ lam  # L'Z'y per group
        ma = minv @ a  # (g, 2, p)
        mc = np.einsum("gij,gj->gi", minv, c)
        xvx = self.xtx - np.tensordot(a, ma, axes=([0, 1], [0, 1]))
        xvy = self.xty - np.einsum("gip,gi->p", a, mc)
        yvy = self.yty - float(np.einsum("gi,gi->", c, mc))
        sign, logdet_x = np.linalg.slogdet(xvx)
        logdet_v = float(np.linalg.slogdet(m)[1].sum())
        b = np.linalg.solve(xvx, xvy)
        df = self.n - self.p
        s2 = (yvy - float(b @ xvy)) / df
        crit = logdet_v + logdet_x + df * (1.0 + np.log(2.0 * np.pi * s2))
        return float(crit), b, float(s2), np.linalg.inv(xvx)

    def fit(self):
        """Minimise the criterion with Powell's method (bounded: the diagonal of L >= 0)
        from L = I, tolerances 1e-10 in theta and 1e-14 relative in the criterion."""
        from scipy import optimize

        return optimize.minimize(
            lambda t: self.solve(t)[0],
            [1.0, 0.0, 1.0],
            method="Powell",
            options={"xtol": 1e-10, "ftol": 1e-14, "maxiter": 20000},
            bounds=[(0.0, None), (None, None), (0.0, None)],
        )


def mixed_model(
    long: pd.DataFrame, dv: str, factors, subject: str, *, levels: dict | None = None, level: float = 0.95
) -> MixedModelResult:
    """Fit the mixed model described in the module docstring to long data (one row per
    observation; incomplete participants allowed). ``levels``: factor -> level order
    (default: categorical order, else sorted)."""
    factors = list(factors)
    if "Method" not in factors:
        raise InvalidInputError(f"the mixed model needs a Method factor; factors: {factors}")
    for col in [dv, subject, *factors]:
        if col not in long.columns:
            raise InvalidInputError(f"column {col!r} is not in the data; columns: {', '.join(map(str, long.columns))}")
    data = long.dropna(subset=[dv]).reset_index(drop=True)
    lv = {}
    for f in factors:
        if levels and f in levels:
            lv[f] = list(levels[f])
        elif isinstance(data[f].dtype, pd.CategoricalDtype):
            lv[f] = [c for c in data[f].cat.categories if c in set(data[f])]
        else:
            lv[f] = sorted(data[f].unique())
    x, names = _design_matrix(data, factors, lv)
    z = np.column_stack([np.ones(len(data)), _sum_coding(data["Method"], lv["Method"])[:, 0]])
    y = data[dv].to_numpy(float)
    reml = _Reml(y, x, z, data[subject].astype(str).to_numpy())
    if np.linalg.matrix_rank(x) < x.shape[1] or len(data) <= x.shape[1]:
        raise InvalidInputError(
            f"the mixed model's {x.shape[1]} fixed effects are not estimable from "
            f"{len(data)} scores (some cell has no data)"
        )
    resid = y - x @ np.linalg.lstsq(x, y, rcond=None)[0]
    if float(resid @ resid) <= 1e-12 * max(float(y @ y), 1e-300):
        raise InvalidInputError("the mixed model is undefined: the scores do not vary beyond the fixed effects")
    opt = reml.fit()
    crit, beta, scale, xvx_inv = reml.solve(opt.x)
    lam = reml.lower(opt.x)
    g = scale * lam @ lam.T
    se = np.sqrt(scale * np.diag(xvx_inv))
    with np.errstate(divide="ignore", invalid="ignore"):
        zval = beta / se
    p = 2.0 * _st.norm.sf(np.abs(zval))
    fixed = pd.DataFrame({"term": names, "estimate": beta, "SE": se, "z": zval, "p": p})
    n_cells = int(np.prod([len(lv[f]) for f in factors]))
    per = data.groupby(subject)[factors].apply(lambda d: len(d.drop_duplicates()))
    mi = names.index("Method1")
    crit_z = float(_st.norm.ppf(0.5 + level / 2.0))
    scale2 = 2.0 if len(lv["Method"]) == 2 else float("nan")  # Method1 = half the A - B difference
    est, s = scale2 * beta[mi], scale2 * se[mi]
    method = {
        "contrast": f"{lv['Method'][0]} - {lv['Method'][-1]}",
        "estimate": float(est),
        "SE": float(s),
        "z": float(zval[mi]),
        "p": float(p[mi]),
        "lower_CL": float(est - crit_z * s),
        "upper_CL": float(est + crit_z * s),
    }
    variances = {
        "participant (Intercept)": float(g[0, 0]),
        "participant Method1": float(g[1, 1]),
        "covariance": float(g[0, 1]),
        "residual": scale,
    }
    return MixedModelResult(
        fixed=fixed,
        variances=variances,
        loglik=-0.5 * crit,
        n_obs=int(len(data)),
        n_participants=int(len(per)),
        n_incomplete=int((per < n_cells).sum()),
        method=method,
        converged=bool(opt.success),
    )


def _signrank_cdf(n: int) -> np.ndarray:
    """Exact null distribution counts of the signed-rank statistic V for n untied ranks."""
    counts = np.zeros(n * (n + 1) // 2 + 1)
    counts[0] = 1.0
    for k in range(1, n + 1):
        counts[k:] = counts[k:] + counts[:-k].copy()
    return np.cumsum(counts) / 2.0**n


def signed_rank_test(d) -> dict:
    """Two-sided Wilcoxon signed-rank test of paired differences ``d``, as R's
    ``wilcox.test(d)``: ``{"n", "V", "p", "method"}`` (method "exact" or "normal"; p NaN
    when every difference is 0)."""
    d = np.asarray(d, dtype=float)
    d = d[d != 0.0]
    n = d.size
    if n == 0:
        return {"n": 0, "V": float("nan"), "p": float("nan"), "method": "none"}
    ranks = _st.rankdata(np.abs(d))
    v = float(ranks[d > 0].sum())
    _, ties = np.unique(ranks, return_counts=True)
    if n < 50 and (ties == 1).all():
        cdf = _signrank_cdf(n)
        lower = cdf[int(round(v))]
        upper = 1.0 - (cdf[int(round(v)) - 1] if v >= 1 else 0.0)
        return {"n": n, "V": v, "p": float(min(1.0, 2.0 * min(lower, upper))), "method": "exact"}
    z = v - n * (n + 1) / 4.0
    sigma = np.sqrt(n * (n + 1) * (2 * n + 1) / 24.0 - float((ties**3 - ties).sum()) / 48.0)
    z = (z - np.sign(z) * 0.5) / sigma
    return {"n": n, "V": v, "p": float(2.0 * min(_st.norm.cdf(z), _st.norm.sf(z))), "method": "normal"}


def sign_test(d) -> dict:
    """Two-sided sign test (R's ``binom.test(n_pos, n_pos + n_neg)``; zeros dropped)."""
    d = np.asarray(d, dtype=float)
    pos, neg = int((d > 0).sum()), int((d < 0).sum())
    if pos + neg == 0:
        return {"n_pos": 0, "n_neg": 0, "p": float("nan")}
    return {"n_pos": pos, "n_neg": neg, "p": float(_st.binomtest(pos, pos + neg, 0.5).pvalue)}


def ordinal_method_check(cm: CellMatrix, *, alpha: float = 0.05) -> pd.DataFrame:
    """Per-participant Method differences (first level minus last, e.g. Baseline - Ours)
    tested without interval assumptions: one row per cell of the other factors and a last
    row ``cell = "all"`` on each participant's mean difference over the cells.

    Columns: the other factors, ``cell``, ``n``, ``n_pos``, ``n_neg``, ``n_zero``,
    ``median_diff`` (points), ``V``, ``p_wilcoxon``, ``wilcoxon_method``, ``p_sign``,
    ``p_t`` (the paired t test on the same differences, for comparison), ``agree``
    (whether the Wilcoxon and t tests agree on p < alpha).
    """
    if "Method" not in cm.factors:
        raise InvalidInputError(f"ordinal_method_check needs a Method factor; factors: {cm.factors}")
    n = cm.values.shape[0]
    mi = cm.factors.index("Method")
    grid = np.moveaxis(cm.values.reshape(n, *cm.shape), 1 + mi, -1)
    diff = grid[..., 0] - grid[..., -1]  # (n, *others)
    others = [f for f in cm.factors if f != "Method"]
    other_levels = [cm.levels[cm.factors.index(f)] for f in others]
    flat = diff.reshape(n, -1)
    rows = []
    labels = list(itertools.product(*other_levels)) if others else [()]
    for j, lab in enumerate(labels + [None]):
        d = flat[:, j] if lab is not None else flat.mean(axis=1)
        w, s = signed_rank_test(d), sign_test(d)
        sd = d.std(ddof=1)
        p_t = float(2.0 * _st.t.sf(abs(d.mean()) / (sd / np.sqrt(n)), n - 1)) if sd > 0 else float("nan")
        row: dict[str, Any] = dict(zip(others, lab, strict=True)) if lab is not None else {f: "" for f in others}
        row.update(
            cell=" ".join(map(str, lab)) if lab is not None else "all",
            n=n,
            n_pos=s["n_pos"],
            n_neg=s["n_neg"],
            n_zero=int((d == 0).sum()),
            median_diff=float(np.median(d)),
            V=w["V"],
            p_wilcoxon=w["p"],
            wilcoxon_method=w["method"],
            p_sign=s["p"],
            p_t=p_t,
            agree=bool((w["p"] < alpha) == (p_t < alpha)),
        )
        rows.append(row)
    out = pd.DataFrame(rows)
    out.attrs["contrast"] = f"{cm.levels[mi][0]} - {cm.levels[mi][-1]}"
    return out

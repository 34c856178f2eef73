"""Robustness analyses of the Method effect, reported beside the repeated-measures ANOVA.

- :func:`mixed_model`: a linear mixed model that keeps incomplete participants (no listwise
  deletion): ``score ~ Density * Viewpoint * Method`` (sum-to-zero coding, as
  ``options(contrasts = c("contr.sum", "contr.poly"))`` in R) with a random intercept and
  k - 1 random method slopes per participant (``(1 + Method | participant)`` in lme4, an
  unstructured k x k covariance), fitted by REML: lme4's profiled criterion over the
  relative covariance factor (k (k + 1) / 2 parameters), minimised with Powell's method
  (~0.1 s for two methods; statsmodels' MixedLM gives the same fit, slower, and is the
  tests' second reference). The method factor may have any name and k >= 2 levels, the
  first the reference; the k - 1 contrasts ``reference - level`` are reported with Wald
  intervals (equal to the coefficients of treatment coding against the reference, negated:
  the same model, reparametrised). Fixed-effect
  standard errors are lme4's: ``s sqrt(diag((X' V^-1 X)^-1))``. Tests of single
  coefficients are Wald z tests (lmerTest's Satterthwaite t tests are in the R reference
  for comparison; with a dozen participants they give somewhat larger p).
- :func:`signed_rank_test`, :func:`sign_test`, :func:`ordinal_method_check`: checks that do
  not treat the Likert points as an interval scale: per participant the sign (and the rank
  of the size) of the Ours - Baseline difference, within every Density x Viewpoint cell and
  over all cells, with R's ``wilcox.test`` (exact when n < 50 without ties or zeros, else
  the normal approximation with continuity and tie correction; zeros dropped) and
  ``binom.test``; with k > 2 methods each method against the reference, Holm-adjusted per
  cell, and :func:`friedman_test` over the k methods per cell.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix
from crowdstudy.stats.scoring import FACTOR_NAMES

__all__ = [
    "mixed_model",
    "MixedModelResult",
    "MIXED_CONTRAST_COLUMNS",
    "friedman_test",
    "FRIEDMAN_COLUMNS",
    "holm",
    "signed_rank_test",
    "sign_test",
    "ordinal_method_check",
]


@dataclasses.dataclass
class MixedModelResult:
    """``fixed``: one row per coefficient (``term`` as R names it under contr.sum:
    "(Intercept)", "Density1", "Density1:Method1" ...; ``estimate``, ``SE``, ``z``, ``p``);
    ``variances``: {"participant (Intercept)", "participant Method1", "covariance",
    "residual"} (dv units squared); ``loglik``: REML log-likelihood; ``n_obs``,
    ``n_participants``, ``n_incomplete`` (participants without every cell, kept);
    ``method``: the first contrast to the reference (``contrast`` "A - B", ``estimate`` = 2
    x the Method1 coefficient for two methods, ``SE``, ``z``, ``p``, ``lower_CL``,
    ``upper_CL``: Wald 95 %); ``contrasts``: every ``reference - level`` contrast (k - 1
    rows, columns :data:`MIXED_CONTRAST_COLUMNS`); ``factor``: the method factor's name.
    For k methods the variances hold one slope per sum-coded method column and
    ``covariance A:B`` per pair (see :func:`_variances`)."""

    fixed: pd.DataFrame
    variances: dict
    loglik: float
    n_obs: int
    n_participants: int
    n_incomplete: int
    method: dict
    converged: bool
    contrasts: pd.DataFrame | None = None
    factor: str = FACTOR_NAMES.method


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
    ``L`` column by column, as lme4 orders it), from per-group cross products (Woodbury
    identities; q random effects per group, q = the number of methods)."""

    def __init__(self, y: np.ndarray, x: np.ndarray, z: np.ndarray, groups: np.ndarray):
        self.n, self.p = x.shape
        codes, self.uniq = pd.factorize(groups)
        g = len(self.uniq)
        self.q = q = z.shape[1]
        self.ztz = np.zeros((g, q, q))
        self.ztx = np.zeros((g, q, self.p))
        self.zty = np.zeros((g, q))
        np.add.at(self.ztz, codes, z[:, :, None] * z[:, None, :])
        np.add.at(self.ztx, codes, z[:, :, None] * x[:, None, :])
        np.add.at(self.zty, codes, z * y[:, None])
        self.xtx, self.xty, self.yty = x.T @ x, x.T @ y, float(y @ y)
        rows, cols = np.tril_indices(q)
        order = np.lexsort((rows, cols))  # column-major, as lme4's theta
        self._rows, self._cols = rows[order], cols[order]

    def lower(self, theta) -> np.ndarray:
        lam = np.zeros((self.q, self.q))
        lam[self._rows, self._cols] = theta
        return lam

    def start(self) -> list[float]:
        """L = I (lme4's start)."""
        return [1.0 if r == c else 0.0 for r, c in zip(self._rows, self._cols, strict=True)]

    def bounds(self) -> list[tuple[float | None, float | None]]:
        """The diagonal of L >= 0."""
        return [(0.0, None) if r == c else (None, None) for r, c in zip(self._rows, self._cols, strict=True)]

    def solve(self, theta):
        """(criterion, b, s^2, (X' V^-1 X)^-1) at ``theta`` (V relative to s^2)."""
        lam = self.lower(theta)
        m = np.eye(self.q)[None] + lam.T @ self.ztz @ lam  # I + L'Z'ZL
        minv = np.linalg.inv(m)
        a = lam.T @ self.ztx  # L'Z'X per group
        c = self.zty @ lam  # L'Z'y per group
        ma = minv @ a  # (g, q, p)
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
        from L = I, tolerances 1e-10 in theta and 1e-14 relative in the criterion (a
        second pass from the first optimum polishes the larger, q > 2, problems)."""
        from scipy import optimize

        opts = {"xtol": 1e-10, "ftol": 1e-14, "maxiter": 50000}

        def run(x0):
            return optimize.minimize(
                lambda t: self.solve(t)[0], x0, method="Powell", options=opts, bounds=self.bounds()
            )

        opt = run(self.start())
        for _ in range(0 if self.q <= 2 else 2):
            opt = run(list(opt.x))
        return opt


def _levels_of(data: pd.DataFrame, factors: list[str], levels: dict | None) -> dict:
    lv = {}
    for f in factors:
        if levels and f in levels:
            lv[f] = list(levels[f])
        elif isinstance(data[f].dtype, pd.CategoricalDtype):
            lv[f] = [c for c in data[f].cat.categories if c in set(data[f])]
        else:
            lv[f] = sorted(data[f].unique())
    return lv


def mixed_model(
    long: pd.DataFrame,
    dv: str,
    factors,
    subject: str,
    *,
    levels: dict | None = None,
    level: float = 0.95,
    method: str = FACTOR_NAMES.method,
) -> MixedModelResult:
    """Fit the mixed model described in the module docstring to long data (one row per
    observation; incomplete participants allowed). ``levels``: factor -> level order
    (default: categorical order, else sorted); ``method``: the name of the method factor
    (one of ``factors``; its first level is the reference)."""
    factors = list(factors)
    if method not in factors:
        raise InvalidInputError(f"the mixed model needs the method factor {method!r}; factors: {factors}")
    for col in [dv, subject, *factors]:
        if col not in long.columns:
            raise InvalidInputError(f"column {col!r} is not in the data; columns: {', '.join(map(str, long.columns))}")
    data = long.dropna(subset=[dv]).reset_index(drop=True)
    lv = _levels_of(data, factors, levels)
    x, names = _design_matrix(data, factors, lv)
    z = np.column_stack([np.ones(len(data)), _sum_coding(data[method], lv[method])])
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
    se = np.sqrt(scale * np.diag(xvx_inv))
    with np.errstate(divide="ignore", invalid="ignore"):
        zval = beta / se
    p = 2.0 * _st.norm.sf(np.abs(zval))
    fixed = pd.DataFrame({"term": names, "estimate": beta, "SE": se, "z": zval, "p": p})
    n_cells = int(np.prod([len(lv[f]) for f in factors]))
    per = data.groupby(subject)[factors].apply(lambda d: len(d.drop_duplicates()))
    contrasts = _reference_contrasts(beta, scale * xvx_inv, names, method, lv[method], level)
    return MixedModelResult(
        fixed=fixed,
        variances=_variances(scale * lam @ lam.T, scale, method, len(lv[method])),
        loglik=-0.5 * crit,
        n_obs=int(len(data)),
        n_participants=int(len(per)),
        n_incomplete=int((per < n_cells).sum()),
        method=contrasts[0],
        converged=bool(opt.success),
        contrasts=pd.DataFrame(contrasts, columns=MIXED_CONTRAST_COLUMNS),
        factor=method,
    )


#: Columns of :attr:`MixedModelResult.contrasts`.
MIXED_CONTRAST_COLUMNS = ("contrast", "estimate", "SE", "z", "p", "lower_CL", "upper_CL")


def _reference_contrasts(
    beta: np.ndarray, cov: np.ndarray, names: list[str], method: str, levels: list, level: float
) -> list[dict]:
    """``reference - level`` for every other level of the method factor, averaged over the
    other factors (their sum-coded columns are 0 on average): a linear combination of the
    sum-coded main-effect coefficients, with its Wald SE, z, p and ``level`` interval. Each
    equals minus the level's coefficient under treatment coding against the reference
    (``contr.treatment`` for the method factor), the same model reparametrised."""
    k = len(levels)
    idx = [names.index(f"{method}{j + 1}") for j in range(k - 1)]
    crit_z = float(_st.norm.ppf(0.5 + level / 2.0))

    def mean_vector(i: int) -> np.ndarray:
        v = np.zeros(len(beta))
        if i < k - 1:
            v[idx[i]] = 1.0
        else:
            v[idx] = -1.0
        return v

    out = []
    for j in range(1, k):
        lvec = mean_vector(0) - mean_vector(j)
        est = float(lvec @ beta)
        s = float(np.sqrt(lvec @ cov @ lvec))
        z = est / s if s > 0 else float("nan")
        out.append(
            {
                "contrast": f"{levels[0]} - {levels[j]}",
                "estimate": est,
                "SE": s,
                "z": float(z),
                "p": float(2.0 * _st.norm.sf(abs(z))),
                "lower_CL": est - crit_z * s,
                "upper_CL": est + crit_z * s,
            }
        )
    return out


def _variances(g: np.ndarray, scale: float, method: str, k: int) -> dict:
    """The random-effect (co)variances by name: for two methods ``participant
    (Intercept)``, ``participant METHOD1``, ``covariance``, ``residual`` (as before); for
    k methods one variance per sum-coded slope and ``covariance A:B`` per pair."""
    terms = ["(Intercept)", *[f"{method}{j + 1}" for j in range(k - 1)]]
    out = {f"participant {t}": float(g[i, i]) for i, t in enumerate(terms)}
    if k == 2:
        out["covariance"] = float(g[0, 1])
    else:
        for i, j in itertools.combinations(range(len(terms)), 2):
            out[f"covariance {terms[i]}:{terms[j]}"] = float(g[i, j])
    out["residual"] = scale
    return out


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


def _method_grid(cm: CellMatrix, method: str) -> tuple[np.ndarray, list[str], list[tuple]]:
    """(n, cells of the other factors, k) values, the other factors, their level tuples."""
    if method not in cm.factors:
        raise InvalidInputError(f"the ordinal check needs the method factor {method!r}; factors: {cm.factors}")
    n = cm.values.shape[0]
    mi = cm.factors.index(method)
    grid = np.moveaxis(cm.values.reshape(n, *cm.shape), 1 + mi, -1)
    others = [f for f in cm.factors if f != method]
    other_levels = [cm.levels[cm.factors.index(f)] for f in others]
    labels = list(itertools.product(*other_levels)) if others else [()]
    return grid.reshape(n, len(labels), cm.shape[mi]), others, labels


def ordinal_method_check(cm: CellMatrix, *, alpha: float = 0.05, method: str = FACTOR_NAMES.method) -> pd.DataFrame:
    """Per-participant differences of the reference method (the first level of ``method``)
    and each other method (e.g. Baseline - Ours) tested without interval assumptions: per
    contrast, one row per cell of the other factors and a last row ``cell = "all"`` on each
    participant's mean difference over the cells.

    Columns: the other factors, ``cell``, ``n``, ``n_pos``, ``n_neg``, ``n_zero``,
    ``median_diff`` (points), ``V``, ``p_wilcoxon``, ``wilcoxon_method``, ``p_sign``,
    ``p_t`` (the paired t test on the same differences, for comparison), ``agree``
    (whether the Wilcoxon and t tests agree on p < alpha). With more than two methods a
    first column ``contrast`` names the pair and ``p_wilcoxon_holm``, ``p_sign_holm``
    adjust each cell's k - 1 tests for multiplicity (Holm).
    """
    grid, others, labels = _method_grid(cm, method)
    n, _, k = grid.shape
    levels = cm.levels[cm.factors.index(method)]
    parts = []
    for j in range(1, k):
        part = _ordinal_rows(grid[..., 0] - grid[..., j], others, labels, alpha)
        if k > 2:
            part.insert(0, "contrast", f"{levels[0]} - {levels[j]}")
        parts.append(part)
    out = pd.concat(parts, ignore_index=True)
    if k > 2:
        for col in ("p_wilcoxon", "p_sign"):
            out[f"{col}_holm"] = out.groupby("cell", sort=False)[col].transform(holm)
    out.attrs["contrast"] = f"{levels[0]} - {levels[-1]}" if k == 2 else f"{levels[0]} - each other {method}"
    return out


def _ordinal_rows(flat: np.ndarray, others: list[str], labels: list[tuple], alpha: float) -> pd.DataFrame:
    """One contrast's rows of :func:`ordinal_method_check`: ``flat`` (n, cells) differences."""
    n = flat.shape[0]
    rows = []
    for j, lab in enumerate(labels + [None]):
        d = flat[:, j] if lab is not None else flat.mean(axis=1)
        w, s = signed_rank_test(d), sign_test(d)
        sd = d.std(ddof=1)
        p_t = float(2.0 * _st.t.sf(abs(d.mean()) / (sd / np.sqrt(n)), n - 1)) if sd > 0 else float("nan")
        row: dict[str, object] = dict(zip(others, lab, strict=True)) if lab is not None else dict.fromkeys(others, "")
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
    return pd.DataFrame(rows)


def holm(p) -> np.ndarray:
    """Holm-adjusted p-values (R's ``p.adjust(p, "holm")``; NaN kept, not counted)."""
    p = np.asarray(p, dtype=float)
    out = np.full_like(p, np.nan)
    ok = ~np.isnan(p)
    q = p[ok]
    m = q.size
    if m == 0:
        return out
    order = np.argsort(q, kind="stable")
    adj = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * q[order]))
    res = np.empty(m)
    res[order] = adj
    out[ok] = res
    return out


#: Columns of :func:`friedman_test` (plus one column per other factor, first).
FRIEDMAN_COLUMNS = ("cell", "n", "k", "chi2", "df", "p")


def friedman_test(cm: CellMatrix, *, method: str = FACTOR_NAMES.method) -> pd.DataFrame:
    """Friedman's rank test of the k methods (R's ``friedman.test``, ties corrected), per
    cell of the other factors and (``cell = "all"``) on each participant's mean per method
    over the cells. Columns: the other factors, then :data:`FRIEDMAN_COLUMNS`; ``df`` = k - 1."""
    grid, others, labels = _method_grid(cm, method)
    n, _, k = grid.shape
    rows = []
    for j, lab in enumerate(labels + [None]):
        x = grid[:, j, :] if lab is not None else grid.mean(axis=1)
        ranks = np.apply_along_axis(_st.rankdata, 1, x)
        ties = sum(float((c**3 - c).sum()) for c in (np.unique(r, return_counts=True)[1] for r in ranks))
        denom = 1.0 - ties / (n * (k**3 - k))
        r = ranks.sum(axis=0)
        chi2 = (12.0 / (n * k * (k + 1)) * float((r**2).sum()) - 3.0 * n * (k + 1)) / denom if denom > 0 else np.nan
        row: dict[str, object] = dict(zip(others, lab, strict=True)) if lab is not None else dict.fromkeys(others, "")
        row.update(
            cell=" ".join(map(str, lab)) if lab is not None else "all",
            n=n,
            k=k,
            chi2=float(chi2),
            df=float(k - 1),
            p=float(_st.chi2.sf(chi2, k - 1)) if np.isfinite(chi2) else float("nan"),
        )
        rows.append(row)
    return pd.DataFrame(rows, columns=[*others, *FRIEDMAN_COLUMNS])

"""Repeated-measures ANOVA for any number of within-subject factors, with Mauchly's test,
Greenhouse-Geisser / Huynh-Feldt corrections and partial / generalized eta squared.

Matches R's ``afex::aov_ez`` (which calls ``car::Anova`` on the multivariate linear model
and ``summary(fit$Anova)``) to floating-point precision; the committed references in
``analysis/reference_r/`` are compared in ``tests/test_stats_anova.py``.

Method. ``Y`` (n subjects x c cells) holds per-subject cell means. For an effect ``S`` (a
set of factors) the contrast matrix is the Kronecker product over factors of orthonormal
(Helmert) contrasts for a factor in ``S`` and ``1/sqrt(k)`` for a factor not in ``S``;
``Z = Y C_S^T`` (n x p, p = product of (k - 1) over ``S``). Then ``SS = n |mean(Z)|^2``,
``SSPE = (Z - mean)^T (Z - mean)``, ``SS_error = tr(SSPE)``, ``F = (SS/p) / (SS_error/(p(n-1)))``.
``eps_GG = tr(SSPE)^2 / (p tr(SSPE^2))``; ``eps_HF = (n p eps_GG - 2) / (p (n - 1 - p eps_GG))``
(car's formula with error df n - 1; reported uncapped as car prints it, capped at 1 for
its corrected p as car and afex do). Mauchly's ``W = det(SSPE) / (tr(SSPE)/p)^p`` with car's
chi-square approximation (including its second-order term).

Where R differs by design: when n_subjects - 1 < an effect's df, the error matrix is
singular; car then prints no Mauchly test and no correction for that effect (afex leaves
it uncorrected). Here Mauchly's W and p are NaN, the GG epsilon is still computed from the
eigenvalues, and ``correction="auto"`` applies it (sphericity cannot be assumed).
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix, cell_matrix

__all__ = ["rm_anova", "anova_from_cells", "ANOVA_COLUMNS", "helmert", "effect_contrasts", "effect_terms"]

#: Columns of the table returned by :func:`rm_anova`, in order.
ANOVA_COLUMNS = (
    "Source",
    "SS",
    "ddof1",
    "ddof2",
    "MS",
    "SS_error",
    "MSE",
    "F",
    "p_unc",
    "eps_GG",
    "eps_HF",
    "ddof1_GG",
    "ddof2_GG",
    "p_GG_corr",
    "p_HF_corr",
    "W_spher",
    "chi2_spher",
    "ddof_spher",
    "p_spher",
    "sphericity",
    "ng2",
    "np2",
    "correction_applied",
    "ddof1_used",
    "ddof2_used",
    "p",
    "n_subjects",
)


def helmert(k: int) -> np.ndarray:
    """Orthonormal contrasts of ``k`` levels: (k - 1, k), rows orthonormal and summing to 0."""
    h = np.zeros((k - 1, k))
    for i in range(1, k):
        h[i - 1, :i] = 1.0
        h[i - 1, i] = -float(i)
        h[i - 1] /= np.sqrt(i * (i + 1))
    return h


def effect_terms(n_factors: int) -> list[tuple[int, ...]]:
    """Effects in R's order: main effects, then two-way interactions ..., as factor indices."""
    return [t for order in range(1, n_factors + 1) for t in itertools.combinations(range(n_factors), order)]


def effect_contrasts(shape: tuple[int, ...], term: tuple[int, ...]) -> np.ndarray:
    """Orthonormal contrast matrix (p, n_cells) of one effect over a row-major cell grid."""
    mat = np.ones((1, 1))
    for i, k in enumerate(shape):
        part = helmert(k) if i in term else np.full((1, k), 1.0 / np.sqrt(k))
        mat = np.kron(mat, part)
    return mat


def _mauchly(sspe: np.ndarray, n_cells: int, df: int) -> tuple[float, float, int, float]:
    """Mauchly's W, chi-square, its df and p as car::summary.Anova.mlm computes them."""
    pp = sspe.shape[0]
    tr = np.trace(sspe)
    sign, logdet = np.linalg.slogdet(sspe)
    if df < pp or sign <= 0 or tr <= 0:
        # fewer subjects than the effect's df + 1 (or a degenerate error matrix): SSPE is
        # singular and the test is undefined
        return float("nan"), float("nan"), pp * (pp + 1) // 2 - 1, float("nan")
    log_w = logdet - pp * np.log(tr / pp)
    rho = 1.0 - (2 * pp**2 + pp + 2) / (6.0 * pp * df)
    # car uses the number of response columns (n_cells) in the last factor of w2.
    w2 = (pp + 2) * (pp - 1) * (pp - 2) * (2 * pp**3 + 6 * pp**2 + 3 * n_cells + 2) / (288.0 * (df * pp * rho) ** 2)
    z = -df * rho * log_w
    f = pp * (pp + 1) // 2 - 1
    pr1 = _st.chi2.sf(z, f)
    pr2 = _st.chi2.sf(z, f + 4)
    return float(np.exp(log_w)), float(z), int(f), float(pr1 + w2 * (pr2 - pr1))


def _correction_mode(correction) -> str:
    if correction is True or correction == "GG":
        return "always"
    if correction is False or correction in ("none", None):
        return "never"
    if correction == "auto":
        return "auto"
    raise InvalidInputError(f"correction must be 'auto', True (always GG) or False (never), got {correction!r}")


def _table(cm: CellMatrix, correction: str, alpha: float) -> pd.DataFrame:
    y = cm.values
    n, c = y.shape
    shape = cm.shape
    mean_all = y.mean(axis=1)
    ss_subjects = float(((mean_all - mean_all.mean()) ** 2).sum() * c)
    tiny = 1e-12 * float((y * y).sum())  # rounding level of the sums of squares
    rows = []
    for term in effect_terms(len(shape)):
        cmat = effect_contrasts(shape, term)
        z = y @ cmat.T
        zbar = z.mean(axis=0)
        zc = z - zbar
        p = cmat.shape[0]
        ss = float(n * zbar @ zbar)
        sspe = zc.T @ zc
        ss_err = float(np.trace(sspe))
        df1, df2 = float(p), float(p * (n - 1))
        undefined = ss <= tiny and ss_err <= tiny  # 0/0: no variation at all
        if undefined:
            f_val = float("nan")
        else:
            f_val = (ss / df1) / (ss_err / df2) if ss_err > tiny else np.inf
        p_unc = float(_st.f.sf(f_val, df1, df2)) if not undefined else float("nan")
        row = {
            "Source": ":".join(cm.factors[i] for i in term),
            "SS": ss,
            "ddof1": df1,
            "ddof2": df2,
            "MS": ss / df1,
            "SS_error": ss_err,
            "MSE": ss_err / df2,
            "F": f_val,
            "p_unc": p_unc,
            "_undefined": undefined,
        }
        if p > 1:
            gg = float(np.trace(sspe) ** 2 / (p * np.sum(sspe * sspe))) if ss_err > tiny else 1.0 / p
            hf = (n * p * gg - 2.0) / (p * (n - 1 - p * gg))
            w, chi2, fdf, p_sph = _mauchly(sspe, c, n - 1)
            hf_c = min(1.0, hf)
            row.update(
                eps_GG=gg,
                eps_HF=hf,
                ddof1_GG=df1 * gg,
                ddof2_GG=df2 * gg,
                p_GG_corr=float(_st.f.sf(f_val, df1 * gg, df2 * gg)),
                p_HF_corr=float(_st.f.sf(f_val, df1 * hf_c, df2 * hf_c)),
                W_spher=w,
                chi2_spher=chi2,
                ddof_spher=float(fdf),
                p_spher=p_sph,
                sphericity=bool(p_sph >= alpha) if np.isfinite(p_sph) else False,
            )
        else:
            row.update(
                eps_GG=1.0,
                eps_HF=1.0,
                ddof1_GG=df1,
                ddof2_GG=df2,
                p_GG_corr=p_unc,
                p_HF_corr=p_unc,
                W_spher=1.0,
                chi2_spher=0.0,
                ddof_spher=0.0,
                p_spher=1.0,
                sphericity=True,
            )
        rows.append(row)
    errors_total = ss_subjects + sum(np.unique([r["SS_error"] for r in rows]))
    for row in rows:
        row["np2"] = row["SS"] / (row["SS"] + row["SS_error"]) if not row["_undefined"] else np.nan
        row["ng2"] = row["SS"] / (row["SS"] + errors_total) if not row["_undefined"] else np.nan
        multi = row["ddof1"] > 1
        apply = multi and (correction == "always" or (correction == "auto" and not row["sphericity"]))
        row["correction_applied"] = bool(apply)
        row["ddof1_used"] = row["ddof1_GG"] if apply else row["ddof1"]
        row["ddof2_used"] = row["ddof2_GG"] if apply else row["ddof2"]
        row["p"] = row["p_GG_corr"] if apply else row["p_unc"]
        row["n_subjects"] = n
    table = pd.DataFrame(rows, columns=list(ANOVA_COLUMNS))
    table.attrs["ss_subjects"] = ss_subjects
    table.attrs["undefined"] = [r["Source"] for r in rows if r["_undefined"]]
    return table


def rm_anova(
    data: pd.DataFrame,
    dv: str | None,
    within,
    subject: str | None,
    *,
    correction="auto",
    effsize: str = "np2",
    alpha: float = 0.05,
    missing: str = "raise",
    duplicates: str = "warn",
) -> pd.DataFrame:
    """Repeated-measures ANOVA with any number of within-subject factors.

    Parameters
    ----------
    data: long DataFrame (one row per observation: ``subject``, the ``within`` columns,
        ``dv``; several rows of one subject x cell are averaged, as afex does, with a
        warning: see ``duplicates``) or, with
        ``dv=None``, wide (index = subjects, one column per cell; MultiIndex columns whose
        level names are the factors, or name them with ``within``).
    dv: column of the dependent variable (numeric); None for wide input.
    within: factor column name(s); levels ordered as categories (if categorical) or sorted.
    subject: subject id column (None for wide input: the index).
    correction: ``"auto"`` applies Greenhouse-Geisser to an effect with more than one df
        when Mauchly's p < ``alpha`` (the paper's rule); ``True`` to every such effect
        (afex's default); ``False`` never. Decides ``correction_applied``, ``ddof*_used``, ``p``.
    effsize: ``"np2"`` or ``"ng2"``: the effect size reports quote (``attrs["effsize"]``);
        both columns are always present.
    alpha: significance level of Mauchly's test for ``"auto"`` (and of the ``sphericity`` flag).
    missing: ``"raise"``: a subject without every cell is an error naming it and the cell;
        ``"drop"``: such subjects are removed (listwise deletion), listed in
        ``attrs["dropped_subjects"]`` and ``attrs["note"]``; ``n_subjects`` counts those kept.
    duplicates: several rows for one subject x cell: ``"warn"`` (average them and warn,
        as afex does), ``"mean"`` (average silently), ``"raise"`` (an error naming them).

    Returns
    -------
    DataFrame, one row per effect in R's order (main effects, then 2-way ... interactions):

    - ``Source``: effect name, factors joined by ":" (``"Density:Method"``), as R prints it.
    - ``SS``, ``ddof1``, ``MS``: effect sum of squares, numerator df, SS / ddof1.
    - ``ddof2``: denominator df, ddof1 * (n_subjects - 1).
    - ``SS_error``, ``MSE``: the effect x subject error term and its mean square.
    - ``F``, ``p_unc``: F ratio and its uncorrected p. NaN (and np2 NaN) when the effect's
      SS and its error SS are both ~0 (below 1e-12 of the data's sum of squares: e.g.
      every score identical), where F is 0/0; ``attrs["undefined"]`` lists such effects
      and ``attrs["note"]`` says so.
    - ``eps_GG``, ``eps_HF``: Greenhouse-Geisser and Huynh-Feldt epsilons (1 for 1-df
      effects; HF uncapped, as car prints it, so it may exceed 1).
    - ``ddof1_GG``, ``ddof2_GG``: GG-corrected dfs (as afex prints them with correction="GG").
    - ``p_GG_corr``, ``p_HF_corr``: corrected p (HF epsilon capped at 1, as car/afex).
    - ``W_spher``, ``chi2_spher``, ``ddof_spher``, ``p_spher``: Mauchly's test (W = 1,
      chi2 = 0, df 0, p = 1 for 1-df effects, where sphericity holds trivially; NaN when
      n_subjects - 1 < ddof1, where the error matrix is singular and the test undefined).
    - ``sphericity``: True when p_spher >= alpha; False when the test is undefined (so
      ``"auto"`` then applies the Greenhouse-Geisser correction, the safe choice).
    - ``ng2``: generalized eta squared (afex: SS / (SS + SS_subjects + all error SS)).
    - ``np2``: partial eta squared, SS / (SS + SS_error).
    - ``correction_applied``: whether GG was applied under ``correction``.
    - ``ddof1_used``, ``ddof2_used``, ``p``: dfs and p under the chosen rule.
    - ``n_subjects``: subjects analysed.

    ``attrs``: factors, levels, correction, alpha, effsize, dropped_subjects, note,
    aggregated, ss_subjects, undefined.
    """
    if effsize not in ("np2", "ng2"):
        raise InvalidInputError(f"effsize must be 'np2' or 'ng2', got {effsize!r}")
    if not isinstance(alpha, (int, float)) or isinstance(alpha, bool) or not 0 < alpha < 1:
        raise InvalidInputError(f"alpha must be a number in (0, 1), got {alpha!r}")
    mode = _correction_mode(correction)
    cm = cell_matrix(data, dv, within, subject, missing=missing, duplicates=duplicates)
    return anova_from_cells(cm, correction=correction, effsize=effsize, alpha=alpha, _mode=mode)


def anova_from_cells(
    cm: CellMatrix, *, correction="auto", effsize: str = "np2", alpha: float = 0.05, _mode: str | None = None
) -> pd.DataFrame:
    """:func:`rm_anova` on an already validated :class:`~crowdstudy.stats._data.CellMatrix`."""
    mode = _mode or _correction_mode(correction)
    table = _table(cm, mode, float(alpha))
    notes = []
    if cm.dropped:
        notes.append(
            f"listwise deletion: {len(cm.dropped)} subject(s) without every cell removed "
            f"({', '.join(map(str, cm.dropped))}); {len(cm.subjects)} analysed"
        )
    if table.attrs["undefined"]:
        notes.append(
            f"F undefined (effect and error sums of squares both ~0: no variation in the scores) for "
            f"{', '.join(table.attrs['undefined'])}"
        )
    note = "; ".join(notes)
    table.attrs.update(
        factors=list(cm.factors),
        levels={f: list(lv) for f, lv in zip(cm.factors, cm.levels, strict=True)},
        correction={"auto": "auto", "always": True, "never": False}[mode],
        alpha=float(alpha),
        effsize=effsize,
        dropped_subjects=list(cm.dropped),
        note=note,
        aggregated=cm.aggregated,
    )
    return table

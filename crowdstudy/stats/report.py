"""Report building blocks: descriptive statistics, significance stars, APA-style text and
table writers (CSV, Markdown, LaTeX) for the ANOVA, post hoc and descriptive tables."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix

__all__ = [
    "stars",
    "format_p",
    "apa_effect",
    "apa_summary",
    "contrast_text",
    "descriptives_from_cells",
    "to_markdown",
    "to_latex",
    "write_table",
]


def stars(p: float) -> str:
    """``"***"`` (p < .001), ``"**"`` (p < .01), ``"*"`` (p < .05), else ``""``."""
    if p is None or not np.isfinite(p):
        return ""
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else ""


def format_p(p: float) -> str:
    """APA p: ``"p < .001"`` or ``"p = .034"`` (no leading zero, three decimals)."""
    if not np.isfinite(p):
        return "p = n/a"
    if p < 0.001:
        return "p < .001"
    text = f"{p:.3f}"
    return "p = " + (text[1:] if text.startswith("0") else text)


def _num(x: float, digits: int = 2) -> str:
    if not np.isfinite(x):
        return "n/a"
    if abs(x - round(x)) < 1e-9 and abs(x) < 1e6:
        return str(int(round(x)))
    return f"{x:.{digits}f}"


def _es(x: float) -> str:
    text = f"{x:.2f}" if x >= 0.005 else f"{x:.3f}"
    return text[1:] if text.startswith("0") else text


def apa_effect(row: pd.Series | dict, effsize: str = "np2") -> str:
    """One effect in APA style: ``F(2.45, 71.05) = 12.30, p < .001, eta_p^2 = .30``
    (dfs under the chosen correction; ``, GG eps = 0.61`` appended when corrected)."""
    es_name = "eta_p^2" if effsize == "np2" else "eta_G^2"
    text = (
        f"F({_num(row['ddof1_used'])}, {_num(row['ddof2_used'])}) = {row['F']:.2f}, {format_p(row['p'])}, "
        f"{es_name} = {_es(row[effsize])}"
    )
    if row.get("correction_applied", False):
        text += f" (Greenhouse-Geisser corrected, eps = {row['eps_GG']:.2f})"
    return text


def apa_summary(
    table: pd.DataFrame, *, alpha: float | None = None, effsize: str | None = None, label: str = ""
) -> list[str]:
    """One sentence per significant effect (``p < alpha`` under the table's rule)."""
    alpha = table.attrs.get("alpha", 0.05) if alpha is None else alpha
    es_col = effsize or str(table.attrs.get("effsize", "np2"))
    out = []
    for _, row in table.iterrows():
        if row["p"] < alpha:
            kind = "interaction" if ":" in row["Source"] else "main effect of"
            name = row["Source"].replace(":", " x ")
            lead = f"{label}: " if label else ""
            what = (
                f"a significant {name} interaction" if kind == "interaction" else f"a significant main effect of {name}"
            )
            out.append(f"{lead}{what}, {apa_effect(row, es_col)}.")
    return out


def contrast_text(row: pd.Series | dict, level: float = 0.95) -> str:
    """One pairwise contrast with its interval and effect sizes, e.g. ``Baseline - Ours =
    -0.52, 95% CI [-0.83, -0.21] (tukey), t(11) = -3.70, p = .004, d_z = -1.07 [-1.78,
    -0.33], g_av = -0.61 [-1.02, -0.19]`` (estimate and CI in dv units, d_z and g_av unitless)."""
    pct = f"{100 * level:g}%"
    text = (
        f"{row['contrast']} = {row['estimate']:.2f}, {pct} CI [{row['lower_CL']:.2f}, {row['upper_CL']:.2f}] "
        f"({row['ci_adjust']}), t({_num(row['df'])}) = {row['t']:.2f}, {format_p(row['p_adj'])}"
    )
    if np.isfinite(row["dz"]):
        text += (
            f", d_z = {row['dz']:.2f} [{row['dz_low']:.2f}, {row['dz_high']:.2f}], "
            f"g_av = {row['g_av']:.2f} [{row['g_av_low']:.2f}, {row['g_av_high']:.2f}]"
        )
    return text


def descriptives_from_cells(cm: CellMatrix, value_name: str = "score") -> pd.DataFrame:
    """Mean +- SD across subjects for every level combination of every effect.

    One row per (effect, level combination): ``effect`` (e.g. ``"Density:Method"``), one
    column per factor (empty string for factors averaged over), ``n``, ``mean``, ``sd``
    (of the per-subject marginal means, ddof 1), ``se``, ``mean_sd`` ("3.41 +- 0.82").
    The full-design cells are the rows whose effect names every factor.
    """
    n = cm.values.shape[0]
    grid = cm.values.reshape(n, *cm.shape)
    k = len(cm.factors)
    rows = []
    for order in range(1, k + 1):
        for term in itertools.combinations(range(k), order):
            other = tuple(1 + i for i in range(k) if i not in term)
            marg = grid.mean(axis=other) if other else grid
            for combo in itertools.product(*[range(len(cm.levels[i])) for i in term]):
                v = marg[(slice(None), *combo)]
                mean, sd = float(v.mean()), float(v.std(ddof=1)) if n > 1 else float("nan")
                row: dict[str, Any] = {"effect": ":".join(cm.factors[i] for i in term)}
                for i in range(k):
                    row[cm.factors[i]] = str(cm.levels[i][combo[term.index(i)]]) if i in term else ""
                row.update(n=n, mean=mean, sd=sd, se=sd / math.sqrt(n), mean_sd=f"{mean:.2f} +- {sd:.2f}")
                rows.append(row)
    out = pd.DataFrame(rows)
    out.attrs["value"] = value_name
    return out


def _cell(v, digits: int) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return "" if np.isnan(v) else ("inf" if v > 0 else "-inf")
        if v != 0 and (abs(v) < 10**-digits or abs(v) >= 1e6):
            return f"{v:.{digits}g}" if abs(v) >= 1e6 else f"{v:.2e}"
        return f"{v:.{digits}f}"
    return str(v)


def to_markdown(df: pd.DataFrame, digits: int = 3) -> str:
    """A GitHub-flavoured Markdown table (floats with ``digits`` decimals)."""
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    rule = "|" + "|".join("---:" if pd.api.types.is_numeric_dtype(df[c]) else "---" for c in df.columns) + "|"
    body = [
        "| " + " | ".join(_cell(v, digits).replace("|", "\\|") for v in row) + " |"
        for row in df.itertuples(index=False)
    ]
    return "\n".join([head, rule, *body]) + "\n"


_LATEX_ESC = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\^{}",
}


def _tex(s: str) -> str:
    return "".join(_LATEX_ESC.get(ch, ch) for ch in s).replace("+-", r"$\pm$")


def to_latex(df: pd.DataFrame, digits: int = 3, caption: str | None = None, label: str | None = None) -> str:
    """A booktabs LaTeX table (``\\usepackage{booktabs}``)."""
    align = "".join("r" if pd.api.types.is_numeric_dtype(df[c]) else "l" for c in df.columns)
    lines = [r"\begin{table}[ht]", r"\centering"]
    if caption:
        lines.append(r"\caption{" + _tex(caption) + "}")
    if label:
        lines.append(r"\label{" + label + "}")
    lines += [
        r"\begin{tabular}{" + align + "}",
        r"\toprule",
        " & ".join(_tex(str(c)) for c in df.columns) + r" \\",
        r"\midrule",
    ]
    for row in df.itertuples(index=False):
        lines.append(" & ".join(_tex(_cell(v, digits)) for v in row) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def write_table(
    df: pd.DataFrame, stem: str | Path, *, formats=("csv", "md", "tex"), caption: str | None = None, digits: int = 3
) -> list[Path]:
    """Write ``df`` as STEM.csv (full precision), STEM.md and STEM.tex; returns the paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for fmt in formats:
        path = stem.with_name(stem.name + "." + fmt)
        if fmt == "csv":
            df.to_csv(path, index=False, float_format="%.10g", lineterminator="\n")
        elif fmt == "md":
            path.write_text((f"**{caption}**\n\n" if caption else "") + to_markdown(df, digits))
        elif fmt == "tex":
            path.write_text(to_latex(df, digits, caption=caption))
        else:
            raise InvalidInputError(f"unknown table format {fmt!r}; expected csv, md or tex")
        written.append(path)
    return written

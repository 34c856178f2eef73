"""The APA-style summary of an analysis (summary.md; what ``crowdstudy analyze`` prints):
the design, participants and exclusions, the settings, item-pair reliability, then per
stage and composite every significant effect, the Method contrast, simple effects,
trends, the robustness checks and the assumption checks."""

from __future__ import annotations

import pandas as pd

from crowdstudy.stats.report import contrast_text, format_p, to_markdown
from crowdstudy.stats.results import AnalysisResult, CompositeResult, Robustness

__all__ = ["summary_text"]


def summary_text(result: AnalysisResult) -> str:
    """summary.md of ``result``: Markdown, one section per (stage, composite)."""
    o = result.options
    lines = ["# Analysis summary", ""]
    if result.simulated:
        lines += [f"**{result.simulated_note}**" + (f": {result.note}" if result.note else ""), ""]
    lines += [f"Design: {result.design.name}", f"Participants: {result.n_participants}"]
    if result.exclusions is not None:
        lines.append(result.exclusions.text())
    lines += [
        f"Sphericity correction: {o.anova_correction!r} (alpha = {o.alpha}); post hoc adjustment: {o.adjust}; "
        f"intervals: {100 * o.level:g}% ({o.adjust}-adjusted where the p is)",
        "",
        "## Item-pair reliability (after reversing the negative items)",
        "",
        to_markdown(result.reliability),
    ]
    for res in result.results.values():
        lines += _composite_lines(res, o.alpha, o.level)
    return "\n".join(lines) + "\n"


def _composite_lines(res: CompositeResult, alpha: float, level: float) -> list[str]:
    table = res.anova
    lines = ["", f"## {res.label}", ""]
    if table.attrs["note"]:
        lines.append(f"Note: {table.attrs['note']}.")
    lines += res.apa or ["No significant effect."]
    lines += ["", "Method: " + "; ".join(contrast_text(r, level) for r in res.method.to_dict("records")) + "."]
    if res.simple_effects is not None:
        sig = res.simple_effects[res.simple_effects["term"] == "Method"]
        lines.append(
            f"Simple effects (Method within each {' x '.join(res.others)} cell, joint_tests, unadjusted): "
            f"p < {alpha} in {int((sig['p'] < alpha).sum())} of {len(sig)} cells."
        )
    if res.trends is not None:
        lin = res.trends[(res.trends["contrast"] == "linear") & (res.trends["by"] == "Method")]
        lines.append(
            "Linear trend over Density: "
            + "; ".join(
                f"{r['Method']} {r['estimate']:.2f} [{r['lower_CL']:.2f}, {r['upper_CL']:.2f}] "
                f"(coefficients {r['coefficients']})"
                for r in lin.to_dict("records")
            )
            + "."
        )
    if res.robustness is not None:
        lines += _robustness_lines(res.robustness, table, alpha)
    lines.append(_assumption_text(res, alpha))
    if not res.stars_shown:
        lines.append(f"Figure stars omitted: the ANOVA's {res.stars_gate} effect is not significant (--stars omnibus).")
    return lines


def _assumption_text(res: CompositeResult, alpha: float) -> str:
    """Shapiro-Wilk per cell and Mauchly's test per effect, in one paragraph."""
    table, shp = res.anova, res.shapiro
    n_bad = int((~shp["normal"]).sum())
    untestable = table["p_spher"].isna() & ~table["F"].isna()
    rejected = ~table["sphericity"] & table["p_spher"].notna()
    text = (
        f"\nShapiro-Wilk: {n_bad} of {len(shp)} cells deviate from normality at alpha = {alpha} "
        f"(see the Q-Q plots). Mauchly: sphericity rejected for "
        f"{', '.join(table.loc[rejected, 'Source']) or 'no effect'}."
    )
    if untestable.any():
        text += (
            f" Not testable with {len(res.cells.subjects)} participants (fewer than df + 1): "
            f"{', '.join(table.loc[untestable, 'Source'])}; treated as violated."
        )
    return text


def _robustness_lines(rob: Robustness, table: pd.DataFrame, alpha: float) -> list[str]:
    lines = []
    anova_p = float(table.set_index("Source").at["Method", "p"])
    mm = rob.mixed
    if mm is not None:
        m = mm.method
        lines.append(
            f"Robustness, mixed model (REML; random intercept and Method slope per participant; "
            f"{mm.n_participants} participants ({mm.n_incomplete} incomplete, kept), "
            f"{mm.n_obs} cell scores): {m['contrast']} = {m['estimate']:.2f}, 95% CI "
            f"[{m['lower_CL']:.2f}, {m['upper_CL']:.2f}], Wald z = {m['z']:.2f}, {format_p(m['p'])} "
            f"(ANOVA Method: {format_p(anova_p)})."
        )
    elif rob.mixed_note:
        lines.append(f"Robustness: {rob.mixed_note}.")
    od = rob.ordinal
    allrow = od[od["cell"] == "all"].iloc[0]
    cells = od[od["cell"] != "all"]
    lines.append(
        f"Robustness, ordinal check (no interval assumption; {od.attrs['contrast']} per participant): "
        f"Wilcoxon signed-rank on each participant's mean difference V = {allrow['V']:g}, "
        f"{format_p(allrow['p_wilcoxon'])}; sign test {int(allrow['n_pos'])}+/{int(allrow['n_neg'])}-, "
        f"{format_p(allrow['p_sign'])}. Per cell: Wilcoxon p < {alpha} in "
        f"{int((cells['p_wilcoxon'] < alpha).sum())} of {len(cells)} cells, paired t in "
        f"{int((cells['p_t'] < alpha).sum())}; the two agree in {int(cells['agree'].sum())}."
    )
    return lines

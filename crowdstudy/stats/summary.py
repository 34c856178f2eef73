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
    ]
    if len(result.reliability):
        lines += [
            "## Item-pair reliability (after reversing the negative items)",
            "",
            to_markdown(result.reliability),
        ]
    for st in result.stages:
        for (number, _), res in result.results.items():
            if number == st.number:
                lines += _composite_lines(res, o.alpha, o.level)
        if st.number in result.choices:
            from crowdstudy.stats.choice_report import choice_summary_lines

            lines += choice_summary_lines(result.choices[st.number], o.alpha)
    return "\n".join(lines) + "\n"


def _composite_lines(res: CompositeResult, alpha: float, level: float) -> list[str]:
    table = res.anova
    lines = ["", f"## {res.label}", ""]
    if table.attrs["note"]:
        lines.append(f"Note: {table.attrs['note']}.")
    lines += res.apa or ["No significant effect."]
    method, density = res.names.method, res.names.density
    pairs = "; ".join(contrast_text(r, level) for r in res.method.to_dict("records"))
    lines += ["", f"{method}: {pairs}."]
    if res.simple_effects is not None:
        sig = res.simple_effects[res.simple_effects["term"] == method]
        lines.append(
            f"Simple effects ({method} within each {' x '.join(res.others)} cell, joint_tests, unadjusted): "
            f"p < {alpha} in {int((sig['p'] < alpha).sum())} of {len(sig)} cells."
        )
    if res.trends is not None:
        lin = res.trends[(res.trends["contrast"] == "linear") & (res.trends["by"] == method)]
        lines.append(
            f"Linear trend over {density}: "
            + "; ".join(
                f"{r[method]} {r['estimate']:.2f} [{r['lower_CL']:.2f}, {r['upper_CL']:.2f}] "
                f"(coefficients {r['coefficients']})"
                for r in lin.to_dict("records")
            )
            + "."
        )
    if res.robustness is not None:
        lines += _robustness_lines(res.robustness, table, alpha, method)
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


def _robustness_lines(rob: Robustness, table: pd.DataFrame, alpha: float, method: str) -> list[str]:
    lines = []
    anova_p = float(table.set_index("Source").at[method, "p"])  # pyright: ignore[reportArgumentType]  # stubs: .at is any scalar
    mm = rob.mixed
    if mm is not None:
        rows = mm.contrasts.to_dict("records") if mm.contrasts is not None else [mm.method]
        text = "; ".join(
            f"{m['contrast']} = {m['estimate']:.2f}, 95% CI [{m['lower_CL']:.2f}, {m['upper_CL']:.2f}], "
            f"Wald z = {m['z']:.2f}, {format_p(m['p'])}"
            for m in rows
        )
        slopes = f"{method} slope" if len(rows) == 1 else f"{len(rows)} {method} slopes"
        lines.append(
            f"Robustness, mixed model (REML; random intercept and {slopes} per participant; "
            f"{mm.n_participants} participants ({mm.n_incomplete} incomplete, kept), "
            f"{mm.n_obs} cell scores): {text} (ANOVA {method}: {format_p(anova_p)})."
        )
    elif rob.mixed_note:
        lines.append(f"Robustness: {rob.mixed_note}.")
    od = rob.ordinal
    groups = [(None, od)] if "contrast" not in od.columns else list(od.groupby("contrast", sort=False))
    for contrast, part in groups:
        allrow = part[part["cell"] == "all"].iloc[0]
        cells = part[part["cell"] != "all"]
        what = od.attrs["contrast"] if contrast is None else contrast
        holm = (
            ""
            if contrast is None
            else f" (Holm over the {len(groups)} contrasts: {format_p(allrow['p_wilcoxon_holm'])})"
        )
        lines.append(
            f"Robustness, ordinal check (no interval assumption; {what} per participant): "
            f"Wilcoxon signed-rank on each participant's mean difference V = {allrow['V']:g}, "
            f"{format_p(allrow['p_wilcoxon'])}{holm}; sign test {int(allrow['n_pos'])}+/{int(allrow['n_neg'])}-, "
            f"{format_p(allrow['p_sign'])}. Per cell: Wilcoxon p < {alpha} in "
            f"{int((cells['p_wilcoxon'] < alpha).sum())} of {len(cells)} cells, paired t in "
            f"{int((cells['p_t'] < alpha).sum())}; the two agree in {int(cells['agree'].sum())}."
        )
    if rob.friedman is not None:
        fr = rob.friedman
        a = fr[fr["cell"] == "all"].iloc[0]
        cells = fr[fr["cell"] != "all"]
        lines.append(
            f"Friedman test of the {int(a['k'])} methods on each participant's means: "
            f"chi2({int(a['df'])}) = {a['chi2']:.2f}, {format_p(a['p'])}; per cell p < {alpha} in "
            f"{int((cells['p'] < alpha).sum())} of {len(cells)} cells."
        )
    return lines

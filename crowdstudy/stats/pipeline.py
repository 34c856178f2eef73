"""The paper's whole analysis of exported responses (what ``crowdstudy analyze`` runs).

Per stage (scenario) and composite (QCR, QCA, QOR): per participant x cell means ->
3-way repeated-measures ANOVA (Density x Viewpoint x Method) -> Tukey post hoc tests for
every significant effect -> descriptives (mean +- SD) -> Shapiro-Wilk and Q-Q plots ->
paper-style figures -> APA summary. Item-pair reliability is reported first.

Output folder layout (``out_dir``)::

    reliability.{csv,md,tex}
    summary.md                     APA text of every significant effect, per stage and composite
    analysis.json                  provenance, settings, key numbers
    stageN_<scenario>/
        <COMP>_anova.{csv,md,tex}  full table in the CSV, the reported columns in md/tex
        <COMP>_posthoc.{csv,md,tex}
        <COMP>_method_by_cell.csv  Method within every Density x Viewpoint cell (the figure's stars)
        <COMP>_descriptives.{csv,md,tex}
        <COMP>_shapiro.csv, <COMP>_qq.png
        <COMP>_by_density.png      one composite; scores_by_density.png: all composites
                                   (each with a .json of the plotted numbers)
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.provenance import provenance
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.anova import anova_from_cells
from crowdstudy.stats.assumptions import qq_figure_from_cells, shapiro_from_cells
from crowdstudy.stats.posthoc import pairwise_from_cells
from crowdstudy.stats.report import apa_summary, descriptives_from_cells, write_table
from crowdstudy.stats.scoring import cell_means, composite_scores, item_reliability, validate_responses

__all__ = ["analyze", "AnalysisResult", "CompositeResult", "FACTORS", "posthoc_for_significant"]

#: The within factors of the study's ANOVA, in order.
FACTORS = ("Density", "Viewpoint", "Method")

_REPORTED = ["Source", "ddof1_used", "ddof2_used", "F", "p", "np2", "ng2", "eps_GG", "W_spher", "p_spher",
             "correction_applied"]
_POSTHOC_REPORTED = ["effect", "factor", "by_level", "contrast", "estimate", "SE", "df", "t", "p_adj"]


@dataclasses.dataclass
class CompositeResult:
    """Everything computed for one (stage, composite)."""
    stage: int
    scenario: str
    composite: str
    anova: pd.DataFrame
    posthoc: pd.DataFrame
    method_by_cell: pd.DataFrame
    descriptives: pd.DataFrame
    shapiro: pd.DataFrame
    apa: list[str]


@dataclasses.dataclass
class AnalysisResult:
    reliability: pd.DataFrame
    results: dict[tuple[int, str], CompositeResult]
    summary: str
    files: list[Path]


def posthoc_for_significant(cm, anova: pd.DataFrame, *, alpha: float, adjust: str = "tukey") -> pd.DataFrame:
    """Pairwise comparisons for every significant effect (``p < alpha`` in ``anova``):
    a main effect -> its levels; an interaction -> each of its factors within the levels
    of the others. Column ``effect`` names the ANOVA effect that triggered the test."""
    parts = []
    for _, row in anova.iterrows():
        if not row["p"] < alpha:
            continue
        factors = row["Source"].split(":")
        for f in factors:
            ph = pairwise_from_cells(cm, f, [g for g in factors if g != f], adjust=adjust)
            ph.insert(0, "effect", row["Source"])
            parts.append(ph)
    if not parts:
        return pd.DataFrame(columns=["effect", "factor", "by", "by_level", "A", "B", "contrast", "estimate", "SE",
                                     "df", "t", "p_unc", "p_adj", "adjust", "n_means", "n_contrasts"])
    return pd.concat(parts, ignore_index=True)


def _stage_dir(stage) -> str:
    return f"stage{stage.number}_{stage.scenario}"


def analyze(responses: pd.DataFrame | str | Path, design=None, out_dir: str | Path | None = None, *,
            correction="auto", alpha: float = 0.05, effsize: str = "np2", composites=None, stages=None,
            missing: str = "raise", adjust: str = "tukey", error: str = "sd", figures: bool = True,
            progress: bool = False, figure_note: str = "") -> AnalysisResult:
    """Run the paper's analysis; write tables, figures and the summary when ``out_dir`` is set.

    ``responses``: a DataFrame in the responses.csv schema or a path to the CSV.
    ``design``: a StudyDesign (default: the paper's). ``correction``/``alpha``/``effsize``/
    ``missing``: as :func:`~crowdstudy.stats.anova.rm_anova`. ``composites``/``stages``:
    subsets (default all; stages by number). ``adjust``: post hoc adjustment. ``error``:
    figure error bars ("sd", "se", "ci95"). ``figure_note``: text appended to every figure
    title (e.g. "simulated participants").
    """
    if design is None:
        from crowdstudy.design import load_design
        design = load_design()
    if isinstance(responses, (str, Path)):
        path = Path(responses)
        if not path.is_file():
            raise InvalidInputError(f"responses file {str(path)!r} does not exist")
        try:
            responses = pd.read_csv(path)
        except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise InvalidInputError(f"responses file {str(path)!r} is not a readable CSV file ({exc})") from None
    data = validate_responses(responses, design)
    comps = list(design.composites) if composites is None else list(composites)
    for c in comps:
        if c not in design.composites:
            raise InvalidInputError(f"unknown composite {c!r}; the design defines {', '.join(design.composites)}")
    present = sorted(set(data["stage"]))
    chosen = [st for st in design.stages if st.number in present and (stages is None or st.number in stages)]
    if not chosen:
        raise InvalidInputError(f"no responses for the chosen stage(s) {stages}; responses hold stage(s) {present}")
    out = Path(out_dir) if out_dir is not None else None
    files: list[Path] = []
    reliability = item_reliability(data, design, by="scenario")
    scored = composite_scores(data, design)
    results: dict[tuple[int, str], CompositeResult] = {}
    lines = ["# Analysis summary", "", f"Design: {design.name}", f"Participants: {data['participant_id'].nunique()}",
             f"Sphericity correction: {correction!r} (alpha = {alpha}); post hoc adjustment: {adjust}", "",
             "## Item-pair reliability (after reversing the negative items)", ""]
    from crowdstudy.stats.report import to_markdown
    lines.append(to_markdown(reliability))
    work = [(st, c) for st in chosen for c in comps]
    iterator = work
    if progress:
        from tqdm import tqdm
        iterator = tqdm(work, desc="analysis", unit="anova", leave=False)
    per_stage_panels: dict[int, dict] = {}
    for st, comp in iterator:
        long = cell_means(scored, comp, design, stage=st.number)
        # a factor with a single level in this stage (a custom design with one viewpoint,
        # say) is left out of the model; Method must vary
        factors = [f for f in FACTORS if f == "Method" or long[f].nunique() > 1]
        cm = cell_matrix(long, comp, factors, "participant_id", missing=missing)
        table = anova_from_cells(cm, correction=correction, effsize=effsize, alpha=alpha)
        ph = posthoc_for_significant(cm, table, alpha=alpha, adjust=adjust)
        by_cell = pairwise_from_cells(cm, "Method", [f for f in factors if f != "Method"], adjust=adjust)
        desc = descriptives_from_cells(cm, comp)
        shp = shapiro_from_cells(cm, alpha=alpha)
        label = f"Stage {st.number} ({st.scenario}), {comp}"
        apa = apa_summary(table, alpha=alpha, effsize=effsize, label=label)
        res = CompositeResult(st.number, st.scenario, comp, table, ph, by_cell, desc, shp, apa)
        results[(st.number, comp)] = res
        per_stage_panels.setdefault(st.number, {})[comp] = (cm, by_cell)
        lines += ["", f"## {label}", ""]
        if cm.dropped:
            lines.append(f"Note: {table.attrs['note']}.")
        lines += apa or ["No significant effect."]
        n_bad = int((~shp["normal"]).sum())
        untestable = table["p_spher"].isna()
        rejected = ~table["sphericity"] & ~untestable
        text = (f"\nShapiro-Wilk: {n_bad} of {len(shp)} cells deviate from normality at alpha = {alpha} "
                f"(see the Q-Q plots). Mauchly: sphericity rejected for "
                f"{', '.join(table.loc[rejected, 'Source']) or 'no effect'}.")
        if untestable.any():
            text += (f" Not testable with {len(cm.subjects)} participants (fewer than df + 1): "
                     f"{', '.join(table.loc[untestable, 'Source'])}; treated as violated.")
        lines.append(text)
        if out is not None:
            d = out / _stage_dir(st)
            files += write_table(table, d / f"{comp}_anova", formats=("csv",))   # every column
            files += write_table(table[_REPORTED], d / f"{comp}_anova", formats=("md", "tex"),
                                 caption=f"{label}: repeated-measures ANOVA")
            files += write_table(ph, d / f"{comp}_posthoc", formats=("csv",))
            files += write_table(ph[_POSTHOC_REPORTED] if len(ph) else ph, d / f"{comp}_posthoc",
                                 formats=("md", "tex"), caption=f"{label}: post hoc ({adjust})")
            files += write_table(by_cell, d / f"{comp}_method_by_cell", formats=("csv",))
            cells = desc[desc["effect"] == ":".join(factors)]
            files += write_table(desc, d / f"{comp}_descriptives", formats=("csv",))
            files += write_table(cells[[*factors, "n", "mean_sd"]], d / f"{comp}_descriptives", formats=("md", "tex"),
                                 caption=f"{label}: mean +- SD per condition")
            files += write_table(shp, d / f"{comp}_shapiro", formats=("csv",))
            if figures:
                from crowdstudy.stats.figures import method_figure
                files.append(qq_figure_from_cells(cm, d / f"{comp}_qq.png", title=f"{label}: residual Q-Q plots",
                                                  shapiro=shp))
            if figures and "Density" in factors:
                files.append(method_figure({comp: (cm, by_cell)}, d / f"{comp}_by_density.png",
                                           density_values=design.densities, error=error, title=label + figure_note))
    if out is not None:
        if figures:
            from crowdstudy.stats.figures import method_figure
            for st in chosen:
                panels = per_stage_panels[st.number]
                if "Density" not in next(iter(panels.values()))[0].factors:
                    continue
                files.append(method_figure(panels, out / _stage_dir(st) / "scores_by_density.png",
                                           density_values=design.densities, error=error,
                                           title=f"Stage {st.number} ({st.scenario}){figure_note}"))
        files += write_table(reliability, out / "reliability", caption="Item-pair reliability")
        summary_path = out / "summary.md"
        summary_path.write_text("\n".join(lines) + "\n")
        files.append(summary_path)
        record = {"provenance": provenance(None, design=str(design.source)),
                  "settings": {"correction": correction, "alpha": alpha, "effsize": effsize, "adjust": adjust,
                               "missing": missing},
                  "participants": int(data["participant_id"].nunique()),
                  "results": [{"stage": r.stage, "scenario": r.scenario, "composite": r.composite,
                               "n_subjects": int(r.anova["n_subjects"].iloc[0]),
                               "dropped_subjects": [str(s) for s in r.anova.attrs.get("dropped_subjects", [])],
                               "effects": {row.Source: {"F": row.F, "ddof1": row.ddof1_used, "ddof2": row.ddof2_used,
                                                        "p": row.p, "np2": row.np2, "ng2": row.ng2,
                                                        "gg_corrected": bool(row.correction_applied)}
                                           for row in r.anova.itertuples()}}
                              for r in results.values()]}
        json_path = out / "analysis.json"
        json_path.write_text(json.dumps(record, indent=2, default=float) + "\n")
        files.append(json_path)
    return AnalysisResult(reliability=reliability, results=results, summary="\n".join(lines) + "\n", files=files)

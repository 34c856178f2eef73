"""The paper's whole analysis of exported responses (what ``crowdstudy analyze`` runs).

Per stage (scenario) and composite (QCR, QCA, QOR): per participant x cell means ->
3-way repeated-measures ANOVA (Density x Viewpoint x Method) -> Tukey post hoc tests for
every significant effect (with intervals, d_z, g_av) -> simple effects of Method per cell
and polynomial trends over Density -> the mixed model and ordinal checks of Method ->
descriptives (mean +- SD) -> Shapiro-Wilk and Q-Q plots -> paper-style figures -> APA
summary. Item-pair reliability is reported first; excluded participants (participants.csv)
are dropped before anything else.

Output folder layout (``out_dir``)::

    reliability.{csv,md,tex}
    summary.md                     APA text of every significant effect, per stage and composite
    analysis.json                  provenance, settings, key numbers
    stageN_<scenario>/
        <COMP>_anova.{csv,md,tex}  full table in the CSV, the reported columns in md/tex
        <COMP>_posthoc.{csv,md,tex}
        <COMP>_method_by_cell.csv  Method within every Density x Viewpoint cell (the figure's stars)
        <COMP>_simple_effects.{csv,md}  joint_tests of Method (and the other factors) per cell
        <COMP>_trends.{csv,md}     polynomial contrasts over Density (pooled and per Method)
        <COMP>_mixed_model.csv     fixed effects of the mixed model (all participants)
        <COMP>_ordinal.{csv,md}    signed-rank / sign tests of Method per cell and overall
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
from crowdstudy.stats.contrasts import polynomial_contrasts, simple_effects
from crowdstudy.stats.inputs import apply_exclusions, read_csv_file, read_participants, read_sidecar
from crowdstudy.stats.posthoc import POSTHOC_COLUMNS, pairwise_from_cells
from crowdstudy.stats.robust import mixed_model, ordinal_method_check
from crowdstudy.stats.report import (apa_summary, contrast_text, descriptives_from_cells, format_p, to_markdown,
                                     write_table)
from crowdstudy.stats.scoring import (cell_means, check_complete, composite_scores, item_reliability,
                                      validate_responses)

__all__ = ["analyze", "AnalysisResult", "CompositeResult", "FACTORS", "posthoc_for_significant"]

#: The within factors of the study's ANOVA, in order.
FACTORS = ("Density", "Viewpoint", "Method")

_REPORTED = ["Source", "ddof1_used", "ddof2_used", "F", "p", "np2", "ng2", "eps_GG", "W_spher", "p_spher",
             "correction_applied"]
_POSTHOC_REPORTED = ["effect", "factor", "by_level", "contrast", "estimate", "lower_CL", "upper_CL", "SE", "df", "t",
                     "p_adj", "dz"]


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


def posthoc_for_significant(cm, anova: pd.DataFrame, *, alpha: float, adjust: str = "tukey",
                            level: float = 0.95) -> pd.DataFrame:
    """Pairwise comparisons for every significant effect (``p < alpha`` in ``anova``):
    a main effect -> its levels; an interaction -> each of its factors within the levels
    of the others. Column ``effect`` names the ANOVA effect that triggered the test."""
    parts = []
    for _, row in anova.iterrows():
        if not row["p"] < alpha:
            continue
        factors = row["Source"].split(":")
        for f in factors:
            ph = pairwise_from_cells(cm, f, [g for g in factors if g != f], adjust=adjust, level=level)
            ph.insert(0, "effect", row["Source"])
            parts.append(ph)
    if not parts:
        return pd.DataFrame(columns=["effect", *POSTHOC_COLUMNS])
    return pd.concat(parts, ignore_index=True)


def _stars_shown(table: pd.DataFrame, alpha: float, rule: str) -> tuple[bool, str]:
    """Whether the figure's per-cell Method stars are drawn, and the ANOVA effect(s) that
    gate them: under ``"omnibus"`` only when the Method main effect or an interaction with
    Method is significant."""
    if rule == "always":
        return True, ""
    involved = table[table["Source"].str.split(":").map(lambda f: "Method" in f)]
    gate = " or ".join(involved["Source"])
    return bool((involved["p"] < alpha).any()), gate


def _stage_dir(stage) -> str:
    return f"stage{stage.number}_{stage.scenario}"


def _load(responses, participants, design):
    """(validated responses, source name, sidecar dict, Exclusions or None)."""
    side: dict = {}
    source = "responses"
    path = None
    if isinstance(responses, (str, Path)):
        path = Path(responses)
        source = str(path)
        side = read_sidecar(path)
        responses = read_csv_file(path, "responses")
    elif not isinstance(responses, pd.DataFrame):
        raise InvalidInputError(f"responses must be a DataFrame or a path, got {type(responses).__name__}")
    else:
        side = {"simulated": True} if responses.attrs.get("simulated") else {}
    if participants is None and path is not None and (path.parent / "participants.csv").is_file():
        participants = path.parent / "participants.csv"
    data = validate_responses(responses.reset_index(drop=True), design, source=source)
    excl = None
    if participants is not None and participants is not False:
        psrc = "participants" if isinstance(participants, pd.DataFrame) else str(participants)
        data, excl = apply_exclusions(data, read_participants(participants), psrc)
    check_complete(data, design, source=source)      # rows named by their index: the file's data rows
    return data, source, side, excl


def analyze(responses: pd.DataFrame | str | Path, design=None, out_dir: str | Path | None = None, *,
            correction="auto", alpha: float = 0.05, effsize: str = "np2", composites=None, stages=None,
            missing: str = "raise", adjust: str = "tukey", error: str = "sd", figures: bool = True,
            progress: bool = False, figure_note: str = "", participants=None, stars: str = "always",
            level: float = 0.95, simulated: bool | None = None, robustness: bool = True) -> AnalysisResult:
    """Run the paper's analysis; write tables, figures and the summary when ``out_dir`` is set.

    ``responses``: a DataFrame in the responses.csv schema or a path to the CSV (its
    sidecar ``STEM.json`` is read: ``"simulated": true`` marks the figures and summary).
    ``design``: a StudyDesign (default: the paper's). ``correction``/``alpha``/``effsize``/
    ``missing``: as :func:`~crowdstudy.stats.anova.rm_anova`. ``composites``/``stages``:
    subsets (default all; stages by number, each must be a stage of the design). ``adjust``:
    post hoc adjustment. ``error``: figure error bars ("sd", "se", "ci95").
    ``figure_note``: text appended to every figure title. ``participants``: the study
    export's participants.csv (path or DataFrame; default: participants.csv beside a
    responses path when it exists; False: none): excluded participants are dropped first
    and counted per reason in summary.md and analysis.json. ``stars``: ``"always"`` draws
    the per-cell Method stars, ``"omnibus"`` only where the ANOVA's Method effect or an
    interaction with Method is significant. ``level``: confidence level of the intervals.
    ``simulated``: overrides the sidecar (True prints "SIMULATED data" on every figure).
    ``robustness``: also fit the mixed model (all participants, incomplete ones too) and
    run the ordinal (signed-rank / sign) checks of the Method effect
    (:mod:`crowdstudy.stats.robust`), written beside the ANOVA.

    Each participant must answer each stimulus once (a repeated answer is an error naming
    participant, cell and rows) and every stage present must have all its design levels.
    """
    if design is None:
        from crowdstudy.design import load_design
        design = load_design()
    if stars not in ("always", "omnibus"):
        raise InvalidInputError(f"stars must be 'always' or 'omnibus', got {stars!r}")
    if not 0 < level < 1:
        raise InvalidInputError(f"level must be in (0, 1), got {level!r}")
    data, source, side, excl = _load(responses, participants, design)
    is_sim = bool(side.get("simulated", False)) if simulated is None else bool(simulated)
    sim_note = "SIMULATED data (not real participants)" if is_sim else ""
    comps = list(design.composites) if composites is None else list(composites)
    for c in comps:
        if c not in design.composites:
            raise InvalidInputError(f"unknown composite {c!r}; the design defines {', '.join(design.composites)}")
    numbers = [st.number for st in design.stages]
    for number in stages or ():
        if number not in numbers:
            raise InvalidInputError(f"stage {number!r} is not in the design ({design.source}); "
                                    f"it defines {', '.join(map(str, numbers))}")
    present = sorted(set(data["stage"]))
    chosen = [st for st in design.stages if st.number in present and (stages is None or st.number in stages)]
    if not chosen:
        raise InvalidInputError(f"no responses for the chosen stage(s) {stages}; responses hold stage(s) {present}")
    out = Path(out_dir) if out_dir is not None else None
    files: list[Path] = []
    reliability = item_reliability(data, design, by="scenario")
    scored = composite_scores(data, design)
    results: dict[tuple[int, str], CompositeResult] = {}
    lines = ["# Analysis summary", ""]
    if is_sim:
        lines += [f"**{sim_note}**" + (f": {side['note']}" if side.get("note") else ""), ""]
    lines += [f"Design: {design.name}", f"Participants: {data['participant_id'].nunique()}"]
    if excl is not None:
        lines.append(excl.text())
    lines += [f"Sphericity correction: {correction!r} (alpha = {alpha}); post hoc adjustment: {adjust}; "
              f"intervals: {100 * level:g}% ({adjust}-adjusted where the p is)", "",
              "## Item-pair reliability (after reversing the negative items)", "", to_markdown(reliability)]
    work = [(st, c) for st in chosen for c in comps]
    iterator = work
    if progress:
        from crowdstudy.progress import progress_bar
        iterator = progress_bar(work, desc="analysis", unit="anova", leave=False)
    per_stage_panels: dict[int, dict] = {}
    extras: dict[tuple[int, str], dict] = {}
    for st, comp in iterator:
        long = cell_means(scored, comp, design, stage=st.number)
        # a factor with a single level in this stage (a custom design with one viewpoint,
        # say) is left out of the model; Method must vary
        sizes = {"Density": len(design.densities), "Viewpoint": len(st.viewpoints), "Method": len(design.methods)}
        factors = [f for f in FACTORS if f == "Method" or sizes[f] > 1]
        try:
            cm = cell_matrix(long, comp, factors, "participant_id", missing=missing, duplicates="raise")
        except InvalidInputError as exc:
            raise InvalidInputError(f"{source}: stage {st.number} ({st.scenario}), {comp}: {exc}") from None
        table = anova_from_cells(cm, correction=correction, effsize=effsize, alpha=alpha)
        ph = posthoc_for_significant(cm, table, alpha=alpha, adjust=adjust, level=level)
        others = [f for f in factors if f != "Method"]
        by_cell = pairwise_from_cells(cm, "Method", others, adjust=adjust, level=level)
        method_main = pairwise_from_cells(cm, "Method", [], adjust=adjust, level=level)
        simple = simple_effects(cm, others) if others else None
        trends = (pd.concat([polynomial_contrasts(cm, "Density", level=level),
                             polynomial_contrasts(cm, "Density", "Method", level=level)], ignore_index=True)
                  if "Density" in factors else None)
        desc = descriptives_from_cells(cm, comp)
        shp = shapiro_from_cells(cm, alpha=alpha)
        label = f"Stage {st.number} ({st.scenario}), {comp}"
        apa = apa_summary(table, alpha=alpha, effsize=effsize, label=label)
        res = CompositeResult(st.number, st.scenario, comp, table, ph, by_cell, desc, shp, apa)
        results[(st.number, comp)] = res
        show, gate = _stars_shown(table, alpha, stars)
        per_stage_panels.setdefault(st.number, {})[comp] = (cm, by_cell if show else None, gate)
        extras[(st.number, comp)] = {"method": method_main, "simple": simple, "trends": trends,
                                     "mixed": None, "ordinal": None}
        if robustness:
            extras[(st.number, comp)].update(_robustness(long, comp, factors, cm, alpha))
        lines += ["", f"## {label}", ""]
        if table.attrs["note"]:
            lines.append(f"Note: {table.attrs['note']}.")
        lines += apa or ["No significant effect."]
        lines += ["", "Method: " + "; ".join(contrast_text(r, level) for r in method_main.to_dict("records")) + "."]
        if simple is not None:
            sig = simple[simple["term"] == "Method"]
            lines.append(f"Simple effects (Method within each {' x '.join(others)} cell, joint_tests, unadjusted): "
                         f"p < {alpha} in {int((sig['p'] < alpha).sum())} of {len(sig)} cells.")
        if trends is not None:
            lin = trends[(trends["contrast"] == "linear") & (trends["by"] == "Method")]
            lines.append("Linear trend over Density: " + "; ".join(
                f"{r['Method']} {r['estimate']:.2f} [{r['lower_CL']:.2f}, {r['upper_CL']:.2f}] "
                f"(coefficients {r['coefficients']})" for r in lin.to_dict("records")) + ".")
        lines += _robustness_lines(extras[(st.number, comp)], table, alpha)
        n_bad = int((~shp["normal"]).sum())
        untestable = table["p_spher"].isna() & ~table["F"].isna()
        rejected = ~table["sphericity"] & table["p_spher"].notna()
        text = (f"\nShapiro-Wilk: {n_bad} of {len(shp)} cells deviate from normality at alpha = {alpha} "
                f"(see the Q-Q plots). Mauchly: sphericity rejected for "
                f"{', '.join(table.loc[rejected, 'Source']) or 'no effect'}.")
        if untestable.any():
            text += (f" Not testable with {len(cm.subjects)} participants (fewer than df + 1): "
                     f"{', '.join(table.loc[untestable, 'Source'])}; treated as violated.")
        lines.append(text)
        if not show:
            lines.append(f"Figure stars omitted: the ANOVA's {gate} effect is not significant (--stars omnibus).")
        if out is not None:
            files += _write_composite(out / _stage_dir(st), comp, label, res, factors, adjust,
                                      extras[(st.number, comp)])
            if figures:
                from crowdstudy.stats.figures import method_figure, stars_caption
                d = out / _stage_dir(st)
                files.append(qq_figure_from_cells(cm, d / f"{comp}_qq.png", title=f"{label}: residual Q-Q plots",
                                                  shapiro=shp))
                if "Density" in factors:
                    caption = stars_caption(adjust, len(design.methods), rule=stars, gate=gate)
                    files.append(method_figure({comp: per_stage_panels[st.number][comp][:2]},
                                               d / f"{comp}_by_density.png", density_values=design.densities,
                                               error=error, title=label + figure_note, caption=caption,
                                               note=sim_note))
    if out is not None:
        if figures:
            from crowdstudy.stats.figures import method_figure, stars_caption
            for st in chosen:
                panels = per_stage_panels[st.number]
                if "Density" not in next(iter(panels.values()))[0].factors:
                    continue
                gates = sorted({g for _, _, g in panels.values() if g})
                files.append(method_figure({k: v[:2] for k, v in panels.items()},
                                           out / _stage_dir(st) / "scores_by_density.png",
                                           density_values=design.densities, error=error,
                                           title=f"Stage {st.number} ({st.scenario}){figure_note}",
                                           caption=stars_caption(adjust, len(design.methods), rule=stars,
                                                                 gate=gates[0] if gates else ""),
                                           note=sim_note))
        files += write_table(reliability, out / "reliability", caption="Item-pair reliability")
        summary_path = out / "summary.md"
        summary_path.write_text("\n".join(lines) + "\n")
        files.append(summary_path)
        record = {"provenance": provenance(None, design=str(design.source)),
                  "settings": {"correction": correction, "alpha": alpha, "effsize": effsize, "adjust": adjust,
                               "missing": missing, "stars": stars, "level": level},
                  "source": source, "simulated": is_sim,
                  "participants": int(data["participant_id"].nunique()),
                  "exclusions": excl.as_dict() if excl is not None else None,
                  "results": [_record(r, extras[key]) for key, r in results.items()]}
        json_path = out / "analysis.json"
        json_path.write_text(json.dumps(record, indent=2, default=float) + "\n")
        files.append(json_path)
    return AnalysisResult(reliability=reliability, results=results, summary="\n".join(lines) + "\n", files=files)


def _robustness(long: pd.DataFrame, comp: str, factors: list[str], cm, alpha: float) -> dict:
    out: dict = {"ordinal": ordinal_method_check(cm, alpha=alpha), "mixed": None, "mixed_note": ""}
    try:
        out["mixed"] = mixed_model(long, comp, factors, "participant_id",
                                   levels={f: list(lv) for f, lv in zip(cm.factors, cm.levels)})
    except InvalidInputError as exc:          # degenerate data: said in the summary, not fatal
        out["mixed_note"] = str(exc)
    return out


def _robustness_lines(extra: dict, table: pd.DataFrame, alpha: float) -> list[str]:
    lines = []
    anova_p = float(table.set_index("Source").at["Method", "p"])
    mm = extra.get("mixed")
    if mm is not None:
        m = mm.method
        lines.append(f"Robustness, mixed model (REML; random intercept and Method slope per participant; "
                     f"{mm.n_participants} participants ({mm.n_incomplete} incomplete, kept), "
                     f"{mm.n_obs} cell scores): {m['contrast']} = {m['estimate']:.2f}, 95% CI "
                     f"[{m['lower_CL']:.2f}, {m['upper_CL']:.2f}], Wald z = {m['z']:.2f}, {format_p(m['p'])} "
                     f"(ANOVA Method: {format_p(anova_p)}).")
    elif extra.get("mixed_note"):
        lines.append(f"Robustness: {extra['mixed_note']}.")
    od = extra.get("ordinal")
    if od is not None:
        allrow = od[od["cell"] == "all"].iloc[0]
        cells = od[od["cell"] != "all"]
        lines.append(f"Robustness, ordinal check (no interval assumption; {od.attrs['contrast']} per participant): "
                     f"Wilcoxon signed-rank on each participant's mean difference V = {allrow['V']:g}, "
                     f"{format_p(allrow['p_wilcoxon'])}; sign test {int(allrow['n_pos'])}+/{int(allrow['n_neg'])}-, "
                     f"{format_p(allrow['p_sign'])}. Per cell: Wilcoxon p < {alpha} in "
                     f"{int((cells['p_wilcoxon'] < alpha).sum())} of {len(cells)} cells, paired t in "
                     f"{int((cells['p_t'] < alpha).sum())}; the two agree in {int(cells['agree'].sum())}.")
    return lines


def _record(r: CompositeResult, extra: dict) -> dict:
    m = extra["method"].iloc[0]
    robust = {}
    if extra.get("mixed") is not None:
        mm = extra["mixed"]
        robust["mixed_model"] = {**mm.method, "variances": mm.variances, "loglik": mm.loglik, "n_obs": mm.n_obs,
                                 "n_participants": mm.n_participants, "n_incomplete": mm.n_incomplete}
    if extra.get("ordinal") is not None:
        a = extra["ordinal"][extra["ordinal"]["cell"] == "all"].iloc[0]
        robust["ordinal_all_cells"] = {"V": float(a["V"]), "p_wilcoxon": float(a["p_wilcoxon"]),
                                       "p_sign": float(a["p_sign"]), "n_pos": int(a["n_pos"]),
                                       "n_neg": int(a["n_neg"])}
    return {"stage": r.stage, "scenario": r.scenario, "composite": r.composite,
            "n_subjects": int(r.anova["n_subjects"].iloc[0]),
            "dropped_subjects": [str(s) for s in r.anova.attrs.get("dropped_subjects", [])],
            "undefined_effects": list(r.anova.attrs.get("undefined", [])),
            "effects": {row.Source: {"F": row.F, "ddof1": row.ddof1_used, "ddof2": row.ddof2_used,
                                     "p": row.p, "np2": row.np2, "ng2": row.ng2,
                                     "gg_corrected": bool(row.correction_applied)}
                        for row in r.anova.itertuples()},
            "method_contrast": {k: (m[k] if isinstance(m[k], str) else float(m[k]))
                                for k in ("contrast", "estimate", "lower_CL", "upper_CL", "ci_adjust", "dz",
                                          "dz_low", "dz_high", "g_av", "g_av_low", "g_av_high")},
            "robustness": robust}


def _write_composite(d: Path, comp: str, label: str, res: CompositeResult, factors: list[str], adjust: str,
                     extra: dict) -> list[Path]:
    files = write_table(res.anova, d / f"{comp}_anova", formats=("csv",))   # every column
    files += write_table(res.anova[_REPORTED], d / f"{comp}_anova", formats=("md", "tex"),
                         caption=f"{label}: repeated-measures ANOVA")
    ph = res.posthoc
    files += write_table(ph, d / f"{comp}_posthoc", formats=("csv",))
    files += write_table(ph[_POSTHOC_REPORTED] if len(ph) else ph, d / f"{comp}_posthoc",
                         formats=("md", "tex"), caption=f"{label}: post hoc ({adjust}), 95% CI, d_z")
    files += write_table(res.method_by_cell, d / f"{comp}_method_by_cell", formats=("csv",))
    if extra["simple"] is not None:
        files += write_table(extra["simple"], d / f"{comp}_simple_effects", formats=("csv", "md"),
                             caption=f"{label}: simple effects (emmeans joint_tests, multivariate model)")
    if extra.get("mixed") is not None:
        files += write_table(extra["mixed"].fixed, d / f"{comp}_mixed_model", formats=("csv",))
    if extra.get("ordinal") is not None:
        files += write_table(extra["ordinal"], d / f"{comp}_ordinal", formats=("csv", "md"),
                             caption=f"{label}: Method without interval assumptions (signed-rank, sign test)")
    if extra["trends"] is not None:
        files += write_table(extra["trends"], d / f"{comp}_trends", formats=("csv", "md"),
                             caption=f"{label}: polynomial contrasts over Density")
    cells = res.descriptives[res.descriptives["effect"] == ":".join(factors)]
    files += write_table(res.descriptives, d / f"{comp}_descriptives", formats=("csv",))
    files += write_table(cells[[*factors, "n", "mean_sd"]], d / f"{comp}_descriptives", formats=("md", "tex"),
                         caption=f"{label}: mean +- SD per condition")
    files += write_table(res.shapiro, d / f"{comp}_shapiro", formats=("csv",))
    return files

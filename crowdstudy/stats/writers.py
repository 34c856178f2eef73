"""Writing a computed analysis (:class:`~crowdstudy.stats.results.AnalysisResult`) to a
folder: tables (CSV, Markdown, LaTeX), figures, summary.md and analysis.json.

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
        <COMP>_friedman.csv        Friedman's test of the k methods per cell (k > 2)
        2afc_*                     a 2AFC stage's tables and figures
                                   (:mod:`crowdstudy.stats.choice_report`)

A slider stage's tables are those of a Likert stage, on the 0-100 scale, their captions and
the summary naming the scale.

The figures (matplotlib) are drawn only when the options ask for them, and imported only
then.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pandas as pd

from crowdstudy.design import Stage
from crowdstudy.provenance import provenance
from crowdstudy.stats._data import CellMatrix
from crowdstudy.stats.report import write_table
from crowdstudy.stats.results import AnalysisResult, CompositeResult

__all__ = ["write_analysis", "write_composite_tables", "analysis_record"]

_REPORTED = [
    "Source",
    "ddof1_used",
    "ddof2_used",
    "F",
    "p",
    "np2",
    "ng2",
    "eps_GG",
    "W_spher",
    "p_spher",
    "correction_applied",
]
_ORDINAL_KEYS = ("contrast", "V", "p_wilcoxon", "p_wilcoxon_holm", "p_sign", "p_sign_holm", "n_pos", "n_neg")
_POSTHOC_REPORTED = [
    "effect",
    "factor",
    "by_level",
    "contrast",
    "estimate",
    "lower_CL",
    "upper_CL",
    "SE",
    "df",
    "t",
    "p_adj",
    "dz",
]


def write_analysis(result: AnalysisResult, summary: str, out_dir: Path) -> list[Path]:
    """Write every table and figure of ``result``, ``summary`` (summary.md) and
    analysis.json under ``out_dir``; returns the files written, in order."""
    from crowdstudy.stats.choice_report import choice_figures, write_choice_tables

    files: list[Path] = []
    for res in result.results.values():
        d = out_dir / _stage_dir(res.stage, res.scenario)
        files += write_composite_tables(res, d, result.options.adjust)
        if result.options.figures:
            files += _composite_figures(result, res, d)
    if result.options.figures:
        for st in result.stages:
            if any(number == st.number for number, _ in result.results):
                files += _stage_figure(result, st, out_dir / _stage_dir(st.number, st.scenario))
    for number, ch in result.choices.items():
        d = out_dir / _stage_dir(number, ch.scenario)
        files += write_choice_tables(ch, d)
        if result.options.figures:
            files += choice_figures(ch, d, result.design.densities, note=result.simulated_note)
    if len(result.reliability):
        files += write_table(result.reliability, out_dir / "reliability", caption="Item-pair reliability")
    summary_path = out_dir / "summary.md"
    summary_path.write_text(summary)
    files.append(summary_path)
    json_path = out_dir / "analysis.json"
    json_path.write_text(json.dumps(analysis_record(result), indent=2, default=float) + "\n")
    files.append(json_path)
    return files


def _stage_dir(number: int, scenario: str) -> str:
    return f"stage{number}_{scenario}"


def write_composite_tables(res: CompositeResult, d: Path, adjust: str) -> list[Path]:
    """The tables of one (stage, composite) in folder ``d`` (see the module docstring)."""
    comp, label = res.composite, res.label
    method, density = res.names.method, res.names.density
    files = write_table(res.anova, d / f"{comp}_anova", formats=("csv",))  # every column
    files += write_table(
        res.anova[_REPORTED], d / f"{comp}_anova", formats=("md", "tex"), caption=f"{label}: repeated-measures ANOVA"
    )
    ph = res.posthoc
    files += write_table(ph, d / f"{comp}_posthoc", formats=("csv",))
    files += write_table(
        ph[_POSTHOC_REPORTED] if len(ph) else ph,
        d / f"{comp}_posthoc",
        formats=("md", "tex"),
        caption=f"{label}: post hoc ({adjust}), 95% CI, d_z",
    )
    files += write_table(res.method_by_cell, d / f"{comp}_method_by_cell", formats=("csv",))
    if res.simple_effects is not None:
        files += write_table(
            res.simple_effects,
            d / f"{comp}_simple_effects",
            formats=("csv", "md"),
            caption=f"{label}: simple effects (emmeans joint_tests, multivariate model)",
        )
    rob = res.robustness
    if rob is not None and rob.mixed is not None:
        files += write_table(rob.mixed.fixed, d / f"{comp}_mixed_model", formats=("csv",))
    if rob is not None:
        files += write_table(
            rob.ordinal,
            d / f"{comp}_ordinal",
            formats=("csv", "md"),
            caption=f"{label}: {method} without interval assumptions (signed-rank, sign test)",
        )
    if rob is not None and rob.friedman is not None:
        files += write_table(rob.friedman, d / f"{comp}_friedman", formats=("csv",))
    if res.trends is not None:
        files += write_table(
            res.trends,
            d / f"{comp}_trends",
            formats=("csv", "md"),
            caption=f"{label}: polynomial contrasts over {density}",
        )
    factors = list(res.factors)
    cells = res.descriptives[res.descriptives["effect"] == ":".join(factors)]
    files += write_table(res.descriptives, d / f"{comp}_descriptives", formats=("csv",))
    files += write_table(
        cells[[*factors, "n", "mean_sd"]],
        d / f"{comp}_descriptives",
        formats=("md", "tex"),
        caption=f"{label}: mean +- SD per condition",
    )
    files += write_table(res.shapiro, d / f"{comp}_shapiro", formats=("csv",))
    return files


def _composite_figures(result: AnalysisResult, res: CompositeResult, d: Path) -> list[Path]:
    """The Q-Q plots of one (stage, composite) and, with Density in the model, its scores by density."""
    from crowdstudy.stats.assumptions import qq_figure_from_cells
    from crowdstudy.stats.figures import method_figure, stars_caption

    o, design = result.options, result.design
    files = [
        qq_figure_from_cells(
            res.cells, d / f"{res.composite}_qq.png", title=f"{res.label}: residual Q-Q plots", shapiro=res.shapiro
        )
    ]
    if res.names.density in res.factors:
        k = len(res.cells.levels[res.cells.factors.index(res.names.method)])
        caption = stars_caption(o.adjust, k, rule=o.stars, gate=res.stars_gate, method=res.names.method)
        files.append(
            method_figure(
                {res.composite: _panel(res)},
                d / f"{res.composite}_by_density.png",
                density_values=design.densities,
                error=o.error_bars,
                title=res.label + o.figure_note,
                caption=caption,
                note=result.simulated_note,
                **_scale_args(result, res),
            )
        )
    return files


def _scale_args(result: AnalysisResult, res: CompositeResult) -> dict:
    """method_figure's factor names and y range: the Likert points, or the slider's scale."""
    from crowdstudy.stats.scoring import scale_range

    lo, hi = scale_range(result.design, res.task)
    return {"names": res.names, "ylim": (float(lo), float(hi)), "scale": res.scale}


def _stage_figure(result: AnalysisResult, stage: Stage, d: Path) -> list[Path]:
    """scores_by_density.png: every composite of one stage (none without Density in the model)."""
    from crowdstudy.stats.figures import method_figure, stars_caption

    o, design = result.options, result.design
    comps = [res for (number, _), res in result.results.items() if number == stage.number]
    first = comps[0]
    if first.names.density not in first.factors:
        return []
    gates = sorted({res.stars_gate for res in comps if res.stars_gate})
    k = len(first.cells.levels[first.cells.factors.index(first.names.method)])
    return [
        method_figure(
            {res.composite: _panel(res) for res in comps},
            d / "scores_by_density.png",
            density_values=design.densities,
            error=o.error_bars,
            title=f"Stage {stage.number} ({stage.scenario}){o.figure_note}",
            caption=stars_caption(o.adjust, k, rule=o.stars, gate=gates[0] if gates else "", method=first.names.method),
            note=result.simulated_note,
            **_scale_args(result, first),
        )
    ]


def _panel(res: CompositeResult) -> tuple[CellMatrix, pd.DataFrame | None]:
    """One composite's panel of :func:`~crowdstudy.stats.figures.method_figure`: its cells
    and, where the stars are shown, the per-cell Method comparisons."""
    return res.cells, res.method_by_cell if res.stars_shown else None


def analysis_record(result: AnalysisResult) -> dict:
    """analysis.json: provenance, settings, participants, exclusions and the key numbers
    of every (stage, composite)."""
    ex = result.exclusions
    return {
        "provenance": provenance(None, design=str(result.design.source)),
        "settings": result.options.settings(),
        "source": result.source,
        "simulated": result.simulated,
        "participants": result.n_participants,
        "exclusions": ex.as_dict() if ex is not None else None,
        "results": [_composite_record(r) for r in result.results.values()],
        "factors": dataclasses.asdict(result.names),
        "stages": [_stage_record(result, st) for st in result.stages],
    }


def _stage_record(result: AnalysisResult, stage: Stage) -> dict:
    """One stage's entry of analysis.json: its task, methods (the reference first) and every
    result (a rating stage's composites as in ``results``; a 2AFC stage's shares, pair
    models and Bradley-Terry scale)."""
    from crowdstudy.stats.choice_report import choice_record

    entry = {
        "stage": stage.number,
        "key": stage.key,
        "scenario": stage.scenario,
        "task": stage.task,
        "methods": list(stage.methods),
        "pairs": [list(p) for p in stage.pairs],
    }
    if stage.number in result.choices:
        entry.update(choice_record(result.choices[stage.number]))
    else:
        comps = [r for (n, _), r in result.results.items() if n == stage.number]
        entry["scale"] = comps[0].scale if comps and comps[0].scale else f"likert 1-{result.design.likert_points}"
        entry["results"] = [_composite_record(r) for r in comps]
    return entry


def _composite_record(r: CompositeResult) -> dict:
    m = r.method.iloc[0]
    robust = {}
    rob = r.robustness
    if rob is not None and rob.mixed is not None:
        mm = rob.mixed
        robust["mixed_model"] = {
            **mm.method,
            "contrasts": mm.contrasts.to_dict("records") if mm.contrasts is not None else [mm.method],
            "variances": mm.variances,
            "loglik": mm.loglik,
            "n_obs": mm.n_obs,
            "n_participants": mm.n_participants,
            "n_incomplete": mm.n_incomplete,
        }
    if rob is not None:
        alls = rob.ordinal[rob.ordinal["cell"] == "all"]
        a = alls.iloc[0]
        robust["ordinal_all_cells"] = {
            "V": float(a["V"]),
            "p_wilcoxon": float(a["p_wilcoxon"]),
            "p_sign": float(a["p_sign"]),
            "n_pos": int(a["n_pos"]),
            "n_neg": int(a["n_neg"]),
        }
        if "contrast" in alls.columns:
            robust["ordinal_all_cells_by_contrast"] = [
                {k: (v if isinstance(v, str) else float(v)) for k, v in row.items() if k in _ORDINAL_KEYS}
                for row in alls.to_dict("records")
            ]
        if rob.friedman is not None:
            f = rob.friedman[rob.friedman["cell"] == "all"].iloc[0]
            robust["friedman_all_cells"] = {k: float(f[k]) for k in ("chi2", "df", "p", "n", "k")}
    return {
        "stage": r.stage,
        "scenario": r.scenario,
        "composite": r.composite,
        "n_subjects": int(r.anova["n_subjects"].iloc[0]),
        "dropped_subjects": [str(s) for s in r.anova.attrs.get("dropped_subjects", [])],
        "undefined_effects": list(r.anova.attrs.get("undefined", [])),
        "effects": {
            row.Source: {
                "F": row.F,
                "ddof1": row.ddof1_used,
                "ddof2": row.ddof2_used,
                "p": row.p,
                "np2": row.np2,
                "ng2": row.ng2,
                "gg_corrected": bool(row.correction_applied),
            }
            for row in r.anova.itertuples()
        },
        "task": r.task,
        "method_factor": r.names.method,
        "method_contrasts": r.method[["contrast", "estimate", "lower_CL", "upper_CL", "p_adj"]].to_dict("records"),
        "method_contrast": {
            k: (m[k] if isinstance(m[k], str) else float(m[k]))
            for k in (
                "contrast",
                "estimate",
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
        },
        "robustness": robust,
    }

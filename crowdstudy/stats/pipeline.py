"""The paper's whole analysis of exported responses (what ``crowdstudy analyze`` runs).

Per stage (scenario) and composite (QCR, QCA, QOR): per participant x cell means ->
3-way repeated-measures ANOVA (Density x Viewpoint x Method) -> Tukey post hoc tests for
every significant effect (with intervals, d_z, g_av) -> simple effects of Method per cell
and polynomial trends over Density -> the mixed model and ordinal checks of Method ->
descriptives (mean +- SD) -> Shapiro-Wilk and Q-Q plots -> paper-style figures -> APA
summary. Item-pair reliability is reported first; excluded participants (participants.csv)
are dropped before anything else.

:func:`analyze` runs three steps, each usable alone:

1. :func:`~crowdstudy.stats.inputs.load_responses`: read and check the responses;
2. :func:`compute`: every number, as an :class:`~crowdstudy.stats.results.AnalysisResult`
   (no file is read or written);
3. :func:`~crowdstudy.stats.summary.summary_text` and
   :func:`~crowdstudy.stats.writers.write_analysis`: the APA summary, the tables, figures
   and analysis.json (the output folder's layout is described in
   :mod:`crowdstudy.stats.writers`).

The settings are one :class:`~crowdstudy.stats.options.AnalysisOptions`; the within
factors are passed to :func:`compute` (default
:data:`~crowdstudy.stats.scoring.FACTORS`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import pandas as pd

from crowdstudy.design import Stage, StudyDesign
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix, cell_matrix
from crowdstudy.stats.anova import anova_from_cells
from crowdstudy.stats.assumptions import shapiro_from_cells
from crowdstudy.stats.contrasts import polynomial_contrasts, simple_effects
from crowdstudy.stats.inputs import LoadedResponses, load_responses
from crowdstudy.stats.options import AnalysisOptions, StarsRule
from crowdstudy.stats.posthoc import POSTHOC_COLUMNS, pairwise_from_cells
from crowdstudy.stats.report import apa_summary, descriptives_from_cells
from crowdstudy.stats.results import AnalysisResult, CompositeResult, Robustness
from crowdstudy.stats.robust import mixed_model, ordinal_method_check
from crowdstudy.stats.scoring import FACTORS, cell_means, composite_scores, item_reliability

__all__ = ["analyze", "compute", "compute_composite", "AnalysisReport", "posthoc_for_significant"]


@dataclasses.dataclass(frozen=True)
class AnalysisReport:
    """What :func:`analyze` returns: the computed ``result``, the ``summary`` text (as
    summary.md holds it) and the ``files`` written (empty without an output folder)."""

    result: AnalysisResult
    summary: str
    files: list[Path]

    @property
    def results(self) -> dict[tuple[int, str], CompositeResult]:
        """(stage number, composite) -> :class:`~crowdstudy.stats.results.CompositeResult`."""
        return self.result.results

    @property
    def reliability(self) -> pd.DataFrame:
        return self.result.reliability


def analyze(
    responses: pd.DataFrame | str | Path,
    design: StudyDesign | None = None,
    out_dir: str | Path | None = None,
    options: AnalysisOptions | None = None,
    *,
    participants: str | Path | pd.DataFrame | Literal[False] | None = None,
    simulated: bool | None = None,
    progress: bool = False,
) -> AnalysisReport:
    """Run the paper's analysis; write tables, figures and the summary when ``out_dir`` is set.

    ``responses``: a DataFrame in the responses.csv schema or a path to the CSV (its
    sidecar ``STEM.json`` is read: ``"simulated": true`` marks the figures and summary).
    ``design``: a StudyDesign (default: the paper's). ``options``: the settings (default:
    the paper's, :class:`~crowdstudy.stats.options.AnalysisOptions`). ``participants``:
    the study export's participants.csv (path or DataFrame; default: participants.csv
    beside a responses path when it exists; False: none): excluded participants are
    dropped first and counted per reason in summary.md and analysis.json. ``simulated``:
    overrides the sidecar (True prints "SIMULATED data" on every figure). ``progress``: a
    progress bar over the ANOVAs.

    Each participant must answer each stimulus once (a repeated answer is an error naming
    participant, cell and rows) and every stage present must have all its design levels.
    """
    if design is None:
        from crowdstudy.design import load_design

        design = load_design()
    options = AnalysisOptions() if options is None else options
    loaded = load_responses(responses, design, participants=participants, simulated=simulated)
    result = compute(loaded, design, options, progress=progress)
    from crowdstudy.stats.summary import summary_text

    summary = summary_text(result)
    files: list[Path] = []
    if out_dir is not None:
        from crowdstudy.stats.writers import write_analysis

        files = write_analysis(result, summary, Path(out_dir))
    return AnalysisReport(result=result, summary=summary, files=files)


def compute(
    responses: LoadedResponses,
    design: StudyDesign,
    options: AnalysisOptions,
    *,
    factors: Sequence[str] = FACTORS,
    progress: bool = False,
) -> AnalysisResult:
    """Every number of the analysis of ``responses`` (from
    :func:`~crowdstudy.stats.inputs.load_responses`), without file I/O.

    ``factors``: the within factors of the ANOVA, in order (columns of
    :func:`~crowdstudy.stats.scoring.cell_means`); one with a single level in a stage is
    left out of that stage's model, except Method, which must vary."""
    chosen, comps = _selection(responses, design, options)
    data = responses.data
    reliability = item_reliability(data, design, by="scenario")
    scored = composite_scores(data, design)
    results: dict[tuple[int, str], CompositeResult] = {}
    work = [(st, c) for st in chosen for c in comps]
    iterator = work
    if progress:
        from crowdstudy.progress import progress_bar

        iterator = progress_bar(work, desc="analysis", unit="anova", leave=False)
    for st, comp in iterator:
        results[(st.number, comp)] = compute_composite(
            scored, design, st, comp, factors, options, source=responses.source
        )
    return AnalysisResult(
        design=design,
        options=options,
        stages=tuple(chosen),
        source=responses.source,
        simulated=responses.simulated,
        note=responses.note,
        n_participants=int(data["participant_id"].nunique()),
        exclusions=responses.exclusions,
        reliability=reliability,
        results=results,
    )


def _selection(
    responses: LoadedResponses, design: StudyDesign, options: AnalysisOptions
) -> tuple[list[Stage], list[str]]:
    """The stages (present in the responses and chosen) and composites to analyse."""
    comps = list(design.composites) if options.composites is None else list(options.composites)
    for c in comps:
        if c not in design.composites:
            raise InvalidInputError(f"unknown composite {c!r}; the design defines {', '.join(design.composites)}")
    stages = None if options.stages is None else list(options.stages)
    numbers = [st.number for st in design.stages]
    for number in stages or ():
        if number not in numbers:
            raise InvalidInputError(
                f"stage {number!r} is not in the design ({design.source}); it defines {', '.join(map(str, numbers))}"
            )
    present = sorted(set(responses.data["stage"]))
    chosen = [st for st in design.stages if st.number in present and (stages is None or st.number in stages)]
    if not chosen:
        raise InvalidInputError(f"no responses for the chosen stage(s) {stages}; responses hold stage(s) {present}")
    return chosen, comps


def compute_composite(
    scored: pd.DataFrame,
    design: StudyDesign,
    stage: Stage,
    comp: str,
    factors: Sequence[str],
    options: AnalysisOptions,
    *,
    source: str = "responses",
) -> CompositeResult:
    """The analysis of one (stage, composite): ``scored`` from
    :func:`~crowdstudy.stats.scoring.composite_scores`."""
    o = options
    long = cell_means(scored, comp, design, stage=stage.number)
    # a factor with a single level in this stage (a custom design with one viewpoint,
    # say) is left out of the model; Method must vary
    used = [f for f in factors if f == "Method" or long[f].nunique() > 1]
    try:
        cm = cell_matrix(long, comp, used, "participant_id", missing=o.missing, duplicates="raise")
    except InvalidInputError as exc:
        raise InvalidInputError(f"{source}: stage {stage.number} ({stage.scenario}), {comp}: {exc}") from None
    table = anova_from_cells(cm, correction=o.anova_correction, effsize=o.effsize, alpha=o.alpha)
    others = [f for f in used if f != "Method"]
    trends = (
        pd.concat(
            [
                polynomial_contrasts(cm, "Density", level=o.level),
                polynomial_contrasts(cm, "Density", "Method", level=o.level),
            ],
            ignore_index=True,
        )
        if "Density" in used
        else None
    )
    show, gate = _stars_shown(table, o.alpha, o.stars)
    label = f"Stage {stage.number} ({stage.scenario}), {comp}"
    return CompositeResult(
        stage=stage.number,
        scenario=stage.scenario,
        composite=comp,
        factors=tuple(used),
        cells=cm,
        anova=table,
        posthoc=posthoc_for_significant(cm, table, alpha=o.alpha, adjust=o.adjust, level=o.level),
        method_by_cell=pairwise_from_cells(cm, "Method", others, adjust=o.adjust, level=o.level),
        method=pairwise_from_cells(cm, "Method", [], adjust=o.adjust, level=o.level),
        simple_effects=simple_effects(cm, others) if others else None,
        trends=trends,
        descriptives=descriptives_from_cells(cm, comp),
        shapiro=shapiro_from_cells(cm, alpha=o.alpha),
        apa=apa_summary(table, alpha=o.alpha, effsize=o.effsize, label=label),
        robustness=_robustness(long, comp, used, cm, o.alpha) if o.robustness else None,
        stars_shown=show,
        stars_gate=gate,
    )


def posthoc_for_significant(
    cm: CellMatrix, anova: pd.DataFrame, *, alpha: float, adjust: str = "tukey", level: float = 0.95
) -> pd.DataFrame:
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


def _stars_shown(table: pd.DataFrame, alpha: float, rule: StarsRule) -> tuple[bool, str]:
    """Whether the figure's per-cell Method stars are drawn, and the ANOVA effect(s) that
    gate them: under ``"omnibus"`` only when the Method main effect or an interaction with
    Method is significant."""
    if rule == "always":
        return True, ""
    involved = table[table["Source"].str.split(":").map(lambda f: "Method" in f)]
    gate = " or ".join(involved["Source"])
    return bool((involved["p"] < alpha).any()), gate


def _robustness(long: pd.DataFrame, comp: str, factors: list[str], cm: CellMatrix, alpha: float) -> Robustness:
    ordinal = ordinal_method_check(cm, alpha=alpha)
    try:
        mixed = mixed_model(
            long,
            comp,
            factors,
            "participant_id",
            levels={f: list(lv) for f, lv in zip(cm.factors, cm.levels, strict=True)},
        )
    except InvalidInputError as exc:  # degenerate data: said in the summary, not fatal
        return Robustness(ordinal=ordinal, mixed=None, mixed_note=str(exc))
    return Robustness(ordinal=ordinal, mixed=mixed)

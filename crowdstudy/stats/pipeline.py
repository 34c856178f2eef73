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
from crowdstudy.stats.robust import friedman_test, mixed_model, ordinal_method_check
from crowdstudy.stats.scoring import FACTOR_NAMES, FactorNames, cell_means, composite_scores, item_reliability

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
    comparisons: str | Path | pd.DataFrame | Literal[False] | None = None,
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
    progress bar over the ANOVAs. ``comparisons``: the 2AFC trials (comparisons.csv, path
    or DataFrame; default: comparisons.csv beside a responses path when it exists; False:
    none); each 2afc stage of the design present in them is analysed
    (:mod:`crowdstudy.stats.comparisons`). A responses file without rows is allowed when
    there are comparisons (a design whose stages are all 2afc).

    Each participant must answer each stimulus once (a repeated answer is an error naming
    participant, cell and rows) and every stage present must have all its design levels.
    """
    if design is None:
        from crowdstudy.design import load_design

        design = load_design()
    options = AnalysisOptions() if options is None else options
    if comparisons is None and isinstance(responses, (str, Path)):
        beside = Path(responses).parent / "comparisons.csv"
        comparisons = beside if beside.is_file() else None
    choices = None
    if comparisons is not None and comparisons is not False:
        from crowdstudy.stats.comparisons import load_comparisons

        if participants is None and isinstance(responses, (str, Path)):
            beside = Path(responses).parent / "participants.csv"
            participants = beside if beside.is_file() else None
        choices, _ = load_comparisons(
            comparisons, design, participants=participants if participants is not False else None
        )
    loaded = load_responses(
        responses, design, participants=participants, simulated=simulated, allow_empty=choices is not None
    )
    result = compute(loaded, design, options, progress=progress, comparisons=choices)
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
    factors: Sequence[str] | None = None,
    names: FactorNames = FACTOR_NAMES,
    progress: bool = False,
    comparisons: pd.DataFrame | None = None,
) -> AnalysisResult:
    """Every number of the analysis of ``responses`` (from
    :func:`~crowdstudy.stats.inputs.load_responses`), without file I/O.

    ``names``: the names of the within factors (:class:`~crowdstudy.stats.scoring.FactorNames`;
    every table, figure and summary uses them); ``factors``: the within factors of the
    ANOVA, in order (default ``names.order``); one with a single level in a stage is left
    out of that stage's model, except the method factor, which must vary. Each stage is
    analysed by its task: ``likert`` and ``slider`` stages from ``responses``, ``2afc``
    stages from ``comparisons`` (validated by
    :func:`~crowdstudy.stats.comparisons.validate_comparisons`; None: none) with
    :func:`~crowdstudy.stats.comparisons.compute_choices`."""
    factors = names.order if factors is None else tuple(factors)
    chosen, comps, afc = _selection(responses, design, options, comparisons)
    data = responses.data
    reliability = _reliability(data, design) if len(data) else pd.DataFrame()
    scored = composite_scores(data, design) if len(data) else data
    results: dict[tuple[int, str], CompositeResult] = {}
    work = [(st, c) for st in chosen for c in comps]
    iterator = work
    if progress:
        from crowdstudy.progress import progress_bar

        iterator = progress_bar(work, desc="analysis", unit="anova", leave=False)
    for st, comp in iterator:
        results[(st.number, comp)] = compute_composite(
            scored, design, st, comp, factors, options, source=responses.source, names=names
        )
    choices = {}
    if afc:
        from crowdstudy.stats.comparisons import compute_choices

        choices = {st.number: compute_choices(comparisons, design, st, level=options.level, names=names) for st in afc}
    people = set(data["participant_id"].astype(str)) if len(data) else set()
    if comparisons is not None:
        people |= set(comparisons["participant_id"].astype(str))
    return AnalysisResult(
        design=design,
        options=options,
        stages=tuple(st for st in design.stages if st in chosen or st in afc),
        source=responses.source,
        simulated=responses.simulated,
        note=responses.note,
        n_participants=len(people),
        exclusions=responses.exclusions,
        reliability=reliability,
        results=results,
        names=names,
        choices=choices,
    )


def _reliability(data: pd.DataFrame, design: StudyDesign) -> pd.DataFrame:
    """Item-pair reliability per scenario; with slider stages, per scenario and task (a
    ``task`` column first), since the two scales do not mix."""
    from crowdstudy.stats.scoring import row_tasks

    tasks = row_tasks(data)
    if (tasks == "likert").all():
        return item_reliability(data, design, by="scenario")
    parts = []
    for task in dict.fromkeys(tasks):
        part = item_reliability(data[(tasks == task).to_numpy()], design, by="scenario")
        part.insert(0, "task", task)
        parts.append(part)
    return pd.concat(parts, ignore_index=True)


def _selection(
    responses: LoadedResponses, design: StudyDesign, options: AnalysisOptions, comparisons: pd.DataFrame | None
) -> tuple[list[Stage], list[str], list[Stage]]:
    """The rating stages (present in the responses and chosen), the composites and the
    2afc stages (present in the comparisons and chosen) to analyse."""
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
    present = sorted(set(responses.data["stage"])) if len(responses.data) else []
    chosen = [st for st in design.stages if st.number in present and (stages is None or st.number in stages)]
    compared = sorted(set(comparisons["stage"])) if comparisons is not None else []
    afc = [st for st in design.stages if st.number in compared and (stages is None or st.number in stages)]
    if not chosen and not afc:
        raise InvalidInputError(
            f"no responses for the chosen stage(s) {stages}; responses hold stage(s) {present}"
            + (f", comparisons stage(s) {compared}" if comparisons is not None else "")
        )
    return chosen, comps, afc


def compute_composite(
    scored: pd.DataFrame,
    design: StudyDesign,
    stage: Stage,
    comp: str,
    factors: Sequence[str],
    options: AnalysisOptions,
    *,
    source: str = "responses",
    names: FactorNames = FACTOR_NAMES,
) -> CompositeResult:
    """The analysis of one (stage, composite): ``scored`` from
    :func:`~crowdstudy.stats.scoring.composite_scores`."""
    o = options
    method, density = names.method, names.density
    long = cell_means(scored, comp, design, stage=stage.number, names=names)
    # a factor with a single level in this stage (a custom design with one viewpoint,
    # say) is left out of the model; the method factor must vary
    used = [f for f in factors if f == method or long[f].nunique() > 1]
    try:
        cm = cell_matrix(long, comp, used, "participant_id", missing=o.missing, duplicates="raise")
    except InvalidInputError as exc:
        raise InvalidInputError(f"{source}: stage {stage.number} ({stage.scenario}), {comp}: {exc}") from None
    table = anova_from_cells(cm, correction=o.anova_correction, effsize=o.effsize, alpha=o.alpha)
    others = [f for f in used if f != method]
    trends = (
        pd.concat(
            [
                polynomial_contrasts(cm, density, level=o.level),
                polynomial_contrasts(cm, density, method, level=o.level),
            ],
            ignore_index=True,
        )
        if density in used
        else None
    )
    show, gate = _stars_shown(table, o.alpha, o.stars, method)
    scale = _scale_name(design, stage)
    label = f"Stage {stage.number} ({stage.scenario}), {comp}" + (f" ({scale})" if scale else "")
    return CompositeResult(
        stage=stage.number,
        scenario=stage.scenario,
        composite=comp,
        factors=tuple(used),
        cells=cm,
        anova=table,
        posthoc=posthoc_for_significant(cm, table, alpha=o.alpha, adjust=o.adjust, level=o.level),
        method_by_cell=pairwise_from_cells(cm, method, others, adjust=o.adjust, level=o.level),
        method=pairwise_from_cells(cm, method, [], adjust=o.adjust, level=o.level),
        simple_effects=simple_effects(cm, others) if others else None,
        trends=trends,
        descriptives=descriptives_from_cells(cm, comp),
        shapiro=shapiro_from_cells(cm, alpha=o.alpha),
        apa=apa_summary(table, alpha=o.alpha, effsize=o.effsize, label=label),
        robustness=_robustness(long, comp, used, cm, o.alpha, method) if o.robustness else None,
        stars_shown=show,
        stars_gate=gate,
        names=names,
        task=stage.task,
        scale=scale,
    )


def _scale_name(design: StudyDesign, stage: Stage) -> str:
    """How the tables name a stage's answer scale: "" for the paper's Likert stages (their
    tables are as before), ``"slider 0-100"`` for a slider stage."""
    if stage.task == "slider":
        from crowdstudy.stats.scoring import scale_range

        lo, hi = scale_range(design, "slider")
        return f"slider {lo}-{hi}"
    return ""


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


def _stars_shown(table: pd.DataFrame, alpha: float, rule: StarsRule, method: str) -> tuple[bool, str]:
    """Whether the figure's per-cell method stars are drawn, and the ANOVA effect(s) that
    gate them: under ``"omnibus"`` only when the method main effect or an interaction with
    the method factor is significant."""
    if rule == "always":
        return True, ""
    involved = table[table["Source"].str.split(":").map(lambda f: method in f)]
    gate = " or ".join(involved["Source"])
    return bool((involved["p"] < alpha).any()), gate


def _robustness(
    long: pd.DataFrame, comp: str, factors: list[str], cm: CellMatrix, alpha: float, method: str
) -> Robustness:
    ordinal = ordinal_method_check(cm, alpha=alpha, method=method)
    k = len(cm.levels[cm.factors.index(method)])
    friedman = friedman_test(cm, method=method) if k > 2 else None
    try:
        mixed = mixed_model(
            long,
            comp,
            factors,
            "participant_id",
            levels={f: list(lv) for f, lv in zip(cm.factors, cm.levels, strict=True)},
            method=method,
        )
    except InvalidInputError as exc:  # degenerate data: said in the summary, not fatal
        return Robustness(ordinal=ordinal, mixed=None, mixed_note=str(exc), friedman=friedman)
    return Robustness(ordinal=ordinal, mixed=mixed, friedman=friedman)

"""What the analysis computes, as typed values: one :class:`CompositeResult` per (stage,
composite) and the whole :class:`AnalysisResult`. Computed by
:func:`~crowdstudy.stats.pipeline.compute` without touching a file; the writers
(:mod:`~crowdstudy.stats.writers`, :mod:`~crowdstudy.stats.summary`) turn them into tables,
text and figures."""

from __future__ import annotations

import dataclasses

import pandas as pd

from crowdstudy.design import Stage, StudyDesign
from crowdstudy.stats._data import CellMatrix
from crowdstudy.stats.comparisons import ChoiceResult
from crowdstudy.stats.inputs import Exclusions
from crowdstudy.stats.options import AnalysisOptions
from crowdstudy.stats.robust import MixedModelResult
from crowdstudy.stats.scoring import FACTOR_NAMES, FactorNames

__all__ = ["Robustness", "CompositeResult", "AnalysisResult"]


@dataclasses.dataclass(frozen=True)
class Robustness:
    """The checks of the Method effect beside the ANOVA: ``ordinal`` (signed-rank and
    sign tests per cell and over all cells, :func:`~crowdstudy.stats.robust.ordinal_method_check`)
    and ``mixed`` (the mixed model of every participant, incomplete ones too), or None with
    ``mixed_note`` saying why the model is undefined on these data."""

    ordinal: pd.DataFrame
    mixed: MixedModelResult | None
    mixed_note: str = ""
    #: Friedman's test over the k methods per cell (None with two methods)
    friedman: pd.DataFrame | None = None


@dataclasses.dataclass(frozen=True)
class CompositeResult:
    """Everything computed for one (stage, composite).

    ``factors``: the within factors of the model (a factor with a single level in this
    stage is left out); ``cells``: per participant x cell means as analysed. ``anova``:
    the repeated-measures ANOVA; ``posthoc``: pairwise comparisons for every significant
    effect; ``method_by_cell``: Method within every cell of the other factors (the
    figure's stars); ``method``: the Method main contrast; ``simple_effects`` (None
    without other factors) and ``trends`` (None without Density); ``descriptives``;
    ``shapiro``; ``apa``: one sentence per significant effect; ``robustness`` (None when
    not asked for). ``stars_shown``: whether the figure draws the per-cell stars, and
    ``stars_gate`` the ANOVA effect(s) that decide it under the ``"omnibus"`` rule.
    ``names``: the factor names; ``task``: the stage's task (``likert`` or ``slider``);
    ``scale``: "" for Likert, ``"slider 0-100"`` for a slider stage.
    """

    stage: int
    scenario: str
    composite: str
    factors: tuple[str, ...]
    cells: CellMatrix
    anova: pd.DataFrame
    posthoc: pd.DataFrame
    method_by_cell: pd.DataFrame
    method: pd.DataFrame
    simple_effects: pd.DataFrame | None
    trends: pd.DataFrame | None
    descriptives: pd.DataFrame
    shapiro: pd.DataFrame
    apa: list[str]
    robustness: Robustness | None
    stars_shown: bool
    stars_gate: str
    names: FactorNames = FACTOR_NAMES
    task: str = "likert"
    scale: str = ""

    @property
    def label(self) -> str:
        """``"Stage 1 (concert), QCR"``: the heading of its summary section and figures
        (a slider stage's ends with its scale, ``" (slider 0-100)"``)."""
        return f"Stage {self.stage} ({self.scenario}), {self.composite}" + (f" ({self.scale})" if self.scale else "")

    @property
    def method_factor(self) -> str:
        """The method factor's name (``names.method``)."""
        return self.names.method

    @property
    def others(self) -> tuple[str, ...]:
        """The factors other than the method: the cells the methods are compared within."""
        return tuple(f for f in self.factors if f != self.names.method)


@dataclasses.dataclass(frozen=True)
class AnalysisResult:
    """The whole analysis of one set of responses.

    ``design``, ``options``: what it ran on and how; ``stages``: the stages analysed, in
    the design's order; ``source``: where the responses came from (a path, or
    "responses"); ``simulated``: the responses are marked as simulated (``note``: the
    sidecar's note); ``n_participants``: participants after the exclusions
    (``exclusions``: who was dropped, or None without a participants table);
    ``reliability``: item-pair reliability per scenario; ``results``: (stage number,
    composite) -> :class:`CompositeResult`, stage by stage (rating stages: Likert and
    slider); ``names``: the factor names; ``choices``: stage number ->
    :class:`~crowdstudy.stats.comparisons.ChoiceResult` for each 2AFC stage analysed.
    """

    design: StudyDesign
    options: AnalysisOptions
    stages: tuple[Stage, ...]
    source: str
    simulated: bool
    note: str
    n_participants: int
    exclusions: Exclusions | None
    reliability: pd.DataFrame
    results: dict[tuple[int, str], CompositeResult]
    names: FactorNames = FACTOR_NAMES
    #: stage number -> the 2AFC analysis of that stage (comparisons.csv)
    choices: dict[int, ChoiceResult] = dataclasses.field(default_factory=dict)

    @property
    def simulated_note(self) -> str:
        """The warning printed on every figure of simulated data ("" otherwise)."""
        return "SIMULATED data (not real participants)" if self.simulated else ""

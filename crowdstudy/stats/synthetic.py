"""Synthetic participants: a generative model of Likert, slider and 2afc answers, for bots
and power analysis.

The model works on the *scored* scale (negative items already reversed, 1..6, higher =
better for the method) and writes *raw* answers, so a negative item (``reverse = true`` in
the design: Q2, Q4, Q6) moves the other way: its raw answer is ``7 - Q'``.

For one participant ``p`` and one stimulus, the latent score of composite ``c`` is::

    mu = base_score[c] + scenario_offsets[scenario] + viewpoint_offsets[viewpoint]
         - density_penalty * (density - reference_density)
         + [method has an effect] * (effect_c(method, density) + participant_method_offset)
         + participant_offset[c]
         + participant_density_slope * (density - reference_density)
         + participant_viewpoint_offset[viewpoint]
    effect_c(m, d) = method_effects[m] * composite_effects[c]
                     * max(0, 1 + density_slope * (reference_density - d))

``method_effects`` are points on the composite scale relative to the design's reference method
(the first of ``[methods] order``, whose effect is 0, as is that of any method not listed); the
scalar ``method_effect`` is the effect of ``treated_method`` ("Ours"), the paper's model.

so with ``density_slope > 0`` the Method effect is larger at low density. The participant's
random Density slope (SD ``participant_density_sd``) and random viewpoint offsets (SD
``participant_viewpoint_sd``) make the covariance of the repeated measures non-spherical
(they default to 0; when 0 they draw nothing, so older seeds give the same answers). Each item of the
composite gets ``mu + N(0, noise_sd)`` independently, rounded to the nearest integer and
clipped to ``1 .. likert_points``.

A slider answer is the same latent score plus noise, mapped linearly onto the 0..100 scale
(``(score - 1) / (likert_points - 1) * 100``), rounded and clipped (a reversed item's raw
answer is ``100 -`` that). A 2afc choice between the videos of methods ``a`` and ``b`` picks
``b`` with probability ``logistic(choice_slope * (effect_b - effect_a + dev_b - dev_a))``,
where ``effect_m`` is ``method_effects[m]`` (nominal: no composite or density factor) and
``dev_m`` the participant's method offset for a method with an effect, 0 for the others.

>>> from crowdstudy.design import load_design
>>> df = simulate_responses(load_design(), n_participants=3, seed=1)
>>> df.shape[0]                                  # 3 participants x 60 trials
180
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
from collections.abc import Mapping
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.schema import CHOICES, COMPARISON_COLUMNS, response_columns

__all__ = ["ResponseModel", "SimulatedStudy", "simulate_responses", "simulate_study", "ITEM_COLUMNS"]

#: The six Likert item columns of responses.csv.
ITEM_COLUMNS = ("Q1", "Q2", "Q3", "Q4", "Q5", "Q6")

_PAPER_COMPOSITES = {"QCR": ("Q1", "Q2"), "QCA": ("Q3", "Q4"), "QOR": ("Q5", "Q6")}
_PAPER_REVERSED = ("Q2", "Q4", "Q6")
_EPOCH = _dt.datetime(2024, 1, 8, 9, 0, 0, tzinfo=_dt.UTC)


def _default_composite_effects() -> dict[str, float]:
    return {"QCR": 1.0, "QCA": 0.6, "QOR": 0.8}


@dataclasses.dataclass(frozen=True)
class ResponseModel:
    """Generative model of one participant's answers (all scores in Likert points).

    Attributes
    ----------
    method_effect: treated_method (Ours) - the reference (Baseline) on QCR at
        ``reference_density`` (points, scored scale).
    method_effects: {method: effect} of the other methods, points relative to the reference
        (like ``method_effect``); an entry for ``treated_method`` sets ``method_effect``.
        :attr:`effects` is the whole map.
    choice_slope: logits per point of a 2afc choice (see the module docstring).
    composite_effects: multiplier of ``method_effect`` per composite (QCR 1.0, QCA 0.6,
        QOR 0.8 by default); a composite missing from the mapping gets 1.0.
    density_slope: relative change of the Method effect per character/m^2 below
        ``reference_density`` (0.15: +33 % at 2.22/m^2, -33 % at 6.66/m^2); clipped at 0.
    reference_density: density (characters/m^2) where the effect equals its nominal size.
    density_penalty: drop of every composite per character/m^2 above the reference
        (denser crowds look less realistic regardless of method).
    base_score: mean scored composite of the untreated method at the reference density.
    noise_sd: SD of the Gaussian noise of each item answer (points).
    participant_sd: SD of each participant's per-composite random offset (points).
    participant_method_sd: SD of each participant's random deviation of the Method effect.
    participant_density_sd: SD of each participant's random slope over density (points per
        character/m^2, shared by the composites): a random Density slope.
    participant_viewpoint_sd: SD of each participant's random offset per viewpoint (points).
    scenario_offsets / viewpoint_offsets: additive shifts by scenario / viewpoint id.
    treated_method: the method that receives the effect ("Ours").
    likert_points: the scale's number of points (answers are clipped to 1..points).
    composites: composite -> item ids; reversed_items: items stored raw as ``points+1-Q'``.
    viewpoint_ids: the viewpoints that get a random offset per participant.
    """

    method_effect: float = 1.0
    method_effects: Mapping[str, float] = dataclasses.field(default_factory=dict)
    choice_slope: float = 1.5
    composite_effects: Mapping[str, float] = dataclasses.field(default_factory=_default_composite_effects)
    density_slope: float = 0.15
    reference_density: float = 4.44
    density_penalty: float = 0.15
    base_score: float = 3.2
    noise_sd: float = 0.9
    participant_sd: float = 0.5
    participant_method_sd: float = 0.3
    participant_density_sd: float = 0.0
    participant_viewpoint_sd: float = 0.0
    scenario_offsets: Mapping[str, float] = dataclasses.field(default_factory=lambda: {"corridor": -0.2})
    viewpoint_offsets: Mapping[str, float] = dataclasses.field(default_factory=dict)
    treated_method: str = "Ours"
    likert_points: int = 6
    composites: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=lambda: dict(_PAPER_COMPOSITES))
    reversed_items: tuple[str, ...] = _PAPER_REVERSED
    viewpoint_ids: tuple[str, ...] = ("V1", "V2", "V3", "V4")

    def __post_init__(self):
        if not isinstance(self.method_effects, Mapping):
            raise InvalidInputError(f"ResponseModel.method_effects must be a mapping, got {self.method_effects!r}")
        others = dict(self.method_effects)
        if self.treated_method in others:
            object.__setattr__(self, "method_effect", others.pop(self.treated_method))
        object.__setattr__(self, "method_effects", others)
        for m, v in others.items():
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v):
                raise InvalidInputError(f"ResponseModel.method_effects[{m!r}] must be a finite number, got {v!r}")
        for name in (
            "method_effect",
            "choice_slope",
            "density_slope",
            "reference_density",
            "density_penalty",
            "base_score",
            "noise_sd",
            "participant_sd",
            "participant_method_sd",
            "participant_density_sd",
            "participant_viewpoint_sd",
        ):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not np.isfinite(value):
                raise InvalidInputError(f"ResponseModel.{name} must be a finite number, got {value!r}")
        for name in (
            "noise_sd",
            "participant_sd",
            "participant_method_sd",
            "participant_density_sd",
            "participant_viewpoint_sd",
        ):
            if getattr(self, name) < 0:
                raise InvalidInputError(f"ResponseModel.{name} must be >= 0, got {getattr(self, name)!r}")
        if not isinstance(self.likert_points, int) or self.likert_points < 2:
            raise InvalidInputError(f"ResponseModel.likert_points must be an integer >= 2, got {self.likert_points!r}")
        for c in self.composite_effects:
            if c not in self.composites:
                raise InvalidInputError(
                    f"ResponseModel.composite_effects names unknown composite {c!r}; "
                    f"known: {', '.join(self.composites)}"
                )

    @property
    def effects(self) -> dict[str, float]:
        """{method: effect in points relative to the reference} of every method with one."""
        return {self.treated_method: float(self.method_effect), **{m: float(v) for m, v in self.method_effects.items()}}

    def effect_of(self, method: str) -> float:
        """The effect (points, relative to the reference) of ``method``; 0 without one."""
        return float(self.effects.get(method, 0.0))

    @classmethod
    def for_design(cls, design, **kwargs) -> ResponseModel:
        """A model whose composites, reversed items and scale come from a StudyDesign;
        ``method_effects`` must name methods of the design other than its reference."""
        for m in kwargs.get("method_effects") or {}:
            if m not in design.methods or m == design.reference_method:
                raise InvalidInputError(
                    f"method_effects: {m!r} is not a method of the design other than its reference "
                    f"{design.reference_method!r} (methods: {', '.join(design.methods)})"
                )
        kwargs.setdefault("composites", {k: tuple(v) for k, v in design.composites.items()})
        kwargs.setdefault("reversed_items", tuple(it.id for it in design.items if it.reverse))
        kwargs.setdefault("likert_points", int(design.likert_points))
        kwargs.setdefault("viewpoint_ids", tuple(design.viewpoints))
        if "composite_effects" not in kwargs:
            defaults = _default_composite_effects()
            kwargs["composite_effects"] = {c: defaults.get(c, 1.0) for c in kwargs["composites"]}
        return cls(**kwargs)

    def draw_participant(self, rng: np.random.Generator) -> dict[str, float]:
        """One participant's random offsets: ``{composite: offset, ..., "method": offset}``,
        plus ``"density_slope"`` and ``"viewpoint:<id>"`` entries when their SDs are > 0
        (drawn after the others, so a zero SD leaves the random stream unchanged)."""
        rng = _as_rng(rng)
        offsets = {c: float(rng.normal(0.0, self.participant_sd)) for c in self.composites}
        offsets["method"] = float(rng.normal(0.0, self.participant_method_sd))
        if self.participant_density_sd > 0:
            offsets["density_slope"] = float(rng.normal(0.0, self.participant_density_sd))
        if self.participant_viewpoint_sd > 0:
            views = sorted(set(self.viewpoint_offsets) | set(self.viewpoint_ids))
            for v in views:
                offsets[f"viewpoint:{v}"] = float(rng.normal(0.0, self.participant_viewpoint_sd))
        return offsets

    def method_effect_at(self, composite: str, density: float, method: str | None = None) -> float:
        """Expected difference (points) of ``composite`` at ``density`` between ``method``
        (default: treated_method) and the reference."""
        scale = max(0.0, 1.0 + self.density_slope * (self.reference_density - float(density)))
        effect = self.method_effect if method is None else self.effect_of(method)
        return effect * float(self.composite_effects.get(composite, 1.0)) * scale

    def expected_scores(
        self, stimulus: Mapping, participant_offset: float | Mapping[str, float] = 0.0
    ) -> dict[str, float]:
        """Latent (unrounded, unclipped) composite scores on the scored scale."""
        for key in ("density", "method"):
            if key not in stimulus:
                raise InvalidInputError(f"stimulus has no {key!r} key (expected a manifest row)")
        try:
            density = float(stimulus["density"])
        except (TypeError, ValueError):
            raise InvalidInputError(f"stimulus['density'] must be a number, got {stimulus['density']!r}") from None
        method = stimulus["method"]
        treated = method in self.effects
        common = (
            self.base_score
            + float(self.scenario_offsets.get(stimulus.get("scenario"), 0.0))
            + float(self.viewpoint_offsets.get(stimulus.get("viewpoint"), 0.0))
            - self.density_penalty * (density - self.reference_density)
        )
        if isinstance(participant_offset, Mapping):
            p_method = float(participant_offset.get("method", 0.0))
            common += float(participant_offset.get("density_slope", 0.0)) * (density - self.reference_density) + float(
                participant_offset.get(f"viewpoint:{stimulus.get('viewpoint')}", 0.0)
            )
            p_comp = {c: float(participant_offset.get(c, 0.0)) for c in self.composites}
        else:
            p_method = 0.0
            p_comp = {c: float(participant_offset) for c in self.composites}
        out = {}
        for c in self.composites:
            mu = common + p_comp[c]
            if treated:
                mu += self.method_effect_at(c, density, method) + p_method
            out[c] = mu
        return out

    def answer(
        self,
        stimulus: Mapping,
        participant_offset: float | Mapping[str, float] = 0.0,
        rng: np.random.Generator | int | None = None,
        *,
        task: str = "likert",
    ) -> dict[str, int]:
        """Raw answers ``{"Q1": int, ...}`` (negative items NOT reversed): Likert points
        1..likert_points, or for ``task="slider"`` integers 0..100.

        ``stimulus``: a manifest row / ``Stimulus.as_dict()`` (uses density, method, and
        scenario / viewpoint when present). ``participant_offset``: a float added to every
        composite, or the dict of :meth:`draw_participant`.
        """
        rng = _as_rng(rng)
        scores = self.expected_scores(stimulus, participant_offset)
        answers = {}
        for c, items in self.composites.items():
            for item in items:
                latent = np.array([scores[c] + rng.normal(0.0, self.noise_sd)])
                answers[item] = int(self._raw(latent, item in self.reversed_items, task)[0])
        return {k: answers[k] for k in sorted(answers, key=_item_order)}

    def _raw(self, latent: np.ndarray, reverse, task: str) -> np.ndarray:
        """Raw answers (int64, the shape of ``latent``) of latent scored-scale values: Likert
        points, or slider positions 0..100; ``reverse`` (bool or bool array) flips them."""
        top = self.likert_points
        if task == "slider":
            scored = np.clip(np.rint((latent - 1.0) / (top - 1) * 100.0), 0, 100).astype(np.int64)
            return np.where(reverse, 100 - scored, scored)
        scored = np.clip(np.rint(latent), 1, top).astype(np.int64)
        return np.where(reverse, top + 1 - scored, scored)

    def choice_probability(
        self, method_left: str, method_right: str, participant_offset: float | Mapping[str, float] = 0.0
    ) -> float:
        """Probability that a participant with ``participant_offset`` (the dict of
        :meth:`draw_participant`) chooses the right video of a 2afc trial."""
        p_method = float(participant_offset.get("method", 0.0)) if isinstance(participant_offset, Mapping) else 0.0
        effects = self.effects

        def utility(m: str) -> float:
            return effects[m] + p_method if m in effects else 0.0

        z = self.choice_slope * (utility(method_right) - utility(method_left))
        return float(1.0 / (1.0 + np.exp(-z)))

    def choose(
        self,
        method_left: str,
        method_right: str,
        participant_offset: float | Mapping[str, float] = 0.0,
        rng: np.random.Generator | int | None = None,
    ) -> str:
        """A 2afc answer, ``"left"`` or ``"right"`` (one uniform draw of ``rng``)."""
        p = self.choice_probability(method_left, method_right, participant_offset)
        return CHOICES[int(_as_rng(rng).random() < p)]

    def answer_many(
        self,
        stimuli,
        participant_offset: float | Mapping[str, float] = 0.0,
        rng: np.random.Generator | int | None = None,
        *,
        task: str = "likert",
    ) -> tuple[list[str], np.ndarray]:
        """Raw answers of one participant to several stimuli at once (same model as
        :meth:`answer`, noise drawn as one (T, items) block).

        Returns ``(item_ids, answers)``: item ids in questionnaire order and a (T, items)
        int64 array of raw answers (1..likert_points; ``task="slider"``: 0..100).
        """
        rng = _as_rng(rng)
        comps = list(self.composites)
        items = sorted((it for c in comps for it in self.composites[c]), key=_item_order)
        owner = {it: comps.index(c) for c in comps for it in self.composites[c]}
        mu = np.array(
            [[sc[c] for c in comps] for sc in (self.expected_scores(s, participant_offset) for s in stimuli)],
            dtype=float,
        ).reshape(-1, len(comps))
        noise = rng.normal(0.0, self.noise_sd, size=(mu.shape[0], len(items)))
        rev = np.array([it in self.reversed_items for it in items])
        return items, self._raw(mu[:, [owner[it] for it in items]] + noise, rev, task)


def _item_order(item: str):
    digits = "".join(ch for ch in item if ch.isdigit())
    return (int(digits) if digits else 0, item)


def _as_rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer)):
        return np.random.default_rng(rng)
    raise InvalidInputError(f"rng must be a numpy Generator, an int seed or None, got {type(rng).__name__}")


class SimulatedStudy(NamedTuple):
    """The answers of a simulated study: ``responses`` (Likert and slider trials, the
    responses.csv schema of the design's items) and ``comparisons`` (2afc trials, the
    comparisons.csv schema; no rows without a 2afc stage)."""

    responses: pd.DataFrame
    comparisons: pd.DataFrame


def _check_inputs(design, n_participants, model, seed) -> ResponseModel:
    if isinstance(n_participants, bool) or not isinstance(n_participants, (int, np.integer)) or n_participants < 1:
        raise InvalidInputError(f"n_participants must be an integer >= 1, got {n_participants!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidInputError(f"seed must be a non-negative integer, got {seed!r}")
    if model is None:
        model = ResponseModel.for_design(design)
    elif not isinstance(model, ResponseModel):
        raise InvalidInputError(f"model must be a ResponseModel, got {type(model).__name__}")
    modelled = {it for members in model.composites.values() for it in members}
    unmodelled = [it.id for it in design.items if it.id not in modelled]
    if unmodelled:
        raise InvalidInputError(
            f"model.composites must cover every item of the design; {', '.join(unmodelled)} belong to no composite"
        )
    return model


def _stage_numbers(design, stages) -> list[int]:
    all_stages = [st.number for st in design.stages]
    if stages is None:
        return all_stages
    chosen = sorted({int(x) for x in stages})
    unknown = [x for x in chosen if x not in all_stages]
    if unknown:
        raise InvalidInputError(f"stages: unknown stage number {unknown[0]}; the design has {all_stages}")
    return chosen


def _stage_material(design, numbers: list[int]) -> dict[int, tuple[str, list]]:
    """{stage: (task, units)}: a rated stage's stimuli (dicts), a 2afc stage's comparisons
    ({pair: [(stimulus of the pair's first method, of its second), one per cell]})."""
    stimuli = [s.as_dict() for s in design.stimuli()]
    out: dict[int, tuple[str, list]] = {}
    for st in design.stages:
        if st.number not in numbers:
            continue
        mine = [s for s in stimuli if s["stage"] == st.number]
        if st.task != "2afc":
            out[st.number] = (st.task, mine)
            continue
        cell = {(s["density_level"], s["viewpoint"], s["method"]): s for s in mine}
        pairs = [
            [(cell[(lv, vp, a)], cell[(lv, vp, b)]) for lv in design.densities for vp in st.viewpoints]
            for a, b in st.pairs
        ]
        out[st.number] = ("2afc", pairs)
    return out


def _participant_order(material, rng: np.random.Generator) -> list[tuple[str, object]]:
    """One participant's trials in session order: (task, stimulus) or ("2afc", (left, right));
    2afc sides counterbalanced per method pair across its cells, then shuffled."""
    order: list[tuple[str, object]] = []
    for _stage, (task, units) in sorted(material.items()):
        if task != "2afc":
            order.extend((task, units[int(k)]) for k in rng.permutation(len(units)))
            continue
        trials = []
        for cells in units:
            n = len(cells)
            n_first = n // 2 + (int(rng.random() < 0.5) if n % 2 else 0)
            first_left = rng.permutation(n) < n_first
            trials.extend((a, b) if fl else (b, a) for (a, b), fl in zip(cells, first_left, strict=True))
        order.extend(("2afc", trials[int(k)]) for k in rng.permutation(len(trials)))
    return order


def _times(rng: np.random.Generator, p: int, n: int, epoch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """rt (ms), shown_at and answered_at of one participant's ``n`` trials."""
    rt = np.round(8000.0 + rng.lognormal(np.log(14000.0), 0.35, size=n), 1)
    # each answer is followed by a 1.5 s pause before the next video starts
    start_ms = 3_600_000.0 * p + np.concatenate([[0.0], np.cumsum(rt + 1500.0)[:-1]])
    shown = epoch + np.round(start_ms).astype("timedelta64[ms]")
    answered = epoch + np.round(start_ms + rt).astype("timedelta64[ms]")
    return rt, np.datetime_as_string(shown, unit="ms"), np.datetime_as_string(answered, unit="ms")


def _one_participant(model, material, item_ids, rng, p: int, epoch) -> tuple[list[dict], list[dict]]:
    """The responses.csv and comparisons.csv rows of simulated participant ``p``."""
    offsets = model.draw_participant(rng)
    order = _participant_order(material, rng)
    ratings: dict[int, dict] = {}
    for task in ("likert", "slider"):
        idx = [k for k, (t, _) in enumerate(order) if t == task]
        if idx:
            items, answers = model.answer_many([order[k][1] for k in idx], offsets, rng, task=task)
            for row, k in enumerate(idx):
                ratings[k] = {q: int(answers[row, items.index(q)]) for q in item_ids}
    choices = {
        k: model.choose(u[0]["method"], u[1]["method"], offsets, rng) for k, (t, u) in enumerate(order) if t == "2afc"
    }
    rt, shown, answered = _times(rng, p, len(order), epoch)
    pid = f"sim-{p + 1:03d}"
    rated, compared = [], []
    for k, (task, unit) in enumerate(order):
        times = {"rt_ms": float(rt[k]), "shown_at": shown[k] + "Z", "answered_at": answered[k] + "Z"}
        first = unit if task != "2afc" else unit[0]
        head = {"participant_id": pid, "stage": int(first["stage"]), "scenario": first["scenario"], "task": task}
        cell = {
            "trial_index": k,
            "density_level": first["density_level"],
            "density": float(first["density"]),
            "viewpoint": first["viewpoint"],
        }
        if task != "2afc":
            rated.append(
                {**head, **cell, "stimulus_id": first["stimulus_id"], "method": first["method"], **ratings[k], **times}
            )
            continue
        left, right = unit
        choice = choices[k]
        compared.append(
            {
                **head,
                **cell,
                "stimulus_left": left["stimulus_id"],
                "stimulus_right": right["stimulus_id"],
                "method_left": left["method"],
                "method_right": right["method"],
                "choice": choice,
                "chosen_method": (left if choice == "left" else right)["method"],
                **times,
            }
        )
    return rated, compared


def simulate_study(
    design, n_participants: int, model: ResponseModel | None = None, seed: int = 0, *, stages=None
) -> SimulatedStudy:
    """Simulate a whole study in-process: ``n_participants`` answering every trial of the
    design, each stage by its task.

    ``stages``: optional subset of stage numbers to simulate (default: every stage).

    Each participant sees the stages in design order, each stage's trials in an independently
    shuffled order (a 2afc stage: every method pair in every cell once, sides counterbalanced
    per pair across the cells); ``trial_index`` counts over the whole schedule.
    ``participant_id`` is ``"sim-001"``...; ``rt_ms`` float milliseconds; ``shown_at`` /
    ``answered_at`` ISO 8601 UTC (deterministic, from a fixed epoch). Same seed -> identical
    frames; the paper's design gives the answers of earlier versions.
    """
    import pandas as pd

    model = _check_inputs(design, n_participants, model, seed)
    material = _stage_material(design, _stage_numbers(design, stages))
    item_ids = [it.id for it in design.items]
    root = np.random.SeedSequence([int(seed), 0x51A75])
    epoch = np.datetime64(_EPOCH.replace(tzinfo=None), "ms")
    rated: list[dict] = []
    compared: list[dict] = []
    for p, child in enumerate(root.spawn(int(n_participants))):
        r, c = _one_participant(model, material, item_ids, np.random.default_rng(child), p, epoch)
        rated.extend(r)
        compared.extend(c)
    responses = pd.DataFrame(rated, columns=list(response_columns(item_ids)))
    comparisons = pd.DataFrame(compared, columns=list(COMPARISON_COLUMNS))
    for df in (responses, comparisons):
        df["trial_index"] = df["trial_index"].astype(np.int64)
        df["stage"] = df["stage"].astype(np.int64)
        df.attrs["simulated"] = True
        df.attrs["seed"] = int(seed)
    for q in item_ids:
        responses[q] = responses[q].astype(np.int64)
    return SimulatedStudy(responses, comparisons)


def simulate_responses(design, n_participants: int, model: ResponseModel | None = None, seed: int = 0, *, stages=None):
    """The Likert and slider answers of :func:`simulate_study` (a pandas DataFrame in the
    responses.csv schema of the design's items, :func:`crowdstudy.schema.response_columns`),
    one row per trial, sorted by participant and trial_index; a design's 2afc answers are in
    :func:`simulate_study`'s ``comparisons``."""
    return simulate_study(design, n_participants, model, seed, stages=stages).responses

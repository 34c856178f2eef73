"""Synthetic participants: a generative model of Likert answers, for bots and power analysis.

The model works on the *scored* scale (negative items already reversed, 1..6, higher =
better for the method) and writes *raw* answers, so a negative item (``reverse = true`` in
the design: Q2, Q4, Q6) moves the other way: its raw answer is ``7 - Q'``.

For one participant ``p`` and one stimulus, the latent score of composite ``c`` is::

    mu = base_score[c] + scenario_offsets[scenario] + viewpoint_offsets[viewpoint]
         - density_penalty * (density - reference_density)
         + [method == treated_method] * (effect_c(density) + participant_method_offset)
         + participant_offset[c]
         + participant_density_slope * (density - reference_density)
         + participant_viewpoint_offset[viewpoint]
    effect_c(d) = method_effect * composite_effects[c]
                  * max(0, 1 + density_slope * (reference_density - d))

so with ``density_slope > 0`` the Method effect is larger at low density. The participant's
random Density slope (SD ``participant_density_sd``) and random viewpoint offsets (SD
``participant_viewpoint_sd``) make the covariance of the repeated measures non-spherical
(they default to 0; when 0 they draw nothing, so older seeds give the same answers). Each item of the
composite gets ``mu + N(0, noise_sd)`` independently, rounded to the nearest integer and
clipped to ``1 .. likert_points``.

>>> from crowdstudy.design import load_design
>>> df = simulate_responses(load_design(), n_participants=3, seed=1)
>>> df.shape[0]                                  # 3 participants x 60 trials
180
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
from collections.abc import Mapping

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.schema import RESPONSE_COLUMNS

__all__ = ["ResponseModel", "simulate_responses", "ITEM_COLUMNS"]

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
    method_effect: Ours - Baseline on QCR at ``reference_density`` (points, scored scale).
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
        for name in (
            "method_effect",
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

    @classmethod
    def for_design(cls, design, **kwargs) -> ResponseModel:
        """A model whose composites, reversed items and scale come from a StudyDesign."""
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

    def method_effect_at(self, composite: str, density: float) -> float:
        """Expected Ours - Baseline difference (points) of ``composite`` at ``density``."""
        scale = max(0.0, 1.0 + self.density_slope * (self.reference_density - float(density)))
        return self.method_effect * float(self.composite_effects.get(composite, 1.0)) * scale

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
        treated = stimulus["method"] == self.treated_method
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
                mu += self.method_effect_at(c, density) + p_method
            out[c] = mu
        return out

    def answer(
        self,
        stimulus: Mapping,
        participant_offset: float | Mapping[str, float] = 0.0,
        rng: np.random.Generator | int | None = None,
    ) -> dict[str, int]:
        """Raw answers ``{"Q1": int, ...}`` (1..likert_points, negative items NOT reversed).

        ``stimulus``: a manifest row / ``Stimulus.as_dict()`` (uses density, method, and
        scenario / viewpoint when present). ``participant_offset``: a float added to every
        composite, or the dict of :meth:`draw_participant`.
        """
        rng = _as_rng(rng)
        scores = self.expected_scores(stimulus, participant_offset)
        top = self.likert_points
        answers = {}
        for c, items in self.composites.items():
            for item in items:
                scored = int(np.clip(np.rint(scores[c] + rng.normal(0.0, self.noise_sd)), 1, top))
                answers[item] = top + 1 - scored if item in self.reversed_items else scored
        return {k: answers[k] for k in sorted(answers, key=_item_order)}

    def answer_many(
        self,
        stimuli,
        participant_offset: float | Mapping[str, float] = 0.0,
        rng: np.random.Generator | int | None = None,
    ) -> tuple[list[str], np.ndarray]:
        """Raw answers of one participant to several stimuli at once (same model as
        :meth:`answer`, noise drawn as one (T, items) block).

        Returns ``(item_ids, answers)``: item ids in questionnaire order and a (T, items)
        int64 array of raw answers (1..likert_points).
        """
        rng = _as_rng(rng)
        comps = list(self.composites)
        items = sorted((it for c in comps for it in self.composites[c]), key=_item_order)
        owner = {it: comps.index(c) for c in comps for it in self.composites[c]}
        mu = np.array(
            [[sc[c] for c in comps] for sc in (self.expected_scores(s, participant_offset) for s in stimuli)],
            dtype=float,
        ).reshape(-1, len(comps))
        top = self.likert_points
        noise = rng.normal(0.0, self.noise_sd, size=(mu.shape[0], len(items)))
        scored = np.clip(np.rint(mu[:, [owner[it] for it in items]] + noise), 1, top).astype(np.int64)
        rev = np.array([it in self.reversed_items for it in items])
        return items, np.where(rev, top + 1 - scored, scored)


def _item_order(item: str):
    digits = "".join(ch for ch in item if ch.isdigit())
    return (int(digits) if digits else 0, item)


def _as_rng(rng) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, (int, np.integer)):
        return np.random.default_rng(rng)
    raise InvalidInputError(f"rng must be a numpy Generator, an int seed or None, got {type(rng).__name__}")


def simulate_responses(design, n_participants: int, model: ResponseModel | None = None, seed: int = 0, *, stages=None):
    """Simulate a whole study in-process: ``n_participants`` answering every stimulus.

    ``stages``: optional subset of stage numbers to simulate (default: every stage).

    Each participant sees stage 1 then stage 2 (design order), each stage's trials in an
    independently shuffled order; ``trial_index`` counts over the whole schedule.

    Returns a pandas DataFrame in the responses.csv schema
    (:data:`crowdstudy.schema.RESPONSE_COLUMNS`), one
    row per trial, sorted by participant and trial_index; ``participant_id`` is
    ``"sim-001"``...; ``rt_ms`` float milliseconds; ``shown_at`` / ``answered_at`` ISO 8601
    UTC (deterministic, from a fixed epoch). Same seed -> identical frame.
    """
    import pandas as pd

    if isinstance(n_participants, bool) or not isinstance(n_participants, (int, np.integer)) or n_participants < 1:
        raise InvalidInputError(f"n_participants must be an integer >= 1, got {n_participants!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidInputError(f"seed must be a non-negative integer, got {seed!r}")
    if model is None:
        model = ResponseModel.for_design(design)
    elif not isinstance(model, ResponseModel):
        raise InvalidInputError(f"model must be a ResponseModel, got {type(model).__name__}")
    item_ids = [it.id for it in design.items]
    missing = [q for q in ITEM_COLUMNS if q not in item_ids]
    if missing:
        raise InvalidInputError(
            f"design {design.source}: responses.csv needs items {', '.join(ITEM_COLUMNS)}; missing {', '.join(missing)}"
        )
    modelled = {it for members in model.composites.values() for it in members}
    unmodelled = [q for q in ITEM_COLUMNS if q not in modelled]
    if unmodelled:
        raise InvalidInputError(
            f"model.composites must cover every item of responses.csv; {', '.join(unmodelled)} belong to no composite"
        )
    stimuli = [s.as_dict() for s in design.stimuli()]
    all_stages = sorted({s["stage"] for s in stimuli})
    if stages is None:
        stages = all_stages
    else:
        stages = sorted({int(x) for x in stages})
        unknown = [x for x in stages if x not in all_stages]
        if unknown:
            raise InvalidInputError(f"stages: unknown stage number {unknown[0]}; the design has {all_stages}")
    by_stage = {st: [s for s in stimuli if s["stage"] == st] for st in stages}
    rows = []
    root = np.random.SeedSequence([int(seed), 0x51A75])
    epoch = np.datetime64(_EPOCH.replace(tzinfo=None), "ms")
    for p, child in enumerate(root.spawn(int(n_participants))):
        rng = np.random.default_rng(child)
        offsets = model.draw_participant(rng)
        order = [by_stage[st][int(k)] for st in stages for k in rng.permutation(len(by_stage[st]))]
        items, answers = model.answer_many(order, offsets, rng)
        rt = np.round(8000.0 + rng.lognormal(np.log(14000.0), 0.35, size=len(order)), 1)
        # each answer is followed by a 1.5 s pause before the next video starts
        start_ms = 3_600_000.0 * p + np.concatenate([[0.0], np.cumsum(rt + 1500.0)[:-1]])
        shown = epoch + np.round(start_ms).astype("timedelta64[ms]")
        answered = epoch + np.round(start_ms + rt).astype("timedelta64[ms]")
        frame = {
            "participant_id": [f"sim-{p + 1:03d}"] * len(order),
            "stage": [int(s_["stage"]) for s_ in order],
            "scenario": [s_["scenario"] for s_ in order],
            "trial_index": np.arange(len(order)),
            "stimulus_id": [s_["stimulus_id"] for s_ in order],
            "density_level": [s_["density_level"] for s_ in order],
            "density": [float(s_["density"]) for s_ in order],
            "viewpoint": [s_["viewpoint"] for s_ in order],
            "method": [s_["method"] for s_ in order],
            **{q: answers[:, items.index(q)] for q in ITEM_COLUMNS},
            "rt_ms": rt,
            "shown_at": np.datetime_as_string(shown, unit="ms"),
            "answered_at": np.datetime_as_string(answered, unit="ms"),
        }
        rows.append(frame)
    df = pd.DataFrame({c: np.concatenate([np.asarray(f[c]) for f in rows]) for c in RESPONSE_COLUMNS})
    for col in ("shown_at", "answered_at"):
        df[col] = df[col].astype(str) + "Z"
    df.attrs["simulated"] = True
    df.attrs["seed"] = int(seed)
    return df

"""Simulated participants for any design: per-method effects, slider answers, 2afc choices."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.schema import COMPARISON_COLUMNS, response_columns
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses, simulate_study

DESIGN = Path(__file__).resolve().parent / "data" / "three_tasks.toml"


def test_the_papers_design_gives_the_answers_of_earlier_versions():
    # digest of the frame (without the new task column) written by the version before
    # per-method effects and tasks, for the same seed
    df = simulate_responses(load_design(), 4, seed=9)
    assert set(df["task"]) == {"likert"}
    text = df.drop(columns=["task"]).to_csv(index=False)
    assert (
        hashlib.sha256(text.encode()).hexdigest() == "66df1093fcd3d234fd1cbc47ce53ef04d657f63a2f95ade6ff9f607e85de792f"
    )


def test_method_effects_are_relative_to_the_reference_and_replace_keeps_working():
    m = ResponseModel(method_effects={"Ours": 2.0, "Stiff": 0.5})
    assert m.method_effect == 2.0 and m.effects == {"Ours": 2.0, "Stiff": 0.5} and m.effect_of("Baseline") == 0.0
    assert dataclasses.replace(m, method_effect=1.0).effects == {"Ours": 1.0, "Stiff": 0.5}
    stim = {"density": 4.44, "method": "Stiff"}
    base = ResponseModel().expected_scores({**stim, "method": "Baseline"})["QCR"]
    assert m.expected_scores(stim)["QCR"] - base == pytest.approx(0.5)
    with pytest.raises(InvalidInputError, match="method_effects: 'Nope'"):
        ResponseModel.for_design(load_design(DESIGN), method_effects={"Nope": 1.0})
    with pytest.raises(InvalidInputError, match="reference 'Plain'"):
        ResponseModel.for_design(load_design(DESIGN), method_effects={"Plain": 1.0})


def test_slider_answers_map_the_latent_score_onto_0_100():
    m = ResponseModel(noise_sd=0.0, participant_sd=0.0, likert_points=6)
    stim = {"density": 4.44, "method": "Baseline"}
    likert = m.answer(stim, 0.0, 1)
    slider = m.answer(stim, 0.0, 1, task="slider")
    latent = m.base_score  # no noise, the reference method at the reference density
    expected = int(np.rint((latent - 1) / 5 * 100))
    assert slider["Q1"] == expected and slider["Q2"] == 100 - expected  # Q2 reversed
    assert likert["Q1"] == int(np.rint(latent))
    assert all(0 <= v <= 100 for v in m.answer({**stim, "method": "Ours"}, 9.0, 2, task="slider").values())


def test_choices_follow_the_logistic_of_the_effect_difference():
    m = ResponseModel(method_effects={"Ours": 1.0, "Stiff": 0.5}, choice_slope=1.5)
    assert m.choice_probability("Baseline", "Ours") == pytest.approx(1 / (1 + np.exp(-1.5)))
    assert m.choice_probability("Ours", "Stiff") == pytest.approx(1 / (1 + np.exp(0.75)))
    # the participant's method deviation moves the treated methods against the reference only
    assert m.choice_probability("Ours", "Stiff", {"method": 0.7}) == pytest.approx(
        m.choice_probability("Ours", "Stiff")
    )
    assert m.choice_probability("Baseline", "Stiff", {"method": -0.5}) == pytest.approx(0.5)


def test_a_study_with_three_tasks_and_its_effects_recovered():
    design = load_design(DESIGN)
    model = ResponseModel.for_design(
        design, method_effects={"Physics": 1.0, "Stiff": 0.4}, participant_method_sd=0.0, choice_slope=1.5
    )
    sim = simulate_study(design, 80, model, seed=3)
    r, c = sim.responses, sim.comparisons
    assert tuple(r.columns) == response_columns(("R1", "R2", "R3")) and tuple(c.columns) == COMPARISON_COLUMNS
    assert len(r) == 80 * 18 and len(c) == 80 * 6 and set(c["task"]) == {"2afc"}
    assert r[r.task == "slider"][["R1", "R2", "R3"]].to_numpy().max() <= 100
    # every pair in every cell once per participant, each method left once per pair
    one = c[c.participant_id == "sim-001"]
    assert (
        sorted(map(frozenset, zip(one.method_left, one.method_right, strict=True))).count(
            frozenset({"Plain", "Physics"})
        )
        == 2
    )
    for (a, b), expected in ((("Plain", "Physics"), 1.5), (("Physics", "Stiff"), -0.9), (("Plain", "Stiff"), 0.6)):
        rows = c[c.method_left.isin([a, b]) & c.method_right.isin([a, b])]
        share = (rows.chosen_method == b).mean()
        p = 1 / (1 + np.exp(-expected))
        se = np.sqrt(p * (1 - p) / len(rows))
        assert abs(share - p) < 4 * se, (a, b, share, p)
    assert sim.responses.equals(simulate_study(design, 80, model, seed=3).responses)

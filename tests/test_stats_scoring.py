"""Scoring (reversal, reliability, composites, cell means) and the synthetic ResponseModel."""

import numpy as np
import pandas as pd
import pytest

from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats.scoring import cell_means, composite_scores, item_reliability, reverse_items, validate_responses
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses
from crowdstudy.study.export import RESPONSE_COLUMNS


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def sim(design):
    return simulate_responses(design, 6, seed=4)


def test_schema_and_determinism(design, sim):
    assert tuple(sim.columns) == RESPONSE_COLUMNS
    assert len(sim) == 6 * 60
    again = simulate_responses(design, 6, seed=4)
    pd.testing.assert_frame_equal(sim, again)
    assert not sim.equals(simulate_responses(design, 6, seed=5))
    assert sim[["Q1", "Q2", "Q3", "Q4", "Q5", "Q6"]].isin(range(1, 7)).all().all()
    for _, g in sim.groupby("participant_id"):
        assert list(g["trial_index"]) == list(range(60))
        assert list(g["stage"]) == [1] * 40 + [2] * 20  # stage 1 then stage 2
        assert g["stimulus_id"].is_unique
    orders = sim[sim.stage == 1].groupby("participant_id")["stimulus_id"].apply(tuple)
    assert orders.nunique() == 6  # each participant has their own order
    assert (pd.to_datetime(sim["answered_at"]) > pd.to_datetime(sim["shown_at"])).all()
    only2 = simulate_responses(design, 2, seed=1, stages=[2])
    assert set(only2.stage) == {2} and len(only2) == 40


def test_negative_items_move_the_other_way(design):
    df = simulate_responses(design, 20, ResponseModel.for_design(design, method_effect=1.5), seed=2)
    means = df.groupby("method")[["Q1", "Q2", "Q3", "Q4", "Q5", "Q6"]].mean()
    for pos, neg in [("Q1", "Q2"), ("Q3", "Q4"), ("Q5", "Q6")]:
        assert means.at["Ours", pos] > means.at["Baseline", pos] + 0.3
        assert means.at["Ours", neg] < means.at["Baseline", neg] - 0.3
    scored = composite_scores(df, design)
    eff = scored.groupby("method")[["QCR", "QCA", "QOR"]].mean().diff().iloc[1]
    assert eff["QCR"] > eff["QOR"] > eff["QCA"] > 0  # per-composite multipliers 1.0, 0.8, 0.6


def test_answer_model_details(design):
    stim = design.stimuli()[0].as_dict()
    model = ResponseModel(noise_sd=0.0, participant_sd=0.0, participant_method_sd=0.0, base_score=9.0)
    assert model.answer(stim, 0.0, np.random.default_rng(0)) == {"Q1": 6, "Q2": 1, "Q3": 6, "Q4": 1, "Q5": 6, "Q6": 1}
    m = ResponseModel(density_slope=0.2, method_effect=1.0)
    assert m.method_effect_at("QCR", 2.22) > m.method_effect_at("QCR", 4.44) > m.method_effect_at("QCR", 6.66)
    assert m.method_effect_at("QCA", 4.44) == pytest.approx(0.6)
    ours = dict(stim, method="Ours")
    base = dict(stim, method="Baseline")
    d = m.expected_scores(ours, {"QCR": 0.1, "method": 0.2})["QCR"] - m.expected_scores(base, {"QCR": 0.1})["QCR"]
    assert d == pytest.approx(m.method_effect_at("QCR", stim["density"]) + 0.2)
    with pytest.raises(InvalidInputError, match="noise_sd"):
        ResponseModel(noise_sd=-1.0)
    with pytest.raises(InvalidInputError, match="composite_effects names unknown composite 'QXX'"):
        ResponseModel(composite_effects={"QXX": 1.0})
    with pytest.raises(InvalidInputError, match="'density'"):
        m.answer({"method": "Ours"}, 0.0, 1)
    with pytest.raises(InvalidInputError, match="n_participants"):
        simulate_responses(design, 0)


def test_reversal_and_composites(design, sim):
    rev = reverse_items(sim, design)
    for q in ("Q2", "Q4", "Q6"):
        np.testing.assert_array_equal(rev[q], 7 - sim[q])
    for q in ("Q1", "Q3", "Q5"):
        np.testing.assert_array_equal(rev[q], sim[q])
    scored = composite_scores(sim, design)
    np.testing.assert_allclose(scored["QCR"], (sim["Q1"] + 7 - sim["Q2"]) / 2)
    np.testing.assert_allclose(scored["QOR"], (sim["Q5"] + 7 - sim["Q6"]) / 2)


def test_reliability_by_hand(design):
    df = pd.DataFrame(
        {
            "participant_id": ["a", "a", "b", "b", "c", "c"],
            "stage": 1,
            "scenario": "concert",
            "density_level": "D1",
            "viewpoint": "V1",
            "method": ["Baseline", "Ours"] * 3,
            "Q1": [1, 2, 4, 5, 6, 3],
            "Q2": [6, 4, 3, 2, 2, 4],
            "Q3": [1, 2, 3, 4, 5, 6],
            "Q4": [6, 5, 4, 3, 2, 1],
            "Q5": [2, 2, 3, 3, 5, 6],
            "Q6": [5, 4, 4, 3, 1, 2],
        }
    )
    rel = item_reliability(df, design).set_index("composite")
    q1, q2r = df["Q1"].to_numpy(float), 7 - df["Q2"].to_numpy(float)
    r = np.corrcoef(q1, q2r)[0, 1]
    assert rel.at["QCR", "pearson_r"] == pytest.approx(r)
    assert rel.at["QCR", "spearman_brown"] == pytest.approx(2 * r / (1 + r))
    alpha = 2 * (1 - (q1.var(ddof=1) + q2r.var(ddof=1)) / (q1 + q2r).var(ddof=1))
    assert rel.at["QCR", "cronbach_alpha"] == pytest.approx(alpha)
    assert rel.at["QCA", "pearson_r"] == pytest.approx(1.0)  # Q4 = 7 - Q3 exactly
    assert rel.at["QCA", "cronbach_alpha"] == pytest.approx(1.0)


def test_cell_means_average_repeated_trials(design, sim):
    doubled = pd.concat([sim, sim.assign(Q1=np.where(sim.Q1 < 6, sim.Q1 + 1, sim.Q1 - 1))], ignore_index=True)
    scored = composite_scores(doubled, design)
    cells = cell_means(scored, "QCR", design, stage=2)
    assert list(cells.columns) == ["participant_id", "Density", "Viewpoint", "Method", "QCR"]
    assert len(cells) == 6 * 20
    assert list(cells["Viewpoint"].cat.categories) == ["V3", "V4"]
    one = scored[(scored.participant_id == "sim-002") & (scored.stimulus_id == "S2-D4-V3-Ours")]["QCR"].mean()
    row = cells[
        (cells.participant_id == "sim-002")
        & (cells.Density == "D4")
        & (cells.Viewpoint == "V3")
        & (cells.Method == "Ours")
    ]
    assert row["QCR"].iloc[0] == pytest.approx(one)


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (lambda d: d.drop(columns=["Q4"]), "missing column.*'Q4'"),
        (lambda d: d.drop(columns=["viewpoint"]), "missing column.*'viewpoint'"),
        (
            lambda d: d.assign(Q3=d.Q3.astype(object).where(d.index != 3, "agree")),
            r"'Q3' row 4 \(participant 'sim-001'\) holds 'agree'",
        ),
        (lambda d: d.assign(Q5=d.Q5.where(d.index != 10, 7)), r"'Q5' row 11 .* holds 7; expected an integer 1..6"),
        (lambda d: d.assign(Q1=d.Q1.astype(float).where(d.index != 2, 2.5)), r"'Q1' row 3 .* holds 2.5;"),
        (
            lambda d: d.assign(method=d.method.where(d.index != 0, "Physics")),
            "'method' row 1 .*unknown level 'Physics'",
        ),
        (lambda d: d.iloc[:0], "no rows"),
    ],
)
def test_bad_responses(design, sim, mutate, pattern):
    with pytest.raises(InvalidInputError, match=pattern):
        validate_responses(mutate(sim.copy()), design)

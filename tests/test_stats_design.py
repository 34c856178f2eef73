"""Analyses that follow the design: k methods (the mixed model, rank tests, Friedman), a
2AFC stage (shares, glmer, Bradley-Terry) against R (analysis/reference_r/design_reference.R),
and the whole analysis of a design with other names, three methods, a slider stage and a
2AFC stage."""

import copy
import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from crowdstudy.design import default_design_path, parse_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.choice_models import bradley_terry
from crowdstudy.stats.comparisons import compute_choices, load_comparisons, validate_comparisons
from crowdstudy.stats.options import AnalysisOptions
from crowdstudy.stats.pipeline import analyze
from crowdstudy.stats.robust import friedman_test, holm, mixed_model, ordinal_method_check
from crowdstudy.stats.synthetic import simulate_responses

REF = Path(__file__).resolve().parent.parent / "analysis" / "reference_r"
PAPER = tomllib.loads(default_design_path().read_text())


def _design(task2="2afc", task1="likert", methods=("Baseline", "Ours", "Stiff")):
    raw = copy.deepcopy(PAPER)
    raw["methods"] = {"order": list(methods)}
    for name in methods:
        if name not in ("Baseline", "Ours"):
            raw["methods"][name] = {"correction": "physics", "config": {"damping": 0.06}}
    raw["stages"]["stationary"]["task"] = task1
    raw["stages"]["walking"]["task"] = task2
    raw["questionnaire"]["comparison"] = {"text": "In which video do the people move more naturally?"}
    return parse_design(raw, "three.toml")


@pytest.fixture(scope="module")
def three():
    return _design()


# ---- k methods against R ------------------------------------------------------------


@pytest.fixture(scope="module")
def mixed3():
    data = pd.read_csv(REF / "likert_incomplete_5x2x3.csv").rename(columns={"Method": "Technique"})
    return mixed_model(data, "y", ["Density", "Viewpoint", "Technique"], "subject", method="Technique")


def test_mixed_model_with_three_methods_and_any_factor_name_matches_lmer(mixed3):
    ref = pd.read_csv(REF / "ref_likert_incomplete_5x2x3_mixed.csv").set_index("term")
    fixed = mixed3.fixed.assign(term=mixed3.fixed["term"].str.replace("Technique", "Method")).set_index("term")
    assert len(fixed) == 30 and mixed3.converged
    np.testing.assert_allclose(fixed["estimate"], ref.loc[fixed.index, "estimate"], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(fixed["SE"], ref.loc[fixed.index, "SE"], rtol=1e-6)
    for key, value in mixed3.variances.items():
        assert value == pytest.approx(ref.at["var:" + key.replace("Technique", "Method"), "estimate"], rel=1e-5), key
    assert len(mixed3.variances) == 7  # 3 variances, 3 covariances, the residual
    assert mixed3.loglik == pytest.approx(ref.at["loglik", "estimate"], rel=1e-10)
    assert mixed3.n_obs == 390 == int(ref.at["n_obs", "estimate"])
    # k - 1 contrasts to the reference = minus the treatment-coded coefficients of the same model
    c = mixed3.contrasts.set_index("contrast")
    assert list(c.index) == ["Baseline - Ours", "Baseline - Stiff"]
    for name in c.index:
        assert c.at[name, "estimate"] == pytest.approx(ref.at[f"contrast:{name}", "estimate"], abs=1e-7)
        assert c.at[name, "SE"] == pytest.approx(ref.at[f"contrast:{name}", "SE"], rel=1e-6)
    assert mixed3.method["contrast"] == "Baseline - Ours" and mixed3.factor == "Technique"


@pytest.fixture(scope="module")
def cells3():
    data = pd.read_csv(REF / "likert_5x2x3.csv")
    return cell_matrix(data, "y", ["Density", "Viewpoint", "Method"], "subject")


def test_rank_tests_of_each_method_against_the_reference_match_r(cells3):
    ours = ordinal_method_check(cells3)
    ref = pd.read_csv(REF / "ref_likert_5x2x3_wilcoxon.csv", keep_default_na=False)
    m = ours.merge(ref, on=["contrast", "cell"], suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(ref) == 22
    for col in ("V", "p_wilcoxon", "p_sign", "p_t", "p_wilcoxon_holm", "p_sign_holm"):
        np.testing.assert_allclose(m[col].astype(float), m[f"{col}_r"].astype(float), rtol=1e-6, err_msg=col)
    assert (m["n_pos"] == m["n_pos_r"]).all() and (m["n_neg"] == m["n_neg_r"]).all()


def test_friedman_over_three_methods_matches_r(cells3):
    ours = friedman_test(cells3)
    ref = pd.read_csv(REF / "ref_likert_5x2x3_friedman.csv")
    m = ours.merge(ref, on="cell", suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == 11 and (m["df"] == 2).all()
    np.testing.assert_allclose(m["chi2"], m["chi2_r"], rtol=1e-6)
    np.testing.assert_allclose(m["p"], m["p_r"], rtol=1e-6)


def test_holm_is_r_p_adjust():
    np.testing.assert_allclose(holm([0.01, 0.04, 0.03, np.nan]), [0.03, 0.06, 0.06, np.nan])


# ---- 2AFC against R -----------------------------------------------------------------


@pytest.fixture(scope="module")
def choices(three):
    data, _ = load_comparisons(REF / "comparisons_2afc.csv", three)
    return compute_choices(data, three, three.stages[1])


def test_choice_shares_and_position_bias_match_binom_test(choices):
    ref = pd.read_csv(REF / "ref_comparisons_2afc_shares.csv")
    m = choices.shares.merge(ref, on=["method", "cell"], suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == 33  # 3 methods x (10 cells + all)
    for col in ("share", "lower_CL", "upper_CL", "p"):
        np.testing.assert_allclose(m[col], m[f"{col}_r"], rtol=1e-6, err_msg=col)
    assert (m["chosen"] == m["chosen_r"]).all() and (m["shown"] == m["shown_r"]).all()
    left = ref[ref.method == "left"].iloc[0]
    pos = choices.position
    assert pos["left"] == left["chosen"] and pos["trials"] == 600
    for col in ("share", "lower_CL", "upper_CL", "p"):
        assert pos[col] == pytest.approx(left[col], rel=1e-6)


def test_pair_models_match_glmer_within_1e4(choices):
    ref = pd.read_csv(REF / "ref_comparisons_2afc_glmer.csv")
    assert [pm.pair for pm in choices.pairs] == ["Baseline vs Ours", "Baseline vs Stiff", "Ours vs Stiff"]
    for pm in choices.pairs:
        r = ref[ref.pair == pm.pair].set_index("term")
        fixed = pm.fit.fixed.set_index("term")
        assert pm.terms == "Density" and len(fixed) == 5
        np.testing.assert_allclose(fixed["estimate"], r.loc[fixed.index, "estimate"], atol=1e-4)
        np.testing.assert_allclose(fixed["SE"], r.loc[fixed.index, "SE"], atol=1e-4)
        assert pm.fit.variance == pytest.approx(r.at["var:participant (Intercept)", "estimate"], abs=1e-4)
        assert pm.fit.loglik == pytest.approx(r.at["loglik", "estimate"], abs=1e-4)
    assert choices.pairs[2].fit.singular  # lme4: "boundary (singular) fit"


def test_bradley_terry_matches_btm(choices):
    ref = pd.read_csv(REF / "ref_comparisons_2afc_bt.csv").set_index("term")
    ab = choices.bradley_terry.abilities.set_index("method")
    assert list(ab.index) == ["Baseline", "Ours", "Stiff"] and ab.at["Baseline", "ability"] == 0.0
    np.testing.assert_allclose(ab["ability"], ref.loc[ab.index, "estimate"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(ab["SE"], ref.loc[ab.index, "SE"], rtol=1e-6, atol=1e-9)
    assert choices.bradley_terry.loglik == pytest.approx(ref.at["loglik", "estimate"], rel=1e-10)
    with pytest.raises(InvalidInputError, match="'Mine' is not one of"):
        bradley_terry(["Mine"], ["Ours"], [1], ["Baseline", "Ours"])


@pytest.mark.parametrize(
    "edit, needle",
    [
        (lambda t: t.drop(columns="choice"), "missing column\\(s\\) 'choice'"),
        (lambda t: t.assign(choice=["up"] + list(t.choice[1:])), "column 'choice' row 1 .* 'up'; expected 'left'"),
        (lambda t: t.assign(stage=1), "column 'stage' row 1 .* not a 2afc stage"),
        (lambda t: t.assign(method_left="Mine"), "column 'method_left' row 1 .* unknown level 'Mine'"),
        (lambda t: t.assign(chosen_method="Stiff"), "column 'chosen_method' row 1 .* 'Stiff', but choice 'left'"),
        (
            lambda t: pd.concat([t, t.iloc[:1]]),
            "participant .p01. compared Baseline vs Ours .* 2 times \\(rows 1, 601\\)",
        ),
    ],
)
def test_bad_comparisons_name_the_file_column_and_row(three, edit, needle):
    table = pd.read_csv(REF / "comparisons_2afc.csv")
    with pytest.raises(InvalidInputError, match="my.csv: " + needle):
        validate_comparisons(edit(table), three, source="my.csv")


# ---- the whole analysis of a design of one's own ------------------------------------


def _ratings(design, stage, n=8, seed=3, task=None):
    data = simulate_responses(design, n, seed=seed)
    data = data[data.stage == stage].reset_index(drop=True)
    if task is not None:
        if "task" in data.columns:
            data["task"] = task
        else:
            data.insert(3, "task", task)
    return data


@pytest.fixture(scope="module")
def own(tmp_path_factory, three):
    """Likert stage with three methods + 2AFC stage, through files as the CLI reads them."""
    d = tmp_path_factory.mktemp("own")
    _ratings(three, 1, task="likert").to_csv(d / "responses.csv", index=False)
    pd.read_csv(REF / "comparisons_2afc.csv").to_csv(d / "comparisons.csv", index=False)
    options = AnalysisOptions(composites=["QCR"])
    report = analyze(d / "responses.csv", three, d / "out", options, simulated=True)
    return d, report


def test_a_three_method_likert_stage_has_method_with_two_df(own):
    _, report = own
    res = report.results[(1, "QCR")]
    anova = res.anova.set_index("Source")
    assert anova.at["Method", "ddof1"] == 2 and anova.at["Density:Method", "ddof1"] == 8
    assert list(res.method["contrast"]) == ["Baseline - Ours", "Baseline - Stiff", "Ours - Stiff"]
    assert len(res.robustness.mixed.contrasts) == 2 and res.robustness.friedman is not None
    assert set(res.robustness.ordinal["contrast"]) == {"Baseline - Ours", "Baseline - Stiff"}
    assert "Friedman test of the 3 methods" in report.summary and "2 Method slopes" in report.summary


def test_the_2afc_stage_is_analysed_from_comparisons_beside_responses(own):
    d, report = own
    ch = report.result.choices[2]
    assert ch.n_trials == 600 and ch.bradley_terry is not None
    assert "## Stage 2 (corridor), 2AFC" in report.summary and "Bradley-Terry scale" in report.summary
    out = d / "out" / "stage2_corridor"
    for name in ("2afc_shares.csv", "2afc_pairs.csv", "2afc_glmer.csv", "2afc_bradley_terry.csv", "2afc_shares.png"):
        assert (out / name).is_file(), name
    record = json.loads((d / "out" / "analysis.json").read_text())
    stages = {s["stage"]: s for s in record["stages"]}
    assert stages[1]["task"] == "likert" and 1 <= stages[1]["results"][0]["effects"]["Method"]["ddof1"] <= 2
    assert stages[2]["task"] == "2afc" and len(stages[2]["shares"]) == 33
    assert stages[2]["bradley_terry"]["abilities"][0] == pytest.approx(
        {"method": "Baseline", "ability": 0.0, "SE": 0.0, "lower_CL": 0.0, "upper_CL": 0.0, "z": None, "p": None}
    )


def test_other_method_names_and_factor_names_flow_through(tmp_path):
    from crowdstudy.stats.inputs import load_responses
    from crowdstudy.stats.pipeline import compute
    from crowdstudy.stats.scoring import FactorNames
    from crowdstudy.stats.summary import summary_text

    design = _design(task2="likert", methods=("Plain", "Soft", "Firm", "Hard"))
    loaded = load_responses(_ratings(design, 2, n=6), design)
    names = FactorNames(density="Crowding", viewpoint="Camera", method="Technique")
    result = compute(loaded, design, AnalysisOptions(composites=["QOR"]), names=names)
    res = result.results[(2, "QOR")]
    assert res.factors == ("Crowding", "Camera", "Technique")
    assert res.anova.set_index("Source").at["Technique", "ddof1"] == 3
    assert list(res.robustness.mixed.contrasts["contrast"]) == ["Plain - Soft", "Plain - Firm", "Plain - Hard"]
    text = summary_text(result)
    assert "Technique: Plain - Soft" in text and "Linear trend over Crowding" in text
    assert "Method" not in text.replace("methods", "")


def test_a_slider_stage_is_analysed_on_its_scale(tmp_path):
    design = _design(task1="slider", task2="likert", methods=("Baseline", "Ours"))
    plain = _design(task2="likert", methods=("Baseline", "Ours"))
    likert = _ratings(plain, 1, n=6, task="likert")
    items = [f"Q{i}" for i in range(1, 7)]
    slider = likert.assign(task="slider")
    slider[items] = ((likert[items] - 1) * 20).astype(int)  # 1..6 -> 0..100
    report = analyze(slider, design, options=AnalysisOptions(composites=["QCR"], figures=False))
    res = report.results[(1, "QCR")]
    assert res.task == "slider" and res.label == "Stage 1 (concert), QCR (slider 0-100)"
    ref = analyze(likert, plain, options=AnalysisOptions(composites=["QCR"], figures=False, robustness=False))
    # 100 - x reversal and means: the slider scores are (Likert scores - 1) x 20
    np.testing.assert_allclose(res.cells.values, (ref.results[(1, "QCR")].cells.values - 1) * 20)
    assert res.anova["F"].to_numpy() == pytest.approx(ref.results[(1, "QCR")].anova["F"].to_numpy())
    assert "QCR (slider 0-100)" in report.summary
    with pytest.raises(InvalidInputError, match="column 'Q1' row 1 .* expected an integer 0..100 \\(slider answer\\)"):
        analyze(slider.assign(Q1=[101] + list(slider.Q1[1:])), design)


def test_task_column_must_match_the_design(three):
    data = _ratings(three, 1, n=3, task="slider")
    with pytest.raises(InvalidInputError, match="column 'task' row 1 .* says 'slider', but stage 1 .* likert stage"):
        analyze(data, three)
    with pytest.raises(InvalidInputError, match="2AFC trials belong in comparisons.csv"):
        analyze(data.assign(task="2afc"), three)


def test_cli_reads_comparisons_from_a_flag(tmp_path, three, capsys):
    from crowdstudy.cli import main

    design = tmp_path / "three.toml"
    text = default_design_path().read_text()
    text = text.replace(
        'order = ["Baseline", "Ours"]\n',
        'order = ["Baseline", "Ours", "Stiff"]\n\n[methods.Stiff]\ncorrection = "physics"\n'
        "config = { damping = 0.06 }\n",
    )
    text = text.replace("[stages.walking]\n", '[stages.walking]\ntask = "2afc"\n')
    text = text.replace(
        "[questionnaire]\n", '[questionnaire.comparison]\ntext = "Which looks more natural?"\n\n[questionnaire]\n'
    )
    design.write_text(text)
    _ratings(three, 1, n=8, task="likert").to_csv(tmp_path / "responses.csv", index=False)
    rc = main(
        [
            "analyze",
            str(tmp_path / "responses.csv"),
            "--design",
            str(design),
            "--comparisons",
            str(REF / "comparisons_2afc.csv"),
            "--out",
            str(tmp_path / "out"),
            "--no-figures",
        ]
    )
    assert rc == 0 and (tmp_path / "out" / "stage2_corridor" / "2afc_pairs.csv").is_file()
    assert "Position bias" in capsys.readouterr().out


def test_simulated_effects_are_recovered_within_their_intervals(tmp_path, three):
    """The simulated participants' method effects (stats.synthetic) come back out of the
    analysis: the Likert contrasts to the reference and each 2AFC pair's logit."""
    synthetic = pytest.importorskip("crowdstudy.stats.synthetic")
    if not hasattr(synthetic, "simulate_study"):
        pytest.skip("simulate_study (simulated 2afc choices) is not in this version of stats.synthetic")
    model = synthetic.ResponseModel.for_design(
        three, method_effect=0.8, method_effects={"Stiff": 0.3}, density_slope=0.0
    )
    study = synthetic.simulate_study(three, 30, model, seed=7)
    study.responses.to_csv(tmp_path / "responses.csv", index=False)
    study.comparisons.to_csv(tmp_path / "comparisons.csv", index=False)
    report = analyze(tmp_path / "responses.csv", three, options=AnalysisOptions(composites=["QCR"], figures=False))
    contrasts = report.results[(1, "QCR")].robustness.mixed.contrasts.set_index("contrast")
    for name, truth in (("Baseline - Ours", -0.8), ("Baseline - Stiff", -0.3)):
        assert contrasts.at[name, "lower_CL"] < truth < contrasts.at[name, "upper_CL"], name
    for pm in report.result.choices[2].pairs:
        truth = model.choice_slope * (model.effect_of(pm.method_b) - model.effect_of(pm.method_a))
        row = pm.fit.fixed.iloc[0]
        assert abs(row["estimate"] - truth) < 1.96 * row["SE"], pm.pair


def test_power_method_effect_option_takes_names(three):
    from crowdstudy.stats.cli_power import _method_effects

    assert _method_effects(["0.5", "Stiff=0.3"], three) == {"Ours": 0.5, "Stiff": 0.3}
    for bad, needle in (
        (["Mine=1"], "'Mine' is not a method of the design other than its reference 'Baseline'"),
        (["Baseline=1"], "'Baseline' is not a method"),
        (["Stiff=x"], "expected POINTS or NAME=POINTS"),
        (["0.5", "Ours=1"], "'Ours' is given twice"),
    ):
        with pytest.raises(InvalidInputError, match=needle):
            _method_effects(bad, three)


def test_power_with_three_methods_tests_each_against_the_reference(three):
    from crowdstudy.stats.power import power_analysis

    result = power_analysis(three, 6, sims=2, seed=3, stage=1, composites=["QCR"])
    table = result.table.set_index("effect")
    assert list(table.index) == ["Method", "Density:Method", "Baseline - Ours", "Baseline - Stiff"]
    assert table["sims"].eq(2).all() and table.at["Baseline - Ours", "dz_median"] > 0
    assert result.settings["task"] == "likert"


def test_power_of_a_2afc_stage_is_per_pair(three):
    synthetic = pytest.importorskip("crowdstudy.stats.synthetic")
    if not hasattr(synthetic, "simulate_study"):
        pytest.skip("simulate_study (simulated 2afc choices) is not in this version of stats.synthetic")
    from crowdstudy.stats.power import power_analysis

    model = synthetic.ResponseModel.for_design(three, method_effect=1.0, method_effects={"Stiff": 0.0})
    result = power_analysis(three, 8, model=model, sims=3, seed=3, stage=2)
    table = result.table.set_index("effect")
    assert list(table.index) == ["Baseline vs Ours", "Baseline vs Stiff", "Ours vs Stiff"]
    assert table.at["Baseline vs Ours", "share_b_median"] > 0.5 > table.at["Ours vs Stiff", "share_b_median"]
    assert result.settings["task"] == "2afc" and list(result.p_values.columns)[0] == "2afc/Baseline vs Ours"

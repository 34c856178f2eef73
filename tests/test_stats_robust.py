"""The mixed model against lme4 / lmerTest on a dataset with incomplete participants, and the
ordinal checks against R's wilcox.test / binom.test (analysis/reference_r/robust_reference.R)."""

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.anova import rm_anova
from crowdstudy.stats.robust import (
    _design_matrix,
    _sum_coding,
    mixed_model,
    ordinal_method_check,
    sign_test,
    signed_rank_test,
)

REF = Path(__file__).resolve().parent.parent / "analysis" / "reference_r"
W = ["Density", "Viewpoint", "Method"]


@pytest.fixture(scope="module")
def fitted():
    data = pd.read_csv(REF / "likert_incomplete_5x2x2.csv")
    return data, mixed_model(data, "y", W, "subject")


def test_mixed_model_matches_lme4(fitted):
    data, res = fitted
    ref = pd.read_csv(REF / "ref_likert_incomplete_5x2x2_mixed.csv")
    fixed = ref[~ref.term.str.startswith("var:") & ~ref.term.isin(["loglik", "n_obs"])]
    m = res.fixed.merge(fixed, on="term", suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(fixed) == len(res.fixed) == 20
    # both optimisers stop on a flat REML surface: observed estimates within 3e-9, SEs 2e-7,
    # variance components 3e-6 (lme4: bobyqa, rhoend 1e-12; here Powell, xtol 1e-10)
    np.testing.assert_allclose(m["estimate"], m["estimate_r"], rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(m["SE"], m["SE_r"], rtol=1e-6)
    extra = ref.set_index("term")["estimate"]
    for key in ("participant (Intercept)", "participant Method1", "covariance", "residual"):
        assert res.variances[key] == pytest.approx(extra[f"var:{key}"], rel=1e-5), key
    assert res.loglik == pytest.approx(extra["loglik"], rel=1e-10)
    assert res.n_obs == int(extra["n_obs"]) == 288 and res.converged


def test_mixed_model_matches_statsmodels_mixedlm(fitted):
    sm = pytest.importorskip("statsmodels.regression.mixed_linear_model")
    data, res = fitted
    levels = {f: sorted(data[f].unique()) for f in W}
    x, names = _design_matrix(data, W, levels)
    z = np.column_stack([np.ones(len(data)), _sum_coding(data["Method"], levels["Method"])[:, 0]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = sm.MixedLM(data["y"].to_numpy(float), x, data["subject"].to_numpy(), exog_re=z).fit(
            reml=True, method=["bfgs"], gtol=1e-10
        )
    np.testing.assert_allclose(res.fixed["estimate"], np.asarray(fit.fe_params), rtol=1e-6, atol=1e-8)
    assert res.loglik == pytest.approx(float(fit.llf), rel=1e-10)
    assert res.variances["residual"] == pytest.approx(float(fit.scale), rel=1e-5)
    assert res.variances["participant (Intercept)"] == pytest.approx(float(np.asarray(fit.cov_re)[0, 0]), rel=1e-4)


def test_mixed_model_keeps_the_incomplete_participants(fitted):
    data, res = fitted
    assert res.n_participants == 16 and res.n_incomplete == 13
    anova = rm_anova(data, "y", W, "subject", missing="drop")
    assert anova["n_subjects"].iloc[0] == 3  # listwise deletion keeps 3
    # two methods: the Method contrast is twice the sum-coded coefficient, Wald interval around it
    m1 = res.fixed.set_index("term").loc["Method1"]
    assert res.method["contrast"] == "Baseline - Ours"
    assert res.method["estimate"] == pytest.approx(2 * m1["estimate"]) and res.method["p"] == pytest.approx(m1["p"])
    assert res.method["lower_CL"] < res.method["estimate"] < res.method["upper_CL"] < 0
    with pytest.raises(InvalidInputError, match="Method"):
        mixed_model(data, "y", ["Density", "Viewpoint"], "subject")


@pytest.mark.parametrize("name", ["spherical_5x4x2", "likert_5x2x2"])
def test_ordinal_check_matches_wilcox_and_binom(name):
    ref = pd.read_csv(REF / f"ref_{name}_wilcoxon.csv", keep_default_na=False)
    cm = cell_matrix(pd.read_csv(REF / f"{name}.csv"), "y", W, "subject")
    ours = ordinal_method_check(cm)
    m = ours.merge(ref, on="cell", suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(ref) == len(ours) and ours["cell"].iloc[-1] == "all"
    np.testing.assert_array_equal(m["n_pos"], m["n_pos_r"])
    np.testing.assert_allclose(m["V"], m["V_r"].astype(float), rtol=1e-12)
    for col in ("p_wilcoxon", "p_sign", "p_t"):
        np.testing.assert_allclose(m[col], m[f"{col}_r"].astype(float), rtol=1e-6, err_msg=col)
    # continuous scores: exact test; half-point Likert scores: ties, normal approximation
    assert set(ours["wilcoxon_method"]) == ({"exact"} if name.startswith("spherical") else {"normal"})


def test_rank_tests_small_cases():
    # R: wilcox.test(c(1.5, -0.5, 2, 3, 4.5))$p.value = 0.125; binom.test(4, 5)$p.value = 0.375
    assert signed_rank_test([1.5, -0.5, 2, 3, 4.5])["p"] == pytest.approx(0.125)
    assert sign_test([1.5, -0.5, 2, 3, 4.5])["p"] == pytest.approx(0.375)
    assert np.isnan(signed_rank_test([0.0, 0.0])["p"]) and signed_rank_test([0.0, 0.0])["method"] == "none"
    # a zero difference is dropped, as R does
    assert signed_rank_test([0.0, 1.5, -0.5, 2, 3, 4.5])["n"] == 5


def test_analyze_reports_the_robustness_checks(tmp_path):
    import json

    from crowdstudy.design import load_design
    from crowdstudy.stats.options import AnalysisOptions
    from crowdstudy.stats.pipeline import analyze
    from crowdstudy.stats.synthetic import simulate_responses

    design = load_design()
    df = simulate_responses(design, 6, seed=5, stages=[2])
    holes = df.drop(df.index[(df.participant_id == "sim-004")][:3])  # sim-004 lacks 3 cells
    res = analyze(holes, design, tmp_path, AnalysisOptions(composites=("QCR",), missing="drop", figures=False))
    assert res.results[(2, "QCR")].anova["n_subjects"].iloc[0] == 5
    record = json.loads((tmp_path / "analysis.json").read_text())["results"][0]["robustness"]
    assert record["mixed_model"]["n_participants"] == 6 and record["mixed_model"]["n_incomplete"] == 1
    assert record["mixed_model"]["n_obs"] == 6 * 20 - 3
    assert "6 participants (1 incomplete, kept)" in res.summary
    assert "Wilcoxon signed-rank on each participant's mean difference" in res.summary
    ordinal = pd.read_csv(tmp_path / "stage2_corridor" / "QCR_ordinal.csv", keep_default_na=False)
    assert len(ordinal) == 10 + 1 and ordinal["n"].iloc[0] == 5  # the ANOVA's participants
    fixed = pd.read_csv(tmp_path / "stage2_corridor" / "QCR_mixed_model.csv")
    assert fixed["term"].iloc[0] == "(Intercept)" and len(fixed) == 20

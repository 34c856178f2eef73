"""Confidence intervals of contrasts, d_z / g_av, simple effects (joint_tests) and polynomial
trends against emmeans / effectsize in R (analysis/reference_r/intervals_reference.R)."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats._tukey import studentized_range_ppf
from crowdstudy.stats.contrasts import poly_coefficients, polynomial_contrasts, simple_effects
from crowdstudy.stats.effects import critical_value, dz_interval
from crowdstudy.stats.posthoc import pairwise_from_cells

REF = Path(__file__).resolve().parent.parent / "analysis" / "reference_r"
W = ["Density", "Viewpoint", "Method"]
NAMES = ["spherical_5x4x2", "violated_5x4x2", "likert_5x2x2"]
_CM: dict = {}


def _cm(name):
    if name not in _CM:
        _CM[name] = cell_matrix(pd.read_csv(REF / f"{name}.csv"), "y", W, "subject")
    return _CM[name]


def _ref(name, kind):
    return pd.read_csv(REF / f"ref_{name}_{kind}.csv", keep_default_na=False)


@pytest.mark.parametrize("name", NAMES)
def test_contrast_intervals_match_emmeans(name):
    ref = _ref(name, "confint")
    cm = _cm(name)
    checked = 0
    for (factor, by, adjust), r in ref.groupby(["factor", "by", "adjust"], sort=True):
        ours = pairwise_from_cells(cm, factor, by.split(",") if by else [], adjust=adjust)
        m = ours.merge(r, on=["by_level", "contrast"], suffixes=("", "_r"), validate="one_to_one")
        assert len(m) == len(r) == len(ours)
        assert set(m["ci_adjust"]) == {"bonferroni" if adjust == "holm" else adjust}
        np.testing.assert_allclose(m["lower_CL"], m["lower_CL_r"].astype(float), rtol=1e-6, atol=1e-10)
        np.testing.assert_allclose(m["upper_CL"], m["upper_CL_r"].astype(float), rtol=1e-6, atol=1e-10)
        checked += len(m)
    assert checked == len(ref)


@pytest.mark.parametrize("name", NAMES)
def test_dz_and_g_av_match_r(name):
    ref = _ref(name, "effsize")
    cm = _cm(name)
    by_cell = pairwise_from_cells(cm, "Method", ["Density", "Viewpoint"])
    dens = pairwise_from_cells(cm, "Density", [])
    ours = pd.concat([by_cell, dens], ignore_index=True)
    m = ours.merge(ref, on=["factor", "by_level", "contrast"], suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(ref)
    for col in ("dz", "dz_low", "dz_high", "g_av", "g_av_low", "g_av_high"):
        np.testing.assert_allclose(m[col], m[f"{col}_r"].astype(float), rtol=1e-6, err_msg=col)
    # effectsize::cohens_d(paired = TRUE): same d_z; its interval comes from optim() (Nelder-Mead,
    # abstol 1e-9 on the probabilities), observed up to 0.75 % off the exact root found above
    np.testing.assert_allclose(m["dz"], m["effectsize_d"].astype(float), rtol=1e-9)
    np.testing.assert_allclose(m["dz_low"], m["effectsize_low"].astype(float), rtol=1e-2)
    np.testing.assert_allclose(m["dz_high"], m["effectsize_high"].astype(float), rtol=1e-2)


@pytest.mark.parametrize("name", NAMES)
def test_simple_effects_match_joint_tests(name):
    ref = _ref(name, "joint")
    cm = _cm(name)
    parts = [simple_effects(cm, by.split(",")) for by in ref["by"].unique()]
    ours = pd.concat(parts, ignore_index=True)
    ours["key"] = ours["term"].map(lambda t: ":".join(sorted(t.split(":"))))
    ref = ref.assign(key=ref["term"].map(lambda t: ":".join(sorted(t.split(":")))))
    m = ours.merge(ref, on=["by", "by_level", "key"], suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(ref) == len(ours)
    np.testing.assert_array_equal(m["df1"], m["df1_r"].astype(float))
    np.testing.assert_array_equal(m["df2"], m["df2_r"].astype(float))
    np.testing.assert_allclose(m["p"], m["p_r"].astype(float), rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(m["F"], m["F_from_p"].astype(float), rtol=1e-6)
    np.testing.assert_allclose(m["F"], m["F_rounded"].astype(float), atol=5.1e-4)  # joint_tests prints 3 decimals
    # a 1-df simple effect is the paired comparison's t squared
    one = m[(m.by == "Density,Viewpoint")]
    pw = pairwise_from_cells(cm, "Method", ["Density", "Viewpoint"]).set_index("by_level")
    np.testing.assert_allclose(one["F"], pw.loc[one["by_level"], "t"] ** 2, rtol=1e-10)


@pytest.mark.parametrize("name", NAMES)
def test_polynomial_contrasts_match_emmeans(name):
    ref = _ref(name, "poly")
    cm = _cm(name)
    ours = pd.concat(
        [polynomial_contrasts(cm, "Density"), polynomial_contrasts(cm, "Density", "Method")], ignore_index=True
    )
    m = ours.merge(ref, on=["by", "by_level", "contrast"], suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(ref) == len(ours)
    assert (m["coefficients"] == m["coefficients_r"]).all()
    for col in ("estimate", "SE", "t", "p", "lower_CL", "upper_CL"):
        np.testing.assert_allclose(m[col], m[f"{col}_r"].astype(float), rtol=1e-6, atol=1e-12, err_msg=col)


def test_qtukey_and_critical_values_follow_r():
    # R 4.2.2: qtukey(0.95, 5, 19), qtukey(0.95, 2, 15), qtukey(0.95, 10, 7)
    for (k, df), r in {(5, 19): 4.2528308219230677, (2, 15): 3.0143247949591689, (10, 7): 6.1579437044766028}.items():
        assert studentized_range_ppf(0.95, k, df) == pytest.approx(r, rel=1e-12)
    from scipy import stats

    assert critical_value("none", level=0.95, df=15, n_means=2, n_contrasts=1) == pytest.approx(stats.t.ppf(0.975, 15))
    bonf = critical_value("bonferroni", level=0.95, df=15, n_means=5, n_contrasts=10)
    assert bonf == pytest.approx(stats.t.ppf(1 - 0.05 / 20, 15))
    assert critical_value("tukey", level=0.95, df=15, n_means=5, n_contrasts=10) < bonf
    with pytest.raises(InvalidInputError, match="level"):
        critical_value("tukey", level=95, df=15, n_means=5, n_contrasts=10)


def test_dz_interval_coverage_and_degenerate():
    # exact under normality: ~95 % of intervals cover the true d_z
    rng = np.random.default_rng(5)
    hits = sum(lo <= 0.5 <= hi for _, lo, hi in (dz_interval(rng.normal(0.5, 1.0, 12)) for _ in range(400)))
    assert 0.91 <= hits / 400 <= 0.985
    assert all(np.isnan(dz_interval(np.zeros(5))))
    with pytest.raises(InvalidInputError, match="at least 2"):
        dz_interval([1.0])


def test_poly_coefficients_and_bad_arguments():
    np.testing.assert_array_equal(poly_coefficients(3), [[-1, 0, 1], [1, -2, 1]])
    np.testing.assert_array_equal(poly_coefficients(4), [[-3, -1, 1, 3], [1, -1, -1, 1], [-1, 3, -3, 1]])
    cm = _cm("likert_5x2x2")
    with pytest.raises(InvalidInputError, match="'Speed'"):
        polynomial_contrasts(cm, "Speed")
    with pytest.raises(InvalidInputError, match="itself"):
        polynomial_contrasts(cm, "Density", "Density")
    with pytest.raises(InvalidInputError, match="at least one by"):
        simple_effects(cm, [])

"""pairwise() against emmeans (multivariate model, committed references) and its adjustments."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats.posthoc import adjust_pvalues, pairwise, tukey_p

REF = Path(__file__).resolve().parent.parent / "analysis" / "reference_r"
W = ["Density", "Viewpoint", "Method"]


def _cases():
    for name in ["spherical_5x4x2", "violated_5x4x2", "likert_5x2x2", "likert_5x2x3"]:
        ref = pd.read_csv(REF / f"ref_{name}_posthoc.csv", keep_default_na=False)
        for (factor, by, adjust), _ in ref.groupby(["factor", "by", "adjust"], sort=True):
            yield name, factor, by, adjust


_DATA: dict = {}


def _data(name):
    if name not in _DATA:
        _DATA[name] = (
            pd.read_csv(REF / f"{name}.csv"),
            pd.read_csv(REF / f"ref_{name}_posthoc.csv", keep_default_na=False),
        )
    return _DATA[name]


@pytest.mark.parametrize("name, factor, by, adjust", list(_cases()))
def test_matches_emmeans(name, factor, by, adjust):
    data, ref = _data(name)
    ref = ref[(ref.factor == factor) & (ref.by == by) & (ref.adjust == adjust)]
    ours = pairwise(data, "y", W, "subject", factor=factor, by=by.split(",") if by else None, adjust=adjust)
    assert len(ours) == len(ref)
    m = ours.merge(ref, on=["by_level", "contrast"], suffixes=("", "_r"), validate="one_to_one")
    assert len(m) == len(ref)
    np.testing.assert_allclose(m["estimate"], m["estimate_r"].astype(float), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(m["SE"], m["SE_r"].astype(float), rtol=1e-6)
    np.testing.assert_allclose(m["df"], m["df_r"].astype(float), rtol=1e-12)
    np.testing.assert_allclose(m["t"], m["t_ratio"].astype(float), rtol=1e-6, atol=1e-9)
    # the bar is rtol 1e-3 for Tukey; the R-algorithm ptukey reaches 1e-6 (observed < 2e-8)
    np.testing.assert_allclose(m["p_adj"], m["p_value"].astype(float), rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize(
    "q, k, df, r_value",
    [  # R 4.2.2: ptukey(q, k, df, lower.tail = FALSE)
        (3, 5, 19, 0.25181210312867008),
        (4.5, 3, 10, 0.024255808749401697),
        (2, 10, 1000, 0.92288628676658913),
        (5, 4, 150, 0.0030130617092911649),
        (3.2, 6, 30000, 0.209488675920116),
    ],
)
def test_studentized_range_matches_r_and_scipy(q, k, df, r_value):
    from crowdstudy.stats._tukey import studentized_range_sf

    ours = studentized_range_sf([q], k, df)[0]
    assert ours == pytest.approx(r_value, rel=1e-9, abs=1e-15)
    # above 25000 df R (and we) use the infinite-df range distribution
    assert ours == pytest.approx(stats.studentized_range.sf(q, k, df), rel=1e-4 if df <= 25000 else 1e-3)


def test_tukey_two_means_is_the_t_test_and_monotone():
    t = np.array([0.0, 0.5, 2.0, 4.0])
    np.testing.assert_allclose(tukey_p(t, 2, 19), 2 * stats.t.sf(np.abs(t), 19), rtol=1e-12)
    p3 = tukey_p(t, 3, 19)
    p5 = tukey_p(t, 5, 19)
    assert np.all(np.diff(p5) < 0) and np.all(p5[1:] > p3[1:])  # more means, larger p
    assert p3[0] == 1.0


def test_bonferroni_and_holm():
    p = np.array([0.01, 0.04, 0.03, 0.5])
    np.testing.assert_allclose(adjust_pvalues(p, "bonferroni"), [0.04, 0.16, 0.12, 1.0])
    np.testing.assert_allclose(adjust_pvalues(p, "holm"), [0.04, 0.09, 0.09, 0.5])
    np.testing.assert_allclose(adjust_pvalues(p, "none"), p)
    with pytest.raises(InvalidInputError, match="adjust"):
        adjust_pvalues(p, "sidak")


def test_layout_and_default_factor():
    data, _ = _data("likert_5x2x2")
    ph = pairwise(data, "y", W, "subject", by=["Density", "Viewpoint"])
    assert set(ph["factor"]) == {"Method"} and len(ph) == 10
    assert {"Density", "Viewpoint"} <= set(ph.columns)
    assert (ph["n_means"] == 2).all() and (ph["df"] == 15).all()
    first = ph.iloc[0]
    assert first["contrast"] == "Baseline - Ours" and first["by_level"] == "D1,V3"
    # the marginal comparison over a single-factor frame equals averaging first
    marg = data.groupby(["subject", "Density"], as_index=False)["y"].mean()
    a = pairwise(data, "y", W, "subject", factor="Density")
    b = pairwise(marg, "y", "Density", "subject")
    np.testing.assert_allclose(a["p_adj"], b["p_adj"], rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        (dict(factor="Angle"), "factor 'Angle'"),
        (dict(factor="Density", by="Density"), "by factor 'Density' is the compared factor"),
        (dict(factor="Density", by="Light"), "by factor 'Light'"),
        (dict(), "factor is ambiguous"),
        (dict(factor="Method", adjust="scheffe"), "adjust"),
    ],
)
def test_bad_arguments(kwargs, pattern):
    data, _ = _data("likert_5x2x2")
    with pytest.raises(InvalidInputError, match=pattern):
        pairwise(data, "y", W, "subject", **kwargs)

"""rm_anova against R (afex::aov_ez + car, committed references), against statsmodels'
AnovaRM, its input handling and its error rate under the null."""

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats.anova import ANOVA_COLUMNS, effect_contrasts, helmert, rm_anova

REF = Path(__file__).resolve().parent.parent / "analysis" / "reference_r"
DATASETS = ["spherical_5x4x2", "violated_5x4x2", "likert_5x2x2", "likert_5x2x3"]
W = ["Density", "Viewpoint", "Method"]


def _load(name):
    data = pd.read_csv(REF / f"{name}.csv")
    ref = pd.read_csv(REF / f"ref_{name}_anova.csv").set_index("Source")
    return data, ref


def _close(ours, theirs, rtol, atol=1e-12):
    theirs = np.asarray(theirs, float)
    ours = np.asarray(ours, float)
    mask = ~np.isnan(theirs)
    np.testing.assert_allclose(ours[mask], theirs[mask], rtol=rtol, atol=atol)


@pytest.mark.parametrize("name", DATASETS)
def test_matches_afex_and_car(name):
    data, ref = _load(name)
    table = rm_anova(data, "y", W, "subject", correction=True).set_index("Source")
    assert list(table.index) == list(ref.index)  # R's effect order and names
    src = table.index
    for ours, theirs in [
        ("SS", "SS"),
        ("ddof1", "num_df"),
        ("ddof2", "den_df"),
        ("SS_error", "SS_error"),
        ("F", "F"),
        ("p_unc", "p_unc"),
        ("eps_GG", "eps_GG"),
        ("eps_HF", "eps_HF"),
        ("p_GG_corr", "p_GG"),
        ("p_HF_corr", "p_HF"),
        ("W_spher", "W"),
        ("p_spher", "p_W"),
        ("ddof1_used", "afex_GG_num_df"),
        ("ddof2_used", "afex_GG_den_df"),
        ("p", "afex_GG_p"),
        ("ng2", "ges"),
        ("np2", "pes"),
    ]:
        _close(table[ours], ref.loc[src, theirs], rtol=1e-6, atol=1e-10)
    none = rm_anova(data, "y", W, "subject", correction=False).set_index("Source")
    _close(none["p"], ref.loc[src, "afex_none_p"], rtol=1e-6, atol=1e-12)
    _close(none["ng2"], ref.loc[src, "afex_none_ges"], rtol=1e-6, atol=1e-12)
    assert not none["correction_applied"].any()
    one_df = table["ddof1"] == 1
    assert (table.loc[one_df, "eps_GG"] == 1).all() and table.loc[~one_df, "correction_applied"].all()


def test_violated_dataset_triggers_the_papers_rule():
    data, ref = _load("violated_5x4x2")
    auto = rm_anova(data, "y", W, "subject", correction="auto").set_index("Source")
    violated = ref["p_W"] < 0.05
    assert violated.sum() >= 3  # the dataset violates sphericity clearly
    for src in ref.index:
        assert auto.at[src, "correction_applied"] == bool(violated[src])
        expected = ref.at[src, "p_GG"] if violated[src] else ref.at[src, "p_unc"]
        assert auto.at[src, "p"] == pytest.approx(expected, rel=1e-6)
        assert auto.at[src, "sphericity"] == (not violated[src])
    # HF epsilon is reported uncapped (as car prints it) but capped at 1 for its p
    spher = rm_anova(*[_load("spherical_5x4x2")[0]], "y", W, "subject").set_index("Source")
    assert (spher["eps_HF"] > 1).any()
    big = spher["eps_HF"] > 1
    np.testing.assert_allclose(spher.loc[big, "p_HF_corr"], spher.loc[big, "p_unc"], rtol=1e-12)


def test_columns_and_attrs():
    data, _ = _load("likert_5x2x2")
    t = rm_anova(data, "y", W, "subject", effsize="ng2")
    assert tuple(t.columns) == ANOVA_COLUMNS
    assert t.attrs["effsize"] == "ng2" and t.attrs["factors"] == W
    assert t.attrs["levels"]["Density"] == ["D1", "D2", "D3", "D4", "D5"]
    assert (t["n_subjects"] == 16).all()
    assert all(c.isidentifier() for c in t.columns)


def test_contrasts_orthonormal():
    for k in (2, 3, 5):
        h = helmert(k)
        np.testing.assert_allclose(h @ h.T, np.eye(k - 1), atol=1e-12)
        np.testing.assert_allclose(h.sum(axis=1), 0, atol=1e-12)
    c = effect_contrasts((5, 4, 2), (0, 2))
    assert c.shape == (4, 40)
    np.testing.assert_allclose(c @ c.T, np.eye(4), atol=1e-12)


def test_four_factors_match_statsmodels():
    from statsmodels.stats.anova import AnovaRM

    rng = np.random.default_rng(5)
    idx = pd.MultiIndex.from_product(
        [range(9), ["a1", "a2"], ["b1", "b2", "b3"], ["c1", "c2"], ["d1", "d2", "d3"]],
        names=["s", "F1", "F2", "F3", "F4"],
    ).to_frame(index=False)
    idx["y"] = rng.normal(size=len(idx)) + (idx["F1"] == "a2") * 0.5 + idx["s"] * 0.2
    ours = rm_anova(idx, "y", ["F1", "F2", "F3", "F4"], "s").set_index("Source")
    assert len(ours) == 15
    theirs = AnovaRM(idx, "y", "s", within=["F1", "F2", "F3", "F4"]).fit().anova_table
    for src, row in theirs.iterrows():
        key = src
        assert ours.at[key, "F"] == pytest.approx(row["F Value"], rel=1e-9)
        assert ours.at[key, "ddof2"] == row["Den DF"]
        assert ours.at[key, "p_unc"] == pytest.approx(row["Pr > F"], rel=1e-7)


def test_wide_input_and_replicates_match_long():
    data, _ = _load("spherical_5x4x2")
    long = rm_anova(data, "y", W, "subject")
    wide = data.pivot_table(index="subject", columns=W, values="y")
    from_wide = rm_anova(wide, None, None, None)
    np.testing.assert_allclose(from_wide["F"], long["F"], rtol=1e-12)
    # two rows per cell that average to the original value: same ANOVA, flagged as aggregated
    twice = pd.concat([data.assign(y=data.y + 0.5), data.assign(y=data.y - 0.5)], ignore_index=True)
    with pytest.warns(UserWarning, match=r"subject 's01' has 2 'y' values for the cell Density='D1'.*averaged"):
        rep = rm_anova(twice, "y", W, "subject")
    with pytest.raises(InvalidInputError, match=r"subject 's01' has 2 'y' values.*one value per subject"):
        rm_anova(twice, "y", W, "subject", duplicates="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_allclose(rm_anova(twice, "y", W, "subject", duplicates="mean")["F"], long["F"], rtol=1e-10)
    np.testing.assert_allclose(rep["F"], long["F"], rtol=1e-10)
    assert rep.attrs["aggregated"] and not long.attrs["aggregated"]
    # categorical order changes nothing in the statistics
    cat = data.assign(Density=pd.Categorical(data.Density, categories=["D5", "D4", "D3", "D2", "D1"]))
    t = rm_anova(cat, "y", W, "subject")
    np.testing.assert_allclose(t["F"], long["F"], rtol=1e-10)
    assert t.attrs["levels"]["Density"][0] == "D5"


def test_missing_cells_raise_or_drop():
    data, _ = _load("likert_5x2x2")
    holes = data.drop(data.index[(data.subject == "sim-004") & (data.Density == "D3") & (data.Method == "Ours")])
    with pytest.raises(InvalidInputError, match=r"sim-004.*Density='D3'"):
        rm_anova(holes, "y", W, "subject")
    t = rm_anova(holes, "y", W, "subject", missing="drop")
    assert t.attrs["dropped_subjects"] == ["sim-004"] and "sim-004" in t.attrs["note"]
    assert (t["n_subjects"] == 15).all()
    ref = rm_anova(data[data.subject != "sim-004"], "y", W, "subject")
    np.testing.assert_allclose(t["F"], ref["F"], rtol=1e-12)
    nan_dv = data.copy()
    nan_dv.loc[nan_dv.index[5], "y"] = np.nan
    with pytest.raises(InvalidInputError, match=str(nan_dv.subject.iloc[5])):
        rm_anova(nan_dv, "y", W, "subject")


@pytest.mark.parametrize(
    "mutate, kwargs, pattern",
    [
        (None, dict(dv="score"), "dv column 'score'"),
        (None, dict(subject="participant"), "subject column 'participant'"),
        (None, dict(within=["Density", "Angle"]), "within column 'Angle'"),
        (lambda d: d.assign(y=d.y.astype(object).where(d.index != 7, "high")), {}, "dv column 'y'.*'high'"),
        (lambda d: d[d.Method == "Ours"], {}, "within factor 'Method' has a single level 'Ours'"),
        (None, dict(correction="sometimes"), "correction"),
        (None, dict(effsize="d"), "effsize"),
        (None, dict(alpha=1.5), "alpha"),
        (None, dict(missing="ignore"), "missing"),
    ],
)
def test_bad_input_names_the_culprit(mutate, kwargs, pattern):
    data, _ = _load("likert_5x2x2")
    if mutate is not None:
        data = mutate(data)
    args = dict(dv="y", within=W, subject="subject")
    args.update(kwargs)
    with pytest.raises(InvalidInputError, match=pattern):
        rm_anova(data, args.pop("dv"), args.pop("within"), args.pop("subject"), **args)


def test_type_one_error_under_the_null():
    # 300 null studies with non-spherical errors: GG-corrected tests keep the nominal rate
    rng = np.random.default_rng(3)
    n, k = 12, 4
    scale = np.array([0.3, 0.6, 1.2, 2.4])  # unequal variances: sphericity violated
    subjects = np.repeat(np.arange(n), k)
    levels = np.tile([f"L{i}" for i in range(k)], n)
    rej_gg = rej_unc = 0
    sims = 300
    for _ in range(sims):
        y = (rng.normal(size=(n, 1)) + rng.normal(size=(n, k)) * scale).ravel()
        t = rm_anova(pd.DataFrame({"s": subjects, "A": levels, "y": y}), "y", "A", "s", correction=True)
        rej_gg += t["p_GG_corr"].iloc[0] < 0.05
        rej_unc += t["p_unc"].iloc[0] < 0.05
    # binomial 99.9 % band around 0.05 for 300 draws is about [0.015, 0.095]
    assert 0.015 <= rej_gg / sims <= 0.085
    assert rej_unc >= rej_gg


def test_mauchly_undefined_with_few_subjects():
    # 10 subjects, a 12-df interaction: the error matrix is singular; car prints no test
    # ("non-sphericity tests and corrections not available"); we report NaN and, under
    # "auto", apply the Greenhouse-Geisser correction (computed from the eigenvalues)
    data, _ = _load("spherical_5x4x2")
    few = data[data.subject.isin([f"s{i:02d}" for i in range(1, 11)])]
    t = rm_anova(few, "y", W, "subject").set_index("Source")
    row = t.loc["Density:Viewpoint"]
    assert np.isnan(row["W_spher"]) and np.isnan(row["p_spher"]) and not row["sphericity"]
    assert row["correction_applied"] and 1 / 12 <= row["eps_GG"] < 1
    # R (car 3.1-1) on the same data for a testable effect: W = 0.44556, p = 0.75047
    assert t.at["Density", "W_spher"] == pytest.approx(0.44556, abs=5e-6)
    assert t.at["Density", "p_spher"] == pytest.approx(0.75047, abs=5e-6)
    assert t.at["Density", "eps_GG"] == pytest.approx(0.7734416, abs=5e-8)


def test_degenerate_data_gives_undefined_f_not_significance():
    # every score identical: 0/0 for every effect; no "significant" effect may come out
    data, _ = _load("likert_5x2x2")
    flat = data.assign(y=3.5)
    t = rm_anova(flat, "y", W, "subject")
    assert t["F"].isna().all() and t["p"].isna().all() and t["np2"].isna().all()
    assert t.attrs["undefined"] == list(t["Source"]) and "F undefined" in t.attrs["note"]
    from crowdstudy.stats.report import apa_summary

    assert apa_summary(t) == []
    # an effect with a real SS but an exactly zero error (every subject shifts the same) stays F = inf
    shifted = data.assign(y=3.0 + (data.Method == "Ours") * 1.0)
    t2 = rm_anova(shifted, "y", W, "subject").set_index("Source")
    assert np.isinf(t2.at["Method", "F"]) and t2.at["Method", "p"] == 0.0
    assert np.isnan(t2.at["Density", "F"]) and t2.attrs["undefined"] == [s for s in t2.index if s != "Method"]

"""Report pieces (APA text, tables), the analyze pipeline, the CLI commands and power."""

import json

import numpy as np
import pandas as pd
import pytest

from crowdstudy.cli import main as cli_main
from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.options import AnalysisOptions
from crowdstudy.stats.pipeline import analyze
from crowdstudy.stats.power import power_analysis
from crowdstudy.stats.report import (
    apa_effect,
    apa_summary,
    descriptives_from_cells,
    format_p,
    stars,
    to_latex,
    to_markdown,
)
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def responses(design):
    return simulate_responses(design, 8, seed=7)


def test_stars_and_p_format():
    assert [stars(p) for p in (0.0004, 0.004, 0.04, 0.06, float("nan"))] == ["***", "**", "*", "", ""]
    assert format_p(0.0004) == "p < .001" and format_p(0.0312) == "p = .031" and format_p(0.5) == "p = .500"


def test_apa_text():
    row = {
        "Source": "Density:Method",
        "ddof1_used": 2.4513,
        "ddof2_used": 71.087,
        "F": 12.3049,
        "p": 0.00002,
        "np2": 0.2977,
        "ng2": 0.05,
        "correction_applied": True,
        "eps_GG": 0.6128,
    }
    assert apa_effect(row) == (
        "F(2.45, 71.09) = 12.30, p < .001, eta_p^2 = .30 (Greenhouse-Geisser corrected, eps = 0.61)"
    )
    table = pd.DataFrame(
        [
            row,
            {
                **row,
                "Source": "Viewpoint",
                "p": 0.2,
                "ddof1_used": 3.0,
                "ddof2_used": 87.0,
                "correction_applied": False,
            },
        ]
    )
    table.attrs.update(alpha=0.05, effsize="np2")
    lines = apa_summary(table, label="Stage 1, QCR")
    assert lines == [
        "Stage 1, QCR: a significant Density x Method interaction, F(2.45, 71.09) = 12.30, "
        "p < .001, eta_p^2 = .30 (Greenhouse-Geisser corrected, eps = 0.61)."
    ]


def test_tables_render():
    df = pd.DataFrame({"Source": ["Density", "a_b"], "F": [1.23456, 1e-9], "ok": [True, False]})
    md = to_markdown(df)
    assert md.splitlines()[0] == "| Source | F | ok |" and "| Density | 1.235 | yes |" in md
    tex = to_latex(df, caption="x +- y")
    assert r"\toprule" in tex and r"a\_b" in tex and r"$\pm$" in tex and tex.count(r"\\") == 3


def test_descriptives_by_hand(design, responses):
    from crowdstudy.stats.scoring import cell_means, composite_scores

    long = cell_means(composite_scores(responses, design), "QCA", design, stage=1)
    cm = cell_matrix(long, "QCA", ["Density", "Viewpoint", "Method"], "participant_id")
    desc = descriptives_from_cells(cm, "QCA")
    assert len(desc) == 5 + 4 + 2 + 20 + 10 + 8 + 40
    ours = desc[(desc.effect == "Method") & (desc.Method == "Ours")].iloc[0]
    per_subject = long[long.Method == "Ours"].groupby("participant_id")["QCA"].mean()
    assert ours["mean"] == pytest.approx(per_subject.mean()) and ours["sd"] == pytest.approx(per_subject.std())
    assert ours["mean_sd"] == f"{per_subject.mean():.2f} +- {per_subject.std():.2f}"


def test_analyze_writes_the_report(design, responses, tmp_path):
    res = analyze(responses, design, tmp_path, AnalysisOptions(stages=(2,), composites=("QCR",)))
    r = res.results[(2, "QCR")]
    assert list(r.anova["Source"])[:3] == ["Density", "Viewpoint", "Method"]
    assert r.anova.set_index("Source").at["Method", "p"] < 0.05  # the simulated effect is found
    method_rows = r.posthoc[r.posthoc["effect"] == "Method"]
    assert len(method_rows) == 1 and method_rows["estimate"].iloc[0] < 0  # Baseline - Ours < 0
    assert len(r.method_by_cell) == 10
    d = tmp_path / "stage2_corridor"
    for name in (
        "QCR_anova.csv",
        "QCR_anova.md",
        "QCR_anova.tex",
        "QCR_posthoc.csv",
        "QCR_descriptives.tex",
        "QCR_shapiro.csv",
        "QCR_qq.png",
        "QCR_by_density.png",
        "scores_by_density.png",
    ):
        assert (d / name).stat().st_size > 0, name
    summary = (tmp_path / "summary.md").read_text()
    assert "a significant main effect of Method, F(1, 7) = " in summary and "Item-pair reliability" in summary
    record = json.loads((tmp_path / "analysis.json").read_text())
    assert record["results"][0]["effects"]["Method"]["p"] == pytest.approx(
        r.anova.set_index("Source").at["Method", "p"]
    )
    assert "git_sha" in record["provenance"]
    back = pd.read_csv(d / "QCR_anova.csv")
    np.testing.assert_allclose(back["F"], r.anova["F"], rtol=1e-9)


def test_analyze_listwise_deletion(design, responses):
    holes = responses.drop(responses.index[(responses.participant_id == "sim-003") & (responses.stage == 2)][:1])
    with pytest.raises(InvalidInputError, match="sim-003"):
        analyze(holes, design, None, AnalysisOptions(stages=(2,), composites=("QCR",)))
    res = analyze(holes, design, None, AnalysisOptions(stages=(2,), composites=("QCR",), missing="drop"))
    assert res.results[(2, "QCR")].anova.attrs["dropped_subjects"] == ["sim-003"]
    assert "listwise deletion" in res.summary


def test_cli_analyze(design, responses, tmp_path, capsys):
    csv = tmp_path / "responses.csv"
    responses.to_csv(csv, index=False)
    assert cli_main(["analyze", str(csv), "--out", str(tmp_path / "out"), "--no-figures", "--stage", "1"]) == 0
    assert (tmp_path / "out" / "stage1_concert" / "QOR_anova.tex").is_file()
    assert not (tmp_path / "out" / "stage2_corridor").exists()
    assert cli_main(["analyze", str(tmp_path / "nope.csv"), "--out", str(tmp_path / "x")]) == 2
    responses.drop(columns=["Q2"]).to_csv(csv, index=False)
    assert cli_main(["analyze", str(csv), "--out", str(tmp_path / "y")]) == 2
    assert "'Q2'" in capsys.readouterr().err


def test_power(design, tmp_path, capsys):
    res = power_analysis(
        design,
        6,
        model=ResponseModel.for_design(design, method_effect=2.0),
        sims=4,
        seed=3,
        stage=2,
        composites=["QCR"],
    )
    table = res.table.set_index("effect")
    assert table.at["Method", "power"] == 1.0 and table.at["Method", "mc_se"] == 0.0
    assert res.p_values.shape == (4, 2)
    null = power_analysis(
        design,
        6,
        model=ResponseModel.for_design(design, method_effect=0.0, participant_method_sd=0.0),
        sims=4,
        seed=3,
        stage=2,
        composites=["QCR"],
    )
    assert null.p_values["QCR/Method"].median() > res.p_values["QCR/Method"].median()
    out = tmp_path / "power.json"
    assert (
        cli_main(
            [
                "power",
                "-n",
                "5",
                "--method-effect",
                "0.5",
                "--sims",
                "2",
                "--seed",
                "1",
                "--stage",
                "2",
                "--composite",
                "QCR",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    data = json.loads(out.read_text())
    assert {r["effect"] for r in data["table"]} == {"Method", "Density:Method"}
    assert "power" in capsys.readouterr().out
    with pytest.raises(InvalidInputError, match="sims"):
        power_analysis(design, 6, sims=0)


def test_single_viewpoint_design_and_determinism(tmp_path):
    import tomllib

    from crowdstudy.design import default_design_path, parse_design

    raw = tomllib.loads(default_design_path().read_text())
    raw["stages"]["walking"]["viewpoints"] = ["V4"]
    one_view = parse_design(raw)
    df = simulate_responses(one_view, 6, seed=2, stages=[2])
    runs = [
        analyze(df, one_view, tmp_path / f"run{i}", AnalysisOptions(composites=("QCA",), figures=False))
        for i in range(2)
    ]
    table = runs[0].results[(2, "QCA")].anova
    assert list(table["Source"]) == ["Density", "Method", "Density:Method"]  # Viewpoint left out
    assert len(runs[0].results[(2, "QCA")].method_by_cell) == 5
    for name in ("QCA_anova.csv", "QCA_anova.tex", "QCA_posthoc.csv", "QCA_descriptives.md"):
        a = (tmp_path / "run0" / "stage2_corridor" / name).read_bytes()
        assert a == (tmp_path / "run1" / "stage2_corridor" / name).read_bytes(), name


def test_shapiro_per_cell_and_qq_figure(tmp_path, saved_figures):
    from pathlib import Path

    from scipy import stats

    from crowdstudy.stats.assumptions import qq_figure, shapiro_by_cell

    data = pd.read_csv(Path(__file__).resolve().parent.parent / "analysis" / "reference_r" / "violated_5x4x2.csv")
    w = ["Density", "Viewpoint", "Method"]
    shp = shapiro_by_cell(data, "y", w, "subject")
    assert len(shp) == 40 and list(shp.columns[:3]) == w
    cell = data[(data.Density == "D5") & (data.Viewpoint == "V4") & (data.Method == "Ours")]["y"]
    expected = stats.shapiro(cell - cell.mean())
    row = shp[shp.cell == "D5 V4 Ours"].iloc[0]
    assert row["W"] == pytest.approx(expected.statistic) and row["p"] == pytest.approx(expected.pvalue)
    assert row["n"] == 20
    import matplotlib
    from PIL import Image

    v1 = data[data.Viewpoint == "V1"]
    with matplotlib.rc_context({"savefig.bbox": "tight"}):  # as the paper figures' style sets it
        out = qq_figure(v1, "y", ["Density", "Method"], "subject", tmp_path / "qq.png")
    fig = saved_figures[-1]
    # the laid-out figure is saved whole (110 dpi), not re-cropped by the caller's rcParams
    size, whole = Image.open(out).size, fig.get_size_inches() * 110
    assert abs(size[0] - whole[0]) <= 1 and abs(size[1] - whole[1]) <= 1, (size, whole)
    panels = [ax for ax in fig.axes if ax.lines]
    assert len(panels) == 10  # 5 densities x 2 methods
    shp_v1 = shapiro_by_cell(v1, "y", ["Density", "Method"], "subject")
    for ax, (_, r) in zip(panels, shp_v1.iterrows(), strict=True):
        assert ax.get_title() == f"{r['cell']}\np={r['p']:.3f}"
        d, m = r["cell"].split()
        y = v1[(v1.Density == d) & (v1.Method == m)].groupby("subject")["y"].mean()
        osm, osr = stats.probplot(y - y.mean(), dist="norm")[0]
        np.testing.assert_allclose(ax.lines[0].get_ydata(), osr, atol=1e-12)
        np.testing.assert_allclose(ax.lines[0].get_xdata(), osm, atol=1e-12)

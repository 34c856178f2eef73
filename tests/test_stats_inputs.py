"""What analyze refuses or reports instead of reshaping silently: repeated answers, missing or
foreign levels and stages, unreadable files, degenerate data; participants.csv exclusions;
"simulated" on figures and summary; the stars' caption and the omnibus gate."""

import json

import numpy as np
import pandas as pd
import pytest

from crowdstudy.cli import main as cli_main
from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import cell_matrix
from crowdstudy.stats.figures import method_figure, stars_caption
from crowdstudy.stats.options import AnalysisOptions
from crowdstudy.stats.pipeline import analyze
from crowdstudy.stats.scoring import cell_means, composite_scores
from crowdstudy.stats.synthetic import ResponseModel, simulate_responses


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def walk(design):
    """6 simulated participants, walking stage only (20 trials each)."""
    return simulate_responses(design, 6, seed=11, stages=[2])


def _run(df, design, participants=None, **kw):
    kw.setdefault("composites", ("QCR",))
    return analyze(df, design, None, AnalysisOptions(figures=False, **kw), participants=participants)


def test_a_repeated_answer_is_refused_naming_participant_cell_and_rows(design, walk):
    again = walk.iloc[[5]].assign(Q1=(walk.Q1.iloc[5] % 6) + 1)  # answered twice, differently
    df = pd.concat([walk, again], ignore_index=True)
    row = walk.iloc[5]
    with pytest.raises(
        InvalidInputError,
        match=(
            rf"participant '{row.participant_id}' answered stage 2, density_level '{row.density_level}', "
            rf"viewpoint '{row.viewpoint}', method '{row.method}' 2 times \(rows 6, {len(walk) + 1}\)"
        ),
    ):
        _run(df, design)


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (
            lambda d: d.assign(viewpoint=d.viewpoint.replace("V4", "V1")),
            r"'viewpoint' row \d+ .*unknown level 'V1': stage 2 \(corridor\) .* viewpoint\(s\) V3, V4",
        ),
        (lambda d: d[d.density_level != "D5"], r"stage 2 \(corridor\) has no rows for the density level 'D5'"),
        (lambda d: d[d.viewpoint != "V3"], r"has no rows for the viewpoint 'V3'"),
        (
            lambda d: d.assign(stage=np.where(d.index == 3, 3, d.stage)),
            r"'stage' row 4 .*holds stage 3, which the design",
        ),
        (lambda d: d.assign(scenario="concert"), r"'scenario' row 1 .*unknown level 'concert'"),
        (lambda d: d.assign(Q5=np.where(d.index == 9, 7, d.Q5)), r"'Q5' row 10 \(participant 'sim-001'\) holds 7;"),
    ],
)
def test_the_design_is_never_shrunk_silently(design, walk, mutate, pattern):
    with pytest.raises(InvalidInputError, match=pattern) as info:
        _run(mutate(walk.copy()), design)
    assert "np." not in str(info.value)
    with pytest.raises(InvalidInputError, match=r"stage 3 is not in the design"):
        _run(walk, design, stages=[3])


def test_files_are_named_in_every_error(design, walk, tmp_path, capsys):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"PK\x03\x04\x00\x00\xff\xfe" * 64)
    headers_only = tmp_path / "headers.csv"
    walk.iloc[:0].to_csv(headers_only, index=False)
    for path, what in ((empty, "is empty"), (binary, "binary data"), (headers_only, "no rows")):
        assert cli_main(["analyze", str(path), "--out", str(tmp_path / "o"), "--no-figures"]) == 2
        err = capsys.readouterr().err
        assert str(path) in err and what in err, err
    bad = tmp_path / "bad.csv"
    walk.assign(Q2=np.where(walk.index == 0, 9, walk.Q2)).to_csv(bad, index=False)
    assert cli_main(["analyze", str(bad), "--out", str(tmp_path / "o"), "--no-figures"]) == 2
    assert (
        f"{bad}: column 'Q2' row 1 (participant 'sim-001') holds 9; expected an integer 1..6" in capsys.readouterr().err
    )


def test_a_missing_cell_names_file_stage_and_participant(design, walk, tmp_path):
    csv = tmp_path / "responses.csv"
    walk.drop(walk.index[(walk.participant_id == "sim-002")][:1]).to_csv(csv, index=False)
    with pytest.raises(InvalidInputError, match=rf"{csv}: stage 2 \(corridor\), QCR: subject 'sim-002' has no"):
        analyze(csv, design, None, AnalysisOptions(composites=("QCR",), figures=False))


def test_identical_scores_report_no_effect(design, walk):
    flat = walk.assign(Q1=4, Q2=3, Q3=4, Q4=3, Q5=4, Q6=3)
    res = _run(flat, design)
    table = res.results[(2, "QCR")].anova
    assert table["F"].isna().all() and table["np2"].isna().all()
    assert "No significant effect." in res.summary and "F undefined" in res.summary
    assert "significant main effect" not in res.summary
    assert "mixed model is undefined" in res.summary


def _participants(walk, excluded: dict[str, str]) -> pd.DataFrame:
    ids = sorted(walk.participant_id.unique())
    return pd.DataFrame(
        {
            "participant": ids,
            "excluded": [int(i in excluded) for i in ids],
            "exclusion_reason": [excluded.get(i, "") for i in ids],
        }
    )


def test_participants_csv_excludes_and_counts_reasons(design, walk, tmp_path):
    folder = tmp_path / "export"
    folder.mkdir()
    walk.to_csv(folder / "responses.csv", index=False)
    _participants(walk, {"sim-002": "attention_check;too_fast", "sim-005": "too_fast"}).to_csv(
        folder / "participants.csv", index=False
    )
    out = tmp_path / "out"
    # found beside responses.csv without being named
    assert (
        cli_main(["analyze", str(folder / "responses.csv"), "--out", str(out), "--no-figures", "--stars", "omnibus"])
        == 0
    )
    record = json.loads((out / "analysis.json").read_text())
    assert record["settings"]["stars"] == "omnibus"
    assert record["participants"] == 4 and record["results"][0]["n_subjects"] == 4
    assert record["exclusions"]["n_excluded"] == 2 and record["exclusions"]["excluded"] == ["sim-002", "sim-005"]
    assert record["exclusions"]["reasons"] == {"too_fast": 2, "attention_check": 1}
    summary = (out / "summary.md").read_text()
    assert "2 of 6 participants excluded before the analysis (too_fast: 2, attention_check: 1)" in summary
    # the same numbers as dropping them by hand
    by_hand = _run(walk[~walk.participant_id.isin(["sim-002", "sim-005"])], design, composites=None)
    assert record["results"][0]["effects"]["Method"]["F"] == pytest.approx(
        by_hand.results[(2, "QCR")].anova.set_index("Source").at["Method", "F"], rel=1e-12
    )
    # an explicit --participants file; nobody excluded
    other = tmp_path / "people.csv"
    _participants(walk, {}).to_csv(other, index=False)
    res = analyze(
        folder / "responses.csv", design, None, AnalysisOptions(figures=False, composites=("QCR",)), participants=other
    )
    assert "none of 6 participants excluded" in res.summary
    assert res.results[(2, "QCR")].anova["n_subjects"].iloc[0] == 6


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (lambda p: p[p.participant != "sim-003"], r"participant 'sim-003' of the responses is not listed"),
        (
            lambda p: p.assign(excluded=np.where(p.index == 1, 2, p.excluded)),
            r"'excluded' row 2 .*holds 2; expected 0 or 1",
        ),
        (lambda p: p.drop(columns=["exclusion_reason"]), r"missing column\(s\) 'exclusion_reason'"),
        (lambda p: p.assign(excluded=1), r"every participant of the responses is excluded"),
    ],
)
def test_bad_participants_tables(design, walk, tmp_path, mutate, pattern):
    path = tmp_path / "participants.csv"
    mutate(_participants(walk, {})).to_csv(path, index=False)
    with pytest.raises(InvalidInputError, match=pattern) as info:
        _run(walk, design, participants=path)
    assert str(path) in str(info.value)


def test_simulated_data_are_labelled_and_the_stars_explained(design, tmp_path):
    null = ResponseModel.for_design(design, method_effect=0.0, participant_method_sd=0.0)
    df = simulate_responses(design, 6, null, seed=3, stages=[2])
    csv = tmp_path / "responses.csv"
    df.to_csv(csv, index=False)
    (tmp_path / "responses.json").write_text(json.dumps({"simulated": True, "note": "bots"}))
    res = analyze(csv, design, tmp_path / "a", AnalysisOptions(composites=("QCR",), stars="omnibus"))
    table = res.results[(2, "QCR")].anova.set_index("Source")
    assert not (table.loc[[s for s in table.index if "Method" in s], "p"] < 0.05).any()  # no Method effect
    assert "SIMULATED data" in res.summary and "Figure stars omitted" in res.summary
    fig = json.loads((tmp_path / "a" / "stage2_corridor" / "QCR_by_density.json").read_text())
    assert fig["note"].startswith("SIMULATED") and "drawn only if an ANOVA effect involving Method" in fig["caption"]
    assert "paired t test" in fig["caption"] and "no correction across cells" in fig["caption"]
    assert all(p["stars"] == "" for p in fig["series"]["QCR"])
    assert json.loads((tmp_path / "a" / "analysis.json").read_text())["simulated"] is True
    # without the sidecar: not labelled; "always" draws whatever the per-cell tests give
    (tmp_path / "responses.json").unlink()
    res = analyze(csv, design, tmp_path / "b", AnalysisOptions(composites=("QCR",), stars="always", figures=False))
    record = json.loads((tmp_path / "b" / "analysis.json").read_text())
    assert "SIMULATED" not in res.summary and record["simulated"] is False
    cells = res.results[(2, "QCR")].method_by_cell
    cells = cells.assign(p_adj=np.where(np.arange(len(cells)) == 3, 0.0004, cells["p_adj"]))  # one sure star
    long = cell_means(composite_scores(df, design), "QCR", design, stage=2)
    cm = cell_matrix(long, "QCR", ["Density", "Viewpoint", "Method"], "participant_id")
    out = method_figure({"QCR": (cm, cells)}, tmp_path / "b" / "fig.png", caption=stars_caption("tukey", 2))
    fig = json.loads(out.with_suffix(".json").read_text())
    assert fig["note"] == "" and "drawn only" not in fig["caption"]
    expected = {(r.Density, r.Viewpoint): r.p_adj < 0.05 for r in cells.itertuples()}
    drawn = {(p["density"], p["viewpoint"]): p["stars"] != "" for p in fig["series"]["QCR"]}
    assert drawn == expected and sum(drawn.values()) >= 1


def test_stars_caption_names_the_test_and_adjustment():
    assert "bonferroni-adjusted within a cell" in stars_caption("bonferroni", 3)
    assert "the ANOVA's Method effect" in stars_caption("tukey", 2, rule="omnibus", gate="Method")

"""The analysis as three steps: load, compute (typed result, no file I/O), write; and its
settings as one validated AnalysisOptions."""

import json

import pytest

from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.stats.inputs import load_responses
from crowdstudy.stats.options import AnalysisOptions
from crowdstudy.stats.pipeline import analyze, compute
from crowdstudy.stats.results import CompositeResult
from crowdstudy.stats.summary import summary_text
from crowdstudy.stats.synthetic import simulate_responses
from crowdstudy.stats.writers import write_analysis


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def walk(design):
    return simulate_responses(design, 6, seed=11, stages=[2])


@pytest.mark.parametrize(
    "kw, needle",
    [
        (dict(stars="sometimes"), "stars must be 'always' or 'omnibus', got 'sometimes'"),
        (dict(adjust="scheffe"), "adjust must be 'tukey' or 'bonferroni' or 'holm'"),
        (dict(correction=True), "correction must be 'auto' or 'always' or 'never', got True"),
        (dict(effsize="d"), "effsize"),
        (dict(missing="ignore"), "missing"),
        (dict(error_bars="iqr"), "error_bars"),
        (dict(level=1.0), r"level must be in \(0, 1\), got 1.0"),
        (dict(alpha=0), r"alpha must be in \(0, 1\)"),
        (dict(composites="QCR"), "composites must be a list"),
    ],
)
def test_options_reject_bad_settings_naming_them(kw, needle):
    with pytest.raises(InvalidInputError, match=needle):
        AnalysisOptions(**kw)


def test_options_are_frozen_and_normalised():
    o = AnalysisOptions(stages=[1, 2], composites=["QCR"])
    assert o.stages == (1, 2) and o.composites == ("QCR",)
    with pytest.raises(AttributeError):
        o.alpha = 0.1
    # what summary.md and analysis.json state: rm_anova's spelling of the rule
    assert [AnalysisOptions(correction=c).settings()["correction"] for c in ("auto", "always", "never")] == [
        "auto",
        True,
        False,
    ]


def test_compute_then_write_is_analyze(design, walk, tmp_path, monkeypatch):
    options = AnalysisOptions(composites=("QCR", "QOR"), figures=False)
    monkeypatch.chdir(tmp_path)
    result = compute(load_responses(walk, design), design, options)
    assert list(tmp_path.iterdir()) == []  # computing writes nothing
    assert list(result.results) == [(2, "QCR"), (2, "QOR")]
    r = result.results[(2, "QCR")]
    assert isinstance(r, CompositeResult) and r.factors == ("Density", "Viewpoint", "Method")
    assert r.label == "Stage 2 (corridor), QCR" and r.robustness is not None and r.robustness.mixed is not None
    assert result.n_participants == 6 and result.exclusions is None
    assert result.simulated and result.simulated_note.startswith("SIMULATED")  # simulate_responses marks it

    files = write_analysis(result, summary_text(result), tmp_path / "steps")
    report = analyze(walk, design, tmp_path / "whole", options)
    assert report.summary == summary_text(result)
    assert [f.relative_to(tmp_path / "steps") for f in files] == [
        f.relative_to(tmp_path / "whole") for f in report.files
    ]
    for f in files:
        if f.name != "analysis.json":
            assert f.read_bytes() == (tmp_path / "whole" / f.relative_to(tmp_path / "steps")).read_bytes(), f
    record = json.loads((tmp_path / "steps" / "analysis.json").read_text())
    assert record["settings"]["correction"] == "auto" and record["participants"] == 6


def test_the_factors_are_passed_to_compute(design, walk):
    loaded = load_responses(walk, design)
    options = AnalysisOptions(composites=("QCA",), robustness=False)
    result = compute(loaded, design, options, factors=("Method", "Density", "Viewpoint"))
    r = result.results[(2, "QCA")]
    assert r.factors == ("Method", "Density", "Viewpoint") and r.cells.factors == r.factors
    assert list(r.anova["Source"])[:3] == ["Method", "Density", "Viewpoint"]
    assert r.robustness is None and list(r.others) == ["Density", "Viewpoint"]
    default = compute(loaded, design, options).results[(2, "QCA")]
    by_source = default.anova.set_index("Source")
    assert r.anova.set_index("Source").at["Method", "F"] == pytest.approx(by_source.at["Method", "F"], rel=1e-12)

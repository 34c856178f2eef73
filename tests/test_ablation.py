"""What each addition buys (issue #41): the groups of PhysicsConfig fields that switch each
addition to the paper's method off (crowdstudy.physics.ablation) and ``crowdstudy bench
physics --ablation`` (crowdstudy.evaluation.ablation_run, .ablation_report), on small crowds
and short clips."""

from __future__ import annotations

import collections
import json
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.ablation import (
    ADDITIONS,
    INERT_IN_PAPER,
    KEPT_IN_PAPER,
    OFF_BY_DEFAULT,
    PAPER_FIELDS,
    parse_additions,
    without,
)
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.config_keys import leaves


def _value(config: PhysicsConfig, path: str):
    for part in path.split("."):
        config = getattr(config, part)
    return config


def _differences(a: PhysicsConfig, b: PhysicsConfig) -> set[str]:
    return {path for path in leaves(PhysicsConfig) if _value(a, path) != _value(b, path)}


def test_every_field_is_accounted_for_exactly_once():
    """Each field of the configuration is the paper's (PAPER_FIELDS), kept by its preset
    (KEPT_IN_PAPER), an addition the defaults leave off (OFF_BY_DEFAULT) or in exactly one
    addition's group; a new field must be placed before this passes."""
    owned = [f for a in ADDITIONS.values() for f in a.fields]
    owned += [*PAPER_FIELDS, *KEPT_IN_PAPER, *OFF_BY_DEFAULT]
    twice = [path for path, n in collections.Counter(owned).items() if n > 1]
    assert not twice, f"fields in two places: {twice}"
    assert set(owned) == set(leaves(PhysicsConfig))


def test_every_addition_off_gives_the_paper_preset():
    """The defaults with every addition off are PhysicsConfig.paper(), but for the fields of
    INERT_IN_PAPER; the paper's fields keep the defaults' values in the preset."""
    off = without(ADDITIONS)
    paper = PhysicsConfig.paper()
    assert _differences(off, paper) == set(INERT_IN_PAPER)
    assert off.with_values({path: _value(paper, path) for path in INERT_IN_PAPER}) == paper
    default = PhysicsConfig()
    for path in [*PAPER_FIELDS, *KEPT_IN_PAPER, *OFF_BY_DEFAULT]:
        assert _value(paper, path) == _value(default, path), path


def test_each_addition_changes_only_its_own_fields():
    default = PhysicsConfig()
    for name, addition in ADDITIONS.items():
        changed = _differences(without([name]), default)
        assert changed == set(addition.changes), name  # every change is a change, and no other field moves
        assert addition.description and set(addition.changes) <= set(addition.fields)


def test_the_inert_differences_do_nothing():
    """Where the preset and the defaults-without-everything differ, the field is idle: no
    skin at a percentile of 0 whatever its cap and the hands' share, no low-pass (and so no
    hold) at zero widths."""
    from crowdstudy.body import load_body
    from crowdstudy.body.capsules import capsule_skin
    from crowdstudy.body.shapes import sample_bodies
    from crowdstudy.physics.finish import smooth_deviation

    body = load_body(sample_bodies(1, 4)[0])
    assert np.any(capsule_skin(body, 90.0, max_skin=0.015, hand_scale=0.5) > 0)
    for cap, hands in ((0.0, 0.0), (0.015, 0.5), (0.04, 1.0)):
        assert np.all(capsule_skin(body, 0.0, max_skin=cap, hand_scale=hands) == 0)
    rng = np.random.default_rng(0)
    rot, ref = rng.normal(size=(12, 2, 24, 3)) * 0.1, rng.normal(size=(12, 2, 24, 3)) * 0.1
    root, ref_root = rng.normal(size=(12, 2, 3)), rng.normal(size=(12, 2, 3))
    for hold in (0.0, 0.6, 0.8):
        out = smooth_deviation(rot, root, ref, ref_root, 0.0, root_sigma_frames=0.0, hold=hold)
        assert out[0] is rot and out[1] is root


def test_additions_are_named_in_order():
    assert parse_additions("") == parse_additions("all") == list(ADDITIONS)
    assert parse_additions(" foot_lock, feedforward") == ["feedforward", "foot_lock"]
    with pytest.raises(InvalidInputError, match=r"--groups: unknown addition\(s\) \['skins'\]"):
        parse_additions("feedforward,skins")
    with pytest.raises(InvalidInputError, match="--groups: an addition is named twice"):
        parse_additions("speed_limit,speed_limit")
    with pytest.raises(InvalidInputError, match="addition 'nope': unknown"):
        without(["nope"])


@pytest.mark.parametrize(
    "args, message",
    [
        (["--groups", "feedforward,nope"], "--groups: unknown addition"),
        (["--seconds", "0"], "--seconds: expected a positive clip length"),
        (["--workers", "0"], "--workers: expected a positive number"),
        (["--cells", "concert:D9"], "--cells: expected SCENE:LEVEL"),
        (["--config", "damping=0.01"], "--config: --ablation compares"),
        (["--design", "nowhere.toml"], "nowhere.toml"),
    ],
)
def test_bad_ablation_options_are_one_line_and_exit_2(args, message, capsys, tmp_path, monkeypatch):
    from crowdstudy.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["bench", "physics", "--ablation", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "build" / "bench" / "physics_ablation.json").exists()


@pytest.fixture(scope="module")
def small_design(tmp_path_factory) -> Path:
    """The paper's design on a 1.5 m x 1.5 m floor: 5 characters at D1, 7 at D2."""
    from crowdstudy.design import default_design_path

    text = default_design_path().read_text(encoding="utf-8")
    text = text.replace("width = 3.0                # x extent", "width = 1.5                # x extent")
    text = text.replace("depth = 3.0                # y extent", "depth = 1.5                # y extent")
    path = tmp_path_factory.mktemp("design") / "small.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def ablation_run(small_design, tmp_path_factory):
    """``crowdstudy bench physics --ablation`` on two small cells, 0.3 s, two additions: the
    folder it ran in and the report."""
    from crowdstudy.cli import main

    folder = tmp_path_factory.mktemp("ablation")
    mp = pytest.MonkeyPatch()
    mp.chdir(folder)
    try:
        argv = ["bench", "physics", "--ablation", "--design", str(small_design), "--seconds", "0.3"]
        argv += ["--cells", "concert:D1,corridor:D2", "--groups", "foot_lock,feedforward"]
        assert main(argv) == 0
    finally:
        mp.undo()
    return folder, argv, json.loads((folder / "build" / "bench" / "physics_ablation.json").read_text())


def test_the_ablation_rows_have_every_column(ablation_run):
    from crowdstudy.evaluation.ablation_run import ROW_COLUMNS

    folder, _, report = ablation_run
    rows = report["rows"]
    assert [(r["cell"], r["variant"]) for r in rows] == [
        (cell, variant)
        for cell in ("concert:D1", "corridor:D2")
        for variant in ("default", "paper", "noise_cg", "noise_k", "feedforward", "foot_lock")
    ]
    assert [r["characters"] for r in rows] == [5] * 6 + [7] * 6
    for row in rows:
        assert list(row) == list(ROW_COLUMNS)
        maybe_none = {"seam_ratio", "ok_seam", "ok_tracking"}  # a short concert does not loop; D2 has no tracking bar
        if row["variant"] == "paper":
            maybe_none.add("profile_weight")  # no density profile to follow
        assert all(row[key] is not None for key in ROW_COLUMNS if key not in maybe_none), row
        assert row["ms_per_step"] > 0 and row["default_ms_per_step"] > 0
        assert row["ms_ratio"] == pytest.approx(row["ms_per_step"] / row["default_ms_per_step"])
    assert rows[0]["ok_tracking"] is not None and rows[6]["ok_tracking"] is None  # D1 has a tracking bar
    paper, default = rows[1], rows[0]
    assert paper["slide_p99_cm_s"] > default["slide_p99_cm_s"]  # no foot anchor, no foot lock: feet slide
    assert [s["variant"] for s in report["summary"]] == [r["variant"] for r in rows[:6]]
    assert set(report["groups"]) == {"feedforward", "foot_lock"} and "noise" in report
    assert report["provenance"]["git_sha"] and report["command"].startswith("crowdstudy bench physics --ablation")
    assert (folder / "build" / "bench" / "physics_ablation.png").stat().st_size > 10_000


def test_a_second_run_takes_every_row_from_the_cache(ablation_run, monkeypatch):
    """Resuming: every (cell, variant) is cached, so a rerun corrects nothing (correct() is
    made to fail) and writes the same rows."""
    import crowdstudy.physics.corrector as corrector
    from crowdstudy.cli import main

    folder, argv, report = ablation_run

    def no_correction(*args, **kwargs):
        raise AssertionError("a cached row was corrected again")

    monkeypatch.setattr(corrector, "correct", no_correction)
    monkeypatch.chdir(folder)
    assert main(argv) == 0
    again = json.loads((folder / "build" / "bench" / "physics_ablation.json").read_text())
    assert again["rows"] == report["rows"]


def test_a_changed_configuration_is_corrected_again(ablation_run, small_design, monkeypatch):
    """A cached row is reused only for the configuration it was measured with: the cached
    defaults come back as they are, changed defaults are corrected again."""
    import crowdstudy.evaluation.ablation_run as run
    import crowdstudy.physics.corrector as corrector
    from crowdstudy.design import load_design

    folder, _, report = ablation_run

    class Stop(Exception):
        pass

    def stop(*args, **kwargs):
        raise Stop

    monkeypatch.setattr(corrector, "correct", stop)
    cell = run.study_cells(load_design(small_design), [("stationary", "D1")])[0]
    options = run.AblationOptions(
        seconds=0.3,
        cache_dir=folder / "build" / "bench" / "physics_ablation_cache",
        design_path=str(small_design.resolve()),
    )
    assert run.cell_rows(cell, {"default": PhysicsConfig()}, options) == report["rows"][:1]
    with pytest.raises(Stop):
        run.cell_rows(cell, {"default": PhysicsConfig().with_values(damping=0.007)}, options)

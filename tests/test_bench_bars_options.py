"""``crowdstudy bench physics --bars`` options: a subset of cells and PhysicsConfig changes
(benchmarks/physics.py, measuring with crowdstudy.evaluation.acceptance, .stadium and
.step_timing), so each setting tried in docs/lab-notes/ has its command."""

from __future__ import annotations

import numpy as np
import pytest

import crowdstudy.evaluation.acceptance as acceptance

LEVELS = ["D1", "D2", "D3", "D4", "D5"]


@pytest.fixture(scope="module")
def bench():
    """``benchmarks/physics.py`` loaded as a module (the benchmarks are scripts, not a
    package): its command line and its tables."""
    from crowdstudy.bench import load_benchmark

    return load_benchmark("physics")


def test_cells_name_scenes_and_levels(bench):
    assert bench.parse_cells("", LEVELS) is None
    assert bench.parse_cells("concert:D1, corridor:D5,walking:D2", LEVELS) == [
        ("stationary", "D1"),
        ("walking", "D5"),
        ("walking", "D2"),
    ]


@pytest.mark.parametrize(
    "text, bad", [("concert:D9", "concert:D9"), ("stadium:D1", "stadium:D1"), ("concert", "concert")]
)
def test_a_bad_cell_is_named(bench, text, bad):
    with pytest.raises(SystemExit, match=f"--cells: .*{bad!r}"):
        bench.parse_cells(text, LEVELS)


def test_measure_bars_runs_only_the_asked_cells_with_the_asked_config(monkeypatch):
    """The cell filter and the config reach ``correct()`` (the physics itself is stubbed
    out: this checks the plumbing, the bars' numbers are the benchmark's)."""
    import crowdstudy.physics.corrector as corrector
    from crowdstudy.physics.config import PhysicsConfig

    seen = []

    class Stop(Exception):
        pass

    def fake_correct(base, config=None, **kw):
        seen.append((base.meta.get("stage"), base.meta.get("density_level"), base.periodic_length is not None, config))
        raise Stop

    monkeypatch.setattr(corrector, "correct", fake_correct)
    cfg = PhysicsConfig().with_values(arm_scale=0.5)
    with pytest.raises(Stop):
        acceptance.measure_bars(0.2, config=cfg, cells=[("walking", "D2")])
    assert len(seen) == 1
    stage, level, periodic, config = seen[0]
    assert (stage, level, periodic) == ("walking", "D2", True) and config is cfg


def test_stadium_runs_take_the_asked_config(bench, monkeypatch):
    """``--stadium N --config K=V`` hands the config to the stadium's ``correct()`` (the crowd
    and the physics are stubbed out: this checks the plumbing)."""
    import crowdstudy.evaluation.stadium as stadium
    import crowdstudy.physics.corrector as corrector
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    seen = []

    class Stop(Exception):
        pass

    def fake_correct(base, config=None, **kw):
        seen.append((base.n_characters, config))
        raise Stop

    monkeypatch.setattr(corrector, "correct", fake_correct)
    monkeypatch.setattr(
        stadium,
        "stadium_crowd",
        lambda n, level, duration: build_baseline(load_design(), "stationary", "D1", duration=0.2),
    )
    with pytest.raises(Stop):
        bench.main(["--stadium", "20", "--stadium-seconds", "0.2", "--config", "skin.max=0.04", "output.hold=0.8"])
    assert len(seen) == 1
    assert seen[0][1].skin.max == 0.04 and seen[0][1].output.hold == 0.8


def test_timed_steps_run_with_the_asked_config():
    """``--config`` reaches the timed steps too (the cost curve's trial runs): a looser CG
    tolerance takes fewer iterations on the same crowd."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.config import PhysicsConfig
    from crowdstudy.physics.step_timing import tile_crowd, time_steps

    crowd = tile_crowd(build_baseline(load_design(), "stationary", "D5", duration=0.5), 6)
    loose = time_steps(crowd, 3, config=PhysicsConfig().with_values(cg_tolerance=1e-2))
    tight = time_steps(crowd, 3, config=PhysicsConfig().with_values(cg_tolerance=1e-6, cg_max_iterations=400))
    assert 0 < loose["cg_iterations"] < tight["cg_iterations"]


def test_seeds_name_the_study_and_integers(bench):
    assert bench.parse_seeds("study") == [None]
    assert bench.parse_seeds("study, 1,22") == [None, 1, 22]
    for text, bad in (("1,x", "'x'"), ("-3", "'-3'"), ("1,1", "twice")):
        with pytest.raises(SystemExit, match=f"--seeds: .*{bad}"):
            bench.parse_seeds(text)


def test_measure_bars_runs_each_cell_on_each_seed(monkeypatch):
    """Cells x seeds, in that order; the plumbing only (one row per call is recorded)."""
    calls = []

    def fake_cell(design, stage, li, level, seed, duration, frame_stride, config, tolerances):
        calls.append((stage, level, seed))
        return {"stage": stage, "level": level, "seed": seed}

    monkeypatch.setattr(acceptance, "measure_cell", fake_cell)
    rows = acceptance.measure_bars(0.2, cells=[("stationary", "D2"), ("walking", "D5")], seeds=[None, 7])
    assert calls == [("stationary", "D2", None), ("stationary", "D2", 7), ("walking", "D5", None), ("walking", "D5", 7)]
    assert [r["seed"] for r in rows] == [None, 7, None, 7]


@pytest.mark.parametrize("seed, study", [(None, True), (7, False)])
def test_a_seed_builds_another_crowd_of_the_cell(monkeypatch, seed, study):
    """The seed reaches the Baseline (its layout and clips) and the row says whether the crowd
    is the study's own."""
    import crowdstudy.physics.corrector as corrector
    from crowdstudy.design import load_design

    design = load_design()
    seen = []

    class Stop(Exception):
        pass

    def fake_correct(base, config=None, **kw):
        seen.append((base.meta["seed"], base.root_translation[0].copy()))
        raise Stop

    monkeypatch.setattr(corrector, "correct", fake_correct)
    with pytest.raises(Stop):
        acceptance.measure_cell(design, "stationary", 1, "D2", seed, 0.2, 10, None)
    expected = design.cell_seed(design.stage("stationary"), "D2") if study else seed
    assert seen[0][0] == expected
    if not study:  # another crowd: the characters stand elsewhere
        with pytest.raises(Stop):
            acceptance.measure_cell(design, "stationary", 1, "D2", None, 0.2, 10, None)
        assert seen[1][0] != seed and not np.allclose(seen[0][1], seen[1][1])


def _row(stage, level, seed, ratio, tracking, failed, study=False, bar=None):
    return {
        "stage": stage,
        "level": level,
        "seed": seed,
        "study_seed": study,
        "mesh_ratio": ratio,
        "mesh_baseline_m3": 1e-4,
        "mesh_ours_m3": ratio * 1e-4,
        "tracking_cm": tracking,
        "bars_failed": failed,
        "tracking_bar_cm": bar,
    }


def test_the_spread_counts_the_crowds_that_meet_each_bar(bench):
    rows = [
        _row("stationary", "D3", 11, 0.044, 2.0, "-", study=True),
        _row("stationary", "D3", 1, 0.056, 2.2, "overlap"),
        _row("stationary", "D3", 2, 0.032, 2.4, "-"),
        _row("walking", "D5", 1, 0.03, 5.5, "tracking,hf", bar=5.0),
        _row("walking", "D5", 2, 0.06, 4.5, "overlap", bar=5.0),
    ]
    spread = {(r["stage"], r["level"]): r for r in bench.seed_spread(rows)}
    d3 = spread[("stationary", "D3")]
    assert d3["seeds"] == 3 and d3["mesh_ratio_study"] == 0.044
    assert d3["mesh_ratio_mean"] == pytest.approx(0.044) and d3["mesh_ratio_sd"] == pytest.approx(0.012)
    assert (d3["mesh_ratio_min"], d3["mesh_ratio_max"]) == (0.032, 0.056)
    assert d3["overlap_met"] == "2/3" and d3["all_bars_met"] == "2/3" and d3["tracking_met"] == ""
    assert d3["tracking_cm_max"] == 2.4
    assert d3["baseline_cm3_mean"] == pytest.approx(100.0) and d3["ours_cm3_mean"] == pytest.approx(4.4)
    assert d3["ours_cm3_max"] == pytest.approx(5.6)
    d5 = spread[("walking", "D5")]
    assert np.isnan(d5["mesh_ratio_study"]) and d5["overlap_met"] == "1/2"
    assert d5["tracking_met"] == "1/2" and d5["all_bars_met"] == "0/2"


def test_the_seed_figure_draws_each_crowd_and_the_bars(bench, tmp_path):
    import matplotlib.image as mpimg

    rows = [
        _row("stationary", "D1", s, r, t, "-", study=s == 0, bar=1.5) for s, r, t in ((0, 0.02, 1.0), (1, 0.03, 1.2))
    ]
    rows += [_row("walking", "D5", s, r, t, "-", bar=5.0) for s, r, t in ((0, 0.04, 4.0), (1, 0.02, 4.5))]
    path = bench.seed_figure(rows, path=tmp_path / "seeds.png")
    img = mpimg.imread(path)[..., :3]
    red = (img[..., 0] > 0.9) & (img[..., 1] < 0.2) & (img[..., 2] < 0.2)  # the bars' dashed lines
    blue = (np.abs(img[..., 0] - 0.12) < 0.08) & (np.abs(img[..., 2] - 0.71) < 0.08)  # the dots
    assert red.sum() > 100 and blue.sum() > 100
    top, bottom = red[: img.shape[0] // 2], red[img.shape[0] // 2 :]
    assert top.any() and bottom.any()  # the overlap bar above, the tracking bars below


def test_measure_bars_draws_the_asked_body_shapes(monkeypatch, bench):
    """``--shapes population`` reaches the Baseline's bodies (the physics stubbed out)."""
    import crowdstudy.physics.corrector as corrector

    seen = []

    class Stop(Exception):
        pass

    def fake_correct(base, config=None, **kw):
        seen.append((base.meta.get("bodies"), base.bodies[0]))
        raise Stop

    monkeypatch.setattr(corrector, "correct", fake_correct)
    for shapes in ("population", "study"):
        with pytest.raises(Stop):
            acceptance.measure_bars(0.2, cells=[("stationary", "D1")], body_shapes=shapes)
    assert seen[0][0] == {"shapes": "population"} and seen[1][0] is None
    assert seen[0][1]["weight"] != seen[1][1]["weight"]
    assert bench._parser().parse_args(["--bars-only", "--shapes", "population"]).shapes == "population"

"""``crowdstudy bench physics --bars`` options: a subset of cells and PhysicsConfig changes
(benchmarks/physics.py), so each tried setting in the README has its command."""

from __future__ import annotations

import pytest

LEVELS = ["D1", "D2", "D3", "D4", "D5"]


def test_cells_name_scenes_and_levels(bench):
    assert bench.parse_cells("", LEVELS) is None
    assert bench.parse_cells("concert:D1, corridor:D5,walking:D2", LEVELS) == [
        ("stationary", "D1"), ("walking", "D5"), ("walking", "D2")]


@pytest.mark.parametrize("text, bad", [("concert:D9", "concert:D9"), ("stadium:D1", "stadium:D1"),
                                       ("concert", "concert")])
def test_a_bad_cell_is_named(bench, text, bad):
    with pytest.raises(SystemExit, match=f"--cells: .*{bad!r}"):
        bench.parse_cells(text, LEVELS)


def test_measure_bars_runs_only_the_asked_cells_with_the_asked_config(bench, monkeypatch):
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
    cfg = PhysicsConfig(arm_scale=0.5)
    with pytest.raises(Stop):
        bench.measure_bars(0.2, config=cfg, cells=[("walking", "D2")])
    assert len(seen) == 1
    stage, level, periodic, config = seen[0]
    assert (stage, level, periodic) == ("walking", "D2", True) and config is cfg


def test_stadium_runs_take_the_asked_config(bench, monkeypatch):
    """``--stadium N --config K=V`` hands the config to the stadium's ``correct()`` (the crowd
    and the physics are stubbed out: this checks the plumbing)."""
    import crowdstudy.physics.corrector as corrector

    seen = []

    class Stop(Exception):
        pass

    def fake_correct(base, config=None, **kw):
        seen.append((base.n_characters, config))
        raise Stop

    monkeypatch.setattr(corrector, "correct", fake_correct)
    monkeypatch.setattr(bench, "stadium_crowd", lambda n, level, duration: bench._scene("D1", 0.2))
    with pytest.raises(Stop):
        bench.main(["--stadium", "20", "--stadium-seconds", "0.2", "--config", "mesh_skin_max=0.04",
                    "output_hold=0.8"])
    assert len(seen) == 1
    assert seen[0][1].mesh_skin_max == 0.04 and seen[0][1].output_hold == 0.8


def test_timed_steps_run_with_the_asked_config(bench):
    """``--config`` reaches the timed steps too (the cost curve's trial runs): a looser CG
    tolerance takes fewer iterations on the same crowd."""
    from crowdstudy.physics.config import PhysicsConfig

    crowd = bench._tile(bench._scene("D5", 0.5), 6)
    loose = bench.time_steps(crowd, 3, config=PhysicsConfig(cg_tolerance=1e-2))
    tight = bench.time_steps(crowd, 3, config=PhysicsConfig(cg_tolerance=1e-6, cg_max_iterations=400))
    assert 0 < loose["cg_iterations"] < tight["cg_iterations"]


def test_the_seam_bar_applies_to_a_looped_concert_only(bench):
    """A concert clip too short to hold whole loops is not looped: its last-to-first jump is
    no seam a viewer sees, so the bar is not checked (the corridor dissolves instead)."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    design = load_design()
    looped = build_baseline(design, "stationary", "D1", duration=2.0, body_model="open")
    short = build_baseline(design, "stationary", "D1", duration=0.3, body_model="open")
    assert bench.loop_mode(looped) == "periodic" and bench.loop_mode(short) == "none"
    row = {"stage": "stationary", "jerk_ratio": 1.0, "hf_share_ours": 0.01, "hf_share_baseline": 0.01,
           "max_joint_speed_ours": 5.0, "max_joint_speed_baseline": 5.0, "pelvis_p99_ours": 1.0,
           "pelvis_p99_baseline": 1.0, "foot_slide_p99_ours": 0.01, "mesh_ratio": 0.01, "tracking_cm": 1.0,
           "seam_ratio_baseline": 7.4, "seam_ratio_ours": 7.5}
    assert bench.bar_checks({**row, "loop": "periodic"}, 2, 5)["seam"] is False
    assert "seam" not in bench.bar_checks({**row, "loop": "none"}, 2, 5)
    assert "seam" not in bench.bar_checks({**row, "stage": "walking", "loop": "dissolve"}, 2, 5)

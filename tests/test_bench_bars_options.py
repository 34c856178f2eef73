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


def test_timed_steps_run_with_the_asked_config(bench):
    """``--config`` reaches the timed steps too (the cost curve's trial runs): a looser CG
    tolerance takes fewer iterations on the same crowd."""
    from crowdstudy.physics.config import PhysicsConfig

    crowd = bench._tile(bench._scene("D5", 0.5), 6)
    loose = bench.time_steps(crowd, 3, config=PhysicsConfig(cg_tolerance=1e-2))
    tight = bench.time_steps(crowd, 3, config=PhysicsConfig(cg_tolerance=1e-6, cg_max_iterations=400))
    assert 0 < loose["cg_iterations"] < tight["cg_iterations"]

"""The live walker (paper Fig. 6): the walk is a straight CMU walk at the clip's speed, the
scene is the concert cell plus that walker, and the frame-by-frame correction sees no
frame ahead of the one it is fed, yet pushes the walker out of the dancers."""

import numpy as np
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.walker import WalkerPath, live_scene, walker_index, walker_motion
from crowdstudy.physics.live import frame_stats, run_live

#: a short crossing into the thick of the D5 crowd (1.2 m, about 40 frames)
SHORT = WalkerPath(start=(-1.2, -0.3), distance=1.2)


@pytest.fixture(scope="module")
def body():
    from crowdstudy.body import sample_bodies

    return sample_bodies(1, 6)[0]


@pytest.fixture(scope="module")
def scene():
    return live_scene(None, "D5", SHORT)


@pytest.fixture(scope="module")
def live(scene):
    return run_live(scene)


def test_the_walker_walks_a_straight_line_at_its_clip_speed(body):
    from crowdstudy.motion.baseline import body_scales
    from crowdstudy.motion.library import load_clip

    path = WalkerPath(start=(0.5, -2.0), heading=np.pi / 2, distance=3.0)
    rot, root, speed = walker_motion(path, body, 30.0)
    assert rot.shape == (len(root), 24, 3) and root.shape[1] == 3
    assert speed == pytest.approx(load_clip(path.clip).speed * body_scales([body])[0])
    # along +y (heading 90 degrees) from the start, the whole distance, at most a sway aside
    travel = root[-1, :2] - root[0, :2]
    assert travel[1] == pytest.approx(3.0, abs=0.15) and abs(travel[0]) < 0.1
    assert np.abs(root[:, 0] - 0.5).max() < 0.08 and abs(root[0, 1] + 2.0) < 0.1
    assert len(root) == pytest.approx(3.0 / speed * 30.0, abs=1.5)
    # the pelvis at walking height, moving on every frame at about the speed
    assert 0.75 < root[:, 2].min() and root[:, 2].max() < 1.1
    step = np.linalg.norm(np.diff(root[:, :2], axis=0), axis=1) * 30.0
    assert np.median(step) == pytest.approx(speed, rel=0.15)


def test_a_bad_walk_is_named():
    with pytest.raises(InvalidInputError, match="distance"):
        WalkerPath(distance=-1.0)
    with pytest.raises(InvalidInputError, match="start"):
        WalkerPath(start=(0.0, float("nan")))
    with pytest.raises(InvalidInputError, match="walking clip"):
        walker_motion(WalkerPath(clip="twist"), {"model": "makehuman", "sex": "female", "height": 1.65}, 30.0)
    with pytest.raises(InvalidInputError, match="CrowdAnimation"):
        run_live("scene.npz")


def test_the_scene_is_the_concert_cell_plus_the_walker(scene):
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    design = load_design()
    n = design.n_characters("D5")
    assert scene.n_characters == n + 1 and walker_index(scene) == n
    assert scene.meta["loop"] == {"mode": "none"} and scene.meta["live_walker"]["clip"] == SHORT.clip
    assert scene.meta["seed"] == design.cell_seed(design.stage("stationary"), "D5")
    cell = build_baseline(design, "stationary", "D5", duration=scene.n_frames / scene.fps)
    np.testing.assert_array_equal(scene.root_translation[:, :n], cell.root_translation[: scene.n_frames])
    assert scene.clips[n]["kind"] == "walk" and len(scene.bodies) == n + 1
    # the walker starts outside the dancers' floor (3 m x 3 m) and walks into it
    x = scene.root_translation[:, n, 0]
    assert x[0] < -1.1 and x[-1] > -0.1


def test_the_live_loop_corrects_every_frame_without_looking_ahead(scene, live):
    ours = live.ours
    assert ours.meta["method"] == "Ours" and ours.meta["live"]["substeps_per_frame"] == live.substeps == 2
    assert ours.joint_rotations.shape == scene.joint_rotations.shape
    assert live.wall_seconds.shape == live.cpu_seconds.shape == (scene.n_frames - 1,)
    # the frames up to k are the same whether or not the frames after k exist: nothing is read ahead
    k = 12
    early = run_live(scene.frames(0, k + 1)).ours
    np.testing.assert_array_equal(early.joint_rotations, ours.joint_rotations[: k + 1])
    np.testing.assert_array_equal(early.root_translation, ours.root_translation[: k + 1])


def test_the_live_loop_pushes_the_walker_out_of_the_dancers(scene, live):
    from crowdstudy.metrics.overlap import overlap_volume
    from crowdstudy.metrics.tracking import tracking_parts

    walker = walker_index(scene)
    frames = np.arange(10, scene.n_frames, 5)
    before = overlap_volume(scene, geometry="capsule", frames=frames).per_character[:, walker].mean()
    after = overlap_volume(live.ours, geometry="capsule", frames=frames).per_character[:, walker].mean()
    assert before > 0.003  # the Baseline walker walks through the dancers: litres of overlap
    assert after < before / 2, (before, after)
    # it still follows its walk: the correction moves it by centimetres, not metres
    per = tracking_parts(live.ours, scene).per_character_cm
    assert 0.5 < per[walker] < 25.0, per[walker]
    end = live.ours.root_translation[-1, walker, :2] - scene.root_translation[-1, walker, :2]
    assert np.linalg.norm(end) < 0.4


def test_frame_stats_against_the_budget():
    s = frame_stats(np.array([0.010, 0.020, 0.030, 0.040]), 30.0)
    assert s["median_ms"] == pytest.approx(25.0) and s["max_ms"] == pytest.approx(40.0)
    assert s["p95_ms"] == pytest.approx(38.5) and s["budget_ms"] == pytest.approx(1000 / 30)
    assert s["over_budget"] == pytest.approx(0.25)


@pytest.mark.slow
def test_bench_live_quick_writes_its_report(tmp_path):
    import json

    from crowdstudy.bench import load_benchmark

    out = tmp_path / "live.json"
    assert load_benchmark("live").main(["--quick", "--variants", "paper", "--out", str(out)]) == 0
    report = json.loads(out.read_text())
    (row,) = report["rows"]
    assert row["variant"] == "paper" and row["substeps"] == 2 and len(row["runs"]) == 2
    for clock in ("wall", "cpu"):
        assert 0 < row[f"{clock}_median_ms"] <= row[f"{clock}_p95_ms"] <= row[f"{clock}_max_ms"]
    assert isinstance(row["bar_cpu"], bool) and report["budget_ms"] == pytest.approx(1000 / 30)
    assert set(row["phases_ms"]) == {"detection", "assembly", "solve", "update", "readback"}
    assert row["ours_walker_overlap_l"] < row["baseline_walker_overlap_l"]
    assert report["scene"]["characters"] == 61 and report["machine"]["load_average"] is not None

"""Baseline crowd animation: dancing concert crowd, walking corridor crowd, the CLI."""

import numpy as np
import pytest

from crowdstudy.body import load_body, sample_bodies
from crowdstudy.body.rotations import axis_angle_to_matrix
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES
from crowdstudy.cli import main
from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion import animate_stationary, animate_walking, build_baseline, foot_skate, list_clips
from crowdstudy.motion.diagnostics import joint_positions
from crowdstudy.scene import Crowd, CrowdAnimation

J = JOINT_INDEX


def _layout(n=18, seed=0):
    rng = np.random.default_rng(seed)
    return Crowd(positions=rng.uniform(-1.4, 1.4, (1, n, 2)), radius=0.2, meta={"scenario": "concert"})


def _ankle_heights(bodies):
    return np.array([load_body(b).pelvis_height + load_body(b).rest_joints[J["left_ankle"], 2] for b in bodies])


@pytest.fixture(scope="module")
def dancers():
    crowd = _layout()
    return crowd, animate_stationary(crowd, duration=4.0, fps=30, seed=7)


def test_stationary_crowd_dances_in_place_facing_the_stage(dancers):
    crowd, anim = dancers
    n = crowd.n_agents
    assert isinstance(anim, CrowdAnimation)
    assert anim.root_translation.shape == (120, n, 3) and anim.joint_rotations.shape == (120, n, 24, 3)
    assert anim.joint_names == JOINT_NAMES and anim.meta["method"] == "Baseline"
    # each character stays on its Poisson-disk spot
    # (the feet stay within 12 cm of it; the Twist's hips swing up to 22 cm over the feet)
    drift = np.linalg.norm(anim.root_translation[..., :2] - crowd.positions[0][None], axis=-1)
    assert drift.max() < 0.25 and np.percentile(drift, 90) < 0.12
    # facing +y with a small jitter: the pelvis forward axis
    forward = axis_angle_to_matrix(anim.joint_rotations[:, :, 0])[..., :2, 1]
    yaw = np.arctan2(-forward[..., 0], forward[..., 1])
    # (the motion-captured dances turn by up to 50 degrees on their spot, plus the 20-degree jitter)
    assert np.abs(yaw).max() < np.radians(75) and 0.02 < np.abs(yaw.mean(0)).mean() < np.radians(20)
    # the clips: a dance each, dealt evenly, random phases
    names = [c["clips"][0] for c in anim.clips]
    default = list_clips("dance", default_only=True)
    assert set(names) == set(default) and len(default) == 7
    assert all(c["kind"] == "dance" and c["weights"] == [1.0] for c in anim.clips)
    # each dancer differs from its neighbours: clip, whole-beat offset, mirroring, amplitude
    assert len({(c["clips"][0], c["beat_offset"], c["mirrored"], round(c["amplitude"], 4)) for c in anim.clips}) == n
    assert len({c["beat_offset"] for c in anim.clips}) > 2
    # bodies from sample_bodies(N, seed)
    assert list(anim.bodies) == sample_bodies(n, 7)


def test_stationary_feet_on_the_floor_without_skating(dancers):
    crowd, anim = dancers
    pos = joint_positions(anim)
    ankle_h = _ankle_heights(anim.bodies)
    lowest = pos[:, :, [J["left_ankle"], J["right_ankle"]], 2].min(axis=(0, 2))
    # soles on z = 0, every body: the lowest ankle is the body's own ankle height (within
    # 1.5 cm: a motion-captured dancer may stay on its toes or heels for the whole 4 s)
    assert np.abs(lowest - ankle_h).max() < 0.015
    assert pos[..., 2].min() > 0.0
    skate = foot_skate(anim)
    # planted feet are held (motion capture: measured p95 1.7 cm, max 6.2 cm, a toe rolling
    # about its held ankle while the heel rises in groove_steps)
    assert skate.size > 2 * crowd.n_agents and np.percentile(skate, 95) < 0.02 and skate.max() < 0.08


def test_stationary_is_deterministic(dancers):
    crowd, anim = dancers
    again = animate_stationary(crowd, duration=4.0, fps=30, seed=7)
    assert np.array_equal(again.joint_rotations, anim.joint_rotations)
    other = animate_stationary(crowd, duration=4.0, fps=30, seed=8)
    assert not np.allclose(other.joint_rotations, anim.joint_rotations)


def _trajectories(n=8, seconds=8.0, fps=30.0, seed=3):
    """Walkers with speed changes (0.6..1.7 m/s) and gentle curves, unwrapped along x."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fps)) / fps
    base = rng.uniform(0.8, 1.4, n)
    speed = base + 0.3 * np.sin(t[:, None] * rng.uniform(0.5, 1.0, n) + rng.uniform(0, 6, n))
    heading = 0.25 * np.sin(t[:, None] * rng.uniform(0.2, 0.4, n))
    vel = np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=-1)
    pos = np.cumsum(vel / fps, axis=0) + np.stack([np.zeros(n), np.linspace(-0.8, 0.8, n)], -1)
    return Crowd(
        positions=pos,
        radius=0.2,
        fps=fps,
        velocities=vel,
        headings=heading,
        meta={"scenario": "corridor", "periodic": {"axis": 0, "length": 4.5}},
    )


@pytest.fixture(scope="module")
def walkers():
    crowd = _trajectories()
    return crowd, animate_walking(crowd, seed=5)


def test_walking_follows_the_trajectories(walkers):
    crowd, anim = walkers
    assert anim.root_translation.shape[:2] == crowd.positions.shape[:2]
    assert anim.meta["periodic"] == {"axis": 0, "length": 4.5}
    # the pelvis sways about its path (measured 6.1 cm at most with the MakeHuman bodies)
    assert np.linalg.norm(anim.root_translation[..., :2] - crowd.positions, axis=-1).max() < 0.065
    forward = axis_angle_to_matrix(anim.joint_rotations[:, :, 0])[..., :2, 1]
    vel = crowd.velocities / np.linalg.norm(crowd.velocities, axis=-1, keepdims=True)
    assert np.sum(forward / np.linalg.norm(forward, axis=-1, keepdims=True) * vel, -1).min() > 0.9
    for rec, v in zip(anim.clips, np.linalg.norm(crowd.velocities, axis=-1).T, strict=True):
        assert rec["kind"] == "walk" and rec["clips"] == list_clips("walk")
        assert sum(rec["weights"]) == pytest.approx(1.0) and 0 <= rec["phase"] < 1
        assert rec["mean_speed"] == pytest.approx(v.mean(), rel=0.05)


def test_walking_feet_do_not_skate(walkers):
    crowd, anim = walkers
    skate = foot_skate(anim)
    # every foot lands at least once per 1.5 s of walking (captured cadences: 73-129 steps/min;
    # a MakeHuman toe joint, lower and more mobile than the authoring skeleton's, is at its
    # floor level in fewer frames: 147 contacts counted, 189 with the mannequins)
    assert skate.size >= 4 * crowd.n_agents * 4
    # measured: MakeHuman bodies p95 1.1 cm, max 2.3 cm; mannequins p95 1.2 cm, max 1.9 cm
    assert np.percentile(skate, 95) < 0.015 and skate.max() < 0.03
    # the gait phase follows the distance walked: about one stride per cycle
    pos = joint_positions(anim)
    lead = pos[:, :, J["left_ankle"], 0] - pos[:, :, J["right_ankle"], 0]
    steps = np.count_nonzero(np.diff(np.sign(lead), axis=0), axis=0)
    dist = np.linalg.norm(np.diff(crowd.positions, axis=0), axis=-1).sum(0)
    assert np.all(steps / dist > 1.0) and np.all(steps / dist < 2.6)  # strides of 0.8..2 m


def test_skate_measure_catches_sliding_feet(walkers):
    crowd, anim = walkers
    # the same poses dragged along twice as fast: feet must slide
    slid = anim.replace(root_translation=anim.root_translation * [2.0, 1.0, 1.0])
    assert foot_skate(slid).max() > 0.05


@pytest.mark.slow
def test_build_baseline_cells():
    design = load_design()
    anim = build_baseline(design, "stationary", "D1", duration=1.0)
    meta = anim.meta
    assert meta["stage"] == "stationary" and meta["scenario"] == "concert" and meta["density_level"] == "D1"
    assert meta["method"] == "Baseline" and meta["seed"] == design.cell_seed(design.stage("stationary"), "D1")
    assert meta["provenance"]["seed"] == meta["seed"] and anim.n_characters == design.n_characters("D1")
    assert anim.n_frames == 30 and anim.fps == 30
    walk = build_baseline(design, 2, "D3", duration=4.0)
    assert walk.meta["stage"] == "walking" and walk.meta["periodic"]["length"] == pytest.approx(4.5)
    assert walk.n_characters == design.n_characters("D3")
    assert foot_skate(walk).max() < 0.045  # measured 4.1 cm with the MakeHuman bodies (1.9 cm mannequins)
    with pytest.raises(InvalidInputError, match="level"):
        build_baseline(design, "stationary", "D9")


def test_same_seed_same_bytes(tmp_path):
    design = load_design()
    paths = [build_baseline(design, "stationary", "D1", duration=0.5).save(tmp_path / f"a{i}.npz") for i in range(2)]
    assert paths[0].read_bytes() == paths[1].read_bytes()
    other = build_baseline(design, "stationary", "D1", duration=0.5, seed=1).save(tmp_path / "b.npz")
    assert other.read_bytes() != paths[0].read_bytes()


def test_bad_inputs_name_the_argument():
    crowd = _layout(4)
    with pytest.raises(InvalidInputError, match="bodies"):
        animate_stationary(crowd, duration=1.0, seed=0, bodies=sample_bodies(3, 0))
    with pytest.raises(InvalidInputError, match="duration"):
        animate_stationary(crowd, duration=-1.0, seed=0)
    with pytest.raises(InvalidInputError, match="crowd"):
        animate_walking(crowd, seed=0)
    with pytest.raises(InvalidInputError, match="crowd"):
        animate_stationary(np.zeros((1, 4, 2)), seed=0)
    walkers = _trajectories(n=2, seconds=1.0)
    with pytest.raises(InvalidInputError, match="facing"):
        animate_walking(walkers, seed=0, facing="backwards")
    with pytest.raises(InvalidInputError, match="facing"):
        animate_walking(walkers.replace(headings=None), seed=0, facing="crowd")


def test_facing_from_motion_matches_the_headings(walkers):
    crowd, anim = walkers
    by_motion = animate_walking(crowd, seed=5, facing="motion")

    def yaw(a):
        forward = axis_angle_to_matrix(a.joint_rotations[:, :, 0])[..., :, 1]
        return np.arctan2(forward[..., 1], forward[..., 0])

    assert np.abs(np.angle(np.exp(1j * (yaw(by_motion) - yaw(anim))))).max() < np.radians(5)


def test_cli_animate(tmp_path, capsys):
    out = tmp_path / "cell.npz"
    assert main(["animate", "--stage", "stationary", "--density", "D1", "--duration", "0.5", "--out", str(out)]) == 0
    anim = CrowdAnimation.load(out)
    assert anim.n_frames == 15 and anim.meta["density_level"] == "D1"
    crowd_file = _trajectories(n=3, seconds=2.0).save(tmp_path / "crowd.npz")
    assert main(["animate", str(crowd_file), "--out", str(tmp_path / "walk.npz"), "--seed", "4"]) == 0
    walk = CrowdAnimation.load(tmp_path / "walk.npz")
    assert walk.n_characters == 3 and walk.meta["periodic"]["axis"] == 0
    layout_file = _layout(5).save(tmp_path / "layout.npz")
    assert main(["animate", str(layout_file), "--out", str(tmp_path / "dance.npz"), "--duration", "1"]) == 0
    dance = CrowdAnimation.load(tmp_path / "dance.npz")
    assert dance.n_frames == 30 and dance.clips[0]["kind"] == "dance"
    assert main(["animate", "--stage", "walking", "--density", "D7", "--out", str(tmp_path)]) == 2
    assert "D7" in capsys.readouterr().err
    assert main(["animate", "--density", "D1", "--out", str(tmp_path)]) == 2

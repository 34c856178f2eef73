"""Shipped motion clips: inventory, distinctness, seamless loops, joint limits, feet."""

import dataclasses
import itertools

import numpy as np
import pytest

from crowdstudy.body.rotations import axis_angle_to_matrix
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion import MotionClip, list_clips, load_clip, seam_discontinuity
from crowdstudy.motion.dance import DANCES, DanceSpec, generate_dance
from crowdstudy.motion.rig import ANKLE_HEIGHT, FOOT_HEIGHT

ALL = list_clips(source="procedural")

# Largest rotation (degrees) of each joint relative to its parent: generous bounds of the
# adult range of motion (the pelvis row is its tilt from upright, checked separately).
LIMITS = {
    "hip": 120,
    "knee": 150,
    "ankle": 60,
    "foot": 70,
    "spine1": 30,
    "spine2": 30,
    "spine3": 30,
    "neck": 45,
    "head": 45,
    "collar": 35,
    "shoulder": 150,
    "elbow": 150,
    "wrist": 80,
    "hand": 40,
}


def _limit(name: str) -> float:
    return LIMITS[name.split("_", 1)[-1]]


def test_inventory_15_dances_4_walks():
    dances, walks = list_clips("dance", "procedural"), list_clips("walk", "procedural")
    assert len(dances) == 15 and len(set(dances)) == 15
    assert len(walks) == 4
    speeds = [load_clip(w).speed for w in walks]
    assert speeds == pytest.approx([0.8, 1.1, 1.4, 1.8], abs=0.05)
    for name in ALL:
        clip = load_clip(name)
        assert clip.joint_rotations.shape == (clip.n_frames, 24, 3) and clip.loop
        assert clip.kind == ("walk" if name in walks else "dance")
    with pytest.raises(InvalidInputError, match="unknown clip"):
        load_clip("moonwalk")
    with pytest.raises(InvalidInputError, match="kind"):
        list_clips("running", "procedural")


def _descriptor(clip):
    """Phase-invariant summary: mean and spread of every joint relative to the pelvis, the
    pelvis' spread, the left-right coordination of wrists and ankles, and the tempo."""
    pos = clip.joint_positions()
    rel = pos - pos[:, :1]

    def coordination(a, b):
        za, zb = pos[:, JOINT_INDEX[a], 2], pos[:, JOINT_INDEX[b], 2]
        if za.std() < 1e-6 or zb.std() < 1e-6:
            return 0.0
        return 0.2 * np.corrcoef(za, zb)[0, 1]

    return np.concatenate(
        [
            rel.mean(0).ravel(),
            rel.std(0).ravel(),
            pos[:, 0].std(0),
            [
                coordination("left_wrist", "right_wrist"),
                coordination("left_ankle", "right_ankle"),
                clip.meta["bpm"] / 1000.0,
            ],
        ]
    )


def test_dances_are_distinct_combinations():
    bpms = [load_clip(d.name).meta["bpm"] for d in DANCES]
    assert min(bpms) >= 90 and max(bpms) <= 140 and max(bpms) - min(bpms) >= 40
    combos = {(d.arms, tuple(load_clip(d.name).meta["moves"]), round(d.bpm)) for d in DANCES}
    assert len(combos) == 15
    arms = {d.arms for d in DANCES}
    assert {"clap", "raise_both", "pump_right"} <= arms and len(arms) >= 8
    moves = set(itertools.chain.from_iterable(load_clip(d.name).meta["moves"] for d in DANCES))
    assert {"bounce", "sway", "nod", "jump", "twist", "step"} <= moves
    desc = {d.name: _descriptor(load_clip(d.name)) for d in DANCES}
    dists = [np.linalg.norm(desc[a] - desc[b]) for a, b in itertools.combinations(desc, 2)]
    assert min(dists) > 0.05  # metres summed over joints: no two dances alike
    # A phase-shifted copy would have (nearly) the same descriptor: the measure can tell.
    clip = load_clip(DANCES[0].name)
    shifted = dataclasses.replace(
        clip,
        joint_rotations=np.roll(clip.joint_rotations, 37, 0),
        root_translation=np.roll(clip.root_translation, 37, 0),
    )
    assert np.linalg.norm(_descriptor(shifted) - desc[clip.name]) < 1e-9


@pytest.mark.parametrize("name", ALL)
def test_loop_is_seamless(name):
    clip = load_clip(name)
    rep = seam_discontinuity(clip)
    # position step and velocity change across the seam are no larger than inside the clip
    assert rep["step_seam"] <= 1.02 * rep["step_max"] + 1e-6
    assert rep["accel_seam"] <= 1.02 * rep["accel_max"] + 1e-6
    # rotations too: the angle between consecutive frames
    q = clip.quaternions
    dots = np.abs(np.sum(q * np.roll(q, -1, axis=0), axis=-1)).clip(max=1.0)
    ang = 2 * np.arccos(dots)  # (T, J), last row is the seam
    assert ang[-1].max() <= 1.02 * ang[:-1].max() + 1e-6
    omega = np.diff(np.concatenate([ang, ang[:1]]), axis=0)  # change of angular step
    assert np.abs(omega[-2:]).max() <= 1.02 * np.abs(omega[:-2]).max() + 1e-6


def test_seam_check_detects_a_broken_loop():
    clip = load_clip("dance_fist_pump_right")
    broken = dataclasses.replace(
        clip, joint_rotations=clip.joint_rotations[:-7], root_translation=clip.root_translation[:-7]
    )
    rep = seam_discontinuity(broken)
    assert rep["accel_seam"] > 1.5 * rep["accel_max"]


@pytest.mark.parametrize("name", ALL)
def test_joint_limits_and_floor(name):
    clip = load_clip(name)
    angles = np.degrees(np.linalg.norm(clip.joint_rotations, axis=-1)).max(axis=0)
    for j, jn in enumerate(JOINT_NAMES[1:], start=1):
        assert angles[j] <= _limit(jn), f"{jn}: {angles[j]:.0f} deg"
    root = axis_angle_to_matrix(clip.joint_rotations[:, 0])
    assert np.degrees(np.arccos(root[:, 2, 2].clip(-1, 1))).max() < 20  # trunk stays upright
    # hinges bend the anatomical way: knees backwards (rotation about -x), elbows forwards
    knees = clip.joint_rotations[:, [JOINT_INDEX["left_knee"], JOINT_INDEX["right_knee"]], 0]
    assert np.degrees(knees).max() < 5
    assert np.degrees(clip.joint_rotations[:, JOINT_INDEX["left_elbow"], 2]).max() < 5
    assert np.degrees(clip.joint_rotations[:, JOINT_INDEX["right_elbow"], 2]).min() > -5
    pos = clip.joint_positions()
    ankles = pos[:, [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]], 2]
    balls = pos[:, [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]], 2]
    assert ankles.min() >= ANKLE_HEIGHT - 1e-3 and balls.min() >= FOOT_HEIGHT - 3e-3  # never below the floor
    assert ankles.min() <= ANKLE_HEIGHT + 1e-3  # and standing on it
    # the wrists stay outside the torso's core (no arm through the body)
    torso = pos[:, JOINT_INDEX["spine3"], :2]
    for wrist in ("left_wrist", "right_wrist"):
        assert np.linalg.norm(pos[:, JOINT_INDEX[wrist], :2] - torso, axis=-1).min() > 0.08


def test_dance_feet_stay_planted_unless_jumping_or_stepping():
    for spec in DANCES:
        if spec.jump or spec.step:
            continue
        pos = load_clip(spec.name).joint_positions()
        for j in ("left_ankle", "right_ankle"):
            p = pos[:, JOINT_INDEX[j]]
            assert np.ptp(p, axis=0).max() < 1e-4, (spec.name, j)
            assert p[:, 2] == pytest.approx(ANKLE_HEIGHT, abs=1e-4)


def test_jumps_leave_the_floor():
    spec = next(d for d in DANCES if d.jump >= 0.1)
    pos = load_clip(spec.name).joint_positions()
    ankles = pos[:, [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]], 2]
    assert ankles.min(axis=1).max() > ANKLE_HEIGHT + 0.03


@pytest.mark.parametrize("name", list_clips("walk", "procedural"))
def test_walk_feet_planted_and_alternating(name):
    clip = load_clip(name)
    t = np.arange(clip.n_frames) / clip.fps
    world = clip.joint_positions() + clip.travel(t)[:, None, :]
    stances = []
    for j in ("left_ankle", "right_ankle"):
        p = world[:, JOINT_INDEX[j]]
        speed = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=-1) * clip.fps
        flat = (p[:-1, 2] < ANKLE_HEIGHT + 1e-4) & (p[1:, 2] < ANKLE_HEIGHT + 1e-4)
        assert 0.3 < flat.mean() < 0.6
        assert speed[flat].max() < 0.01  # no sliding on the ground
        stances.append(flat)
    # the feet alternate: each is flat while the other swings, half a cycle apart
    shift = np.argmax([np.sum(stances[0] == np.roll(stances[1], k)) for k in range(clip.n_frames)])
    assert abs(shift / clip.n_frames - 0.5) < 0.03
    # stride, measured on the feet: where the left foot is planted in two successive cycles
    # (the loop played twice along its travel) lies one stride apart
    t2 = np.arange(2 * clip.n_frames) / clip.fps
    rot2 = np.concatenate([clip.joint_rotations] * 2)
    root2 = np.concatenate([clip.root_translation] * 2) + clip.travel(t2)
    from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, forward_kinematics

    left = forward_kinematics(DEFAULT_REST_JOINTS, rot2, root2)[1][:, JOINT_INDEX["left_ankle"]]
    flat2 = np.concatenate([stances[0]] * 2)
    first = left[: clip.n_frames - 1][flat2[: clip.n_frames - 1]][:, 1].mean()
    second = left[clip.n_frames : 2 * clip.n_frames - 1][flat2[clip.n_frames - 1 : 2 * clip.n_frames - 2]][:, 1].mean()
    assert second - first == pytest.approx(clip.meta["stride_length"], rel=0.01)


def test_sample_interpolates_and_wraps():
    clip = load_clip("walk_normal")
    t = np.arange(clip.n_frames) / clip.fps
    rot, root = clip.sample(t)
    assert np.allclose(axis_angle_to_matrix(rot), axis_angle_to_matrix(clip.joint_rotations), atol=1e-9)
    assert np.allclose(root, clip.root_translation)
    a, _ = clip.sample_quaternions(np.array([0.123, 0.123 + clip.duration, 0.123 - 3 * clip.duration]))
    assert np.allclose(np.abs(np.sum(a[0] * a[1], -1)), 1) and np.allclose(np.abs(np.sum(a[0] * a[2], -1)), 1)
    half = clip.resample(30.0)
    assert half.duration == pytest.approx(clip.duration, rel=0.02)
    assert half.fps == pytest.approx(30.0, rel=0.02)
    # C1: the sampled trajectory has no velocity jumps between stored frames
    fine = np.linspace(0, clip.duration, 2001)
    _, r = clip.sample(fine)
    acc = np.diff(r, 2, axis=0)
    assert np.abs(acc).max() < 1e-4


def test_clip_validation_names_the_field():
    rot = np.zeros((10, 24, 3))
    with pytest.raises(InvalidInputError, match="root_translation"):
        MotionClip("x", "dance", 30, rot, np.zeros((9, 3)))
    with pytest.raises(InvalidInputError, match="joint_rotations"):
        MotionClip("x", "dance", 30, np.zeros((10, 23, 3)), np.zeros((10, 3)))
    with pytest.raises(InvalidInputError, match="fps"):
        MotionClip("x", "dance", -1, rot, np.zeros((10, 3)))
    with pytest.raises(InvalidInputError, match="kind"):
        MotionClip("x", "ballet", 30, rot, np.zeros((10, 3)))
    with pytest.raises(InvalidInputError, match="arms"):
        generate_dance(DanceSpec("bad", 120, "", arms="juggle"))
    with pytest.raises(InvalidInputError, match="sway_beats"):
        generate_dance(DanceSpec("bad", 120, "", sway_beats=3))

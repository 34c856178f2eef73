"""The output stage's speed limit (crowdstudy.physics.speed_limit): a correction that snaps
back is re-timed, the reference's own motion and the held feet are not."""

import numpy as np
import pytest

from crowdstudy.body.skeleton import JOINT_INDEX, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics import joint_speeds
from crowdstudy.physics.speed_limit import limit_joint_speed

FPS = 30.0
N_FRAMES = 60
R_SHOULDER, R_HIP = JOINT_INDEX["right_shoulder"], JOINT_INDEX["right_hip"]
UPPER = [
    JOINT_INDEX[n]
    for n in (
        "spine2",
        "spine3",
        "neck",
        "head",
        "left_collar",
        "right_collar",
        "left_shoulder",
        "right_shoulder",
        "left_elbow",
        "right_elbow",
        "left_wrist",
        "right_wrist",
        "left_hand",
        "right_hand",
    )
]


@pytest.fixture(scope="module")
def rest():
    from crowdstudy.body.shapes import sample_bodies
    from crowdstudy.physics.corrector import load_bodies

    body = load_bodies(sample_bodies(1, 5))[0]
    return np.asarray(body.rest_joints, np.float64)[None], float(body.pelvis_height)


def _reference(height: float, swing_leg: bool = False):
    """One character standing; the right arm swings gently (1 Hz, 0.3 rad); with
    ``swing_leg`` the right hip swings the foot forward over frames 20-40."""
    t = np.arange(N_FRAMES) / FPS
    rot = np.zeros((N_FRAMES, 1, 24, 3))
    rot[:, 0, R_SHOULDER, 1] = 0.3 * np.sin(2 * np.pi * t)
    if swing_leg:
        rot[20:41, 0, R_HIP, 0] = -0.5 * np.sin(np.pi * np.arange(21) / 20)
    root = np.tile([[0.0, 0.0, height]], (N_FRAMES, 1, 1))
    return rot, root


def _max_speed(rest_joints, rot, root, periodic=False):
    pos = forward_kinematics(rest_joints, rot, root)[1]
    return float(joint_speeds(pos, FPS, seam=periodic).max())


def test_a_snapping_arm_is_slowed_to_the_limit_and_keeps_its_correction(rest):
    rest_joints, height = rest
    ref_rot, ref_root = _reference(height)
    rot = ref_rot.copy()
    rot[:30, 0, R_SHOULDER, 2] += 0.8  # held 0.8 rad off, back within one frame at 30
    ref_max = _max_speed(rest_joints, ref_rot, ref_root)
    before = _max_speed(rest_joints, rot, ref_root)
    out, report = limit_joint_speed(rot, ref_root, ref_rot, ref_root, rest_joints, FPS, margin=0.3)
    after = _max_speed(rest_joints, out, ref_root)
    assert before > ref_max + 3.0  # the snap: several m/s faster than the reference
    assert report.fast_samples > 0 and report.characters == (0,) and report.unresolved == 0
    assert report.limit_m_s == pytest.approx(ref_max + 0.3)
    assert after <= report.limit_m_s + 1e-9 and report.max_speed_after_m_s == pytest.approx(after)
    # re-timed, not removed: the correction is whole at the start and gone at the end
    assert out[0, 0, R_SHOULDER, 2] == pytest.approx(0.8, abs=0.05)
    assert abs(out[-1, 0, R_SHOULDER, 2]) < 0.02
    assert np.array_equal(out[:, :, UPPER[2:4]], rot[:, :, UPPER[2:4]])  # neck, head: not on the arm's chain
    # the root, pelvis, spine1 and legs are never changed
    untouched = [j for j in range(24) if j not in UPPER]
    assert np.array_equal(out[:, :, untouched], rot[:, :, untouched])


def test_nothing_fast_leaves_the_output_as_it_is(rest):
    rest_joints, height = rest
    ref_rot, ref_root = _reference(height)
    rot = ref_rot.copy()
    rot[:, 0, R_SHOULDER, 2] += 0.2 * np.sin(np.linspace(0, np.pi, N_FRAMES))  # a slow correction
    out, report = limit_joint_speed(rot, ref_root, ref_rot, ref_root, rest_joints, FPS)
    assert report.fast_samples == 0 and report.characters == ()
    assert np.array_equal(out, rot)


def test_a_leg_is_re_timed_only_while_its_foot_swings(rest):
    rest_joints, height = rest
    # the foot always planted: a fast leg is left alone (the foot hold wins), and reported
    ref_rot, ref_root = _reference(height)
    rot = ref_rot.copy()
    rot[:30, 0, R_HIP, 0] += 0.4
    out, report = limit_joint_speed(rot, ref_root, ref_rot, ref_root, rest_joints, FPS)
    assert report.unresolved > 0
    assert np.array_equal(out[:, :, R_HIP], rot[:, :, R_HIP])
    # the foot swings over frames 20-40: the snap at 30 is spread over the swing's frames only
    ref_rot, ref_root = _reference(height, swing_leg=True)
    rot = ref_rot.copy()
    rot[:30, 0, R_HIP, 0] += 0.4
    out, report = limit_joint_speed(rot, ref_root, ref_rot, ref_root, rest_joints, FPS)
    leg = [JOINT_INDEX[n] for n in ("right_hip", "right_knee", "right_ankle", "right_foot")]
    before = _max_speed(rest_joints, rot, ref_root)
    after = _max_speed(rest_joints, out, ref_root)
    assert after < 0.5 * before
    assert np.array_equal(out[:18, :, leg], rot[:18, :, leg])  # planted frames: held
    assert np.array_equal(out[43:, :, leg], rot[43:, :, leg])
    assert not np.allclose(out[25:35, :, leg], rot[25:35, :, leg])


def test_the_seam_of_a_loop_counts(rest):
    rest_joints, height = rest
    ref_rot, ref_root = _reference(height)  # 60 frames of a 1 Hz swing: periodic
    rot = ref_rot.copy()
    rot[45:, 0, R_SHOULDER, 2] += 0.8  # off until the last frame, then back at frame 0
    plain, _ = limit_joint_speed(rot, ref_root, ref_rot, ref_root, rest_joints, FPS, periodic=False)
    looped, report = limit_joint_speed(rot, ref_root, ref_rot, ref_root, rest_joints, FPS, periodic=True)
    assert _max_speed(rest_joints, plain, ref_root, periodic=True) > report.limit_m_s + 1.0  # seam not seen
    assert _max_speed(rest_joints, looped, ref_root, periodic=True) <= report.limit_m_s + 1e-9
    assert not np.allclose(looped[:3], rot[:3])  # the correction eases in across the seam


def test_bad_arguments_are_named(rest):
    rest_joints, height = rest
    ref_rot, ref_root = _reference(height)
    with pytest.raises(InvalidInputError, match="rot, ref_rot"):
        limit_joint_speed(ref_rot[:, :, :20], ref_root, ref_rot, ref_root, rest_joints, FPS)
    with pytest.raises(InvalidInputError, match="fps"):
        limit_joint_speed(ref_rot, ref_root, ref_rot, ref_root, rest_joints, 0.0)


def test_the_limit_comes_from_the_reference_s_own_steps(rest):
    rest_joints, height = rest
    ref_rot, ref_root = _reference(height)
    ref_rot = ref_rot.copy()
    ref_rot[:, 0, R_SHOULDER, 1] = np.linspace(0.0, 1.2, N_FRAMES)  # a clip cut from a longer motion:
    pos = forward_kinematics(rest_joints, ref_rot, ref_root)[1]  # its last frame is far from its first
    within = float(joint_speeds(pos, FPS).max())
    assert float(joint_speeds(pos, FPS, seam=True).max()) > within + 5.0
    _, report = limit_joint_speed(ref_rot, ref_root, ref_rot, ref_root, rest_joints, FPS, margin=0.3, periodic=True)
    assert report.limit_m_s == pytest.approx(within + 0.3)


def test_a_walker_that_wraps_around_the_corridor_is_not_fast(rest):
    rest_joints, height = rest
    ref_rot, ref_root = _reference(height)
    root = ref_root.copy()
    root[:, 0, 0] = (np.arange(N_FRAMES) * 0.04) % 1.0  # 1.2 m/s along a 1 m periodic corridor
    _, wrapped = limit_joint_speed(ref_rot, root, ref_rot, root, rest_joints, FPS, periodic_length=1.0)
    assert wrapped.fast_samples == 0
    _, naive = limit_joint_speed(ref_rot, root, ref_rot, root, rest_joints, FPS, limit=3.0)
    assert naive.fast_samples > 0  # without the minimum image: jumps

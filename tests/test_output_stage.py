"""The output stage block by block (crowdstudy.physics.output_stage): the same animation and
report as the whole crowd at once, whatever the block size and the number of threads."""

import numpy as np
import pytest

from crowdstudy.body.skeleton import JOINT_INDEX
from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.finish import close_loop, lock_planted_feet, smooth_deviation
from crowdstudy.physics.output_stage import crowd_speed_limit, finish_crowd
from crowdstudy.physics.speed_limit import limit_joint_speed

FPS = 30.0
N_FRAMES, WARMUP, BLEND = 72, 9, 6
N_CHARS = 7


@pytest.fixture(scope="module")
def crowd():
    """Seven characters: each swings its arms and steps (planted feet between steps); the
    "simulated" poses hold some arms off their animation and let them snap back in a frame
    (too fast: the speed limit re-times them), and push the roots a little."""
    from crowdstudy.body.shapes import sample_bodies
    from crowdstudy.physics.corrector import load_bodies

    bodies = load_bodies(sample_bodies(N_CHARS, 11))
    rest = np.stack([np.asarray(b.rest_joints, np.float64) for b in bodies])
    rng = np.random.default_rng(3)
    total = WARMUP + N_FRAMES + BLEND
    t = np.arange(total) / FPS
    ref_rot = np.zeros((total, N_CHARS, 24, 3))
    ref_root = np.zeros((total, N_CHARS, 3))
    for c in range(N_CHARS):
        phase = rng.uniform(0, 2 * np.pi)
        for side, sign in (("left", 1.0), ("right", -1.0)):
            ref_rot[:, c, JOINT_INDEX[f"{side}_shoulder"], 1] = 0.3 * np.sin(2 * np.pi * t + phase) * sign
            # a step every second: the hip swings for 0.4 s, the foot stands still between
            swing = np.clip(np.sin(np.pi * (t * 1.0 + phase / np.pi + (0.5 if sign > 0 else 0.0))), 0.0, None) ** 3
            ref_rot[:, c, JOINT_INDEX[f"{side}_hip"], 0] = -0.4 * swing
        ref_root[:, c] = [1.2 * c, 0.0, rest[c, 0, 2] + 0.9]
    sim_rot = ref_rot + rng.normal(0.0, 0.01, ref_rot.shape)
    sim_root = ref_root + rng.normal(0.0, 0.005, ref_root.shape)
    for c in (1, 4, 5):  # held off, then back within a frame
        hold = slice(10 + 5 * c, 30 + 5 * c)
        sim_rot[hold, c, JOINT_INDEX["right_shoulder"], 2] += 0.9
        sim_rot[hold, c, JOINT_INDEX["left_elbow"], 1] += 0.7
    sim_root[20:40, 2, 0] += 0.05
    # the input is one period of the clip: the simulation saw [T - warmup, T) + [0, T) + [0, blend)
    ref = slice(WARMUP, WARMUP + N_FRAMES)
    return sim_rot, sim_root, ref_rot[ref].copy(), ref_root[ref].copy(), rest


def _whole_crowd(sim_rot, sim_root, ref_rot, ref_root, rest, config):
    """The output stage as correct() ran it before the blocks: every step on the whole crowd
    (a hold that follows the density profile taken at its dense end, as finish_crowd takes it)."""
    out = config.for_dense_crowd().output
    rot, root = close_loop(sim_rot, sim_root, N_FRAMES, WARMUP, BLEND)
    rot, root = smooth_deviation(
        rot,
        root,
        ref_rot,
        ref_root,
        out.smoothing * FPS,
        periodic=True,
        root_sigma_frames=out.smoothing_root * FPS,
        hold=out.hold,
    )
    locked = lock_planted_feet(
        rot, root, ref_rot, ref_root, rest, FPS, planted_speed=out.foot_lock_speed, periodic=True
    )
    assert not np.array_equal(locked, rot)  # the feet were held somewhere
    rot, report = limit_joint_speed(
        locked, root, ref_rot, ref_root, rest, FPS, margin=out.speed_limit_margin, periodic=True
    )
    assert report.characters and report.fast_samples > 0  # the speed limit had work to do
    return rot, root, report


@pytest.mark.parametrize("chunk, threads", [(2, 2), (3, 1), (64, 2)])
def test_blocks_give_the_whole_crowds_animation_and_report(crowd, chunk, threads):
    config = PhysicsConfig()
    want_rot, want_root, want = _whole_crowd(*crowd, config)
    rot, root, report = finish_crowd(
        *crowd, FPS, config, warmup=WARMUP, blend=BLEND, looped=True, chunk=chunk, threads=threads
    )
    assert np.array_equal(rot, want_rot) and np.array_equal(root, want_root)
    assert report == want
    # the simulation's float32 readback is taken as it comes
    rot32, _, _ = finish_crowd(
        crowd[0].astype(np.float32),
        crowd[1].astype(np.float32),
        *crowd[2:],
        FPS,
        config,
        warmup=WARMUP,
        blend=BLEND,
        looped=True,
        chunk=chunk,
        threads=threads,
    )
    assert rot32.dtype == np.float64 and np.abs(rot32 - rot).max() < 1e-3


def test_a_hold_that_follows_the_profile_is_taken_at_its_dense_end(crowd):
    """Without a crowd to measure, finish_crowd uses the dense end for the fields left to
    the density profile: the same bytes as the dense end given by hand, not the sparse."""
    follows = PhysicsConfig()
    assert follows.output.hold is None
    dense = follows.with_values({"output.hold": follows.profile.dense.output_hold})
    sparse = follows.with_values({"output.hold": follows.profile.sparse.output_hold})
    got = finish_crowd(*crowd, FPS, follows, warmup=WARMUP, blend=BLEND, looped=True)
    assert np.array_equal(got[0], finish_crowd(*crowd, FPS, dense, warmup=WARMUP, blend=BLEND, looped=True)[0])
    assert not np.array_equal(got[0], finish_crowd(*crowd, FPS, sparse, warmup=WARMUP, blend=BLEND, looped=True)[0])


def test_the_progress_bar_counts_the_blocks_and_changes_nothing(crowd, capsys, monkeypatch):
    from crowdstudy.progress import PROGRESS_ENV

    monkeypatch.setenv(PROGRESS_ENV, "1")  # captured stderr is no terminal: draw the bar anyway
    config = PhysicsConfig()
    quiet = finish_crowd(*crowd, FPS, config, warmup=WARMUP, blend=BLEND, looped=True, chunk=2, threads=2)
    shown = finish_crowd(
        *crowd, FPS, config, warmup=WARMUP, blend=BLEND, looped=True, chunk=2, threads=2, progress=True
    )
    assert np.array_equal(quiet[0], shown[0]) and quiet[2] == shown[2]
    err = capsys.readouterr().err
    assert "output stage" in err and "0/4 [" in err  # 7 characters: 4 blocks of 2


def test_the_limit_is_the_whole_crowds(crowd):
    _, _, ref_rot, ref_root, rest = crowd
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.metrics import joint_speeds

    whole = joint_speeds(forward_kinematics(rest[None], ref_rot, ref_root)[1], FPS).max()
    assert crowd_speed_limit(ref_rot, ref_root, rest, FPS, 0.3, chunk=2, threads=2) == float(whole) + 0.3


def test_the_stage_can_be_switched_off_step_by_step(crowd):
    sim_rot, sim_root, ref_rot, ref_root, rest = crowd
    config = PhysicsConfig().with_values(
        {"output.foot_lock": False, "output.speed_limit": False, "output.smoothing": 0.0, "output.smoothing_root": 0.0}
    )
    rot, root, report = finish_crowd(
        sim_rot, sim_root, ref_rot, ref_root, rest, FPS, config, warmup=WARMUP, blend=BLEND, looped=True, chunk=3
    )
    want_rot, want_root = close_loop(sim_rot, sim_root, N_FRAMES, WARMUP, BLEND)
    assert report is None
    assert np.array_equal(rot, want_rot) and np.array_equal(root, want_root)


def test_bad_shapes_are_named(crowd):
    sim_rot, sim_root, ref_rot, ref_root, rest = crowd
    with pytest.raises(InvalidInputError, match="sim_rot, sim_root"):
        finish_crowd(
            sim_rot[1:],
            sim_root,
            ref_rot,
            ref_root,
            rest,
            FPS,
            PhysicsConfig(),
            warmup=WARMUP,
            blend=BLEND,
            looped=True,
        )
    with pytest.raises(InvalidInputError, match="rest_joints"):
        finish_crowd(
            sim_rot,
            sim_root,
            ref_rot,
            ref_root,
            rest[1:],
            FPS,
            PhysicsConfig(),
            warmup=WARMUP,
            blend=BLEND,
            looped=True,
        )
    with pytest.raises(InvalidInputError, match="chunk"):
        finish_crowd(
            sim_rot,
            sim_root,
            ref_rot,
            ref_root,
            rest,
            FPS,
            PhysicsConfig(),
            warmup=WARMUP,
            blend=BLEND,
            looped=True,
            chunk=0,
        )

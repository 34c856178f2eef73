"""The motion-capture library: import of the Daz-style CMU BVH, cleaning, loops cut from the
data, the concert on one beat, and hands kept out of the body."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

from crowdstudy.body import load_body, sample_bodies
from crowdstudy.body.rotations import axis_angle_to_quaternion, quaternion_to_axis_angle
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, MIRROR_JOINTS, forward_kinematics, mirror_pose
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion import animate_stationary, load_bvh
from crowdstudy.motion.beat import beat_curve, bounce_phase, circular_spread, low_points, warp_to_tempo
from crowdstudy.motion.clip import MotionClip, seam_discontinuity
from crowdstudy.motion.library import list_clips, load_clip
from crowdstudy.motion.loops import find_loop, in_place_positions, make_loop
from crowdstudy.motion.mocap import clean_take, foot_contacts
from crowdstudy.motion.mocap_library import CREDIT, MAX_TEMPO_RATIO, TAKES, dance_loop, load_mocap, mocap_names
from crowdstudy.motion.selfcontact import clear_hands, hand_penetration
from crowdstudy.scene import Crowd

J = JOINT_INDEX


# ------------------------------------------------------------------------- the library
def test_library_ships_every_take_compactly_with_its_licence():
    root = resources.files("crowdstudy.motion") / "mocap"
    size = sum((root / f).stat().st_size for f in ("takes.npz", "library.json"))
    assert size <= 10 * 2**20
    assert set(mocap_names()) == {t.name for t in TAKES}
    assert len(mocap_names("dance")) == 11 and len(mocap_names("idle")) == 3 and len(mocap_names("walk")) == 6
    assert list_clips("dance") == mocap_names("dance")  # motion capture is the default
    assert {"jump", "groove_knees", "happy_claps", "groove_steps"}.isdisjoint(list_clips("dance", default_only=True))
    for name in mocap_names():
        clip = load_clip(name)
        assert clip.meta["mocap"] and clip.meta["trial"].startswith("CMU ")
        assert "CMU" in clip.meta["licence"] and clip.meta["source"].endswith(".bvh.gz")
    readme = (resources.files("crowdstudy.body") / "ASSETS.md").read_text(encoding="utf-8")
    assert "mocap.cs.cmu.edu" in readme and "NSF EIA-0196217" in CREDIT


def test_rebuilding_a_take_gives_the_shipped_arrays(shared_dir, tmp_path):
    from crowdstudy.motion.mocap_build import build_library

    out = build_library(shared_dir / "data" / "mocap", tmp_path, names=["macarena"])
    with np.load(out / "takes.npz") as z:
        shipped = np.load(resources.files("crowdstudy.motion") / "mocap" / "takes.npz")
        for key in ("macarena.quat", "macarena.root"):
            np.testing.assert_array_equal(z[key], shipped[key])


# ------------------------------------------------------------------------- the importer
def test_daz_bvh_retargets_with_derived_spine_and_toes(shared_dir):
    clip = load_bvh(shared_dir / "data" / "mocap" / "cmu_113_21_idle_standing_still.bvh.gz")
    assert clip.meta["skeleton"] == "daz" and clip.fps == pytest.approx(24.0)
    # spine3 rotates with the chest: a constant rest alignment, no motion of its own
    spine3 = clip.joint_rotations[:, J["spine3"]]
    np.testing.assert_allclose(spine3, np.broadcast_to(spine3[0], spine3.shape), atol=1e-9)
    pos = clip.joint_positions()
    head, pelvis = pos[:, J["head"]], pos[:, J["pelvis"]]
    assert np.all(head[:, 2] - pelvis[:, 2] > 0.5)  # upright
    toes = pos[:, J["left_foot"]] - pos[:, J["left_ankle"]]
    assert np.all(toes[:, 2] < 0.0) and np.all(np.linalg.norm(toes[:, :2], axis=1) > 0.08)  # forward and down
    feet = pos[:, [J["left_ankle"], J["right_ankle"]], 2]
    assert 0.04 < np.median(feet) < 0.15  # grounded: ankles above the floor
    # left and right are not swapped: the left hip is on the left of the facing direction
    fwd = toes[:, :2] / np.linalg.norm(toes[:, :2], axis=1, keepdims=True)
    side = pos[:, J["left_hip"], :2] - pos[:, J["right_hip"], :2]
    assert np.median(fwd[:, 0] * side[:, 1] - fwd[:, 1] * side[:, 0]) > 0  # left = +90 degrees from forward


def test_cleaned_take_faces_the_stage_on_its_spot_with_planted_feet(shared_dir):
    raw = load_bvh(shared_dir / "data" / "mocap" / "cmu_143_35_macarena_dance.bvh.gz")
    clip = clean_take(raw)
    fwd = clip.joint_positions()
    # facing +y: the left hip at -x (the character's left) on average
    assert np.mean(fwd[:, J["left_hip"], 0] - fwd[:, J["right_hip"], 0]) < -0.1
    drift = np.linalg.norm(clip.root_translation[:, :2], axis=1)
    assert drift.max() < 0.1 < np.linalg.norm(np.ptp(raw.root_translation[:, :2], axis=0))
    contacts = foot_contacts(clip)
    for k, side in enumerate(("left", "right")):
        ankle = fwd[:, J[f"{side}_ankle"], :2]
        both = contacts[1:, k] & contacts[:-1, k]
        speed = np.linalg.norm(np.diff(ankle, axis=0), axis=1) * clip.fps
        assert both.sum() > 10 and np.percentile(speed[both], 95) < 0.02  # planted: < 2 cm/s


# ----------------------------------------------------------------------------- loops
def _periodic_clip(period: int, n: int, noise: float = 0.0) -> MotionClip:
    t = np.arange(n)
    rng = np.random.default_rng(0)
    rot = np.zeros((n, 24, 3))
    rot[:, J["left_shoulder"], 2] = 0.8 * np.sin(2 * np.pi * t / period)
    rot[:, J["right_elbow"], 1] = 0.5 * np.sin(4 * np.pi * t / period + 1.0)
    rot += noise * rng.normal(size=rot.shape)
    root = np.zeros((n, 3))
    root[:, 2] = 0.9 + 0.02 * np.cos(2 * np.pi * t / period)
    return MotionClip(name="synthetic", kind="mocap", fps=30.0, joint_rotations=rot, root_translation=root, loop=False)


def test_find_loop_recovers_the_period_of_a_periodic_take():
    clip = _periodic_clip(37, 300)
    choice = find_loop(in_place_positions(clip), [30, 37, 45, 74], window=5, min_start=10)
    assert choice.length == 74 and choice.score < 1e-10  # the longest whole number of periods
    choice = find_loop(in_place_positions(clip), [30, 45], window=5, min_start=10)
    assert choice.score > 1e-4  # no exact match among wrong lengths


def test_blended_seam_is_smooth_and_a_broken_loop_is_caught():
    clip = _periodic_clip(37, 300, noise=0.0)
    # a mismatched cut (not a period) without blending jumps at the seam ...
    broken = make_loop(clip, 20, 50, 0)
    sd = seam_discontinuity(broken)
    assert sd["step_seam"] > 2.0 * sd["step_max"]
    # ... the same cut blended over 12 frames into the frames before its start does not
    fixed = make_loop(clip, 20, 50, 12)
    sd = seam_discontinuity(fixed)
    assert sd["step_seam"] <= 1.2 * sd["step_max"]


@pytest.mark.parametrize("name", list_clips("dance", default_only=True))
def test_every_default_dance_loops_seamlessly_on_whole_bars(name):
    loop = dance_loop(name, 120.0, 30.0, 20.0)
    assert loop.loop and loop.meta["beat_frames"] == 15
    assert loop.n_frames % 60 == 0 and 600 % loop.n_frames == 0  # whole bars that divide 20 s
    assert loop.meta["loop_source"]["start"] % 15 == 0  # cut on a beat
    assert 1 / MAX_TEMPO_RATIO <= loop.meta["tempo_ratio"] <= MAX_TEMPO_RATIO
    sd = seam_discontinuity(loop)
    assert sd["step_seam"] <= 1.5 * sd["step_max"] and sd["accel_seam"] <= 1.5 * sd["accel_max"]


# ------------------------------------------------------------------------------ beats
def test_beat_curve_puts_integers_on_the_low_points():
    fps = 60.0
    t = np.arange(900) / fps
    z = 0.9 + 0.02 * np.cos(2 * np.pi * t / 0.8 - 1.0)
    bc = beat_curve(z, fps)
    assert bc.period == pytest.approx(0.8, rel=0.01) and bc.strength > 0.8
    lows = low_points(z, fps)
    b = np.interp(lows, t, bc.bounces)
    np.testing.assert_allclose(b, np.round(b), atol=0.03)
    assert beat_curve(z, fps, period=0.4).method == "metadata"


def test_warp_to_tempo_lands_the_lows_on_the_grid():
    fps = 60.0
    t = np.arange(600) / fps
    root = np.zeros((600, 3))
    root[:, 2] = 0.9 + 0.02 * np.cos(2 * np.pi * t / 0.55)  # about 109 bounces per minute
    clip = MotionClip(
        name="b", kind="mocap", fps=fps, joint_rotations=np.zeros((600, 24, 3)), root_translation=root, loop=False
    )
    bc = beat_curve(root[:, 2], fps)
    warped = warp_to_tempo(clip, bc.bounces, 120.0, 30.0)
    lows = low_points(warped.root_translation[:, 2], 30.0)
    beats = lows * 2.0  # 120 bpm: 2 beats per second
    np.testing.assert_allclose(beats, np.round(beats), atol=0.08)
    assert warped.meta["tempo_ratio"] == pytest.approx(120.0 / (60 / 0.55), rel=0.02)


def test_bounce_phase_tells_a_shared_beat_from_drifting_dancers():
    fps, bpm = 30.0, 120.0
    t = np.arange(600) / fps
    rng = np.random.default_rng(1)
    on_beat = np.stack([0.9 - 0.02 * np.cos(2 * np.pi * 2.0 * (t - k * 0.5)) for k in rng.integers(0, 8, 12)], 1)
    drifting = np.stack(
        [
            0.9 - 0.02 * np.cos(2 * np.pi * f * t + p)
            for f, p in zip(rng.uniform(1.4, 2.6, 12), rng.uniform(0, 6.3, 12), strict=True)
        ],
        1,
    )
    on, off = bounce_phase(on_beat, fps, bpm), bounce_phase(drifting, fps, bpm)
    assert on["resultant"] > 0.95 and on["circular_sd"] < 0.2
    assert off["resultant"] < 0.3
    assert circular_spread(np.array([0.1, -0.1]))["resultant"] == pytest.approx(np.cos(0.1))


@pytest.fixture(scope="module")
def concert():
    rng = np.random.default_rng(3)
    crowd = Crowd(positions=rng.uniform(-2.5, 2.5, (1, 20, 2)), radius=0.2, meta={"scenario": "concert"})
    on = animate_stationary(crowd, duration=8.0, fps=30.0, seed=5)
    free = animate_stationary(crowd, duration=8.0, fps=30.0, seed=5, tempo=None)
    return on, free


def test_concert_dancers_share_the_beat_and_differ(concert):
    on, free = concert
    assert on.meta["loop"]["mode"] == "periodic" and on.meta["tempo"] == 120.0
    r_on = bounce_phase(on.root_translation[:, :, 2], on.fps, 120.0)
    r_free = bounce_phase(free.root_translation[:, :, 2], free.fps, 120.0)
    assert r_on["resultant"] > 0.5 > 0.25 > r_free["resultant"]  # measured: 0.64 vs 0.04 at D5, 20 s
    recs = on.clips
    assert len({r["clips"][0] for r in recs}) == 7  # each dancer its own clip, all seven dealt
    assert 0 < sum(r["mirrored"] for r in recs) < len(recs)
    amps = np.array([r["amplitude"] for r in recs])
    assert 0.85 <= amps.min() < amps.max() <= 1.15
    for r in recs:
        assert r["loop_frames"] % 60 == 0 and 0 <= r["beat_offset"] < r["loop_frames"] / 15
    # frame T would be frame 0: the seam step is an ordinary step
    step = np.abs(np.diff(on.root_translation, axis=0)).max()
    assert np.abs(on.root_translation[0] - on.root_translation[-1]).max() <= 1.5 * step


def test_mirror_pose_reflects_joint_positions():
    rng = np.random.default_rng(0)
    aa = rng.normal(0, 0.5, (24, 3))
    root = np.array([0.1, 0.2, 0.9])
    q, r = mirror_pose(axis_angle_to_quaternion(aa), root)
    _, p = forward_kinematics(DEFAULT_REST_JOINTS, aa, root)
    _, p2 = forward_kinematics(DEFAULT_REST_JOINTS, quaternion_to_axis_angle(q), r)
    np.testing.assert_allclose(p[MIRROR_JOINTS] * [-1, 1, 1], p2, atol=1e-12)
    q2, r2 = mirror_pose(q, r)
    np.testing.assert_allclose(np.abs(np.sum(q2 * axis_angle_to_quaternion(aa), -1)), 1.0, atol=1e-12)


def test_a_tempo_the_take_cannot_reach_is_refused():
    with pytest.raises(InvalidInputError, match="bpm"):
        dance_loop("chicken_claps", 200.0, 30.0, 20.0)  # 96 bpm, one bounce per beat
    with pytest.raises(InvalidInputError, match="whole number of frames"):
        dance_loop("macarena", 128.0, 30.0, 20.0)


# ----------------------------------------------------------------------- self-contact
def test_hands_are_moved_out_of_a_wider_body():
    take = load_mocap("cheer").resample(30.0)  # fist pumps: hands to the belly
    bodies = [load_body(b) for b in sample_bodies(4, 0)]
    rot = np.repeat(take.joint_rotations[:, None], 4, axis=1)
    root = np.repeat(take.root_translation[:, None], 4, axis=1)
    before = max(hand_penetration(b, rot[:, i], root[:, i]).max() for i, b in enumerate(bodies))
    fixed = clear_hands(rot, root, bodies, take.fps)
    after = [hand_penetration(b, fixed[:, i], root[:, i]) for i, b in enumerate(bodies)]
    assert before > 0.05  # measured 0.097 m beyond the 2 cm slack
    assert max(np.percentile(a.max(axis=1), 95) for a in after) < 0.007  # measured 5.7 mm (MakeHuman bodies)
    # the legs and the frames without contact are untouched
    legs = [J[f"{s}_{n}"] for s in ("left", "right") for n in ("hip", "knee", "ankle")]
    np.testing.assert_array_equal(fixed[:, :, legs], rot[:, :, legs])
    untouched = np.all(np.isclose(fixed, rot).all(axis=(2, 3)), axis=1)
    assert untouched.mean() > 0.2


def test_calibration_frames_at_the_ends_are_cut(shared_dir):
    from crowdstudy.motion.mocap import outlier_ends

    raw = load_bvh(shared_dir / "data" / "mocap" / "cmu_113_21_idle_standing_still.bvh.gz")
    start, end = outlier_ends(raw)
    assert start == pytest.approx(1 / raw.fps) and end == pytest.approx(raw.duration)  # the first frame jumps
    assert load_mocap("idle_still").meta["trim"][0] == pytest.approx(start)
    clean = _periodic_clip(37, 300)
    assert outlier_ends(clean) == (0.0, pytest.approx(clean.duration))
    rot = np.array(clean.joint_rotations)
    rot[-1, J["right_shoulder"], 2] += 1.0  # a glitch in the last frame
    glitch = MotionClip(
        name="g", kind="mocap", fps=30.0, joint_rotations=rot, root_translation=clean.root_translation, loop=False
    )
    assert outlier_ends(glitch)[1] == pytest.approx((clean.n_frames - 2) / 30.0)


def test_contact_sheet_shows_the_clip_in_every_tile(tmp_path):
    from PIL import Image

    from crowdstudy.render.sheets import clip_sheet

    out = clip_sheet(
        [load_clip("jumping_jacks"), load_clip("gait_fast")],
        tmp_path / "sheet.png",
        span=1.0,
        frames=4,
        width=96,
        height=128,
    )
    img = np.asarray(Image.open(out).convert("RGB")).astype(int)
    assert img.shape == (2 * 128, 4 * 96, 3)
    tiles = img.reshape(2, 128, 4, 96, 3).transpose(0, 2, 1, 3, 4)  # (row, col, H, W, 3)
    background = np.median(img[:5].reshape(-1, 3), axis=0)  # the sky above the heads
    for row in tiles:
        middle = [np.mean(np.abs(t[20:110, 38:58] - background).sum(-1) > 60) for t in row]
        edges = [np.mean(np.abs(t[:10] - background).sum(-1) > 60) for t in row]
        assert min(middle) > 0.2 and max(edges) < 0.05  # a body in the middle of each tile
    # the jumping jacks move: the tiles differ
    assert np.abs(tiles[0, 0] - tiles[0, 2]).mean() > 1.0


def test_baseline_beside_ours_sheet_puts_the_reference_above(tmp_path):
    from PIL import Image

    from crowdstudy.render.sheets import animation_sheet, clips_animation

    base = clips_animation([load_clip("cheer"), load_clip("twist")], span=1.0)
    moved = base.replace(root_translation=base.root_translation + np.array([0.0, 0.0, 0.15]))  # "Ours": lifted 15 cm
    both = animation_sheet(moved, tmp_path / "both.png", [1], span=1.0, frames=3, width=80, height=112, reference=base)
    alone = animation_sheet(base, tmp_path / "base.png", [1], span=1.0, frames=3, width=80, height=112)
    b = np.asarray(Image.open(both).convert("RGB")).astype(int)
    a = np.asarray(Image.open(alone).convert("RGB")).astype(int)
    assert b.shape == (2 * 112, 3 * 80, 3)
    np.testing.assert_array_equal(b[:112], a)  # the reference row, same cameras and colours
    assert np.abs(b[112:] - a).mean() > 1.0  # the lifted character looks different
    with pytest.raises(InvalidInputError, match="reference"):
        animation_sheet(moved, tmp_path / "x.png", [0], span=1.0, reference=clips_animation([load_clip("cheer")]))

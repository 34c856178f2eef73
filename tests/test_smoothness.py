"""crowdstudy.metrics.smoothness: jerk, high-frequency energy, speed spikes, pelvis
acceleration, foot sliding and loop seams on signals with known answers, then on
animations and through ``crowdstudy metrics``."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, JOINT_NAMES, PARENTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics import (
    SmoothnessResult,
    foot_slide,
    high_frequency_share,
    joint_jerk,
    mean_jerk,
    peak_joint_speed,
    pelvis_acceleration_p99,
    seam_jump,
    smoothness,
    smoothness_from_positions,
    smoothness_ratios,
)
from crowdstudy.metrics.smoothness import FOOT_JOINTS
from crowdstudy.scene import CrowdAnimation

FPS = 30.0


def sine_positions(freq, amp, n_frames, n_characters=1, n_joints=3, phases=None, fps=FPS):
    """(T, N, J, 3) positions: x = amp sin(2 pi f t + phase), y = z = 0 (plus a joint offset)."""
    t = np.arange(n_frames) / fps
    phases = np.zeros((n_characters, n_joints)) if phases is None else np.asarray(phases)
    pos = np.zeros((n_frames, n_characters, n_joints, 3))
    pos[..., 0] = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phases)
    pos[..., 1] = np.arange(n_joints) * 0.1  # constant offsets: no motion
    return pos


def circle_positions(period_frames, radius, n_frames, phases):
    """(T, N, J, 3) joints running round circles at constant speed (period in frames)."""
    t = np.arange(n_frames)[:, None, None]
    ang = 2 * np.pi * t / period_frames + phases[None]
    pos = np.zeros((n_frames,) + phases.shape + (3,))
    pos[..., 0] = radius * np.cos(ang)
    pos[..., 1] = radius * np.sin(ang)
    pos[..., 2] = 1.0
    return pos


# -------------------------------------------------------------------------- jerk
def test_jerk_of_a_sine_matches_the_analytic_mean():
    amp, freq = 0.05, 1.5
    omega = 2 * np.pi * freq
    pos = sine_positions(freq, amp, 300)  # 10 s: whole periods of 20 frames
    overall, per = joint_jerk(pos, FPS)
    analytic = (2 / np.pi) * amp * omega**3
    # the third difference of sin(omega t) scales omega^3 by sinc(omega dt / 2)^3, about
    # 1 - (omega dt)^2 / 8 (1.2 % at 1.5 Hz and 30 fps); sampling |cos| on 20 points per
    # period adds well under 1 %: the measurement sits below the analytic value
    dt = 1 / FPS
    fd_error = (omega * dt) ** 2 / 8
    assert analytic * (1 - fd_error - 0.01) < overall < analytic
    np.testing.assert_allclose(per, [overall])
    # only x moves: the jerk of the y offsets is 0; a second character twice as fast
    # (amplitude x2) has twice the jerk
    pos2 = np.concatenate([pos, 2 * pos], axis=1)
    pos2[..., 1] = 0.3
    overall2, per2 = joint_jerk(pos2, FPS)
    assert per2[1] == pytest.approx(2 * per2[0], rel=1e-12)
    assert overall2 == pytest.approx(per2.mean(), rel=1e-12)
    # the third difference of a cubic is exact: x = a t^3 has jerk 6a
    t = np.arange(10) / FPS
    cubic = np.zeros((10, 1, 1, 3))
    cubic[:, 0, 0, 2] = 0.7 * t**3
    assert joint_jerk(cubic, FPS)[0] == pytest.approx(6 * 0.7, rel=1e-6)
    with pytest.raises(InvalidInputError, match="pos"):
        joint_jerk(pos[:3], FPS)
    with pytest.raises(InvalidInputError, match="fps"):
        joint_jerk(pos, 0.0)
    with pytest.raises(InvalidInputError, match="pos"):
        joint_jerk(pos[..., :2], FPS)


# ------------------------------------------------------------ high-frequency share
def test_high_frequency_share_of_slow_fast_and_mixed_sines():
    n = 120  # 4 s
    slow, _ = high_frequency_share(sine_positions(2.0, 0.05, n), FPS)
    fast, _ = high_frequency_share(sine_positions(9.0, 0.02, n), FPS)
    assert slow < 0.01
    assert fast > 0.99
    # the cutoff is an argument: 2 Hz is "high" above 1 Hz
    assert high_frequency_share(sine_positions(2.0, 0.05, n), FPS, cutoff_hz=1.0)[0] > 0.99
    # one character each: per-character shares, and the overall share weights by energy:
    # the first difference of A sin(2 pi f t) times fps has amplitude 2 A fps sin(pi f / fps)
    # (A omega times 0.86 at 9 Hz), and both sines span whole periods
    pos = np.concatenate([sine_positions(2.0, 0.05, n), sine_positions(9.0, 0.02, n)], axis=1)
    overall, per = high_frequency_share(pos, FPS)
    assert per[0] < 0.01 and per[1] > 0.99
    e_slow, e_fast = ((2 * a * FPS * np.sin(np.pi * f / FPS)) ** 2 for a, f in ((0.05, 2.0), (0.02, 9.0)))
    assert overall == pytest.approx(e_fast / (e_slow + e_fast), abs=0.01)
    # a still character has no energy: share 0
    assert high_frequency_share(np.zeros((10, 1, 2, 3)), FPS)[0] == 0.0
    with pytest.raises(InvalidInputError, match="cutoff_hz"):
        high_frequency_share(pos, FPS, cutoff_hz=15.0)


# -------------------------------------------------------------- single-frame speed
def test_peak_speed_of_a_sine_and_an_injected_spike():
    amp, freq = 0.05, 1.0
    omega = 2 * np.pi * freq
    rng = np.random.default_rng(0)
    phases = rng.uniform(0, 2 * np.pi, size=(4, 5))
    phases[2, 3] = 0.0
    pos = sine_positions(freq, amp, 90, n_characters=4, n_joints=5, phases=phases)
    clean = peak_joint_speed(pos, FPS)
    # a step of sin moves A (2/dt) sin(omega dt/2) |cos(mid-step phase)|; some mid-step
    # phase lies within omega dt / 2 of a peak, so A omega sinc(omega dt) <= max <= A omega
    dt = 1 / FPS
    assert amp * np.sin(omega * dt) / dt <= clean.value <= amp * omega
    assert clean.value == pytest.approx(amp * omega, rel=0.01)
    np.testing.assert_array_less(clean.per_character, amp * omega + 1e-12)
    # a one-frame 6 cm jump of joint 3 of character 2 at frame 4 (moving +x there: the
    # step into frame 4 is the larger one)
    spiked = pos.copy()
    spiked[4, 2, 3, 0] += 0.06
    peak = peak_joint_speed(spiked, FPS)
    assert (peak.frame, peak.character, peak.joint) == (3, 2, 3)
    assert peak.value == pytest.approx((0.06 + pos[4, 2, 3, 0] - pos[3, 2, 3, 0]) * FPS, rel=1e-12)
    assert peak.value > 1.8
    assert np.argmax(peak.per_character) == 2
    np.testing.assert_allclose(np.delete(peak.per_character, 2), np.delete(clean.per_character, 2))


def test_periodic_scenes_use_the_minimum_image():
    # walking at 2 m/s along x in a corridor of length L, stored wrapped into [0, L)
    length = 6.0
    t = np.arange(150) / FPS
    pos = np.zeros((150, 1, 1, 3))
    pos[:, 0, 0, 0] = np.mod(2.0 * t, length)
    assert peak_joint_speed(pos, FPS).value > 100  # the wrap reads as a jump...
    assert peak_joint_speed(pos, FPS, periodic_length=length).value == pytest.approx(2.0)  # ...but it is not
    assert joint_jerk(pos, FPS, periodic_length=length)[0] == pytest.approx(0.0, abs=1e-9)
    # a clip that walks one length minus one step loops: its seam is one ordinary step
    pos_u = np.zeros((150, 1, 1, 3))
    pos_u[:, 0, 0, 0] = np.arange(150) * (length / 150)
    assert seam_jump(pos_u).ratio > 100
    assert seam_jump(pos_u, periodic_length=length).ratio == pytest.approx(1.0)
    with pytest.raises(InvalidInputError, match="periodic_length"):
        seam_jump(pos_u, periodic_length=-1.0)


# ------------------------------------------------------------------- loop seam
def test_seam_ratio_of_seamless_and_broken_loops():
    rng = np.random.default_rng(1)
    phases = rng.uniform(0, 2 * np.pi, size=(3, 4))
    n = 120
    loop = circle_positions(60, 0.05, n, phases)  # a 2 s period in a 4 s clip
    res = seam_jump(loop)
    step = 2 * 0.05 * np.sin(np.pi / 60)
    assert res.frame_step == pytest.approx(step, rel=1e-9)
    assert res.seam == pytest.approx(step, rel=1e-9)
    assert res.ratio == pytest.approx(1.0, rel=1e-9)
    np.testing.assert_allclose(res.per_character, 1.0, rtol=1e-9)
    # sines with other phases: about 1 too (the seam step is an ordinary step)
    sines = sine_positions(1.0, 0.05, n, n_characters=3, n_joints=4, phases=phases)
    assert 0.7 < seam_jump(sines).ratio < 1.4
    # the last frame of character 1 shifted by 5 cm
    broken = loop.copy()
    broken[-1, 1, :, 2] += 0.05
    res_b = seam_jump(broken)
    assert res_b.ratio > 3
    assert res_b.max_character > 8 and np.argmax(res_b.per_character) == 1
    assert res_b.per_character[0] == pytest.approx(1.0, rel=1e-9)
    # a period (47 frames) that does not divide the clip
    off = seam_jump(circle_positions(47, 0.05, n, phases))
    assert off.ratio > 3
    # nothing moves: a seamless loop
    assert seam_jump(np.zeros((5, 2, 3, 3))).ratio == 1.0


# ------------------------------------------------------------- pelvis acceleration
def test_pelvis_acceleration_of_parabolas():
    t = np.arange(60) / FPS
    root = np.zeros((60, 2, 3))
    root[:, 0, 0] = 0.5 * 1.5 * t**2
    root[:, 0, 1] = 0.5 * 0.6 * t**2 + 0.2 * t
    root[:, 1, 1] = 0.5 * 3.0 * t**2
    root[:, :, 2] = 0.9 + 0.05 * np.sin(2 * np.pi * 2 * t)[:, None]  # vertical bounce: not horizontal
    overall, per = pelvis_acceleration_p99(root, FPS)
    np.testing.assert_allclose(per, [np.hypot(1.5, 0.6), 3.0], rtol=1e-6)
    assert overall == pytest.approx(3.0, rel=1e-6)
    with pytest.raises(InvalidInputError, match="root"):
        pelvis_acceleration_p99(root[:2], FPS)


# ------------------------------------------------------------------- foot slide
def foot_scene(n_frames=90, slide=0.08):
    """One character: reference and measured (T, 1, 24, 3) positions.

    Reference: the left ankle stands still at 8 cm; the right ankle swings at 1 m/s; the
    left toe stands still, on the floor for the first half and lifted 15 cm for the
    second; the right toe moves at 1 m/s. Measured: the same, but the planted left ankle
    slides at ``slide`` m/s and the right ankle stands still.
    """
    t = np.arange(n_frames) / FPS
    ref = np.zeros((n_frames, 1, 24, 3))
    ref[:, 0, :, 2] = 0.5
    la, ra, lt, rt = (JOINT_INDEX[k] for k in ("left_ankle", "right_ankle", "left_foot", "right_foot"))
    ref[:, 0, la, 2] = 0.08
    ref[:, 0, ra, 0] = 1.0 * t
    ref[:, 0, ra, 2] = 0.08
    ref[:, 0, lt, 2] = np.where(np.arange(n_frames) < n_frames // 2, 0.05, 0.20)
    ref[:, 0, rt, 0] = 1.0 * t
    ref[:, 0, rt, 2] = 0.05
    meas = ref.copy()
    meas[:, 0, la, 0] = slide * t
    meas[:, 0, ra, 0] = 0.0
    return ref, meas


def test_foot_slide_with_the_reference_mask():
    assert FOOT_JOINTS == (7, 8, 10, 11)
    n = 90
    ref, meas = foot_scene(n)
    res = foot_slide(meas, FPS, reference=ref, planted_speed=0.1)
    # planted: the left ankle in every step, the left toe in the steps of its first half
    assert res.samples == (n - 1) + (n // 2 - 1)
    assert res.p99 == pytest.approx(0.08, rel=1e-9)
    assert res.p90 == pytest.approx(0.08, rel=1e-9) and res.p50 == pytest.approx(0.08, rel=1e-9)
    assert res.fraction_over_threshold == pytest.approx((n - 1) / res.samples)
    assert res.mean == pytest.approx(0.08 * (n - 1) / res.samples)
    assert res.per_character_samples.tolist() == [res.samples]
    # the mask from the measured animation itself also plants the right ankle (still
    # there): more samples, and the median drops to 0
    own = foot_slide(meas, FPS, planted_speed=0.1)
    assert own.samples == res.samples + (n - 1)
    assert own.p50 == 0.0
    # the default mask (planted below 2 cm/s) does not count the 8 cm/s ankle as planted
    # in the measured animation itself, but the reference's mask still catches its slide
    assert foot_slide(meas, FPS).samples == own.samples - (n - 1)
    assert foot_slide(meas, FPS, reference=ref).p99 == pytest.approx(0.08, rel=1e-9)
    # a slide above planted_speed leaves the measured mask but not the reference's
    ref2, meas2 = foot_scene(n, slide=0.3)
    assert foot_slide(meas2, FPS, reference=ref2, planted_speed=0.1).p99 == pytest.approx(0.3, rel=1e-9)
    # nothing planted: NaN statistics, zero samples
    running = ref.copy()
    running[..., 0] += np.arange(n)[:, None, None] / FPS  # every joint 1 m/s faster
    empty = foot_slide(meas, FPS, reference=running)
    assert empty.samples == 0 and np.isnan(empty.p99)
    with pytest.raises(InvalidInputError, match="reference"):
        foot_slide(meas, FPS, reference=ref[:10])
    with pytest.raises(InvalidInputError, match="foot_joints"):
        foot_slide(meas, FPS, foot_joints=[30])
    with pytest.raises(InvalidInputError, match="planted_speed"):
        foot_slide(meas, FPS, planted_speed=-0.1)


# ------------------------------------------------------------------ on animations
def rest_body():
    return SimpleNamespace(rest_joints=np.array(DEFAULT_REST_JOINTS))


def animation(roots, rotations=None, meta=None, fps=FPS):
    roots = np.asarray(roots, float)
    t, n = roots.shape[:2]
    rot = np.zeros((t, n, 24, 3)) if rotations is None else np.asarray(rotations, float)
    return CrowdAnimation(JOINT_NAMES, PARENTS, roots, rot, fps, [{}] * n, [{}] * n, meta or {})


def test_smoothness_of_a_rigidly_swaying_animation():
    # two characters whose roots sway along x at 1 Hz: every joint follows the root
    n, amp, freq = 90, 0.04, 1.0
    t = np.arange(n) / FPS
    roots = np.zeros((n, 2, 3))
    roots[:, :, 2] = 0.95
    roots[:, 0, 0] = amp * np.sin(2 * np.pi * freq * t)
    roots[:, 1, 0] = 2.0
    base = animation(roots)
    bodies = [rest_body(), rest_body()]
    res = smoothness(base, bodies=bodies)
    pos = np.array(DEFAULT_REST_JOINTS)[None, None] + roots[:, :, None]
    direct = smoothness_from_positions(pos, roots, FPS)
    assert res.jerk_m_s3 == pytest.approx(direct.jerk_m_s3, rel=1e-9)
    assert res.jerk_per_character[1] == 0.0
    assert res.jerk_m_s3 == pytest.approx(mean_jerk(base, bodies=bodies), rel=1e-9)
    assert res.max_joint_speed_character == 0
    assert res.max_joint_speed_m_s == pytest.approx(amp * 2 * np.pi * freq, rel=0.01)
    # 3 whole periods: the seam is the ordinary step from frame 89 to frame 90 = frame 0
    # (character 1 stands still: seam 0)
    assert res.seam_jump_m == pytest.approx(0.5 * amp * abs(np.sin(2 * np.pi * freq * (n - 1) / FPS)), rel=1e-9)
    assert 0.9 < res.seam_ratio_per_character[0] < 1.5 and res.seam_ratio_per_character[1] == 1.0
    assert res.foot_mask_from == "self"
    # "Ours": character 0 jumps 6 cm along y for one frame, character 1 is unchanged
    roots2 = roots.copy()
    roots2[40, 0, 1] += 0.06
    ours = animation(roots2)
    res2 = smoothness(ours, base, bodies=bodies)
    assert res2.foot_mask_from == "reference"
    # the steps into and out of frame 40 (39 -> 40, 40 -> 41) both carry the 6 cm jump
    assert res2.max_joint_speed_character == 0 and res2.max_joint_speed_frame in (39, 40)
    assert res2.max_joint_speed_m_s > 0.06 * FPS
    ratios = smoothness_ratios(res2, res)
    assert set(ratios) == {
        "jerk_ratio",
        "hf_share_ratio",
        "pelvis_accel_p99_ratio",
        "max_joint_speed_diff_m_s",
        "foot_slide_p99_diff_m_s",
    }
    assert ratios["jerk_ratio"] > 2 and ratios["pelvis_accel_p99_ratio"] > 2 and ratios["hf_share_ratio"] > 2
    assert ratios["max_joint_speed_diff_m_s"] == pytest.approx(res2.max_joint_speed_m_s - res.max_joint_speed_m_s)
    same = smoothness_ratios(res, res)
    assert same["jerk_ratio"] == 1.0 and same["max_joint_speed_diff_m_s"] == 0.0
    with pytest.raises(InvalidInputError, match="reference"):
        smoothness(ours, base.frames(0, 50), bodies=bodies)
    with pytest.raises(InvalidInputError, match="4 frames"):
        smoothness(base.frames(0, 3), bodies=bodies)
    with pytest.raises(InvalidInputError, match="result"):
        smoothness_ratios(res.as_dict(), res)


@pytest.fixture(scope="module")
def d1_baseline():
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary", "D1", duration=2.0)


def spiked(anim, character=3, frame=20, dx=0.25):
    roots = np.array(anim.root_translation)
    roots[frame, character, 0] += dx
    return anim.replace(root_translation=roots, meta={"method": "Ours"})


def test_smoothness_of_the_d1_stationary_baseline(d1_baseline):
    base = d1_baseline
    res = smoothness(base)
    assert isinstance(res, SmoothnessResult)
    d = res.as_dict()
    assert list(d) == list(SmoothnessResult.KEYS) + ["per_character"]
    assert set(d["per_character"]) == set(SmoothnessResult.PER_CHARACTER_KEYS)
    assert all(len(v) == base.n_characters for v in d["per_character"].values())
    json.dumps(d, allow_nan=False)
    # dancing people: jerk of tens of m/s^3, little energy above 6 Hz, feet on the floor
    assert 5 < res.jerk_m_s3 < 1000
    assert 0 <= res.hf_share < 0.3
    assert 0.2 < res.max_joint_speed_m_s < 10
    assert res.foot_planted_samples > 0 and res.foot_slide_p50_m_s < 0.05
    # against itself: ratios 1 and differences 0; a spike is found where it was put
    same = smoothness_ratios(smoothness(base, base), res)
    assert same["jerk_ratio"] == pytest.approx(1.0) and same["foot_slide_p99_diff_m_s"] == pytest.approx(0.0)
    ours = smoothness(spiked(base), base)
    assert ours.max_joint_speed_character == 3 and ours.max_joint_speed_frame in (19, 20)
    assert smoothness_ratios(ours, res)["jerk_ratio"] > 1.0


def test_cli_reports_smoothness_against_the_reference(d1_baseline, tmp_path, capsys):
    from crowdstudy import cli

    base = d1_baseline
    f_base = base.save(tmp_path / "base.npz")
    f_ours = spiked(base).save(tmp_path / "ours.npz")
    out = tmp_path / "m.json"
    assert (
        cli.main(
            [
                "metrics",
                str(f_ours),
                "--reference",
                str(f_base),
                "--geometry",
                "capsule",
                "--frames",
                "0,30",
                "--json",
                str(out),
                "--per-character",
                "--no-progress",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    for row in (
        "mean jerk",
        "HF share > 6 Hz",
        "max joint speed",
        "pelvis accel p99",
        "foot slide p99",
        "loop seam jump",
        "ratio",
        "jerk ratio",
    ):
        assert row in text
    m = json.loads(out.read_text())["metrics"]
    for key in SmoothnessResult.KEYS:
        assert key in m and f"reference_{key}" in m
    assert m["max_joint_speed_character"] == 3 and m["max_joint_speed_frame"] in (19, 20)
    assert m["jerk_ratio"] > 1.0 and m["pelvis_accel_p99_ratio"] > 1.0
    assert m["jerk_ratio"] == pytest.approx(m["jerk_m_s3"] / m["reference_jerk_m_s3"])
    assert m["max_joint_speed_diff_m_s"] == pytest.approx(m["max_joint_speed_m_s"] - m["reference_max_joint_speed_m_s"])
    assert m["max_joint_speed_diff_m_s"] > 0
    assert m["foot_mask_from"] == "reference" and m["reference_foot_mask_from"] == "self"
    per = m["smoothness_per_character"]
    assert len(per["jerk_m_s3"]) == base.n_characters
    assert int(np.argmax(per["max_joint_speed_m_s"])) == 3
    ref_per = m["reference_smoothness_per_character"]
    assert per["jerk_m_s3"][0] == pytest.approx(ref_per["jerk_m_s3"][0])  # an untouched character

"""Looping stimuli (docs/concepts/methods.md, "What a stimulus must be"): the concert Baseline is exactly
periodic over the stimulus duration; the corridor's seam is a short cross-dissolve of
frames past the video into its first frames; the pixel seam measure finds a jump."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_fixtures import crowd_animation, grid_positions, mannequin_loader, mannequin_renderer  # noqa: E402

from crowdstudy.design import load_design  # noqa: E402
from crowdstudy.metrics import BarTolerances  # noqa: E402
from crowdstudy.metrics.tracking import joint_positions  # noqa: E402
from crowdstudy.motion import baseline as baseline_mod  # noqa: E402
from crowdstudy.motion.baseline import LOOP_DISSOLVE_SECONDS, MAX_LOOP_TEMPO_CHANGE, build_baseline  # noqa: E402
from crowdstudy.motion.mocap_library import MAX_TEMPO_RATIO  # noqa: E402
from crowdstudy.render.seam import seam_change  # noqa: E402
from crowdstudy.render.video import _frame_plan, blend_frames, video_frame_count  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def concert(design):
    return build_baseline(design, "stationary", "D1")


def _seam_steps(anim):
    """Per frame step (T-1,) and the seam step T-1 -> 0, mean joint displacement (m), and
    the same per character: (T-1, N) and (N,)."""
    pos = joint_positions(anim)  # (T, N, J, 3)
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(axis=-1)
    seam = np.linalg.norm(pos[0] - pos[-1], axis=-1).mean(axis=-1)
    return steps.mean(axis=1), float(seam.mean()), steps, seam


#: the seam bar: the loop's last-to-first step at most this many median frame steps
SEAM_RATIO = BarTolerances().seam_ratio


def _seam_ok(anim, factor: float = SEAM_RATIO) -> bool:
    steps, seam, _, _ = _seam_steps(anim)
    return seam <= factor * float(np.median(steps))


def test_concert_baseline_is_periodic(design, concert):
    n_frames = int(round(design.duration * design.fps))
    assert concert.n_frames == n_frames
    assert concert.meta["loop"] == {"mode": "periodic", "frames": n_frames}
    steps, seam, steps_c, seam_c = _seam_steps(concert)
    assert seam <= SEAM_RATIO * np.median(steps)
    # frame T-1 -> 0 is the step T-1 -> T of the loop: never larger than the character's own steps
    assert np.all(seam_c <= steps_c.max(axis=0) + 1e-9)
    for rec in concert.clips:
        cycles = n_frames / rec["loop_frames"]
        assert abs(cycles - round(cycles)) < 1e-9 and round(cycles) >= 1  # the loop divides T
        # motion capture: the take time-warped onto the beat, loops of whole bars (4 beats)
        assert abs(np.log(rec["tempo"])) <= np.log(MAX_TEMPO_RATIO) + 1e-9
        beat = design.fps * 60.0 / design.scenarios["concert"]["tempo"]
        assert rec["loop_frames"] % (4 * beat) == 0 and 0 <= rec["beat_offset"] < rec["loop_frames"] / beat


def test_every_clip_loop_divides_the_stimulus(design):
    from crowdstudy.motion.library import list_clips, load_clip

    n_frames = int(round(design.duration * design.fps))
    worst = 0.0
    for name in list_clips("dance", "procedural"):
        natural = load_clip(name).duration * design.fps
        k = baseline_mod.loop_cycles(natural, n_frames)
        assert k >= 1, name
        assert n_frames % k == 0, name  # the 15 clips get whole-frame loops at 20 s
        worst = max(worst, abs(natural * k / n_frames - 1.0))
    assert worst <= MAX_LOOP_TEMPO_CHANGE


def test_broken_loop_fails_the_check(design, monkeypatch):
    # procedural clips: the old rounding (each clip at its natural length in frames) does not divide T
    monkeypatch.setattr(baseline_mod, "loop_cycles", lambda natural, n, max_change=0: 0)
    monkeypatch.setitem(design.scenarios["concert"].params, "motion", "procedural")
    broken = build_baseline(design, "stationary", "D1")
    assert broken.meta["loop"] == {"mode": "none"}
    assert not _seam_ok(broken)


def test_broken_mocap_loop_fails_the_check(design, monkeypatch):
    # motion capture: loops a few frames shorter than whole bars no longer divide T
    from crowdstudy.motion import mocap_library

    real = mocap_library._loop_lengths
    monkeypatch.setattr(mocap_library, "_loop_lengths", lambda bars, bar, room: [x - 7 for x in real(bars, bar, room)])
    mocap_library.dance_loop.cache_clear()
    try:
        broken = build_baseline(design, "stationary", "D1")
    finally:
        mocap_library.dance_loop.cache_clear()
    assert broken.meta["loop"] == {"mode": "none"}
    assert not _seam_ok(broken)


def test_short_concert_keeps_natural_length(design, monkeypatch):
    # 1 s holds half a bar: the mocap loops stay whole bars, the animation is not periodic
    short = build_baseline(design, "stationary", "D1", duration=1.0)
    assert short.meta["loop"]["mode"] == "none"
    bar = 4 * design.fps * 60.0 / design.scenarios["concert"]["tempo"]
    assert all(rec["loop_frames"] % bar == 0 for rec in short.clips)
    monkeypatch.setitem(design.scenarios["concert"].params, "motion", "procedural")
    short = build_baseline(design, "stationary", "D1", duration=1.0)
    assert short.meta["loop"]["mode"] == "none"
    assert all(abs(rec["tempo"] - 1.0) < 0.01 for rec in short.clips)


def test_corridor_baseline_has_dissolve_frames(design):
    anim = build_baseline(design, "walking", "D1", duration=4.0)
    n_video = int(round(4.0 * design.fps))
    d = int(round(LOOP_DISSOLVE_SECONDS * design.fps))
    assert anim.n_frames == n_video + d
    assert anim.meta["loop"] == {"mode": "dissolve", "frames": d, "video_frames": n_video}
    assert video_frame_count(anim) == n_video
    plan = _frame_plan(anim, None, design.fps)
    assert len(plan) == n_video and plan.n_blended == d
    none = build_baseline(design, "walking", "D1", duration=4.0, dissolve=0)
    assert none.n_frames == n_video and none.meta["loop"] == {"mode": "none"}
    # the extra frames continue the same walk
    np.testing.assert_allclose(none.root_translation[: n_video - 20], anim.root_translation[: n_video - 20], atol=1e-9)


def test_dissolve_clips_have_no_joint_space_seam(design):
    from crowdstudy.metrics import smoothness

    anim = build_baseline(design, "walking", "D1", duration=4.0)
    assert np.isnan(smoothness(anim).seam_ratio)  # measured in pixels instead
    assert smoothness(anim).as_dict()["seam_ratio"] is None
    # without the dissolve the joint-space seam is measured, and the crowd jumps
    none = build_baseline(design, "walking", "D1", duration=4.0, dissolve=0)
    assert smoothness(none).seam_ratio > 10


def _walkers(n_frames: int, d: int, fps: float = 30.0):
    anim = crowd_animation(
        grid_positions(6, extent=(4.5, 2.0), margin=0.5),
        n_frames=n_frames,
        fps=fps,
        scenario="corridor",
        period=4.5,
        velocity=(1.2, 0.0),
    )
    return anim.replace(meta={"loop": {"mode": "dissolve", "frames": d, "video_frames": n_frames - d}})


def test_frame_plan_blends_as_specified():
    t, d = 40, 5
    anim = _walkers(t + d, d)
    plan = _frame_plan(anim, None, 30.0)
    np.testing.assert_array_equal(plan.source, np.arange(t))
    np.testing.assert_array_equal(plan.partner[:d], t + np.arange(d))
    assert np.all(plan.partner[d:] == -1) and np.all(plan.weight[d:] == 1.0)
    np.testing.assert_allclose(plan.weight[:d], (np.arange(d) + 1) / (d + 1))
    # a periodic (or no) loop renders the frames as they are
    for loop in ({"mode": "periodic", "frames": t + d}, {"mode": "none"}):
        p = _frame_plan(anim.replace(meta={"loop": loop}), None, 30.0)
        assert len(p) == t + d and p.n_blended == 0
    # a shorter render still dissolves the frames that follow it into its start
    p = _frame_plan(anim, 1.0, 30.0)
    np.testing.assert_array_equal(p.partner[:d], 30 + np.arange(d))


def test_blend_is_linear_light_on_constant_frames():
    white = np.full((4, 6, 3), 255, np.uint8)
    black = np.zeros((4, 6, 3), np.uint8)
    d = 5
    for i in range(d):
        w = (i + 1) / (d + 1)
        out = blend_frames(white, black, w)
        assert out.dtype == np.uint8 and out.shape == white.shape
        assert np.all(out == int(np.floor(255 * np.sqrt(w) + 0.5)))  # display = sqrt(linear)
    assert np.all(blend_frames(white, black, 0.25) == 128)
    grey = np.full((4, 6, 3), 100, np.uint8)
    assert np.all(blend_frames(grey, grey, 0.3) == 100)
    raw = blend_frames(white.tobytes(), black.tobytes(), 0.25)  # raw bytes in, bytes out
    assert isinstance(raw, bytes) and set(raw) == {128}


def test_dissolve_video_blends_its_first_frames(tmp_path):
    from crowdstudy.render.video import find_ffmpeg, probe_video, render_video

    w, h, t, d = 192, 108, 12, 4
    anim = _walkers(t + d, d)
    design = load_design()
    out = tmp_path / "corridor.mp4"
    res = render_video(
        anim, "V4", out, width=w, height=h, design=design, progress=False, body_loader=mannequin_loader, crf=12
    )
    assert res["frames"] == t and res["dissolve_frames"] == d and probe_video(out)["frames"] == t
    raw = subprocess.run(
        [find_ffmpeg(), "-loglevel", "error", "-i", str(out), "-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"],
        capture_output=True,
        check=True,
    ).stdout
    video = np.frombuffer(raw, np.uint8).reshape(-1, h, w, 3).astype(int)
    with mannequin_renderer(anim, design, width=w, height=h) as r:
        r.set_view("V4")
        frames = {k: r.render(k) for k in (0, 1, t, t + 1, d, t - 1)}
    for i in (0, 1):
        expected = blend_frames(frames[i], frames[t + i], (i + 1) / (d + 1)).astype(int)
        err = np.abs(video[i] - expected).mean()
        assert err < 3 and err < 0.5 * np.abs(video[i] - frames[i].astype(int)).mean()
    assert np.abs(video[d] - frames[d].astype(int)).mean() < 3  # the clip itself from frame D
    assert np.abs(video[t - 1] - frames[t - 1].astype(int)).mean() < 3


def _bar_frames(n: int, jump: int = 0) -> np.ndarray:
    """A bright bar circling the width of the image once per n frames (a smooth loop);
    ``jump`` pixels of extra offset in the last frame make the seam jump."""
    w = 96
    frames = np.zeros((n, 24, w, 3), np.uint8)
    for k in range(n):
        x = int(round(k * w / n)) + (jump if k == n - 1 else 0)
        frames[k, :, [(x + j) % w for j in range(8)]] = 230
    return frames


def test_seam_measure_finds_an_injected_jump():
    smooth = seam_change(_bar_frames(48))
    assert 0.5 <= smooth["ratio"] <= 1.5
    jump = seam_change(_bar_frames(48, jump=30))
    assert jump["ratio"] > 3
    assert len(jump["steps"]) == 47

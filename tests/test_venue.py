"""The scene around the crowd: the concert venue and its cutaway, the audience figures'
keep-out and beat, the floor pattern's filtering, BT.709 video (tiny sizes)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_fixtures import H, W, crowd_animation, grid_positions, mannequin_renderer  # noqa: E402

from crowdstudy.design import load_design  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def venue(design):
    from crowdstudy.render.scene import build_environment

    return build_environment("concert", design)


def _figures(env):
    from crowdstudy.render.venue import PATTERN_FIGURE

    cut = env.cutaway
    first_rows = cut.indices[cut.first]
    return np.flatnonzero(cut.vertices[first_rows, 9] >= PATTERN_FIGURE)


def test_audience_surrounds_the_area_and_keeps_out_of_it(design, venue):
    from crowdstudy.render.scene import build_environment
    from crowdstudy.render.venue import KEEP_OUT

    cut = venue.cutaway
    figs = _figures(venue)
    assert len(figs) > 200
    limit = np.array(venue.extent) / 2 + KEEP_OUT
    # no vertex of any figure, at any bob height, inside the area grown by KEEP_OUT
    for e in figs:
        xy = cut.vertices[cut.indices[cut.first[e] : cut.first[e] + cut.count[e]], :2]
        assert not np.any(np.all(np.abs(xy) < limit, axis=1)), e
    centre = 0.5 * (cut.lo[figs] + cut.hi[figs])
    behind = centre[:, 1] < -limit[1]
    left, right = (centre[:, 0] < -limit[0]) & ~behind, (centre[:, 0] > limit[0]) & ~behind
    assert behind.sum() > 100 and left.sum() > 30 and right.sum() > 30
    # seeded: the same design gives the same venue, byte for byte; another seed another one
    again = build_environment("concert", design)
    assert again.cutaway.vertices.tobytes() == cut.vertices.tobytes()
    other = build_environment("concert", dataclasses.replace(design, seed=design.seed + 1))
    assert (
        other.cutaway.vertices.shape != cut.vertices.shape or other.cutaway.vertices.tobytes() != cut.vertices.tobytes()
    )


@pytest.mark.parametrize("view", ["V1", "V2", "V3", "V4"])
def test_cutaway_leaves_every_sight_line_to_the_crowd_free(design, venue, view):
    """No kept element's box meets a segment from the eye to random points of the crowd
    box (points the cutaway's own grid does not sample), yet most of the venue stays."""
    from crowdstudy.render.renderer import resolve_camera
    from crowdstudy.render.venue import occluding

    cam = resolve_camera(view, design, venue.extent, W / H)
    cut = venue.cutaway
    keep = ~occluding(cut, cam.eye, venue.extent)
    assert keep.mean() > 0.6
    rng = np.random.default_rng(3)
    w, d = venue.extent
    pts = np.c_[rng.uniform(-w / 2, w / 2, 400), rng.uniform(-d / 2, d / 2, 400), rng.uniform(0, 1.9, 400)]
    eye = np.asarray(cam.eye)
    lo, hi = cut.lo[keep], cut.hi[keep]
    for s in np.linspace(0.0, 1.0, 200)[1:-1]:
        p = eye + s * (pts - eye)  # (400, 3) points on the sight lines
        inside = np.all((p[:, None] >= lo[None]) & (p[:, None] <= hi[None]), axis=2)
        assert not inside.any(), f"{view}: a kept element stands between the camera and the crowd"


@pytest.mark.parametrize("view", ["V1", "V2", "V3", "V4"])
def test_venue_hides_no_character_and_fills_the_background(design, view):
    anim = crowd_animation(grid_positions(12, margin=0.45), n_frames=2)
    away = anim.replace(root_translation=anim.root_translation + [0, 0, -50.0])
    images = {}
    for name, a in (("crowd", anim), ("empty", away)):
        for bare in (False, True):
            with mannequin_renderer(a, design) as r:
                r.set_view(view)
                if bare:  # the same scene without the venue's cut-away elements
                    r.set_cutaway([])
                images[name, bare] = r.render(1).astype(int)
    mask = np.abs(images["crowd", True] - images["empty", True]).sum(axis=2) > 30  # the characters' pixels
    for axis in (0, 1):  # ... less their anti-aliased edges, which blend with the background
        mask &= np.roll(mask, 1, axis) & np.roll(mask, -1, axis)
    assert mask.mean() > 0.02
    same = np.abs(images["crowd", False] - images["crowd", True]).max(axis=2)[mask]
    assert np.mean(same > 12) < 0.02, "venue geometry covers the characters"
    # ... while it changes the picture around them (a hall, not a void)
    if view != "V4":
        assert np.mean(np.abs(images["empty", False] - images["empty", True]).max(axis=2) > 12) > 0.15


def test_audience_bobs_on_the_beat(design):
    anim = crowd_animation(grid_positions(4, margin=0.45), n_frames=16)  # 30 fps; 120 bpm: a beat is 15 frames
    anim = anim.replace(root_translation=anim.root_translation + [0, 0, -50.0])
    with mannequin_renderer(anim, design, width=320, height=180) as r:
        r.set_view("V1")
        a, half, beat = (r.render(f).astype(int) for f in (0, 7, 15))
    moved = np.abs(a - half).max(axis=2) > 8  # half a beat later the figures stand higher ...
    assert moved.mean() > 0.01
    assert np.abs(a - beat).max() <= 2  # ... and a whole beat later where they stood


def _floor_view(design, width, height):
    """The bare hall floor (no crowd, no venue elements) from low above the stage, looking
    over the floor to the back wall 21 m away: the tiles shrink below a pixel there."""
    from crowdstudy.render.camera import free_camera

    anim = crowd_animation(np.array([[0.0, 0.0]]), n_frames=1)
    anim = anim.replace(root_translation=anim.root_translation + [0, 0, -50.0])
    with mannequin_renderer(anim, design, width=width, height=height, msaa=0, shadows=False) as r:
        r.set_view(free_camera((0.3, 8.0, 0.5), (0.0, -20.0, 0.35), 40.0))
        r.set_cutaway([])
        return r.render(0).astype(np.float64)


def test_floor_pattern_is_filtered_at_the_horizon(design):
    """Rendered without MSAA, the distant floor is smooth and matches a 4 x 4 supersampled
    reference: the tile joints fade to their mean instead of breaking into dashes (the
    unfiltered pattern: row std 3, error 1.7 grey levels; filtered: 0.35 and 0.3)."""
    small = _floor_view(design, 240, 136)
    big = _floor_view(design, 960, 544).reshape(136, 4, 240, 4, 3).mean(axis=(1, 3))
    far = (slice(72, 75), slice(40, 200))  # floor rows 14-20 m away, just below the back wall
    assert small[far].mean(axis=2).std(axis=1).max() < 1.5
    assert np.abs(small[far] - big[far]).mean() < 0.8


def test_video_is_bt709_and_tagged(tmp_path):
    from crowdstudy.render.video import VideoWriter, find_ffmpeg, probe_video

    w, h, rgb = 64, 48, (200, 39, 44)
    writer = VideoWriter(tmp_path / "red.mp4", w, h, 30, bottom_up=False)
    for _ in range(3):
        writer.write(np.full((h, w, 3), rgb, np.uint8))
    writer.close()
    info = probe_video(tmp_path / "red.mp4")
    assert (info["color_space"], info["color_primaries"], info["color_transfer"]) == ("bt709",) * 3
    assert info["color_range"] == "tv"
    raw = subprocess.run(
        [
            find_ffmpeg(),
            "-loglevel",
            "error",
            "-i",
            str(tmp_path / "red.mp4"),
            "-frames:v",
            "1",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "yuv420p",
            "pipe:1",
        ],
        capture_output=True,
        check=True,
    ).stdout
    y = np.frombuffer(raw[: w * h], np.uint8).mean()
    u = np.frombuffer(raw[w * h : w * h * 5 // 4], np.uint8).mean()
    v = np.frombuffer(raw[w * h * 5 // 4 :], np.uint8).mean()
    # a BT.709 limited-range decode (what a browser applies to HD video)
    kr, kb = 0.2126, 0.0722
    luma, cb, cr = (y - 16) / 219, (u - 128) / 224, (v - 128) / 224
    r, b = luma + 2 * (1 - kr) * cr, luma + 2 * (1 - kb) * cb
    g = (luma - kr * r - kb * b) / (1 - kr - kb)
    assert np.allclose(np.array([r, g, b]) * 255, rgb, atol=3), np.array([r, g, b]) * 255


def test_frustum_culling_of_the_venue_keeps_the_picture(design):
    """The elements outside the camera's view are not submitted; the image is the same."""
    from crowdstudy.render.venue import visible_indices

    anim = crowd_animation(grid_positions(4, margin=0.45), n_frames=1)
    with mannequin_renderer(anim, design) as r:
        r.set_view("V4")
        culled = r.environment.cut_count
        a = r.render(0).astype(int)
        every = visible_indices(r.env.cutaway, r.camera.eye, r.env.extent)
        r.set_cutaway(every)
        b = r.render(0).astype(int)
    assert culled < 0.7 * len(every)
    assert np.abs(a - b).max() <= 1

"""The stimulus frames' fidelity: the FXAA pass, the supersampled reference and its SSIM,
and renders that do not depend on what the process rendered before."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from render_fixtures import crowd_animation, grid_positions, mannequin_renderer  # noqa: E402

from crowdstudy.design import load_design  # noqa: E402
from crowdstudy.errors import InvalidInputError  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return load_design()


def test_box_downsample_averages_each_block():
    from crowdstudy.render.fidelity import box_downsample

    img = np.zeros((4, 6, 3), np.uint8)
    img[:2, :2] = 200  # one full block
    img[2:, 4:] = [[[10, 0, 0], [30, 0, 0]], [[50, 0, 0], [70, 0, 255]]]
    out = box_downsample(img, 2)
    assert out.shape == (2, 3, 3)
    assert out[0, 0].tolist() == [200, 200, 200] and out[0, 1].tolist() == [0, 0, 0]
    assert out[1, 2].tolist() == [40, 0, 64]
    with pytest.raises(InvalidInputError, match="scale"):
        box_downsample(img[:3], 2)


def test_frame_ssim_is_one_for_the_same_frame_and_drops_with_blur():
    from crowdstudy.render.fidelity import frame_ssim

    rng = np.random.default_rng(0)
    img = (rng.random((64, 96, 3)) > 0.5).astype(np.uint8) * 255
    assert frame_ssim(img, img) == pytest.approx(1.0)
    blurred = ((img.astype(np.float64) + np.roll(img, 1, axis=1)) / 2).astype(np.uint8)
    assert frame_ssim(blurred, img) < 0.9
    with pytest.raises(InvalidInputError, match="image"):
        frame_ssim(img[:32], img)


def test_render_options_name_a_bad_filter_or_detail():
    from crowdstudy.render.assets import RenderOptions

    assert RenderOptions.validated(post_aa="fxaa").post_aa == "fxaa"
    assert RenderOptions.validated(height=2160, detail_height=1080).max_faces == 3000
    with pytest.raises(InvalidInputError, match="post_aa"):
        RenderOptions.validated(post_aa="smaa")
    with pytest.raises(InvalidInputError, match="detail_height"):
        RenderOptions.validated(detail_height=4)
    with pytest.raises(InvalidInputError, match="lod_scale"):
        RenderOptions.validated(lod_scale=-1.0)


def test_fxaa_brings_the_frame_closer_to_its_supersampled_reference(design):
    """On a crowd's silhouettes the FXAA pass moves the frame towards the 2x supersampled,
    4x MSAA reference, and leaves the flat regions as drawn."""
    import functools

    from crowdstudy.render.fidelity import frame_ssim, reference_frame

    anim = crowd_animation(grid_positions(9, margin=0.45), n_frames=1)
    size = {"width": 384, "height": 216}

    def factory(**kw):
        return mannequin_renderer(anim, design, shadows=False, **kw)

    ref = reference_frame(functools.partial(factory), "V3", 0, **size)
    images = {}
    for name, kw in {"none": {"msaa": 0}, "fxaa": {"msaa": 0, "post_aa": "fxaa"}, "msaa": {"msaa": 4}}.items():
        with factory(**size, **kw) as r:
            r.set_view("V3")
            images[name] = r.render(0)
    ssim = {k: frame_ssim(v, ref) for k, v in images.items()}
    assert ssim["fxaa"] > ssim["none"] + 0.003, ssim
    assert ssim["msaa"] > ssim["none"], ssim
    changed = np.any(images["fxaa"] != images["none"], axis=2)
    assert 0.002 < changed.mean() < 0.3, "FXAA should touch the edges only"
    # a pixel whose 3x3 neighbourhood is flat in the unfiltered frame stays as drawn
    luma = images["none"].astype(np.float64) @ [0.299, 0.587, 0.114]
    pad = np.pad(luma, 1, mode="edge")
    win = np.stack(
        [
            pad[1 + dy : 1 + dy + luma.shape[0], 1 + dx : 1 + dx + luma.shape[1]]
            for dy in (-1, 0, 1)
            for dx in (-1, 0, 1)
        ]
    )
    flat = (win.max(axis=0) - win.min(axis=0)) < 1.0
    assert not np.any(changed & flat)


def test_a_crowd_renders_the_same_after_another_crowd():
    """Meshes simplified and dressed for one crowd are never reused for another crowd's
    differently shaped bodies: the same bodies group the same, whatever came before."""
    from crowdstudy.body import load_body, sample_bodies
    from crowdstudy.render import bodies as render_bodies
    from crowdstudy.render import garments

    first = [load_body(r) for r in sample_bodies(2, 11)]
    second = [load_body(r) for r in sample_bodies(2, 12)]

    def faces(bodies):
        return [g.faces.tobytes() for g in render_bodies.group_bodies(bodies, max_faces=1500)]

    render_bodies._DECIMATIONS.clear()
    fresh = faces(second)
    render_bodies._DECIMATIONS.clear()
    faces(first)
    assert faces(second) == fresh

    points_a, points_b = first[0].rest_vertices, second[0].rest_vertices
    mask = points_a[:, 2] < 0.08  # the feet
    garments._FUSE.clear()
    alone = garments._fuse(points_b, mask, 0.03, 2)
    garments._FUSE.clear()
    garments._fuse(points_a, mask, 0.03, 2)
    assert np.array_equal(garments._fuse(points_b, mask, 0.03, 2), alone)


def test_fxaa_filters_exactly_the_pixels_it_marks(design):
    """The FXAA pass skips the blocks without an edge (the mark in the depth buffer): its
    frame equals the filter run on every pixel, and the filter changed some pixels."""
    import moderngl

    anim = crowd_animation(grid_positions(9, margin=0.45), n_frames=1)
    with mannequin_renderer(anim, design, shadows=False, width=384, height=216, msaa=0, post_aa="fxaa") as r:
        r.set_view("V3")
        two_pass = r.render(0)
        scene, _mark, blend = r.targets._fxaa
        r.targets.fbo_out.use()
        r.ctx.disable(moderngl.DEPTH_TEST)
        scene.use(7)
        blend.render(moderngl.TRIANGLES, vertices=3)  # the filter on every pixel
        r.ctx.enable(moderngl.DEPTH_TEST)
        every = np.frombuffer(r.targets.read(), np.uint8).reshape(r.height, r.width, 3)[::-1]
        unfiltered = np.frombuffer(scene.read(), np.uint8).reshape(r.height, r.width, 4)[::-1, :, :3]
    assert np.array_equal(two_pass, every)
    assert np.any(two_pass != unfiltered)

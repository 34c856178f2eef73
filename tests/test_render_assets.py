"""The renderer's CPU-side assets (``crowdstudy.render.assets``), built without OpenGL: the
options, the colours and looks, the per-frame bones, the levels of detail, the light's
reach on the ground and the environment split by how it is drawn."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from render_fixtures import crowd_animation, grid_positions, mannequin_loader  # noqa: E402

from crowdstudy.design import load_design  # noqa: E402
from crowdstudy.errors import InvalidInputError  # noqa: E402
from crowdstudy.render.assets import (
    CharacterMeshes,
    CrowdAssets,
    EnvironmentParts,
    FrameBones,  # noqa: E402
    Lighting,
    RenderOptions,
    shadow_receivers,
)

PERIOD = 4.0


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture
def no_gl(monkeypatch):
    """Every ``import moderngl`` fails: what runs under it needs no OpenGL."""
    monkeypatch.setitem(sys.modules, "moderngl", None)


def _corridor(n_frames: int = 3):
    anim = crowd_animation(
        grid_positions(6, extent=(4.0, 3.0), margin=0.45),
        n_frames=n_frames,
        scenario="corridor",
        period=PERIOD,
        velocity=(1.5, 0.0),
    )
    return anim.replace(root_translation=anim.root_translation + [3.0, 0.0, 0.0])  # some past the seam


def _area(tris: np.ndarray) -> float:
    t = tris[:, :2].reshape(-1, 3, 2).astype(np.float64)
    u, v = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    return float(0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum())


def test_options_resolve_auto_faces_and_name_a_bad_argument():
    opts = RenderOptions.validated()
    assert (opts.width, opts.height, opts.msaa, opts.shadow_size, opts.max_faces) == (1920, 1080, 4, 2048, 3000)
    assert RenderOptions.validated(width=640, height=360).max_faces == 1000
    assert RenderOptions.validated(width=64, height=36).max_faces == 600
    assert RenderOptions.validated(max_faces=None).max_faces is None
    for kw, name in (
        ({"width": 8}, "width"),
        ({"height": 9000}, "height"),
        ({"msaa": -1}, "msaa"),
        ({"msaa": 2.0}, "msaa"),
        ({"max_faces": 50}, "max_faces"),
        ({"max_faces": "all"}, "max_faces"),
        ({"shadow_size": 32}, "shadow_size"),
    ):
        with pytest.raises(InvalidInputError, match=name):
            RenderOptions.validated(**kw)


def test_crowd_assets_wrap_the_corridor_and_repeat_their_colours(design, no_gl):
    anim = _corridor()
    assets = CrowdAssets.build(anim, design, body_loader=mannequin_loader)
    assert assets.period == PERIOD and len(assets.bodies) == len(assets.looks) == 6
    assert assets.colors.shape == (6, 6, 3) and assets.colors.dtype == np.float32
    for f in range(anim.n_frames):
        x = assets.wrapped_roots(f)[:, 0]
        laps = (anim.root_translation[f, :, 0] - x) / PERIOD
        assert np.all((x >= -PERIOD / 2) & (x < PERIOD / 2))
        np.testing.assert_allclose(laps, np.round(laps), atol=1e-12)
        assert np.any(np.round(laps) != 0), "the test crowd should cross the seam"
    again = CrowdAssets.build(anim, design, body_loader=mannequin_loader)
    assert np.array_equal(again.colors, assets.colors) and again.looks == assets.looks
    with pytest.raises(InvalidInputError, match="color_positions"):
        CrowdAssets.build(anim, design, body_loader=mannequin_loader, color_positions=np.zeros((2, 2)))


def test_frame_bones_are_the_bodies_matrices_wrapped(design, no_gl):
    anim = _corridor(n_frames=40)
    assets = CrowdAssets.build(anim, design, body_loader=mannequin_loader)
    bones = FrameBones(anim, assets.bodies)
    for f in (0, 33, 39):  # two chunks of 32 frames
        mats = bones(f)
        assert mats.shape == (6, 24, 3, 4) and mats.dtype == np.float32
        for i in (0, 5):
            root = assets.wrapped_roots(f)[i]
            own = assets.bodies[i].skinning_matrices(anim.joint_rotations[f, i][None], root[None])[0]
            np.testing.assert_allclose(mats[i], own[:, :3, :], atol=1e-5)
    with pytest.raises(InvalidInputError, match="frame"):
        bones(40)


def test_levels_of_detail_halve_the_faces_and_keep_undressed_bodies(design, no_gl):
    anim = crowd_animation(grid_positions(3, margin=0.45), n_frames=1)
    assets = CrowdAssets.build(anim, design, body_loader=mannequin_loader)
    meshes = CharacterMeshes.build(assets.bodies, assets.looks, [None] * 3, height=1080, max_faces=2400)
    assert all(
        d is b for d, b in zip(meshes.drawn_bodies, assets.bodies, strict=True)
    )  # region-coloured: nothing to dress
    faces = [lod.groups[0].faces.shape[0] for lod in meshes.lods]
    assert len(faces) == 3 and faces[0] > faces[1] > faces[2]
    assert [(lod.max_pixels, lod.min_pixels) for lod in meshes.lods] == [(np.inf, 600.0), (600.0, 300.0), (300.0, 0.0)]
    assert meshes.groups is meshes.lods[0].groups and meshes.max_faces == 2400
    assert sorted(int(m) for g in meshes.groups for m in g.members) == [0, 1, 2]


def test_the_shadowed_ground_holds_every_shadow_and_splits_the_floor(design, no_gl):
    anim = _corridor()
    assets = CrowdAssets.build(anim, design, body_loader=mannequin_loader)
    light = Lighting.for_scene(assets.env, assets.period)
    assert np.linalg.norm(light.direction) == pytest.approx(1.0)
    fx0, fy0, fx1, fy1 = light.shadow_footprint()
    x0, y0, x1, y1 = shadow_receivers(anim, light)
    assert fx0 <= x0 < x1 <= fx1 and fy0 <= y0 < y1 <= fy1
    for f in range(anim.n_frames):  # a head's shadow, every periodic copy drawn
        for k in (-2, 0, 2):
            head = assets.wrapped_roots(f) + [k * PERIOD, 0.0, 0.9]
            shadow = head[:, :2] - light.direction[:2] * (head[:, 2:] / light.direction[2])
            assert np.all((shadow[:, 0] > x0) & (shadow[:, 0] < x1) & (shadow[:, 1] > y0) & (shadow[:, 1] < y1))
    lit = EnvironmentParts.build(anim, assets.env, light, shadows=True)
    assert set(lit.triangles) == {"walls", "cutaway", "floor_shadowed", "floor_plain"}
    inner, outer = lit.triangles["floor_shadowed"], lit.triangles["floor_plain"]
    assert _area(inner) + _area(outer) == pytest.approx(_area(assets.env.opaque), rel=1e-6)
    assert inner[:, 0].min() >= x0 - 1e-4 and inner[:, 0].max() <= x1 + 1e-4
    assert not lit.walls_static  # the corridor's walls are in the characters' shadows' reach
    plain = EnvironmentParts.build(anim, assets.env, light, shadows=False)
    assert "floor_shadowed" not in plain.triangles and plain.triangles["floor_plain"] is assets.env.opaque
    assert plain.walls_static

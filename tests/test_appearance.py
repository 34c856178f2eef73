"""Appearance of the MakeHuman characters: palettes, painted textures, dressed surfaces,
UV-preserving levels of detail, and a rendered check."""

from __future__ import annotations

import numpy as np
import pytest

from crowdstudy.body import load_body
from crowdstudy.body.skeleton import JOINT_INDEX as J
from crowdstudy.render.appearance import RACE_SKIN, assign_appearance, fill_from_nearest, nearest_painted, skin_tone
from crowdstudy.render.garments import CLOTH_LIFT, dress_body, vertex_codes
from crowdstudy.render.palette import MIN_SKIN_DELTA_E, SHIRTS, SHOES, SKIN_TONES, TROUSERS, assign_colors, srgb_to_lab

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

RECORDS = [
    {"model": "makehuman", "sex": "female", "height": 1.64, "age": 31, "race": [0.05, 0.05, 0.9]},
    {"model": "makehuman", "sex": "male", "height": 1.80, "age": 35, "race": [0.9, 0.05, 0.05]},
]


def test_no_clothing_colour_is_close_to_any_skin_tone():
    skins = np.array(list(SKIN_TONES) + [np.array(t) * f for t in RACE_SKIN for f in (0.88, 1.0, 1.12)])
    skin_lab = srgb_to_lab(np.clip(skins, 0, 255))
    for palette in (SHIRTS, TROUSERS, SHOES):
        d = np.linalg.norm(srgb_to_lab(np.array(palette))[:, None] - skin_lab[None], axis=-1)
        assert d.min() >= MIN_SKIN_DELTA_E, (palette[int(d.min(axis=1).argmin())], d.min())


def test_skin_tone_follows_the_ancestry_blend():
    rng = np.random.default_rng(0)

    def lum(rec):
        return float(skin_tone(rec, np.random.default_rng(0), 0) @ [0.2126, 0.7152, 0.0722])

    dark = lum({"model": "makehuman", "race": [1, 0, 0]})
    light = lum({"model": "makehuman", "race": [0, 0, 1]})
    mixed = lum({"model": "makehuman", "race": [1, 0, 1]})
    assert dark < mixed < light and light > 4 * dark
    assert skin_tone({"model": "open"}, rng, 3).shape == (3,)  # other bodies: the palette


def test_nearest_fill_gives_every_empty_texel_its_nearest_painted_colour():
    img = np.zeros((4, 6, 4), np.uint8)
    img[1, 1] = (200, 0, 0, 255)
    img[2, 4] = (0, 0, 200, 128)
    out = fill_from_nearest(img, nearest_painted(img[..., 3] > 0))
    assert tuple(out[0, 0]) == (200, 0, 0, 255) and tuple(out[3, 5]) == (0, 0, 200, 128)
    assert tuple(out[1, 1]) == (200, 0, 0, 255)
    assert set(map(tuple, out[..., :3].reshape(-1, 3))) == {(200, 0, 0), (0, 0, 200)}


@pytest.fixture(scope="module")
def renderer():
    from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
    from crowdstudy.render.renderer import CrowdRenderer
    from crowdstudy.scene import CrowdAnimation

    bodies = [load_body(r) for r in RECORDS]
    root = np.array([[[-0.5, 0.0, bodies[0].pelvis_height], [0.5, 0.0, bodies[1].pelvis_height]]] * 2)
    anim = CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=np.zeros((2, 2, 24, 3)),
        fps=30.0,
        bodies=tuple(RECORDS),
        clips=({"kind": "dance", "clips": ["x"]},) * 2,
        meta={"scenario": "concert", "method": "Baseline", "seed": 4},
    )
    with CrowdRenderer(anim, width=320, height=240, msaa=0) as r:
        yield r


def test_painted_textures_put_hair_shirt_trousers_shoes_and_eyes_where_they_belong(renderer):
    for body, look in zip(renderer.bodies, renderer.looks, strict=True):
        codes = np.array(vertex_codes(body, _codes(renderer, body)))
        v, j = body.rest_vertices, body.rest_joints
        top = np.argmax(v[:13380, 2])
        assert codes[top] == "hair"
        chest = np.argmin(np.linalg.norm(v - (j[J["spine3"]] + [0, 0.12, -0.05]), axis=1))
        assert codes[chest] == "shirt"
        thigh = np.argmin(np.linalg.norm(v - (0.5 * (j[J["left_hip"]] + j[J["left_knee"]]) + [0, 0.07, 0]), axis=1))
        assert codes[thigh] in ("trousers",) or look.legwear != "trousers"
        toe = np.argmax(np.where(v[:, 2] < v[:, 2].min() + 0.03, v[:, 1], -np.inf))
        assert codes[toe] == "shoes"
        assert set(codes[13380:]) == {"eye"}
        hand = np.argmin(np.linalg.norm(v - j[J["left_hand"]], axis=1))
        assert codes[hand] == "skin"


def _codes(renderer, body):
    return renderer.surface_codes[renderer.bodies.index(body)]


def test_dressing_lifts_the_clothes_and_keeps_the_eyes(renderer):
    body, look = renderer.bodies[0], renderer.looks[0]
    assert renderer.drawn_bodies[0] is body  # a 240 px tall image: dressing would be sub-pixel, skipped
    drawn = dress_body(body, _codes(renderer, body), look.hair_volume)
    codes = np.array(vertex_codes(drawn, _codes(renderer, body)))
    moved = np.linalg.norm(drawn.rest_vertices - body.rest_vertices, axis=1)
    np.testing.assert_array_equal(moved[13380:], 0.0)  # eyes untouched
    assert np.median(moved[codes == "shirt"]) > 0.5 * CLOTH_LIFT  # fabric stands off the skin
    assert np.median(moved[codes == "skin"]) < 0.2 * CLOTH_LIFT  # bare skin stays
    assert drawn.mesh().volume > body.mesh().volume
    assert drawn.rest_joints is body.rest_joints  # the skeleton is the body's


def test_rendered_characters_show_their_shirt_colours(renderer):
    from crowdstudy.render.camera import Camera

    cam = renderer.set_view(Camera(eye=(0.0, 3.0, 1.1), target=(0.0, 0.0, 1.0), fov=40.0))
    img = renderer.render(0).astype(np.float64)
    vp = cam.view_projection(320 / 240)
    for look, body, x in zip(renderer.looks, renderer.bodies, (-0.5, 0.5), strict=True):
        chest = np.array([x, 0.1, body.pelvis_height + body.rest_joints[J["spine3"], 2] - 0.05, 1.0])
        clip = vp @ chest
        col, row = (clip[:2] / clip[3] * 0.5 + 0.5) * (320, 240)
        patch = img[240 - int(row) - 3 : 240 - int(row) + 3, int(col) - 3 : int(col) + 3].reshape(-1, 3)
        seen = patch.mean(axis=0) / max(patch.mean(axis=0).max(), 1e-6)
        hue = np.sqrt(np.asarray(look.shirt) / max(max(look.shirt), 1e-6))  # display ~ sqrt of linear
        assert np.abs(seen - hue).max() < 0.3, (seen, hue)


def test_appearance_is_seeded_and_varied():
    recs = [
        {"model": "makehuman", "sex": s, "age": a, "race": [0.3, 0.3, 0.4]}
        for s, a in zip(["female", "male"] * 20, np.linspace(18, 70, 40), strict=True)
    ]
    pos = np.stack([np.arange(40) % 8, np.arange(40) // 8], axis=1) * 0.6
    looks = assign_appearance(recs, assign_colors(pos, 3)[1], 3)
    assert looks == assign_appearance(recs, assign_colors(pos, 3)[1], 3)
    assert looks != assign_appearance(recs, assign_colors(pos, 4)[1], 4)
    assert {lk.legwear for lk in looks} >= {"trousers", "shorts"}
    assert len({lk.shirt for lk in looks}) >= 8
    assert any(lk.sleeve > 1 for lk in looks) and any(lk.sleeve < 0.2 for lk in looks)


def test_periodic_copies_wear_other_characters_clothes():
    """A corridor copy k of character i is dressed as character (i + 17 k) mod N."""
    from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
    from crowdstudy.render.camera import Camera
    from crowdstudy.render.renderer import CrowdRenderer
    from crowdstudy.scene import CrowdAnimation

    recs = [dict(r, sex="male") for r in RECORDS]
    bodies = [load_body(r) for r in recs]
    # character 0 at x = -0.6, character 1 at x = +0.6 (outside the view); period 4 m
    root = np.array([[[-0.6, 0.0, bodies[0].pelvis_height], [0.6, 0.0, bodies[1].pelvis_height]]] * 2)
    anim = CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=np.zeros((2, 2, 24, 3)),
        fps=30.0,
        bodies=tuple(recs),
        clips=({"kind": "walk", "clips": ["x"]},) * 2,
        meta={"scenario": "corridor", "method": "Baseline", "seed": 4, "periodic": {"axis": 0, "length": 4.0}},
    )
    with CrowdRenderer(anim, width=320, height=240, msaa=0) as r:
        looks = r.looks
        seen = []
        for x in (-0.6, 3.4):  # character 0 and its copy k = 1 (dressed as character 1)
            cam = r.set_view(Camera(eye=(x, 2.5, 1.2), target=(x, 0.0, 1.1), fov=30.0))
            img = r.render(0).astype(np.float64)
            chest = np.array([x, 0.1, bodies[0].pelvis_height + bodies[0].rest_joints[J["spine3"], 2] - 0.05, 1.0])
            clip = cam.view_projection(320 / 240) @ chest
            col, row = (clip[:2] / clip[3] * 0.5 + 0.5) * (320, 240)
            patch = (
                img[240 - int(row) - 3 : 240 - int(row) + 3, int(col) - 3 : int(col) + 3].reshape(-1, 3).mean(axis=0)
            )
            seen.append(patch / max(patch.max(), 1e-6))
    for k, look in enumerate(looks):
        hue = np.sqrt(np.asarray(look.shirt) / max(max(look.shirt), 1e-6))
        assert np.abs(seen[k] - hue).max() < 0.3, (k, seen[k], hue)
    assert looks[0].shirt != looks[1].shirt


def test_the_texture_array_keeps_within_what_the_driver_holds():
    """A study crowd keeps 1024^2 texels per character at 1080p; a stadium crowd gets smaller
    layers, so the array stays under the budget (llvmpipe refuses 2 GiB: every character
    was drawn black at 1,000 characters)."""
    from crowdstudy.render.appearance import TEXTURE_ARRAY_BUDGET, TEXTURE_SIZE, _array_bytes, texture_size

    assert texture_size(1080, 60) == TEXTURE_SIZE == 1024
    assert texture_size(1080, 1000) == 512 and texture_size(1080, 5000) == 128
    assert texture_size(480, 60) == 512 and texture_size(300) == 256
    for n in (1, 60, 299, 300, 400, 1000, 2000, 5000, 20000):
        size = texture_size(1080, n)
        assert _array_bytes(size, n) <= TEXTURE_ARRAY_BUDGET or size == 64
        assert size == 1024 or _array_bytes(2 * size, n) > TEXTURE_ARRAY_BUDGET  # no smaller than needed
    assert _array_bytes(1024, 500) >= 2**31 > TEXTURE_ARRAY_BUDGET


def test_a_texture_array_the_driver_refuses_is_an_error_not_black_characters():
    from types import SimpleNamespace

    from crowdstudy.errors import InvalidInputError
    from crowdstudy.render.appearance import paint_textures

    class RefusingContext:
        """A GL context whose driver is out of memory after the texture array's allocation."""

        def __init__(self):
            self.reads = 0
            self.released = False

        @property
        def error(self):
            self.reads += 1
            return "GL_NO_ERROR" if self.reads == 1 else "GL_OUT_OF_MEMORY"

        def texture_array(self, size, components):
            return SimpleNamespace(release=lambda: setattr(self, "released", True))

    ctx = RefusingContext()
    bodies = [SimpleNamespace(surface=object()) for _ in range(500)]
    with pytest.raises(InvalidInputError, match=r"could not hold 500 layers of 1024\^2 texels \(2\.6 GiB"):
        paint_textures(ctx, bodies, [None] * 500, program=None, size=1024)
    assert ctx.released

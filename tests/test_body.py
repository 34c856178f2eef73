"""Body models: the open model's geometry, shapes, skinning against hand-computed cases,
batched posing, name maps and bad input."""

import re

import numpy as np
import pytest

import crowdstudy.body as cb
from crowdstudy.body.model import Body, pose_bodies
from crowdstudy.body.rotations import axis_angle_to_matrix
from crowdstudy.body.shapes import HEIGHT_STATS
from crowdstudy.body.skeleton import BVH_NAME_MAPS, DEFAULT_REST_JOINTS, JOINT_NAMES, bvh_name_map, joint_index
from crowdstudy.errors import InvalidInputError

MALE = {"model": "open", "sex": "male", "height": 1.80, "shape": [0.5, -0.3]}
FEMALE = {"model": "open", "sex": "female", "height": 1.58, "shape": [-1.0, 1.0]}


# ---------------------------------------------------------------- the open model


@pytest.mark.parametrize("record", [MALE, FEMALE])
def test_open_body_is_a_watertight_human_sized_mesh(record):
    body = cb.load_body(record)
    assert body.n_vertices >= 5000
    mesh = body.mesh()
    assert mesh.is_watertight and mesh.is_volume
    assert body.faces.dtype == np.int32 and body.rest_vertices.shape == (body.n_vertices, 3)
    assert body.height == pytest.approx(record["height"], abs=1e-9)
    # soles at pelvis_height below the pelvis; the pelvis is the origin of the rest frame
    assert body.rest_vertices[:, 2].min() == pytest.approx(-body.pelvis_height)
    assert 0.45 * record["height"] < body.pelvis_height < 0.62 * record["height"]
    np.testing.assert_allclose(body.rest_joints[0], 0.0, atol=1e-12)
    # about 1000 kg/m^3: a plausible adult mass
    assert 40.0 < 1000.0 * mesh.volume < 110.0


def test_open_body_faces_plus_y_with_left_at_minus_x():
    body = cb.load_body(MALE)
    j = body.rest_joints
    assert j[joint_index("left_hand"), 0] < -0.6 and j[joint_index("right_hand"), 0] > 0.6
    assert j[joint_index("left_foot"), 1] > j[joint_index("left_ankle"), 1]  # toes point to +y
    head = body.rest_vertices[body.rest_vertices[:, 2] > j[joint_index("head"), 2]]
    assert head[:, 1].max() > -head[:, 1].min()  # the face (nose) is on the +y side
    # T-pose: the arms are horizontal
    assert abs(j[joint_index("left_wrist"), 2] - j[joint_index("left_shoulder"), 2]) < 0.03


def test_skinning_weights_are_normalised_and_sparse():
    body = cb.load_body(FEMALE)
    w = body.weights
    assert w.shape == (body.n_vertices, 24) and w.dtype == np.float32
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-5)
    assert np.all(np.count_nonzero(w, axis=1) <= 4) and np.all(w >= 0)
    idx, val = body.top_weights()
    assert idx.shape == (body.n_vertices, 4) and idx.dtype == np.int32 and val.dtype == np.float32
    dense = np.zeros_like(w)
    np.put_along_axis(dense, idx, val, axis=1)
    np.testing.assert_allclose(dense, w, atol=1e-6)
    # every bone moves some vertices
    assert set(np.argmax(w, axis=1).tolist()) == set(range(24))


def test_template_key_shares_topology_and_shapes_change_geometry():
    a = cb.load_body({"model": "open", "sex": "male", "height": 1.7, "shape": [0, 0]})
    b = cb.load_body({"model": "open", "sex": "male", "height": 1.7, "shape": [2, 0]})
    c = cb.load_body(FEMALE)
    assert a.template_key == b.template_key != c.template_key
    assert a.faces is b.faces or np.array_equal(a.faces, b.faces)
    assert b.mesh().volume > 1.15 * a.mesh().volume  # build widens the body
    wide = cb.load_body({"model": "open", "sex": "male", "height": 1.7, "shape": [0, 2]})
    shoulder = joint_index("left_shoulder")
    assert wide.rest_joints[shoulder, 0] < a.rest_joints[shoulder, 0] - 0.02  # broader shoulders
    assert cb.load_body(dict(MALE)) is cb.load_body(dict(MALE))  # cached


def test_sample_bodies_is_balanced_seeded_and_matches_height_statistics():
    recs = cb.sample_bodies(61, seed=5)
    assert sum(r["sex"] == "female" for r in recs) == 31
    assert recs == cb.sample_bodies(61, seed=5)
    assert recs != cb.sample_bodies(61, seed=6)
    big = cb.sample_bodies(4000, seed=np.random.default_rng(1))
    for sex, (mean, sd) in HEIGHT_STATS.items():
        h = np.array([r["height"] for r in big if r["sex"] == sex])
        assert abs(h.mean() - mean) < 0.005 and abs(h.std() - sd) < 0.005
    shape = np.array([r["shape"] for r in cb.sample_bodies(4000, seed=np.random.default_rng(1), model="open")])
    assert shape.shape == (4000, 2) and np.all(np.abs(shape) <= 2.0)
    assert 0.8 < shape.std(axis=0).min() < 1.05
    body = cb.load_body(recs[0])
    assert body.height == pytest.approx(recs[0]["height"])


# ---------------------------------------------------------------- skinning


def _two_bone_body() -> Body:
    """Vertices along the left arm, hand-checkable: v0 on the upper arm (all left_shoulder),
    v1 on the forearm (all left_elbow), v2 half-half at the elbow."""
    joints = np.array(DEFAULT_REST_JOINTS)
    sh, el = joint_index("left_shoulder"), joint_index("left_elbow")
    verts = np.array(
        [
            joints[sh] + (-0.10, 0.0, 0.03),
            joints[el] + (-0.10, 0.0, 0.0),
            joints[el] + (0.0, 0.0, 0.04),
            (0.0, 0.0, 0.0),
        ]
    )
    w = np.zeros((4, 24), dtype=np.float32)
    w[0, sh] = 1.0
    w[1, el] = 1.0
    w[2, sh] = w[2, el] = 0.5
    w[3, 0] = 1.0
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]], dtype=np.int32)
    return Body(
        record={},
        rest_joints=joints,
        rest_vertices=verts,
        faces=faces,
        weights=w,
        pelvis_height=1.0,
        template_key="test",
    )


def test_skinning_against_hand_computed_rotation():
    body = _two_bone_body()
    sh, el = joint_index("left_shoulder"), joint_index("left_elbow")
    j = body.rest_joints
    rot = np.zeros((24, 3))
    rot[el] = (0.0, 0.0, np.pi / 2)  # bend the elbow 90 degrees about +z
    root = np.array([1.0, 2.0, 0.9])
    verts, joints = body.pose(rot, root)
    # forearm vertex: (-0.1, 0, 0) from the elbow turns to (0, -0.1, 0)
    np.testing.assert_allclose(verts[1], root + j[el] + (0.0, -0.10, 0.0), atol=1e-12)
    np.testing.assert_allclose(verts[0], root + j[sh] + (-0.10, 0.0, 0.03), atol=1e-12)
    # half-half: the offset (0, 0, 0.04) is along the rotation axis, so both agree
    np.testing.assert_allclose(verts[2], root + j[el] + (0.0, 0.0, 0.04), atol=1e-12)
    a, b, c = j[joint_index("left_wrist")] - j[el]  # +90 degrees about z: (a, b, c) -> (-b, a, c)
    np.testing.assert_allclose(joints[joint_index("left_wrist")], root + j[el] + (-b, a, c), atol=1e-12)
    # a 90 degree shoulder rotation about +y carries the whole arm, blends average
    rot = np.zeros((24, 3))
    rot[sh] = (0.0, np.pi / 2, 0.0)
    verts, _ = body.pose(rot, np.zeros(3))
    r = axis_angle_to_matrix(np.array([0.0, np.pi / 2, 0.0]))
    np.testing.assert_allclose(verts[0], j[sh] + r @ np.array([-0.10, 0.0, 0.03]), atol=1e-12)
    expected_mid = 0.5 * (j[sh] + r @ (j[el] + (0, 0, 0.04) - j[sh])) + 0.5 * (
        j[sh] + r @ (j[el] - j[sh]) + r @ (0, 0, 0.04)
    )
    np.testing.assert_allclose(verts[2], expected_mid, atol=1e-12)


def test_skinning_matrices_reproduce_pose_and_rest():
    body = cb.load_body(MALE)
    rng = np.random.default_rng(0)
    rot = rng.normal(0, 0.4, (3, 24, 3))
    root = rng.normal(0, 1, (3, 3))
    verts, joints = body.pose(rot, root)
    assert verts.shape == (3, body.n_vertices, 3) and joints.shape == (3, 24, 3)
    m = body.skinning_matrices(rot, root)
    assert m.shape == (3, 24, 4, 4)
    hom = np.c_[body.rest_vertices, np.ones(body.n_vertices)]
    manual = np.einsum("vj,tjab,vb->tva", body.weights.astype(np.float64), m, hom)[..., :3]
    np.testing.assert_allclose(manual, verts, atol=1e-9)
    rest, rest_j = body.pose(np.zeros((24, 3)), np.array([0.0, 0.0, body.pelvis_height]))
    np.testing.assert_allclose(rest, body.rest_vertices + (0, 0, body.pelvis_height), atol=1e-12)
    assert rest[:, 2].min() == pytest.approx(0.0, abs=1e-12)


def test_pose_bodies_and_warp_skinner_match_body_pose():
    recs = cb.sample_bodies(4, seed=3)
    bodies = [cb.load_body(r) for r in recs]
    rng = np.random.default_rng(1)
    rot = rng.normal(0, 0.3, (4, 24, 3))
    root = rng.normal(0, 1, (4, 3))
    batched = pose_bodies(bodies, rot, root)
    from crowdstudy.body.skinning import CrowdSkinner

    skinner = CrowdSkinner(bodies, device="cpu")
    verts, joints = skinner.pose(rot, root)
    for i, body in enumerate(bodies):
        ref, ref_j = body.pose(rot[i], root[i])
        np.testing.assert_allclose(batched[i], ref, atol=2e-5)
        np.testing.assert_allclose(verts[skinner.offsets[i] : skinner.offsets[i + 1]], ref, atol=2e-5)
        np.testing.assert_allclose(joints[i], ref_j, atol=2e-5)
    # every body's faces index its own block of vertices (a MakeHuman body's eyeballs, its
    # last vertices, are drawn but not part of the closed surface)
    for i, body in enumerate(bodies):
        block = skinner.faces[np.isin(skinner.faces[:, 0], np.arange(skinner.offsets[i], skinner.offsets[i + 1]))]
        assert len(block) == len(body.faces) and block.min() >= skinner.offsets[i]
        assert block.max() < skinner.offsets[i + 1]


def _synthetic_body(rng, n_vertices, key, rest_joints=DEFAULT_REST_JOINTS):
    """A point cloud with 1 to 4 random joints per vertex and random weights (many joint
    sets, unlike the open model's ~60)."""
    nk = rng.integers(1, 5, n_vertices)
    weights = np.zeros((n_vertices, 24), np.float32)
    for v in range(n_vertices):
        weights[v, rng.choice(24, nk[v], replace=False)] = rng.dirichlet(np.ones(nk[v]))
    weights /= weights.sum(axis=1, keepdims=True)
    return Body(
        record={},
        rest_joints=np.array(rest_joints, dtype=np.float64),
        rest_vertices=rng.normal(0.0, 0.4, (n_vertices, 3)),
        faces=np.zeros((1, 3), np.int32),
        weights=weights,
        pelvis_height=1.0,
        template_key=key,
    )


@pytest.mark.parametrize(
    "options", [{"threads": 1}, {"threads": 2}, {"threads": 3, "schedule": "segments"}, {"schedule": "vertices"}]
)
def test_crowd_skinner_schedules_equal_body_pose_on_random_poses(options):
    from crowdstudy.body.skinning import CrowdSkinner

    rng = np.random.default_rng(7)
    open_bodies = [cb.load_body(r) for r in cb.sample_bodies(3, seed=11)]
    # two synthetic bodies share a template_key but not their weights: they must not share data
    synthetic = [
        _synthetic_body(rng, 700, "synthetic"),
        _synthetic_body(rng, 500, "synthetic"),
        _synthetic_body(rng, 300, "other", DEFAULT_REST_JOINTS * 1.1),
    ]
    bodies = [open_bodies[0], synthetic[0], open_bodies[1], synthetic[1], open_bodies[2], synthetic[2]]
    skinner = CrowdSkinner(bodies, device="cpu", **options)
    assert skinner.n_segments > 200  # the synthetic bodies have many joint sets
    for trial in range(3):
        rot = rng.normal(0.0, 0.8, (len(bodies), 24, 3))
        rot[:, 5] = 0.0  # the zero-angle branch of the kinematics
        root = rng.normal(0.0, 2.0, (len(bodies), 3))
        verts, joints = skinner.pose(rot, root, copy=True)
        assert verts.dtype == np.float32 and verts.shape == (skinner.n_vertices, 3)
        for i, body in enumerate(bodies):
            ref, ref_j = body.pose(rot[i], root[i])
            np.testing.assert_allclose(
                verts[skinner.offsets[i] : skinner.offsets[i + 1]], ref, atol=1e-5, err_msg=f"body {i}, trial {trial}"
            )
            np.testing.assert_allclose(joints[i], ref_j, atol=1e-5)


def test_crowd_skinner_buffers_and_copies():
    from crowdstudy.body.skinning import CrowdSkinner

    rng = np.random.default_rng(3)
    bodies = [_synthetic_body(rng, 200, "a"), _synthetic_body(rng, 100, "b")]
    skinner = CrowdSkinner(bodies, device="cpu", threads=2)
    rot, root = rng.normal(0, 0.5, (2, 24, 3)), rng.normal(0, 1, (2, 3))
    view, _ = skinner.pose(rot, root)
    kept, _ = skinner.pose(rot, root, copy=True)
    np.testing.assert_array_equal(view, kept)
    other, _ = skinner.pose(rot + 0.3, root, copy=True)
    assert not np.shares_memory(kept, other) and np.abs(kept - other).max() > 1e-3
    device_verts, device_joints = skinner.pose_device(rot, root)
    assert device_verts.shape == (300,) and device_joints.shape == (2, 24)
    np.testing.assert_array_equal(device_verts.numpy(), kept)
    with pytest.raises(InvalidInputError, match="joint_rotations"):
        skinner.pose(rot[:1], root)
    with pytest.raises(InvalidInputError, match="root_translation"):
        skinner.pose(rot, root[:, :2])
    with pytest.raises(InvalidInputError, match="schedule"):
        CrowdSkinner(bodies, device="cpu", schedule="tiles")
    with pytest.raises(InvalidInputError, match="threads"):
        CrowdSkinner(bodies, device="cpu", threads=0)
    with pytest.raises(InvalidInputError, match="bodies"):
        CrowdSkinner([], device="cpu")


# ---------------------------------------------------------------- BVH names


def test_bvh_name_maps_cover_the_skeleton(shared_dir):
    text = (shared_dir / "data" / "cmu_12_01_walk.bvh").read_text()
    names = re.findall(r"(?:ROOT|JOINT)\s+(\S+)", text)
    mapping = bvh_name_map(names)
    assert sorted(mapping.values()) == sorted(JOINT_NAMES)
    assert mapping["LeftUpLeg"] == "left_hip" and mapping["Spine1"] == "spine3"


def test_mixamo_names_with_any_namespace():
    names = [k.replace("mixamorig:", "mixamorig1:") for k in BVH_NAME_MAPS["mixamo"]] + ["mixamorig1:HeadTop_End"]
    mapping = bvh_name_map(names, "mixamo")
    assert mapping["mixamorig1:LeftForeArm"] == "left_elbow" and len(mapping) == 24
    assert bvh_name_map([n.split(":")[1] for n in names])["LeftHand"] == "left_wrist"


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "record, field",
    [
        ({"model": "nope", "sex": "male"}, "model"),
        ({"model": "open", "sex": "robot"}, "sex"),
        ({"model": "open", "sex": "male", "height": "tall"}, "height"),
        ({"model": "open", "sex": "male", "height": 3.5}, "height"),
        ({"model": "open", "sex": "male", "shape": [0, 0, 0]}, "shape"),
        ({"model": "open", "sex": "male", "shape": [float("nan")]}, "shape"),
        ({"model": "open", "sex": "male", "weight_kg": 80}, "weight_kg"),
        ({"model": "smpl", "path": "x.pkl", "gender": "f"}, "gender"),
        ({"model": "smpl", "path": "/nonexistent/SMPL.pkl"}, "path"),
    ],
)
def test_bad_records_name_the_field(record, field):
    with pytest.raises(InvalidInputError, match=field):
        cb.load_body(record)


def test_bad_arguments_are_named():
    body = cb.load_body(MALE)
    with pytest.raises(InvalidInputError, match="joint_rotations"):
        body.pose(np.zeros((23, 3)), np.zeros(3))
    with pytest.raises(InvalidInputError, match="root_translation"):
        body.pose(np.zeros((5, 24, 3)), np.zeros((4, 3)))
    with pytest.raises(InvalidInputError, match="unknown joint name 'elbow'"):
        joint_index("elbow")
    with pytest.raises(InvalidInputError, match="no counterpart"):
        bvh_name_map(["Hips", "Spine"])
    with pytest.raises(InvalidInputError, match="convention"):
        bvh_name_map(["Hips"], "biovision")
    with pytest.raises(InvalidInputError, match="n"):
        cb.sample_bodies(-1, seed=0)
    with pytest.raises(InvalidInputError, match="body record"):
        cb.load_body("male")
    with pytest.raises(InvalidInputError, match="Body.weights"):
        Body(
            record={},
            rest_joints=np.zeros((24, 3)),
            rest_vertices=np.zeros((5, 3)),
            faces=np.zeros((1, 3), np.int32),
            weights=np.zeros((4, 24), np.float32),
            pelvis_height=1.0,
            template_key="x",
        )


def test_open_model_generation_is_deterministic_and_a_bad_cache_is_regenerated(tmp_path, monkeypatch):
    from crowdstudy.body.open_model import OPEN_MODEL_VERSION, open_model

    cached = open_model("female")
    monkeypatch.setenv("CROWDSTUDY_CACHE", str(tmp_path))
    bad = tmp_path / "body-cache" / f"open_female_v{OPEN_MODEL_VERSION}.npz"
    bad.parent.mkdir(parents=True)
    bad.write_bytes(b"not an npz")
    fresh = open_model.__wrapped__("female")  # bypass the in-process cache
    for name in ("v_template", "shapedirs", "j_template", "joint_shapedirs", "faces", "weights"):
        np.testing.assert_array_equal(getattr(fresh, name), getattr(cached, name), err_msg=name)
    assert bad.stat().st_size > 100_000  # rewritten
    with pytest.raises(InvalidInputError, match="sex"):
        open_model("robot")


def test_axis_angle_to_matrix_is_rodrigues():
    """Entry by entry (the closed form of I + a K + b K^2) against scipy's rotation, on a
    crowd-sized batch with the zero rotation, tiny angles (the Taylor branch) and angles
    near pi."""
    from scipy.spatial.transform import Rotation

    from crowdstudy.body.rotations import axis_angle_to_matrix

    rng = np.random.default_rng(11)
    v = rng.normal(size=(400, 24, 3)) * rng.uniform(0, 3.1, size=(400, 24, 1))  # more than one block
    v[0, :6] = [[0, 0, 0], [1e-9, 0, 0], [0, 3e-7, -2e-7], [np.pi, 0, 0], [0, 0, -np.pi + 1e-9], [1, 2, 2]]
    got = axis_angle_to_matrix(v)
    assert got.shape == (400, 24, 3, 3)
    want = Rotation.from_rotvec(v.reshape(-1, 3)).as_matrix().reshape(got.shape)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    assert axis_angle_to_matrix(np.array([0.0, 0.0, np.pi / 2])) @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0])


def test_axis_angle_to_quaternion_is_scipys():
    from scipy.spatial.transform import Rotation

    from crowdstudy.body.rotations import axis_angle_to_quaternion

    rng = np.random.default_rng(12)
    v = rng.normal(size=(500, 24, 3)) * rng.uniform(0, 3.1, size=(500, 24, 1))
    v[0, :3] = [[0, 0, 0], [1e-10, 0, 0], [0, 3e-9, -2e-9]]
    got = axis_angle_to_quaternion(v)
    want = Rotation.from_rotvec(v.reshape(-1, 3)).as_quat().reshape(got.shape)
    want *= np.sign(want[..., 3:]) * np.sign(got[..., 3:])  # scipy picks w >= 0
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
    with pytest.raises(InvalidInputError, match="rotvec"):
        axis_angle_to_quaternion(np.zeros((4, 2)))


def _chain_fk(rest, rot, root, parents):
    """Forward kinematics one pose at a time, straight from the definition."""
    from scipy.spatial.transform import Rotation

    glob = np.empty(rot.shape[:-1] + (3, 3))
    pos = np.empty(rot.shape)
    for idx in np.ndindex(rot.shape[:-2]):
        r = rest[idx[-rest.ndim + 2 :]] if rest.ndim > 2 else rest
        local = Rotation.from_rotvec(rot[idx]).as_matrix()
        for j, p in enumerate(parents):
            if p < 0:
                glob[idx + (j,)], pos[idx + (j,)] = local[j], root[idx]
            else:
                glob[idx + (j,)] = glob[idx + (p,)] @ local[j]
                pos[idx + (j,)] = pos[idx + (p,)] + glob[idx + (p,)] @ (r[j] - r[p])
    return glob, pos


def test_forward_kinematics_in_blocks_is_the_chain_rule():
    """Blocks of poses (several blocks, the last one short; a few poses; one pose; rest
    joints and roots broadcast) against the pose-by-pose definition, and one pose alone
    gives the bits it gets inside a batch."""
    from crowdstudy.body.skeleton import PARENTS, forward_kinematics

    rng = np.random.default_rng(13)
    rest = DEFAULT_REST_JOINTS[None] + rng.normal(0, 0.02, size=(3, 24, 3))
    rot = rng.normal(0, 0.6, size=(1500, 3, 24, 3))  # 4,500 poses: two blocks
    rot[0, 0, 5] = [1e-9, 0, 0]
    root = rng.normal(size=(1500, 3, 3))
    glob, pos = forward_kinematics(rest[None], rot, root)
    assert glob.shape == (1500, 3, 24, 3, 3) and pos.shape == (1500, 3, 24, 3)
    pick = [0, 1, 700, 1100, 1499]
    want_g, want_p = _chain_fk(rest, rot[pick], root[pick], PARENTS)
    np.testing.assert_allclose(glob[pick], want_g, rtol=0, atol=1e-13)
    np.testing.assert_allclose(pos[pick], want_p, rtol=0, atol=1e-13)
    one_g, one_p = forward_kinematics(rest[2], rot[1100, 2], root[1100, 2])
    assert np.array_equal(one_g, glob[1100, 2]) and np.array_equal(one_p, pos[1100, 2])
    few_g, few_p = forward_kinematics(rest[1], rot[:5, 1], np.zeros(3))  # a few poses, the root broadcast
    np.testing.assert_allclose(few_p, _chain_fk(rest[1], rot[:5, 1], np.zeros((5, 3)), PARENTS)[1], rtol=0, atol=1e-13)
    mats = axis_angle_to_matrix(rot[:40])
    mat_g, mat_p = forward_kinematics(rest[None], mats, root[:40], rotations_are_matrices=True)
    assert np.array_equal(mat_g, glob[:40]) and np.array_equal(mat_p, pos[:40])
    with pytest.raises(InvalidInputError, match="joint_rotations"):
        forward_kinematics(rest, rot[0, :, :5], root[0])
    with pytest.raises(InvalidInputError, match="root_translation"):
        forward_kinematics(rest, rot[0], root[0, :, :2])

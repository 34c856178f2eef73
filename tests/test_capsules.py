"""Capsule proxies: fit quality (volume IoU against the mesh), geometry helpers, rest-pose
touching pairs and posed capsules."""

import numpy as np
import pytest
import trimesh

import crowdstudy.body as cb
from crowdstudy.body.capsules import (
    Capsules,
    cached_fit_capsules,
    capsule_mesh_iou,
    capsule_occupancy,
    fit_capsules,
    fit_digest,
    mesh_occupancy,
    posed_capsules,
    segment_distance,
)
from crowdstudy.body.skeleton import PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError


def test_capsule_union_fits_sampled_bodies_with_iou_over_075():
    records = cb.sample_bodies(6, seed=11) + [
        {"model": "open", "sex": "female", "height": 1.50, "shape": [-2.0, 2.0]},
        {"model": "open", "sex": "male", "height": 1.95, "shape": [2.0, -2.0]},
    ]
    ious = []
    for rec in records:
        body = cb.load_body(rec)
        report = capsule_mesh_iou(body, resolution=0.012)
        ious.append(report["iou"])
        # the voxel volume agrees with the mesh's exact volume
        assert report["mesh_volume"] == pytest.approx(body.mesh().volume, rel=0.03)
        caps = body.capsules
        assert caps.start.shape == caps.end.shape == (24, 3) and caps.radius.shape == (24,)
        assert np.all(caps.radius > 0.01) and np.all(caps.radius < 0.2)
    assert min(ious) >= 0.75, ious


def test_cached_fit_is_the_fit_read_back_and_follows_the_body(tmp_path, monkeypatch):
    import crowdstudy.body.capsules as capsules_module

    body = cb.load_body({"model": "open", "sex": "female", "height": 1.62, "shape": [0.5, -0.5]})
    direct = fit_capsules(body)
    first = cached_fit_capsules(body, cache=tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert [f.stem for f in files] == [fit_digest(body)] and not list(tmp_path.glob("*.tmp"))
    for name in ("start", "end", "radius"):
        np.testing.assert_array_equal(getattr(first, name), getattr(direct, name))

    def no_fit(*args, **kwargs):
        raise AssertionError("fitted again although the cache holds this body")

    monkeypatch.setattr(capsules_module, "fit_capsules", no_fit)
    again = cached_fit_capsules(body, cache=tmp_path)
    np.testing.assert_array_equal(again.radius, direct.radius)
    monkeypatch.undo()
    # a damaged file is fitted again and rewritten
    files[0].write_bytes(b"not an npz")
    np.testing.assert_array_equal(cached_fit_capsules(body, cache=tmp_path).start, direct.start)
    with np.load(files[0]) as data:
        np.testing.assert_array_equal(data["end"], direct.end)
    # another body (one vertex moved 1 mm) or another grid is another key
    from types import SimpleNamespace

    verts = np.array(body.rest_vertices, dtype=np.float64)
    verts[0, 2] += 1e-3
    moved = SimpleNamespace(rest_vertices=verts, rest_joints=body.rest_joints, faces=body.faces, weights=body.weights)
    same = SimpleNamespace(
        rest_vertices=body.rest_vertices, rest_joints=body.rest_joints, faces=body.faces, weights=body.weights
    )
    assert fit_digest(same) == fit_digest(body) != fit_digest(moved)
    assert fit_digest(body, 0.03) != fit_digest(body, 0.02)
    # the shared weights' digest is kept for read-only arrays only: a writeable copy with
    # the same values has the same key, and changing it in place changes the key
    weights = np.array(body.weights)
    copied = SimpleNamespace(
        rest_vertices=body.rest_vertices, rest_joints=body.rest_joints, faces=body.faces, weights=weights
    )
    assert fit_digest(copied) == fit_digest(body)
    weights[5] = weights[5][::-1]
    assert fit_digest(copied) != fit_digest(body)
    with pytest.raises(ValueError):
        body.weights[0, 0] = 1.0  # the shared template cannot change under its digest


def test_skins_of_the_grouped_vertices_are_the_per_bone_percentiles():
    """capsule_skin groups the vertices by their dominant bone once per weights array; each
    bone's skin is the percentile of its own vertices' distance outside its capsule."""
    from crowdstudy.body import load_body
    from crowdstudy.body.capsules import capsule_skin
    from crowdstudy.body.shapes import sample_bodies

    body = load_body(sample_bodies(1, 4)[0])
    caps = body.capsules
    dominant = np.asarray(body.weights).argmax(1)
    want = np.zeros(len(caps.radius))
    for j in range(len(want)):
        v = np.asarray(body.rest_vertices, np.float64)[dominant == j]
        if len(v):
            d = caps.end[j] - caps.start[j]
            t = np.clip((v - caps.start[j]) @ d / max(d @ d, 1e-12), 0.0, 1.0)  # a sphere: d = 0
            out = np.linalg.norm(v - (caps.start[j] + t[:, None] * d), axis=1) - caps.radius[j]
            want[j] = np.clip(np.percentile(out, 90.0), 0.0, 0.02)
    got = capsule_skin(body, 90.0, max_skin=0.02, hand_scale=1.0)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert (got > 0).sum() >= 12


def test_mesh_occupancy_matches_analytic_volumes():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    step = 0.01
    origin = np.array([-0.35, -0.35, -0.35]) + step * np.array([0.2071, 0.2887, 0.2236])
    occ = mesh_occupancy(sphere.vertices, sphere.faces, origin, step, (71, 71, 71))
    assert occ.sum() * step**3 == pytest.approx(sphere.volume, rel=0.01)
    # a capsule's occupancy matches its closed-form volume
    caps = Capsules(start=np.zeros((24, 3)), end=np.zeros((24, 3)), radius=np.full(24, 0.01))
    a, b, r = np.array([[-0.1, 0.0, 0.0]]), np.array([[0.1, 0.05, 0.0]]), np.array([0.08])
    occ = capsule_occupancy(a, b, r, origin, step, (71, 71, 71))
    single = Capsules(start=np.repeat(a, 24, 0), end=np.repeat(b, 24, 0), radius=np.repeat(r, 24))
    assert occ.sum() * step**3 == pytest.approx(single.volume[0], rel=0.02)
    assert caps.volume[0] == pytest.approx(4 / 3 * np.pi * 0.01**3)


def test_segment_distance_against_dense_sampling():
    rng = np.random.default_rng(0)
    p0, p1, q0, q1 = rng.normal(size=(4, 50, 3))
    p1[0] = p0[0]  # a degenerate segment
    q1[1] = q0[1] + 1e-14
    p1[2], q0[2], q1[2] = p0[2] + (1, 0, 0), p0[2] + (0, 1, 0), p0[2] + (2, 1, 0)  # parallel
    got = segment_distance(p0, p1, q0, q1)
    s = np.linspace(0, 1, 401)
    a = p0[:, None] + s[None, :, None] * (p1 - p0)[:, None]
    b = q0[:, None] + s[None, :, None] * (q1 - q0)[:, None]
    brute = np.linalg.norm(a[:, :, None] - b[:, None, :], axis=-1).min(axis=(1, 2))
    assert np.all(got <= brute + 1e-12)
    np.testing.assert_allclose(got, brute, atol=5e-3)


def test_rest_touching_pairs_include_adjacent_bones_only_nearby_ones():
    body = cb.load_body({"model": "open", "sex": "male", "height": 1.75, "shape": [0.0, 0.0]})
    pairs = body.rest_touching_pairs()
    assert pairs.dtype == np.int32 and pairs.shape[1] == 2 and np.all(pairs[:, 0] < pairs[:, 1])
    found = set(map(tuple, pairs.tolist()))
    for child, parent in enumerate(PARENTS):
        if parent >= 0:
            assert (min(child, parent), max(child, parent)) in found
    # hands, feet and the head never touch each other or the legs in the T-pose
    assert (15, 20) not in found and (10, 11) not in found and (7, 20) not in found
    assert len(found) < 40


def test_posed_capsules_follow_the_bones():
    body = cb.load_body({"model": "open", "sex": "female", "height": 1.6, "shape": [0.0, 0.0]})
    caps = body.capsules
    root = np.array([0.5, -0.2, body.pelvis_height])
    start, end = posed_capsules(body, np.zeros((24, 3)), root)
    np.testing.assert_allclose(start, caps.start + root, atol=1e-12)
    rng = np.random.default_rng(2)
    rot = rng.normal(0, 0.5, (2, 24, 3))
    start, end = posed_capsules(body, rot, np.zeros((2, 3)))
    glob, pos = forward_kinematics(body.rest_joints, rot, np.zeros((2, 3)))
    j = 18
    np.testing.assert_allclose(end[1, j], glob[1, j] @ (caps.end[j] - body.rest_joints[j]) + pos[1, j])
    # capsule lengths are preserved by the rigid motion
    np.testing.assert_allclose(np.linalg.norm(end - start, axis=-1), np.broadcast_to(caps.length, (2, 24)), atol=1e-12)


def test_bad_capsule_input():
    with pytest.raises(InvalidInputError, match="Capsules.radius"):
        Capsules(start=np.zeros((24, 3)), end=np.zeros((24, 3)), radius=np.zeros(23))
    body = cb.load_body({"model": "open", "sex": "male"})
    with pytest.raises(InvalidInputError, match="resolution"):
        capsule_mesh_iou(body, resolution=0.0)


class _SkinBody:
    """24 vertical capsules (radius 5 cm) with ten vertices each at known distances outside."""

    def __init__(self, excess_cm):
        self.capsules = Capsules(
            start=np.zeros((24, 3)), end=np.tile([0.0, 0.0, 0.1], (24, 1)), radius=np.full(24, 0.05)
        )
        angle = np.linspace(0.0, 2.0 * np.pi, 10, endpoint=False)
        verts, owner = [], []
        for j in range(24):
            r = 0.05 + np.asarray(excess_cm[j]) / 100.0
            verts.append(np.stack([r * np.cos(angle), r * np.sin(angle), np.full(10, 0.05)], axis=1))
            owner += [j] * 10
        self.rest_vertices = np.concatenate(verts)
        self.weights = np.eye(24)[owner]


def test_capsule_skin_is_the_percentile_capped_and_halved_on_the_hands():
    from crowdstudy.body.capsules import HAND_BONES, capsule_skin
    from crowdstudy.body.skeleton import JOINT_NAMES
    from crowdstudy.physics.config import PhysicsConfig

    rng = np.random.default_rng(3)
    excess = rng.uniform(0.0, 4.0, size=(24, 10))  # cm beyond each capsule
    excess[5] = -1.0  # bone 5's mesh lies inside its capsule
    body = _SkinBody(excess)
    expected = np.clip(np.percentile(excess / 100.0, 90, axis=1), 0.0, None)
    np.testing.assert_allclose(
        capsule_skin(body, 90.0, max_skin=0.04, hand_scale=1.0), np.minimum(expected, 0.04), atol=1e-12
    )
    skin = capsule_skin(body)  # defaults: the physics' 1.5 cm cap, hands halved
    capped = np.minimum(expected, 0.015)
    assert sorted(JOINT_NAMES[j] for j in HAND_BONES) == ["left_hand", "left_wrist", "right_hand", "right_wrist"]
    others = [j for j in range(24) if j not in HAND_BONES]
    np.testing.assert_allclose(skin[others], capped[others], atol=1e-12)
    np.testing.assert_allclose(skin[list(HAND_BONES)], 0.5 * capped[list(HAND_BONES)], atol=1e-12)
    assert skin[5] == 0.0 and skin.max() <= 0.015
    # the physics reads its skin through its configuration
    cfg = PhysicsConfig().with_values({"skin.percentile": 50.0, "skin.max": 0.03, "skin.hand_scale": 0.25})
    np.testing.assert_allclose(cfg.mesh_skin(body), capsule_skin(body, 50.0, max_skin=0.03, hand_scale=0.25))
    assert np.all(PhysicsConfig().with_values({"skin.percentile": 0.0}).mesh_skin(body) == 0.0)
    # left to the density profile, the skin is its dense end's (what a CrowdCorrector uses)
    dense = PhysicsConfig().profile.dense
    np.testing.assert_allclose(
        PhysicsConfig().mesh_skin(body),
        capsule_skin(body, 90.0, max_skin=dense.skin_max, hand_scale=dense.skin_hand_scale),
    )
    with pytest.raises(InvalidInputError, match="hand_scale"):
        capsule_skin(body, hand_scale=-1.0)
    with pytest.raises(InvalidInputError, match="skin.max"):
        PhysicsConfig().with_values({"skin.max": -0.01})

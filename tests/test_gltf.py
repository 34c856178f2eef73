"""glTF 2.0 both ways: export of a CrowdAnimation (structure, Khronos validator, animation
read back, three.js in Chromium against the toolkit's forward kinematics) and import of
skinned characters (round trip of an export, a Mixamo-style rig in another rest pose)."""

from __future__ import annotations

import functools
import http.server
import json
import math
import re
import shutil
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest
from gltf_fixtures import EXTRA_TARGET, write_mixamo_character

from crowdstudy.body import load_body
from crowdstudy.body.gltf_container import Z_UP_TO_Y_UP, read_gltf
from crowdstudy.body.gltf_model import (
    ARM_ELEVATION_LIMIT,
    map_skin_joints,
    node_local_matrix,
    node_parents,
    node_world_matrices,
    read_character,
    read_skin_binds,
    read_skinned_mesh,
)
from crowdstudy.body.rotations import axis_angle_to_matrix, quaternion_to_matrix
from crowdstudy.body.shapes import sample_bodies
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS, forward_kinematics
from crowdstudy.cli import main
from crowdstudy.errors import InvalidInputError
from crowdstudy.gltf.export import build_gltf, character_prefix, export_gltf
from crowdstudy.scene import CrowdAnimation

ROOT = Path(__file__).resolve().parent.parent
JS = ROOT / "tests" / "js"
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--headless",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]
N, T, FPS = 3, 12, 30.0


def small_animation(seed: int = 3) -> CrowdAnimation:
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None] / FPS
    roots = np.array([[0.0, 0.0, 0.95], [1.2, 0.4, 0.93], [-0.8, 1.1, 0.97]])[None] + t * [[0.5, 0.2, 0.0]]
    rot = rng.normal(0.0, 0.35, (T, N, 24, 3))
    rot[:, :, 0] += np.array([0.0, 0.0, 1.0])  # turned about z
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=roots,
        joint_rotations=rot,
        fps=FPS,
        bodies=tuple(sample_bodies(N, seed)),
        clips=tuple({} for _ in range(N)),
        meta={"seed": seed, "scenario": "test"},
    )


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    anim = small_animation()
    path = export_gltf(anim, tmp_path_factory.mktemp("gltf") / "crowd.glb")
    return anim, path


def _node_by_name(doc: dict) -> dict[str, int]:
    return {n.get("name"): i for i, n in enumerate(doc["nodes"])}


def _sample(gltf, channel_path: str, node: int) -> np.ndarray:
    anim = gltf.doc["animations"][0]
    for ch in anim["channels"]:
        if ch["target"]["node"] == node and ch["target"]["path"] == channel_path:
            return gltf.accessor(anim["samplers"][ch["sampler"]]["output"]).astype(np.float64)
    raise AssertionError(f"no {channel_path} channel for node {node}")


def _world_at_frame(gltf, frame: int) -> np.ndarray:
    """World matrices of every node with the animation's values at a keyframe applied."""
    doc = gltf.doc
    nodes = [dict(n) for n in doc["nodes"]]
    anim = doc["animations"][0]
    for ch in anim["channels"]:
        out = gltf.accessor(anim["samplers"][ch["sampler"]]["output"])
        nodes[ch["target"]["node"]][ch["target"]["path"]] = [float(x) for x in out[frame]]
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    world = {}

    def get(i):
        if i not in world:
            local = node_local_matrix(nodes[i])
            world[i] = local if i not in parent else get(parent[i]) @ local
        return world[i]

    return np.stack([get(i) for i in range(len(nodes))])


# ---------------------------------------------------------------------- export


def test_export_structure(exported):
    anim, path = exported
    gltf = read_gltf(path)
    doc = gltf.doc
    assert len(doc["skins"]) == N and len(doc["meshes"]) == N and len(doc["animations"]) == 1
    assert all(len(s["joints"]) == 24 for s in doc["skins"])
    assert len(doc["animations"][0]["channels"]) == N * 25  # 24 rotations + 1 translation each
    times = gltf.accessor(doc["animations"][0]["samplers"][0]["input"])
    np.testing.assert_allclose(times, np.arange(T) / FPS, atol=1e-7)
    names = _node_by_name(doc)
    for i, rec in enumerate(anim.bodies):
        body = load_body(rec)
        prim = doc["meshes"][i]["primitives"][0]
        np.testing.assert_allclose(gltf.accessor(prim["attributes"]["POSITION"]), body.rest_vertices, atol=1e-6)
        assert "COLOR_0" in prim["attributes"]  # open bodies have no texture: the renderer's colours
        idx, val = body.top_weights(4)
        # unused slots (weight 0) point at joint 0
        np.testing.assert_array_equal(gltf.accessor(prim["attributes"]["JOINTS_0"]), np.where(val > 0, idx, 0))
        np.testing.assert_allclose(gltf.accessor(prim["attributes"]["WEIGHTS_0"]), val, atol=1e-7)
        ibm = gltf.accessor(doc["skins"][i]["inverseBindMatrices"])
        np.testing.assert_allclose(ibm[:, :3, 3], -body.rest_joints, atol=1e-6)
        assert doc["skins"][i]["joints"][0] == names[character_prefix(i, N) + "pelvis"]


def test_export_animation_reads_back_as_input(exported):
    anim, path = exported
    gltf = read_gltf(path)
    names = _node_by_name(gltf.doc)
    for i in range(N):
        pre = character_prefix(i, N)
        for j, jname in enumerate(JOINT_NAMES):
            q = _sample(gltf, "rotation", names[pre + jname])
            np.testing.assert_allclose(
                quaternion_to_matrix(q), axis_angle_to_matrix(anim.joint_rotations[:, i, j]), atol=2e-6
            )
            # consecutive keys on the same hemisphere (LINEAR interpolation takes the short way)
            assert np.all(np.sum(q[1:] * q[:-1], axis=1) >= 0)
        np.testing.assert_allclose(
            _sample(gltf, "translation", names[pre + "pelvis"]), anim.root_translation[:, i], atol=1e-6
        )


def test_export_world_is_y_up_and_matches_forward_kinematics(exported):
    """The joints' world positions at a keyframe (node hierarchy + animation, as any glTF
    viewer computes them) are the toolkit's FK positions turned by (x, y, z) -> (-x, z, y)."""
    anim, path = exported
    gltf = read_gltf(path)
    names = _node_by_name(gltf.doc)
    frame = 7
    world = _world_at_frame(gltf, frame)
    for i, rec in enumerate(anim.bodies):
        body = load_body(rec)
        _, pos = forward_kinematics(body.rest_joints, anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        got = np.stack([world[names[character_prefix(i, N) + j]][:3, 3] for j in JOINT_NAMES])
        np.testing.assert_allclose(got, pos @ Z_UP_TO_Y_UP.T, atol=1e-5)
        # head above pelvis along +Y: glTF's up
        assert got[JOINT_INDEX["head"], 1] > got[0, 1] - 0.2
    np.testing.assert_allclose(Z_UP_TO_Y_UP @ [0, 0, 1], [0, 1, 0])  # up -> +Y
    np.testing.assert_allclose(Z_UP_TO_Y_UP @ [0, 1, 0], [0, 0, 1])  # facing +y -> +Z
    assert np.isclose(np.linalg.det(Z_UP_TO_Y_UP), 1.0)


def test_export_is_deterministic(exported, tmp_path):
    anim, path = exported
    assert build_gltf(anim).to_glb() == path.read_bytes()


def _textured(body, seed: int):
    """The body with ``uv`` and ``texture`` (the interface i12-body adds to Body)."""
    rng = np.random.default_rng(seed)
    v = body.rest_vertices
    body.uv = np.stack(
        [(v[:, 0] - v[:, 0].min()) / np.ptp(v[:, 0]), (v[:, 2] - v[:, 2].min()) / np.ptp(v[:, 2])], axis=1
    ).astype(np.float32)
    body.texture = rng.integers(0, 256, (32, 16, 3), dtype=np.uint8)
    return body


@pytest.fixture(scope="module")
def textured(exported, tmp_path_factory):
    anim, _ = exported
    from crowdstudy.body.model import Body

    bodies = []
    for i, rec in enumerate(anim.bodies):  # fresh objects: load_body's are cached and shared
        b = load_body(rec)
        bodies.append(
            _textured(
                Body(
                    record=dict(rec),
                    rest_joints=b.rest_joints,
                    rest_vertices=b.rest_vertices,
                    faces=b.faces,
                    weights=b.weights,
                    pelvis_height=b.pelvis_height,
                    template_key=b.template_key,
                ),
                i,
            )
        )
    return bodies, export_gltf(anim, tmp_path_factory.mktemp("textured") / "textured.glb", bodies=bodies)


def test_export_textures_round_trip(textured):
    bodies, path = textured
    gltf = read_gltf(path)
    assert len(gltf.doc["images"]) == N and len(gltf.doc["textures"]) == N
    for i, body in enumerate(bodies):
        prim = gltf.doc["meshes"][i]["primitives"][0]
        assert "COLOR_0" not in prim["attributes"]
        uv = gltf.accessor(prim["attributes"]["TEXCOORD_0"])
        np.testing.assert_allclose(uv[:, 1], 1.0 - body.uv[:, 1], atol=1e-6)  # glTF: top-left origin
        ch = read_character(path, skin=i)
        np.testing.assert_array_equal(ch.texture, body.texture)
        np.testing.assert_allclose(ch.uv, body.uv, atol=1e-6)
    if shutil.which("node") and (JS / "node_modules" / "gltf-validator").is_dir():
        res = subprocess.run(["node", str(JS / "validate.mjs"), str(path)], capture_output=True, text=True, timeout=60)
        assert json.loads(res.stdout)["numErrors"] == 0, res.stdout


def test_export_rejects_bad_arguments(exported, tmp_path):
    anim, _ = exported
    with pytest.raises(InvalidInputError, match="path"):
        export_gltf(anim, tmp_path / "crowd.gltf")
    with pytest.raises(InvalidInputError, match="bodies"):
        build_gltf(anim, bodies=[load_body(anim.bodies[0])])


@pytest.mark.skipif(
    shutil.which("node") is None or not (JS / "node_modules" / "gltf-validator").is_dir(),
    reason="node or tests/js/node_modules missing (make setup)",
)
def test_export_passes_khronos_validator(exported, tmp_path):
    _, path = exported
    fixture = tmp_path / "mixamo.glb"
    write_mixamo_character(fixture, load_body({"model": "open", "sex": "female", "height": 1.62}))
    res = subprocess.run(
        ["node", str(JS / "validate.mjs"), str(path), str(fixture)], capture_output=True, text=True, timeout=120
    )
    reports = [json.loads(line) for line in res.stdout.splitlines()]
    assert len(reports) == 2, res.stderr
    for rep in reports:
        assert rep["numErrors"] == 0, rep["messages"]
    assert reports[0]["numWarnings"] == 0, reports[0]["messages"]
    # the validator does find errors: a file whose weights do not sum to one
    doc_path = tmp_path / "broken.glb"
    data = bytearray(path.read_bytes())
    gltf = read_gltf(path)
    acc = gltf.doc["accessors"][gltf.doc["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"]]
    view = gltf.doc["bufferViews"][acc["bufferView"]]
    json_len = int.from_bytes(data[12:16], "little")
    start = 12 + 8 + json_len + 8 + view["byteOffset"]
    data[start : start + 4] = np.float32(3.0).tobytes()
    doc_path.write_bytes(bytes(data))
    res = subprocess.run(["node", str(JS / "validate.mjs"), str(doc_path)], capture_output=True, text=True, timeout=60)
    assert json.loads(res.stdout)["numErrors"] > 0


# ---------------------------------------------------------------------- import


def test_round_trip_export_import(exported):
    anim, path = exported
    for i, rec in enumerate(anim.bodies):
        body = load_body(rec)
        imported = load_body({"model": "gltf", "path": str(path), "skin": i})
        np.testing.assert_allclose(imported.rest_vertices, body.rest_vertices, atol=1e-6)
        np.testing.assert_allclose(imported.rest_joints, body.rest_joints, atol=1e-6)
        idx, val = body.top_weights(4)
        full = np.zeros_like(body.weights)
        np.put_along_axis(full, idx.astype(np.int64), val, axis=1)
        np.testing.assert_allclose(imported.weights, full, atol=1e-6)
        np.testing.assert_array_equal(imported.faces, body.faces)
        assert imported.pelvis_height == pytest.approx(body.pelvis_height, abs=1e-6)
        # the imported body poses like the original (top-4 weights)
        rot = anim.joint_rotations[5, i]
        v_imp, j_imp = imported.pose(rot, anim.root_translation[5, i])
        _, j_orig = body.pose(rot, anim.root_translation[5, i])
        np.testing.assert_allclose(j_imp, j_orig, atol=1e-6)


@pytest.fixture(scope="module")
def mixamo(tmp_path_factory):
    body = load_body({"model": "open", "sex": "male", "height": 1.78, "shape": [0.5, -0.3]})
    path = tmp_path_factory.mktemp("mixamo") / "mixamo_character.glb"
    expected = write_mixamo_character(path, body)
    return body, path, expected


def test_import_mixamo_rig_in_another_rest_pose(mixamo):
    body, path, expected = mixamo
    ch = read_character(path)
    assert ch.convention == "mixamo" and ch.synthesized == []
    assert ch.unmapped == EXTRA_TARGET
    # centimetres, Y-up armature rotation and the 90 deg turn undone: joints off the arms
    # are where the toolkit's body has them, and so are the vertices they alone move
    arm = [JOINT_INDEX[f"{s}_{j}"] for s in ("left", "right") for j in ("elbow", "wrist", "hand")]
    still = [j for j in range(24) if j not in arm]
    np.testing.assert_allclose(ch.joints[still], body.rest_joints[still], atol=1e-6)
    arm_weight = body.weights[
        :, [JOINT_INDEX[f"{s}_{j}"] for s in ("left", "right") for j in ("shoulder", "elbow", "wrist", "hand")]
    ].sum(axis=1)
    np.testing.assert_allclose(ch.vertices[arm_weight == 0], body.rest_vertices[arm_weight == 0], atol=1e-5)
    assert ch.height == pytest.approx(body.height, abs=1e-6)
    # the A-pose is lifted to the rest convention: arms within the limit of horizontal, in
    # the coronal plane (the bones keep their forward offset)
    for s, sign in (("left", -1), ("right", 1)):
        for a, b in (("shoulder", "elbow"), ("elbow", "wrist")):
            d = ch.joints[JOINT_INDEX[f"{s}_{b}"]] - ch.joints[JOINT_INDEX[f"{s}_{a}"]]
            assert abs(math.atan2(d[2], abs(d[0]))) <= ARM_ELEVATION_LIMIT + 1e-6
            assert np.sign(d[0]) == sign
            d0 = body.rest_joints[JOINT_INDEX[f"{s}_{b}"]] - body.rest_joints[JOINT_INDEX[f"{s}_{a}"]]
            assert np.linalg.norm(d) == pytest.approx(np.linalg.norm(d0), abs=1e-6)
            assert d[1] == pytest.approx(d0[1], abs=1e-6)
    # exactly: the original T-pose with each upper arm turned about y to the limit
    rot = np.zeros((24, 3))
    for s, sign in (("left", -1), ("right", 1)):
        d0 = body.rest_joints[JOINT_INDEX[f"{s}_elbow"]] - body.rest_joints[JOINT_INDEX[f"{s}_shoulder"]]
        delta = -ARM_ELEVATION_LIMIT - math.atan2(d0[2], abs(d0[0]))
        rot[JOINT_INDEX[f"{s}_shoulder"], 1] = delta if sign < 0 else -delta
    want_v, want_j = body.pose(rot, np.zeros(3))
    np.testing.assert_allclose(ch.joints, want_j, atol=1e-6)
    err = np.linalg.norm(ch.vertices - want_v, axis=1)
    assert np.median(err) < 1e-5 and np.percentile(err, 99) < 0.01
    # facing +y: toes in front of the ankles, left side at -x
    assert ch.joints[JOINT_INDEX["left_foot"], 1] > ch.joints[JOINT_INDEX["left_ankle"], 1]
    assert ch.joints[JOINT_INDEX["left_hip"], 0] < 0 < ch.joints[JOINT_INDEX["right_hip"], 0]


def test_import_reweights_unmapped_joints_to_mapped_ancestors(mixamo):
    body, path, expected = mixamo
    ch = read_character(path)
    names = expected["names"]
    want = np.zeros((body.n_vertices, 24))
    for k, name in enumerate(names):
        ours = EXTRA_TARGET.get(name) or JOINT_NAMES[k]
        want[:, JOINT_INDEX[ours]] += expected["weights"][:, k]
    np.testing.assert_allclose(ch.weights, want, atol=1e-6)
    # the index finger's vertices now follow the wrist, the finger tips still the hand
    k_index = names.index("mixamorig:LeftHandIndex1")
    moved = expected["weights"][:, k_index] > 0.5
    assert moved.sum() > 10
    assert np.all(ch.weights[moved, JOINT_INDEX["left_wrist"]] > 0.5)
    np.testing.assert_allclose(ch.weights.sum(axis=1), 1.0, atol=1e-6)


def test_import_pieces_read_a_skin_its_joints_and_its_mesh(mixamo):
    body, path, expected = mixamo
    gltf = read_gltf(path)
    parent = node_parents(gltf.doc)
    joint_map = map_skin_joints(gltf.doc, 0, parent, path)
    assert joint_map.convention == "mixamo" and not joint_map.missing
    node = _node_by_name(gltf.doc)
    assert joint_map.weight_joint(node["mixamorig:LeftHandIndex1"]) == "left_wrist"
    assert joint_map.weight_joint(node["mixamorig:Hips"]) == "pelvis"
    binds = read_skin_binds(gltf, joint_map, node_world_matrices(gltf.doc, parent), path)
    assert sorted(binds) == [0] and binds[0].ibm.shape == (len(joint_map.nodes), 4, 4)
    mesh = read_skinned_mesh(gltf, binds, 0, path)
    assert mesh.vertices.shape == (body.n_vertices, 3) and mesh.weights.shape == (body.n_vertices, 24)
    np.testing.assert_allclose(mesh.weights, read_character(path).weights, atol=1e-6)
    with pytest.raises(InvalidInputError, match="skin: expected an index"):
        map_skin_joints(gltf.doc, 1, parent, path)


def test_import_texture_and_record(mixamo):
    body, path, expected = mixamo
    ch = read_character(path)
    np.testing.assert_array_equal(ch.texture, expected["texture"])
    np.testing.assert_allclose(ch.uv, expected["uv"], atol=1e-6)  # bottom-left origin again
    rec = {"model": "gltf", "path": str(path), "height": 1.6, "sex": "female"}
    imported = load_body(rec)
    assert imported.height == pytest.approx(1.6, abs=1e-9)
    assert imported.template_key == load_body({"model": "gltf", "path": str(path)}).template_key
    verts, joints = imported.pose(np.zeros((24, 3)), np.array([0.0, 0.0, imported.pelvis_height]))
    assert verts[:, 2].min() == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(
    "convention, omit, vrm, expect",
    [
        ("mixamo", (), False, "mixamo"),  # Ready Player Me: Mixamo names without the prefix (below)
        ("vrm", ("spine3", "left_foot", "right_foot"), False, "vrm"),  # upperChest and toes are optional in VRM
        ("vroid", (), False, "vroid"),
        ("rigify", ("left_hand", "right_hand"), False, "rigify"),
        ("generic", ("spine3",), True, "vrm-extension"),  # bone_NN names, VRM 1.0 humanoid table
        ("cmu", (), False, "cmu"),
    ],
)
def test_import_other_rigs(tmp_path, convention, omit, vrm, expect):
    body = load_body({"model": "open", "sex": "female", "height": 1.6})
    path = tmp_path / f"{convention}.glb"
    write_mixamo_character(path, body, convention=convention, omit=omit, vrm_extension=vrm, texture=False)
    if convention == "mixamo":  # strip the namespace: Ready Player Me's names (JSON padded with spaces)
        path.write_bytes(
            re.sub(rb'"mixamorig:(\w+)"', lambda m: b'"' + m.group(1) + b'"' + b" " * 10, path.read_bytes())
        )
    ch = read_character(path)
    assert ch.convention == expect and sorted(ch.synthesized) == sorted(omit)
    kept = [j for j in JOINT_NAMES if j not in omit]
    arm = {f"{s}_{j}" for s in ("left", "right") for j in ("elbow", "wrist", "hand")}
    still = [JOINT_INDEX[j] for j in kept if j not in arm]
    np.testing.assert_allclose(ch.joints[still], body.rest_joints[still], atol=1e-6)
    np.testing.assert_allclose(ch.weights.sum(axis=1), 1.0, atol=1e-6)
    for j in omit:
        assert np.all(ch.weights[:, JOINT_INDEX[j]] == 0)  # placed, but moves no vertex
    if "spine3" in omit:
        mid = 0.5 * (body.rest_joints[JOINT_INDEX["spine2"]] + body.rest_joints[JOINT_INDEX["neck"]])
        np.testing.assert_allclose(ch.joints[JOINT_INDEX["spine3"]], mid, atol=1e-6)
    if "left_foot" in omit:
        foot, ankle = ch.joints[JOINT_INDEX["left_foot"]], ch.joints[JOINT_INDEX["left_ankle"]]
        assert foot[1] > ankle[1] + 0.08 and foot[2] < ankle[2]
    if "left_hand" in omit:  # beyond the wrist, along the forearm
        hand, wrist = ch.joints[JOINT_INDEX["left_hand"]], ch.joints[JOINT_INDEX["left_wrist"]]
        assert hand[0] < wrist[0] - 0.05
    rec = load_body({"model": "gltf", "path": str(path)})
    verts, _ = rec.pose(np.zeros((24, 3)), np.zeros(3))
    assert verts.shape == body.rest_vertices.shape


def test_import_errors_name_the_problem(mixamo, tmp_path):
    body, path, _ = mixamo
    with pytest.raises(InvalidInputError, match="not found"):
        load_body({"model": "gltf", "path": str(tmp_path / "missing.glb")})
    with pytest.raises(InvalidInputError, match="skin"):
        load_body({"model": "gltf", "path": str(path), "skin": 3})
    with pytest.raises(InvalidInputError, match="unknown field"):
        load_body({"model": "gltf", "path": str(path), "betas": [0.0]})
    with pytest.raises(InvalidInputError, match="height"):
        load_body({"model": "gltf", "path": str(path), "height": 7})
    # a hip joint whose name is in no table: the skeleton's shape finds it, the names the rest
    raw = path.read_bytes().replace(b'"mixamorig:Hips"', b'"mixamorig:Ribs"')
    renamed = tmp_path / "ribs.glb"
    renamed.write_bytes(raw)
    ch = read_character(renamed)
    assert ch.joint_map["mixamorig:Ribs"] == "pelvis" and ch.convention == "topology+mixamo"
    assert ch.rig_map.joints["pelvis"].how == "topology" and ch.rig_map.joints["left_knee"].how == "name"
    (tmp_path / "junk.glb").write_bytes(b"glTF\x02\x00\x00\x00\x20\x00\x00\x00" + b"\x00" * 20)
    with pytest.raises(InvalidInputError, match="junk.glb"):
        read_character(tmp_path / "junk.glb")


def test_cli_export_and_import(exported, tmp_path, capsys):
    anim, _ = exported
    npz = anim.save(tmp_path / "anim.npz")
    out = tmp_path / "out" / "crowd.glb"
    assert main(["export-gltf", str(npz), str(out), "--stop", "4", "--quiet"]) == 0
    gltf = read_gltf(out)
    assert gltf.accessor(gltf.doc["animations"][0]["samplers"][0]["input"]).shape == (4,)
    rec_path = tmp_path / "body.json"
    assert main(["import-gltf", str(out), "--skin", "2", "--out", str(rec_path)]) == 0
    rec = json.loads(rec_path.read_text())
    assert rec["model"] == "gltf" and rec["skin"] == 2
    np.testing.assert_allclose(load_body(rec).rest_vertices, load_body(anim.bodies[2]).rest_vertices, atol=1e-6)
    assert "c02_left_wrist" in capsys.readouterr().out
    assert main(["export-gltf", str(npz), str(tmp_path / "x.obj")]) == 2


# ---------------------------------------------------------------------- three.js


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture(scope="module")
def browser_page(tmp_path_factory):
    if not Path(CHROMIUM).exists():
        pytest.skip("Debian chromium is not installed")
    if not (JS / "node_modules" / "three").is_dir():
        pytest.skip("tests/js/node_modules missing (make setup)")
    from playwright.sync_api import sync_playwright

    site = tmp_path_factory.mktemp("site")
    (site / "node_modules").symlink_to(JS / "node_modules")
    shutil.copy(JS / "gltf_page.html", site / "index.html")
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page()
        page.goto(f"http://127.0.0.1:{server.server_address[1]}/index.html")
        page.wait_for_function("window.crowdReady === true", timeout=30000)
        yield site, page
        browser.close()
    server.shutdown()


@pytest.mark.browser
@pytest.mark.slow
def test_threejs_loads_export_and_poses_it_like_the_toolkit(exported, browser_page):
    anim, path = exported
    site, page = browser_page
    shutil.copy(path, site / "crowd.glb")
    info = page.evaluate("crowd.load('crowd.glb')")
    assert info["skinnedMeshes"] == N and info["bones"] == N * 24 and info["animations"] == 1
    assert info["duration"] == pytest.approx((T - 1) / FPS, abs=1e-6)
    assert info["vertexColors"] == N
    frame = 9
    names = [character_prefix(i, N) + j for i in range(N) for j in JOINT_NAMES]
    verts = [[character_prefix(i, N) + "body", v] for i in range(N) for v in (0, 1234, 4321)]
    got = page.evaluate("([t, b, v]) => crowd.pose(t, b, v)", [frame / FPS, names, verts])
    bones = np.array(got["bones"]).reshape(N, 24, 3)
    vertices = np.array(got["vertices"]).reshape(N, 3, 3)
    for i, rec in enumerate(anim.bodies):
        body = load_body(rec)
        _, pos = forward_kinematics(body.rest_joints, anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        np.testing.assert_allclose(bones[i], pos @ Z_UP_TO_Y_UP.T, atol=1e-4)
        idx, val = body.top_weights(4)
        top = np.zeros_like(body.weights)
        np.put_along_axis(top, idx.astype(np.int64), val, axis=1)
        posed = type(body)(
            record=body.record,
            rest_joints=body.rest_joints,
            rest_vertices=body.rest_vertices,
            faces=body.faces,
            weights=top,
            pelvis_height=body.pelvis_height,
            template_key="top4",
        )
        v_world, _ = posed.pose(anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        np.testing.assert_allclose(vertices[i], v_world[[0, 1234, 4321]] @ Z_UP_TO_Y_UP.T, atol=1e-4)


@pytest.mark.browser
@pytest.mark.slow
def test_threejs_loads_textured_export(textured, browser_page):
    _, path = textured
    site, page = browser_page
    shutil.copy(path, site / "textured.glb")
    info = page.evaluate("crowd.load('textured.glb')")
    assert info["skinnedMeshes"] == N and info["textures"] == N and info["vertexColors"] == 0


# ---------------------------------------------------------------------- Blender (optional)

BLENDER = shutil.which("blender")
needs_blender = pytest.mark.skipif(BLENDER is None, reason="Blender not installed (optional: apt-get install blender)")


def _blender(script: str, *args) -> subprocess.CompletedProcess:
    res = subprocess.run(
        [
            BLENDER,
            "-b",
            "--factory-startup",
            "--python",
            str(ROOT / "tests" / "blender" / script),
            "--",
            *map(str, args),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    return res


@needs_blender
@pytest.mark.slow
def test_blender_imports_export_and_poses_it_like_the_toolkit(exported, tmp_path):
    """Blender's glTF importer: same bones and skinned vertices at a keyframe, in Blender's
    Z-up world where the toolkit's (x, y, z) read (-x, -y, z)."""
    anim, path = exported
    frame = 6
    exp = {"fps": anim.fps, "frame": frame, "bones": {}, "vertices": {}}
    want_vertices = {}
    for i, rec in enumerate(anim.bodies):
        body = load_body(rec)
        pre = character_prefix(i, N)
        _, pos = forward_kinematics(body.rest_joints, anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        exp["bones"].update({pre + j: pos[k].tolist() for k, j in enumerate(JOINT_NAMES)})
        idx, val = body.top_weights(4)
        top = np.zeros_like(body.weights)
        np.put_along_axis(top, idx.astype(np.int64), val, axis=1)
        v, _ = type(body)(
            record=body.record,
            rest_joints=body.rest_joints,
            rest_vertices=body.rest_vertices,
            faces=body.faces,
            weights=top,
            pelvis_height=body.pelvis_height,
            template_key="top4",
        ).pose(anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        exp["vertices"][pre + "body"] = {str(k): v[k].tolist() for k in (0, 3000, 6000)}
        want_vertices[pre + "body"] = v
    (tmp_path / "expected.json").write_text(json.dumps(exp))
    _blender("check_export.py", path, tmp_path / "expected.json", tmp_path / "out.json")
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["armatures"] == 1 and out["bones"] == N * 24 and out["actions"] == 1
    assert out["frame_ranges"] == [[0.0, float(T - 1)]]
    flip = np.diag([-1.0, -1.0, 1.0])
    assert set(out["bone_positions"]) == set(exp["bones"])
    for name, p in exp["bones"].items():
        np.testing.assert_allclose(out["bone_positions"][name], flip @ np.asarray(p), atol=1e-5)
    for mesh, verts in exp["vertices"].items():
        for k, p in verts.items():
            np.testing.assert_allclose(out["vertices"][mesh][k], flip @ np.asarray(p), atol=1e-5)


@needs_blender
@pytest.mark.slow
def test_import_character_written_by_blender(mixamo, tmp_path):
    """The Mixamo-style fixture through Blender's importer and exporter (Blender's node
    layout, bone axes, armature object) imports to the same body."""
    from scipy.spatial import cKDTree

    body, path, _ = mixamo
    out = tmp_path / "blender.glb"
    _blender("reexport.py", path, out)
    assert "Blender" in read_gltf(out).doc["asset"].get("generator", "")
    ours, theirs = read_character(path), read_character(out)
    assert theirs.convention == "mixamo" and theirs.unmapped == EXTRA_TARGET
    np.testing.assert_allclose(theirs.joints, ours.joints, atol=1e-5)
    dist, nearest = cKDTree(ours.vertices).query(theirs.vertices)
    assert len(theirs.vertices) == len(ours.vertices) and dist.max() < 1e-5
    np.testing.assert_allclose(theirs.weights, ours.weights[nearest], atol=1e-5)
    np.testing.assert_array_equal(theirs.texture, ours.texture)

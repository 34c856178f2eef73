"""Test characters written as glTF by crowdstudy's own writer (no third-party files).

:func:`write_mixamo_character` turns a toolkit body into a Mixamo-rigged character as a
Blender export of a Mixamo FBX looks: ``mixamorig:``-named joints with extra bones (index
and middle finger joints, a forearm twist bone, ``HeadTop_End``), an ``Armature`` node
carrying a -90 deg turn about X and a 0.01 scale (bind space in centimetres, Z up), joint
nodes with non-identity rest rotations, eight influences per vertex (JOINTS_0/1), the arms
lowered into an A-pose, the whole figure turned to face another way, and a small texture.
"""

from __future__ import annotations

import math

import numpy as np

from crowdstudy.body.gltf_container import GltfBuilder
from crowdstudy.body.joint_names import NAME_MAPS
from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_quaternion
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS, forward_kinematics
from crowdstudy.gltf.export import add_skinned_mesh

MIXAMO = {ours: "mixamorig:" + name for name, ours in NAME_MAPS["mixamo"].items()}
#: extra bones: name -> (parent name, our joint near which it sits, offset in m (T-pose, toolkit axes))
EXTRA = {
    "mixamorig:LeftHandIndex1": ("mixamorig:LeftHand", "left_hand", (0.0, 0.03, 0.0)),
    "mixamorig:LeftHandMiddle2": ("mixamorig:LeftHandMiddle1", "left_hand", (-0.04, 0.0, 0.0)),
    "mixamorig:LeftForeArmTwist": ("mixamorig:LeftForeArm", "left_elbow", (-0.12, 0.0, 0.0)),
    "mixamorig:HeadTop_End": ("mixamorig:Head", "head", (0.0, 0.0, 0.2)),
}
#: our joint that each extra bone's weights must end on after import
EXTRA_TARGET = {
    "mixamorig:LeftHandIndex1": "left_wrist",
    "mixamorig:LeftHandMiddle2": "left_hand",
    "mixamorig:LeftForeArmTwist": "left_elbow",
    "mixamorig:HeadTop_End": "head",
}
A_POSE = math.radians(40.0)
YAW = math.radians(90.0)


def _trs(m: np.ndarray) -> dict:
    return {
        "translation": [float(x) for x in m[:3, 3]],
        "rotation": [float(x) for x in matrix_to_quaternion(m[:3, :3])],
    }


def mixamo_weights(body) -> tuple[list[str], np.ndarray]:
    """Skin joint names (24 Mixamo joints, then the extras) and (V, K) weights: the body's
    weights with parts handed to the extra bones."""
    names = [MIXAMO[j] for j in JOINT_NAMES] + list(EXTRA)
    w = np.zeros((body.n_vertices, len(names)))
    w[:, :NUM_JOINTS] = body.weights
    v, rest = body.rest_vertices, body.rest_joints
    hand, elbow, wrist = (JOINT_INDEX[n] for n in ("left_hand", "left_elbow", "left_wrist"))
    k = {n: names.index(n) for n in EXTRA}
    front = (v[:, 1] > rest[hand, 1] + 0.01) & (w[:, hand] > 0)
    w[front, k["mixamorig:LeftHandIndex1"]] = w[front, hand]
    w[front, hand] = 0.0
    tip = (v[:, 0] < rest[hand, 0] - 0.03) & (w[:, hand] > 0)
    w[tip, k["mixamorig:LeftHandMiddle2"]] = w[tip, hand]
    w[tip, hand] = 0.0
    twist = (v[:, 0] < 0.5 * (rest[elbow, 0] + rest[wrist, 0])) & (w[:, elbow] > 0)
    w[twist, k["mixamorig:LeftForeArmTwist"]] = 0.5 * w[twist, elbow]
    w[twist, elbow] *= 0.5
    crown = (v[:, 2] > rest[JOINT_INDEX["head"], 2] + 0.1) & (w[:, JOINT_INDEX["head"]] > 0)
    w[crown, k["mixamorig:HeadTop_End"]] = w[crown, JOINT_INDEX["head"]]
    w[crown, JOINT_INDEX["head"]] = 0.0
    # eight largest influences, renormalised (what the file holds)
    order = np.argsort(-w, axis=1, kind="stable")[:, :8]
    top = np.take_along_axis(w, order, axis=1)
    out = np.zeros_like(w)
    np.put_along_axis(out, order, top / top.sum(axis=1, keepdims=True), axis=1)
    return names, out


def a_pose_rotations() -> np.ndarray:
    """(24, 3) axis-angle: shoulders lowered by A_POSE, the rest as in the T-pose."""
    rot = np.zeros((NUM_JOINTS, 3))
    rot[JOINT_INDEX["left_shoulder"]] = (0.0, -A_POSE, 0.0)
    rot[JOINT_INDEX["right_shoulder"]] = (0.0, A_POSE, 0.0)
    return rot


def _rename(names: list[str], weights: np.ndarray, convention: str, omit: tuple[str, ...]):
    """Other rigs: joint names of ``convention`` (a NAME_MAPS key, or "generic" for
    ``bone_NN`` names), joints in ``omit`` removed (their weights go to their parent)."""
    table = {ours: name for name, ours in NAME_MAPS[convention].items()} if convention != "generic" else {}
    w = weights.copy()
    keep = list(range(len(names)))
    for ours in omit:
        j = JOINT_INDEX[ours]
        w[:, JOINT_INDEX[JOINT_NAMES[PARENTS[j]]]] += w[:, j]
        keep.remove(j)
    new = []
    for k, name in enumerate(names):
        if k < NUM_JOINTS:
            new.append(table.get(JOINT_NAMES[k], f"bone_{k:02d}") if convention != "generic" else f"bone_{k:02d}")
        else:
            new.append(name.split(":", 1)[1] if convention != "generic" else f"bone_{k:02d}")
    return new, w, keep


def write_mixamo_character(
    path,
    body,
    *,
    texture: bool = True,
    convention: str = "mixamo",
    omit: tuple[str, ...] = (),
    vrm_extension: bool = False,
) -> dict:
    """Write ``body`` as a Mixamo-style skinned .glb; returns what a test compares against:
    ``{"names", "weights" (V, K), "uv" (V, 2) bottom-left origin, "texture" (H, W, 3)}``.

    ``convention`` names the 24 joints after another rig (``NAME_MAPS`` key, or "generic":
    ``bone_NN``, usable with ``vrm_extension`` which writes a VRM 1.0 humanoid table);
    ``omit`` drops joints (weights to the parent, children re-parented)."""
    names, weights = mixamo_weights(body)
    mix_names = list(names)
    names, weights, keep = (
        _rename(names, weights, convention, omit)
        if (convention != "mixamo" or omit)
        else (names, weights, list(range(len(names))))
    )
    rot = a_pose_rotations()
    local = axis_angle_to_matrix(rot)
    glob, pos = forward_kinematics(body.rest_joints, local, np.zeros(3), rotations_are_matrices=True)
    verts, _ = body.pose(rot, np.zeros(3))  # the toolkit's weights pose the A-pose mesh
    turn = axis_angle_to_matrix(np.array([0.0, 0.0, YAW]))
    cm = 100.0
    # bind-time joint frames (armature space: centimetres, Z up, turned by YAW); each joint's
    # frame is its A-pose rotation times a Blender-like bone roll (local +Y along the bone)
    roll = axis_angle_to_matrix(np.array([-math.pi / 2, 0.0, 0.0]))
    frames = {}
    for j, name in enumerate(JOINT_NAMES):
        m = np.eye(4)
        m[:3, :3] = turn @ glob[j] @ roll
        m[:3, 3] = cm * (turn @ pos[j])
        frames[MIXAMO[name]] = m
    for name, (_parent, near, offset) in EXTRA.items():
        j = JOINT_INDEX[near]
        m = np.eye(4)
        m[:3, :3] = turn @ glob[j] @ roll
        m[:3, 3] = cm * (turn @ (pos[j] + glob[j] @ np.asarray(offset)))
        frames[name] = m
    parents = {
        MIXAMO[n]: (MIXAMO[JOINT_NAMES[PARENTS[j]]] if PARENTS[j] >= 0 else None) for j, n in enumerate(JOINT_NAMES)
    }
    parents.update({n: p for n, (p, _, _) in EXTRA.items()})

    # re-key by the file's names, re-parent children of omitted joints
    rename = dict(zip(mix_names, names, strict=True))
    omitted = {mix_names[JOINT_INDEX[o]] for o in omit}

    old_parents = parents

    def kept_parent(name):
        par = old_parents[name]
        while par is not None and par in omitted:
            par = old_parents[par]
        return par

    frames = {rename[k]: v for k, v in frames.items()}
    parents = {
        rename[k]: (None if kept_parent(k) is None else rename[kept_parent(k)]) for k in mix_names if k not in omitted
    }
    weights = weights[:, keep]
    names = [names[k] for k in keep]
    b = GltfBuilder(generator="crowdstudy test fixture (Mixamo-style)")
    armature = b.add(
        "nodes",
        {
            "name": "Armature",
            "rotation": [-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)],
            "scale": [0.01, 0.01, 0.01],
            "children": [],
        },
    )
    index = {}
    for name in names:  # parents come first (24 joints in tree order, then the extras)
        par = parents[name]
        rel = frames[name] if par is None else np.linalg.inv(frames[par]) @ frames[name]
        index[name] = b.add("nodes", {"name": name, **_trs(rel)})
        if par is None:
            b.doc["nodes"][armature]["children"].append(index[name])
        else:
            b.doc["nodes"][index[par]].setdefault("children", []).append(index[name])
    ibm = np.stack([np.linalg.inv(frames[n]) for n in names])
    order = np.argsort(-weights, axis=1, kind="stable")[:, :8]
    vals = np.take_along_axis(weights, order, axis=1).astype(np.float32)
    vals /= vals.sum(axis=1, keepdims=True)
    bind_verts = cm * (verts @ turn.T)
    uv = tex = None
    if texture:
        v = body.rest_vertices
        uv = np.stack([(v[:, 0] - v[:, 0].min()) / np.ptp(v[:, 0]), (v[:, 2] - v[:, 2].min()) / np.ptp(v[:, 2])], 1)
        yy, xx = np.mgrid[0:16, 0:16]
        tex = np.stack([xx * 16, yy * 16, ((xx // 4 + yy // 4) % 2) * 255], axis=-1).astype(np.uint8)
    mesh_node = add_skinned_mesh(
        b,
        name="Body",
        vertices=bind_verts,
        faces=body.faces,
        joints=order[:, :4],
        weights=vals[:, :4],
        joint_nodes=[index[n] for n in names],
        inverse_bind=ibm,
        skeleton=index[names[0]],
        uv=None if uv is None else np.stack([uv[:, 0], 1.0 - uv[:, 1]], 1),
        texture=tex,
    )
    # the other four influences as JOINTS_1 / WEIGHTS_1
    prim = b.doc["meshes"][b.doc["nodes"][mesh_node]["mesh"]]["primitives"][0]
    j1 = np.where(vals[:, 4:] > 0, order[:, 4:], 0).astype(np.uint8)
    prim["attributes"]["JOINTS_1"] = b.accessor(j1, target=34962)
    prim["attributes"]["WEIGHTS_1"] = b.accessor(vals[:, 4:].copy(), target=34962)
    if vrm_extension:
        b.doc["extensionsUsed"] = ["VRMC_vrm"]
        bones = {
            vrm: {"node": index[rename[mix_names[JOINT_INDEX[ours]]]]}
            for vrm, ours in NAME_MAPS["vrm"].items()
            if ours not in omit
        }
        b.doc["extensions"] = {"VRMC_vrm": {"specVersion": "1.0", "humanoid": {"humanBones": bones}}}
    b.doc["scenes"] = [{"nodes": [armature, mesh_node]}]
    b.doc["scene"] = 0
    b.write(path)
    full = np.zeros_like(weights)
    np.put_along_axis(full, order, vals.astype(np.float64), axis=1)
    return {"names": names, "weights": full, "uv": uv, "texture": tex}

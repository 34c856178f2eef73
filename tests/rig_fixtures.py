"""Animated test characters in the layouts of real third-party rigs, written by crowdstudy's
own glTF writer from a toolkit body and motion (no third-party file is committed; the
real files' names and layouts are described in tests/data/SOURCES.md):

* ``blender``: three.js' RobotExpressive layout: Blender-style names (``Body``, ``Hips``,
  ``UpperArm.L``, ``LowerLeg.L``), the legs hanging from ``Body`` beside the spine, end
  bones (``LowerLeg.L_end``), an armature node scaled by 100 over centimetre-sized joint
  offsets, and every part a rigid mesh parented to its bone (no skin);
* ``numbered``: Khronos' CesiumMan layout: numbered joints (``Skeleton_torso_joint_1``,
  ``leg_joint_L_1``, ``Skeleton_arm_joint_L__4_``), no collars, upper chest or hands,
  one skinned mesh;
* ``unnamed``: the numbered rig with every node name removed.

Every joint's bind frame is turned by a random "bone roll", so the animation's local
rotations are not the toolkit's; :func:`write_rig_character` returns the toolkit motion
it encodes (the ground truth an import must give back).
"""

from __future__ import annotations

import math

import numpy as np

from crowdstudy.body.gltf_container import GltfBuilder
from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_quaternion, quat_align_signs
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS, forward_kinematics
from crowdstudy.gltf.export import add_skinned_mesh

_SIDE = {"left": "L", "right": "R"}
NAMINGS: dict[str, dict[str, str | None]] = {
    "blender": {
        "pelvis": "Body",
        "spine1": "Hips",
        "spine2": "Abdomen",
        "spine3": "Torso",
        "neck": "Neck",
        "head": "Head",
        **{
            f"{s}_{j}": f"{n}.{_SIDE[s]}"
            for s in ("left", "right")
            for j, n in (
                ("collar", "Shoulder"),
                ("shoulder", "UpperArm"),
                ("elbow", "LowerArm"),
                ("wrist", "Palm"),
                ("hand", "Middle1"),
                ("hip", "UpperLeg"),
                ("knee", "LowerLeg"),
                ("ankle", "Foot"),
                ("foot", "Toe"),
            )
        },
    },
    "numbered": {
        "pelvis": "Skeleton_torso_joint_1",
        "spine1": "Skeleton_torso_joint_2",
        "spine2": "torso_joint_3",
        "spine3": None,
        "neck": "Skeleton_neck_joint_1",
        "head": "Skeleton_neck_joint_2",
        "left_collar": None,
        "right_collar": None,
        "left_shoulder": "Skeleton_arm_joint_L__4_",
        "left_elbow": "Skeleton_arm_joint_L__3_",
        "left_wrist": "Skeleton_arm_joint_L__2_",
        "left_hand": None,
        "right_shoulder": "Skeleton_arm_joint_R",
        "right_elbow": "Skeleton_arm_joint_R__2_",
        "right_wrist": "Skeleton_arm_joint_R__3_",
        "right_hand": None,
        **{
            f"{s}_{j}": f"leg_joint_{_SIDE[s]}_{k}"
            for s in ("left", "right")
            for j, k in (("hip", 1), ("knee", 2), ("ankle", 3), ("foot", 5))
        },
    },
}
NAMINGS["unnamed"] = NAMINGS["numbered"]


def kept_joints(naming: str) -> list[str]:
    """Our joints the rig has (the others are folded into their parents)."""
    return [j for j in JOINT_NAMES if NAMINGS[naming][j] is not None]


def _trs(m: np.ndarray) -> dict:
    return {
        "translation": [float(x) for x in m[:3, 3]],
        "rotation": [float(x) for x in matrix_to_quaternion(m[:3, :3])],
    }


def write_rig_character(
    path,
    body,
    rotations: np.ndarray,
    root: np.ndarray,
    fps: float,
    *,
    naming: str = "numbered",
    seed: int = 0,
    centimetres: bool | None = None,
    rigid: bool | None = None,
) -> dict:
    """Write ``body`` moving by ``rotations`` (T, 24, 3) and ``root`` (T, 3) (toolkit frame)
    as a glTF character in the ``naming`` layout; returns ``{"names": {our joint: node
    name}, "global": (T, 24, 3, 3) the toolkit's global rotations, "positions": (T, 24, 3)}``.
    ``centimetres`` / ``rigid`` default to the layout's (the ``blender`` layout: both)."""
    centimetres = naming == "blender" if centimetres is None else centimetres
    rigid = naming == "blender" if rigid is None else rigid
    kept = kept_joints(naming)
    rng = np.random.default_rng(seed)
    roll = {j: axis_angle_to_matrix(rng.normal(0.0, 0.6, 3)) for j in kept}
    rest = np.asarray(body.rest_joints)
    rotations = np.array(rotations, dtype=np.float64)
    rotations[:, [JOINT_INDEX[j] for j in JOINT_NAMES if j not in kept]] = 0.0  # what the rig cannot show
    g, p = forward_kinematics(rest, rotations, root)
    unit = 100.0 if centimetres else 1.0
    parent_of = {}
    for j in kept:
        k = int(PARENTS[JOINT_INDEX[j]])
        while k >= 0 and JOINT_NAMES[k] not in kept:
            k = int(PARENTS[k])
        parent_of[j] = JOINT_NAMES[k] if k >= 0 else None
    b = GltfBuilder(generator=f"crowdstudy test fixture ({naming} layout)")
    arm = b.add(
        "nodes",
        {
            "name": "Armature",
            "rotation": [0.0, math.sqrt(0.5), math.sqrt(0.5), 0.0],
            "scale": [1 / unit] * 3,
            "children": [],
        },
    )
    # bind frames in armature space (toolkit axes, `unit` per metre): rest position, roll
    bind = {}
    for j in kept:
        m = np.eye(4)
        m[:3, :3] = roll[j]
        m[:3, 3] = unit * rest[JOINT_INDEX[j]]
        bind[j] = m
    nodes = {}
    for j in kept:
        par = parent_of[j]
        rel = bind[j] if par is None else np.linalg.inv(bind[par]) @ bind[j]
        node = {"name": NAMINGS[naming][j], **_trs(rel)}
        if naming == "unnamed":
            node.pop("name")
        nodes[j] = b.add("nodes", node)
        if par is None:
            b.doc["nodes"][arm]["children"].append(nodes[j])
        else:
            b.doc["nodes"][nodes[par]].setdefault("children", []).append(nodes[j])
    if naming == "blender":  # end bones at the tips of the shins and the head
        for j, tip in (("left_knee", "left_ankle"), ("right_knee", "right_ankle"), ("head", None)):
            off = (rest[JOINT_INDEX[tip]] - rest[JOINT_INDEX[j]]) if tip else np.array([0.0, 0.0, 0.2])
            end = b.add(
                "nodes",
                {"name": f"{NAMINGS[naming][j]}_end", "translation": [float(x) for x in unit * (roll[j].T @ off)]},
            )
            b.doc["nodes"][nodes[j]].setdefault("children", []).append(end)
    owner = _owners(body, kept)
    scene = [arm]
    if rigid:
        _rigid_parts(b, body, kept, owner, bind, nodes, unit)
    else:
        scene.append(_skinned_mesh(b, body, kept, bind, nodes, unit))
    _animation(b, g, p, kept, parent_of, roll, nodes, unit, fps)
    b.doc["scenes"] = [{"nodes": scene}]
    b.doc["scene"] = 0
    b.write(path)
    return {"names": {j: NAMINGS[naming][j] for j in kept}, "global": g, "positions": p, "rotations": rotations}


def _owners(body, kept: list[str]) -> np.ndarray:
    """(24,) the kept joint that takes each joint's weights (the joint or an ancestor)."""
    out = np.zeros(len(JOINT_NAMES), dtype=np.int64)
    for j in range(len(JOINT_NAMES)):
        k = j
        while JOINT_NAMES[k] not in kept:
            k = int(PARENTS[k])
        out[j] = kept.index(JOINT_NAMES[k])
    return out


def _skinned_mesh(b, body, kept, bind, nodes, unit) -> int:
    w = np.zeros((body.n_vertices, len(kept)))
    for j in range(len(JOINT_NAMES)):
        w[:, _owners(body, kept)[j]] += body.weights[:, j]
    idx = np.argsort(-w, axis=1, kind="stable")[:, :4]
    val = np.take_along_axis(w, idx, axis=1)
    val = (val / val.sum(axis=1, keepdims=True)).astype(np.float32)
    ibm = np.stack([np.linalg.inv(bind[j]) for j in kept])
    return add_skinned_mesh(
        b,
        name="Body",
        vertices=unit * np.asarray(body.rest_vertices),
        faces=body.faces,
        joints=idx,
        weights=val,
        joint_nodes=[nodes[j] for j in kept],
        inverse_bind=ibm,
        skeleton=nodes[kept[0]],
    )


def _rigid_parts(b, body, kept, owner, bind, nodes, unit) -> None:
    """Each kept joint's part (faces whose corners it dominates) as a mesh node under it."""
    dominant = owner[np.argmax(body.weights, axis=1)]
    faces = np.asarray(body.faces)
    face_owner = dominant[faces[:, 0]]
    for k, j in enumerate(kept):
        f = faces[face_owner == k]
        if not len(f):
            continue
        used, inv = np.unique(f.reshape(-1), return_inverse=True)
        local = np.linalg.inv(bind[j])
        v = unit * np.asarray(body.rest_vertices)[used]
        v = v @ local[:3, :3].T + local[:3, 3]
        prim = {
            "attributes": {"POSITION": b.accessor(v.astype(np.float32), target=34962, bounds=True)},
            "indices": b.accessor(inv.reshape(-1, 3).reshape(-1).astype(np.uint32), target=34963),
            "mode": 4,
        }
        mesh = b.add("meshes", {"name": f"{j}_part", "primitives": [prim]})
        part = b.add("nodes", {"name": f"{j}_part", "mesh": mesh})
        b.doc["nodes"][nodes[j]].setdefault("children", []).append(part)


def _animation(b, g, p, kept, parent_of, roll, nodes, unit, fps) -> None:
    """Local rotations (every kept joint) and the pelvis translation, keyed at every frame.
    A joint's animated frame is its toolkit global rotation times its roll."""
    t = np.arange(len(g), dtype=np.float32) / np.float32(fps)
    anim = {"name": "take", "channels": [], "samplers": []}
    time_acc = b.accessor(t, bounds=True)
    for j in kept:
        glob = g[:, JOINT_INDEX[j]] @ roll[j]
        par = parent_of[j]
        local = glob if par is None else np.swapaxes(g[:, JOINT_INDEX[par]] @ roll[par], -1, -2) @ glob
        q = quat_align_signs(matrix_to_quaternion(local), axis=0).astype(np.float32)
        anim["samplers"].append({"input": time_acc, "output": b.accessor(q), "interpolation": "LINEAR"})
        anim["channels"].append(
            {"sampler": len(anim["samplers"]) - 1, "target": {"node": nodes[j], "path": "rotation"}}
        )
    pelvis = (unit * p[:, 0]).astype(np.float32)
    anim["samplers"].append({"input": time_acc, "output": b.accessor(pelvis), "interpolation": "LINEAR"})
    anim["channels"].append(
        {"sampler": len(anim["samplers"]) - 1, "target": {"node": nodes[kept[0]], "path": "translation"}}
    )
    b.add("animations", anim)

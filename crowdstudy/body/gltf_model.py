"""Import a glTF character as a toolkit body (``{"model": "gltf", ...}`` records).

A body record::

    {"model": "gltf", "path": "character.glb", "skin": 0, "height": 1.74, "sex": "female"}

``skin`` (default 0) picks the skinned character that uses that skin (a crowdstudy export
holds one per character; skins over the same joints are one character, every mesh bound
to them merged, with the meshes parented rigidly under its joints); ``node`` instead picks a
rigid-parts character by its root node (meshes parented to animated joints, no skin:
:mod:`crowdstudy.body.gltf_rig`). ``map`` ({physics joint: joint name or index}) forces
joints of the mapping. ``height`` (optional) rescales the character uniformly to that
stature in metres; ``sex`` is a label.

Steps (:func:`read_character`):

1. The mesh and the joints are taken in the bind pose (the inverse bind matrices), carried
   to the file's world (glTF's Y-up metres) by ``J_r IBM_r`` of the skeleton's top joint r
   (armature scale and rotation included; an animated default pose does not deform it);
   rigid parts and rigid-parts characters in the default pose.
2. Joints are mapped to the 24 joints by :func:`crowdstudy.body.rig_map.map_rig`: a VRM
   file's humanoid table, else the naming tables (:mod:`crowdstudy.body.joint_names`), else
   the skeleton's topology and rest geometry. Missing optional joints are placed from their
   neighbours: ``spine3`` half-way between ``spine2`` and ``neck``; a collar 40 % of the way
   from ``spine3`` to the shoulder; ``*_hand`` 0.3 of the forearm's length beyond the wrist;
   ``*_foot`` 0.35 of the shin's length beyond the ankle, forward and down to the sole.
3. Weights: every rig joint gives its weights (and its rigid parts) to the physics joint of
   :meth:`~crowdstudy.body.rig_map.RigMap.weight_joint` (its nearest mapped ancestor:
   fingers to ``*_hand`` or ``*_wrist``, twist bones to their limb joint, an armature root
   above the hips to ``pelvis``; an IK target beside the legs to the nearest mapped joint).
   Skin weights that do not sum to one are normalised.
4. Frame: glTF -> toolkit axes (inverse of the export's ``(x, y, z) -> (-x, z, y)``), then
   the up direction (pelvis to head) snapped to the nearest axis is turned to +z and the
   hips' left-right line turned about z so the character faces +y, pelvis at the origin.
5. Rest pose (the toolkit's T-pose convention): upper arms and forearms more than
   ``ARM_ELEVATION_LIMIT`` above or below horizontal (an A-pose) are raised or lowered to
   that limit by a turn about the forward axis (in the coronal plane); thighs and shins
   more than ``LEG_TILT_LIMIT`` from vertical are brought to it. The mesh follows by linear
   blend skinning with the 24-joint weights. A file already in the toolkit's convention
   (a crowdstudy export) passes through unchanged.

:class:`GltfCharacter` keeps what an importer of the character's animation needs to turn
the file's joint motion into the 24 joints' and back (``rig``, ``rig_map``, ``frame``,
``pelvis``, ``rest_fix``: :mod:`crowdstudy.interchange.retarget`). The older name-only
pieces :func:`map_skin_joints`, :func:`read_skin_binds` and :func:`read_skinned_mesh` read
one skin on the node tree of :func:`node_parents` and :func:`node_world_matrices`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from pathlib import Path

import numpy as np

from crowdstudy.body.gltf_container import Z_UP_TO_Y_UP, GltfFile, read_gltf
from crowdstudy.body.gltf_rig import CharacterSpec, Rig, character_for_record, read_rig
from crowdstudy.body.joint_names import VRM_BONES, match_names
from crowdstudy.body.model import Body, check_fields
from crowdstudy.body.rig_map import OPTIONAL_JOINTS, RigMap, check_hierarchy, map_rig
from crowdstudy.body.rotations import axis_angle_to_matrix, quaternion_to_matrix, rotation_between
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError

__all__ = [
    "GltfCharacter",
    "read_character",
    "character_from_gltf",
    "body_from_character",
    "load_gltf_body",
    "open_scene",
    "node_local_matrix",
    "RECORD_FIELDS",
    "ARM_ELEVATION_LIMIT",
    "LEG_TILT_LIMIT",
    "map_character_rig",
    "SkinJointMap",
    "map_skin_joints",
    "SkinBind",
    "read_skin_binds",
    "SkinnedMesh",
    "read_skinned_mesh",
    "node_parents",
    "node_world_matrices",
]

#: Fields a ``{"model": "gltf"}`` body record may hold.
RECORD_FIELDS = ("model", "path", "skin", "node", "map", "height", "sex")
#: Largest angle (radians) of an upper arm or forearm above/below horizontal in the rest pose.
ARM_ELEVATION_LIMIT = math.radians(5.0)
#: Largest angle (radians) of a thigh or shin from vertical in the rest pose.
LEG_TILT_LIMIT = math.radians(10.0)


@dataclasses.dataclass
class GltfCharacter:
    """A character read from a glTF file, in the toolkit's rest frame (metres, Z up,
    facing +y, pelvis at the origin, T-pose).

    Attributes:
        vertices: (V, 3) float64; faces: (F, 3) int32; weights: (V, 24) float32 (rows sum to 1).
        joints: (24, 3) float64 rest joint positions.
        uv: (V, 2) float32, origin bottom-left, or None; texture: (H, W, 3) uint8 or None.
        joint_map: {file node name: our joint}; unmapped: {file node name: our joint that
            takes its weights}; synthesized: joints placed from their neighbours.
        convention: how the joints were found: a naming convention ("mixamo", "vrm", ...),
            "topology", or both ("topology+rigify").
        sha256: of the file's bytes.
        spec, rig, rig_map: the character in the file (:class:`~crowdstudy.body.gltf_rig.CharacterSpec`),
            its rig and mesh in the bind pose (:class:`~crowdstudy.body.gltf_rig.Rig`) and the
            mapping of its joints (:class:`~crowdstudy.body.rig_map.RigMap`).
        frame: (3, 3) rotation from the toolkit's axes of the file's world (glTF -> Z up) to the
            rest frame (facing +y); pelvis: (3,) the pelvis at bind time in those Z-up axes, m;
            rest_fix: (24, 3, 3) global rotation that brought each joint into the rest
            convention (step 5; identity for most joints); scale: the ``height`` rescale.
            A vertex at bind-time world position x (glTF axes) rests at
            ``scale * rest_fix_j (frame (C x - pelvis) - joint_j) + ...`` (LBS over joints j),
            with ``C = Z_UP_TO_Y_UP.T``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    joints: np.ndarray
    uv: np.ndarray | None
    texture: np.ndarray | None
    joint_map: dict
    unmapped: dict
    synthesized: list
    convention: str
    sha256: str
    spec: CharacterSpec | None = None
    rig: Rig | None = None
    rig_map: RigMap | None = None
    frame: np.ndarray | None = None
    pelvis: np.ndarray | None = None
    rest_fix: np.ndarray | None = None
    scale: float = 1.0

    @property
    def height(self) -> float:
        return float(self.vertices[:, 2].max() - self.vertices[:, 2].min())


def node_local_matrix(node: dict) -> np.ndarray:
    """(4, 4) float64 local transform of a glTF node (``matrix`` or T * R * S)."""
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    s = np.asarray(node.get("scale", (1.0, 1.0, 1.0)), dtype=np.float64)
    m[:3, :3] = quaternion_to_matrix(np.asarray(node.get("rotation", (0.0, 0.0, 0.0, 1.0)), dtype=np.float64)) * s
    m[:3, 3] = node.get("translation", (0.0, 0.0, 0.0))
    return m


def node_parents(doc: dict) -> np.ndarray:
    """(nodes,) int64 parent node index of every node of a glTF document (-1 for roots)."""
    nodes = doc.get("nodes", [])
    parent = np.full(len(nodes), -1, dtype=np.int64)
    for i, node in enumerate(nodes):
        for c in node.get("children", []):
            parent[c] = i
    return parent


def node_world_matrices(doc: dict, parent: np.ndarray) -> np.ndarray:
    """(nodes, 4, 4) float64 world transforms of every node in the document's default pose
    (no animation applied); ``parent`` from :func:`node_parents`."""
    nodes = doc.get("nodes", [])
    local = [node_local_matrix(n) for n in nodes]
    world: list[np.ndarray | None] = [None] * len(nodes)

    def get(i: int) -> np.ndarray:
        chain = []
        while i >= 0 and world[i] is None:
            chain.append(i)
            i = int(parent[i])
        known = world[i] if i >= 0 else None  # not None once the walk up stopped at i >= 0
        m = np.eye(4) if known is None else known
        for k in reversed(chain):
            m = m @ local[k]
            world[k] = m
        return m

    return np.stack([get(i) for i in range(len(nodes))]) if nodes else np.zeros((0, 4, 4))


def _vrm_map(doc: dict) -> dict[int, str]:
    ext = doc.get("extensions", {})
    out: dict[int, str] = {}
    if "VRMC_vrm" in ext:  # VRM 1.0
        for bone, item in ext["VRMC_vrm"].get("humanoid", {}).get("humanBones", {}).items():
            if bone in VRM_BONES and "node" in item:
                out[int(item["node"])] = VRM_BONES[bone]
    elif "VRM" in ext:  # VRM 0.x
        for item in ext["VRM"].get("humanoid", {}).get("humanBones", []):
            if item.get("bone") in VRM_BONES and "node" in item:
                out[int(item["node"])] = VRM_BONES[item["bone"]]
    return out


def _rest_fix(d: np.ndarray, kind: str) -> np.ndarray:
    """(3, 3) world rotation bringing bone direction d into the rest-pose limits (identity
    when within them). Arms turn about the forward axis y (in the coronal plane, so the
    bones below keep their forward offsets); legs by the smallest rotation."""
    u = d / np.linalg.norm(d)
    if kind == "arm":
        horiz = abs(u[0])
        elev = math.atan2(u[2], horiz)
        if abs(elev) <= ARM_ELEVATION_LIMIT or horiz < 1e-9:
            return np.eye(3)
        delta = math.copysign(ARM_ELEVATION_LIMIT, elev) - elev
        theta = delta if u[0] < 0 else -delta
        return axis_angle_to_matrix(np.array([0.0, theta, 0.0]))
    tilt = math.acos(max(-1.0, min(1.0, -u[2])))
    if tilt <= LEG_TILT_LIMIT:
        return np.eye(3)
    horiz = math.hypot(u[0], u[1])
    h = (u[0] / horiz, u[1] / horiz) if horiz > 1e-9 else (0.0, 0.0)
    target = np.array([h[0] * math.sin(LEG_TILT_LIMIT), h[1] * math.sin(LEG_TILT_LIMIT), -math.cos(LEG_TILT_LIMIT)])
    return rotation_between(u, target)


#: Bones straightened into the rest convention: (joint, child joint, kind).
_STRAIGHTEN = tuple(
    (f"{s}_{a}", f"{s}_{b}", kind)
    for s in ("left", "right")
    for a, b, kind in (
        ("hip", "knee", "leg"),
        ("knee", "ankle", "leg"),
        ("shoulder", "elbow", "arm"),
        ("elbow", "wrist", "arm"),
    )
)


def _synthesize(pos: dict[str, np.ndarray], missing: list[str]) -> None:
    """Place optional joints from their neighbours (file axes, after the up/facing fix)."""
    for name in missing:
        side = name.split("_", 1)[0]
        if name == "spine3":
            pos[name] = 0.5 * (pos["spine2"] + pos["neck"])
        elif name.endswith("_collar"):
            pos[name] = pos["spine3"] + 0.4 * (pos[f"{side}_shoulder"] - pos["spine3"])
        elif name.endswith("_hand"):
            pos[name] = pos[f"{side}_wrist"] + 0.3 * (pos[f"{side}_wrist"] - pos[f"{side}_elbow"])
        elif name.endswith("_foot"):
            shin = np.linalg.norm(pos[f"{side}_knee"] - pos[f"{side}_ankle"])
            pos[name] = pos[f"{side}_ankle"] + shin * np.array([0.0, 0.3, -0.12])


def read_character(
    path: str | Path,
    *,
    skin: int | None = 0,
    node: int | None = None,
    height: float | None = None,
    overrides: dict | None = None,
) -> GltfCharacter:
    """Read one character of a glTF file as a :class:`GltfCharacter` (see the module
    docstring): the skinned character with skin ``skin``, or the rigid-parts character whose
    root is node ``node``; ``overrides`` ({physics joint: joint name or index}) force joints
    of the mapping (:func:`~crowdstudy.body.rig_map.map_rig`).

    Raises InvalidInputError naming the file and what is missing (no skin, required joints
    without a counterpart, a rig that is not a humanoid's).
    """
    path = Path(path)
    gltf = open_scene(path)
    parent = node_parents(gltf.doc)
    world = node_world_matrices(gltf.doc, parent)
    spec = character_for_record(gltf.doc, parent, path, skin=skin, node=node)
    return character_from_gltf(gltf, spec, parent, world, height=height, overrides=overrides)


def open_scene(path: Path) -> GltfFile:
    """A glTF file, or a USD file's UsdSkel characters as glTF (:mod:`crowdstudy.body.usd_stage`)."""
    from crowdstudy.body.usd_stage import USD_SUFFIXES, read_usd

    if Path(path).suffix.lower() in USD_SUFFIXES:
        return read_usd(path).gltf
    return read_gltf(path)


def character_from_gltf(
    gltf: GltfFile,
    spec: CharacterSpec,
    parent: np.ndarray,
    world: np.ndarray,
    *,
    height: float | None = None,
    overrides: dict | None = None,
    sha256: str | None = None,
) -> GltfCharacter:
    """:func:`read_character` on a loaded file: character ``spec`` of ``gltf`` with the
    document's ``parent`` (nodes,) and default-pose ``world`` (nodes, 4, 4) matrices."""
    path = gltf.path
    rig = read_rig(gltf, spec, parent, world, path)
    rmap = map_character_rig(gltf.doc, rig, spec, world, path, overrides)
    targets = np.array([JOINT_INDEX[rmap.weight_joint(k)] for k in range(len(rig.nodes))])
    weights = np.zeros((len(rig.vertices), NUM_JOINTS))
    for k in range(len(rig.nodes)):
        weights[:, targets[k]] += rig.weights[:, k]
    v, joints, frame, pelvis = _upright_rig(rig, rmap)
    v, new_joints, fix = _straighten_rest_pose(v, joints, weights)
    scale = 1.0
    if height is not None:
        scale = float(height) / float(v[:, 2].max() - v[:, 2].min())
        v, new_joints = v * scale, new_joints * scale
    uv, texture = _merge_uv(path, gltf, rig.uvs, rig.images)
    hows = {m.how if m.how != "name" else m.detail for m in rmap.joints.values()}
    return GltfCharacter(
        vertices=v,
        faces=rig.faces,
        weights=weights.astype(np.float32),
        joints=new_joints,
        uv=uv,
        texture=texture,
        joint_map={rmap.names[m.source]: j for j, m in rmap.joints.items()},
        unmapped={rmap.names[k]: rmap.weight_joint(k) for k in range(len(rig.nodes)) if k not in rmap.source_to_joint},
        synthesized=list(rmap.missing),
        convention="+".join(sorted(hows, key=lambda h: (h != "topology", h))),
        sha256=sha256 or hashlib.sha256(path.read_bytes()).hexdigest(),
        spec=spec,
        rig=rig,
        rig_map=rmap,
        frame=frame,
        pelvis=pelvis,
        rest_fix=fix,
        scale=scale,
    )


def map_character_rig(
    doc: dict, rig: Rig, spec: CharacterSpec, world: np.ndarray, path: Path, overrides: dict | None = None
) -> RigMap:
    """The :class:`~crowdstudy.body.rig_map.RigMap` of a character's rig: a VRM humanoid
    table when the file has one naming at least 15 joints, else names and topology; the
    rest positions in Z-up axes, and glTF's front (+Z under the skeleton's parent) as the
    forward direction when nothing else tells left from right."""
    conv = Z_UP_TO_Y_UP.T  # glTF -> toolkit axes
    rest = rig.bind[:, :3, 3] @ conv.T
    index = {int(n): k for k, n in enumerate(rig.nodes)}
    vrm = {index[n]: j for n, j in _vrm_map(doc).items() if n in index}
    top_parent = node_parents(doc)[spec.root]
    up_frame = world[top_parent][:3, :3] if top_parent >= 0 else np.eye(3)
    forward = conv @ (up_frame @ np.array([0.0, 0.0, 1.0]))
    label = f"glTF file {path}: character at node {spec.root}"
    table = ("vrm-extension", vrm) if len(vrm) >= 15 else None
    return map_rig(rig.names, rig.parents, rest, forward=forward, overrides=overrides, label=label, table=table)


def _upright_rig(rig: Rig, rmap: RigMap) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The bind-pose mesh (file world) -> the toolkit's rest frame (Z up, facing +y, pelvis
    at the origin): ``(vertices (V, 3), joints (24, 3), frame (3, 3), pelvis (3,))``,
    missing optional joints placed from their neighbours."""
    conv = Z_UP_TO_Y_UP.T  # glTF -> toolkit
    v = rig.vertices @ conv.T
    pos = {j: conv @ rig.bind[m.source][:3, 3] for j, m in rmap.joints.items()}
    missing = rmap.missing
    _synthesize(pos, [j for j in JOINT_NAMES if j in missing and j not in ("left_foot", "right_foot")])
    frame = _upright_frame(pos)
    pelvis = pos["pelvis"].copy()
    v = (v - pelvis) @ frame.T
    pos = {k: frame @ (p - pelvis) for k, p in pos.items()}
    _synthesize(pos, [j for j in ("left_foot", "right_foot") if j in missing])
    return v, np.stack([pos[j] for j in JOINT_NAMES]), frame, pelvis


def _check_skin(doc: dict, skin: int, path: Path) -> None:
    """``skin`` must index one of the file's skins."""
    skins = doc.get("skins", [])
    if not skins:
        raise InvalidInputError(f"glTF file {path}: no skin (a rigged character needs a skinned mesh)")
    if not isinstance(skin, (int, np.integer)) or not 0 <= skin < len(skins):
        raise InvalidInputError(f"skin: expected an index in 0..{len(skins) - 1} for {path}, got {skin!r}")


@dataclasses.dataclass(frozen=True)
class SkinJointMap:
    """How the joints of one glTF skin map to the 24-joint skeleton.

    Attributes:
        skin: the skin's index in the file; nodes: its joints' node indices, in skin order.
        parent: (nodes in the file,) int64 parent node of every node (-1 for roots).
        names: {node: the node's name in the file}.
        node_map: {node: our joint name} for the skin joints that have a counterpart.
        convention: the naming convention matched ("mixamo", "vrm-extension", ...).
        missing: our (optional) joints with no counterpart, in skeleton order.
        unmapped: {file name: our joint that takes its weights} for the other skin joints.
    """

    skin: int
    nodes: tuple[int, ...]
    parent: np.ndarray
    names: dict[int, str]
    node_map: dict[int, str]
    convention: str
    missing: tuple[str, ...]
    unmapped: dict[str, str]

    def weight_joint(self, node: int) -> str:
        """Our joint that takes the skin weights of file node ``node``: its nearest mapped
        ancestor (itself when mapped), ``pelvis`` above the mapped joints."""
        return _nearest_mapped(node, self.node_map, self.parent)


def _nearest_mapped(node: int, node_map: dict[int, str], parent: np.ndarray) -> str:
    """Our joint of ``node``'s nearest ancestor in ``node_map`` (itself included), else "pelvis"."""
    k = node
    while k >= 0:
        if k in node_map:
            return node_map[k]
        k = int(parent[k])
    return "pelvis"


def map_skin_joints(doc: dict, skin: int, parent: np.ndarray, path: Path) -> SkinJointMap:
    """Map the joints of skin ``skin`` of the glTF document ``doc`` (read from ``path``) to
    the 24-joint skeleton: a VRM humanoid table when it names at least 15 of them, else the
    joint names (:func:`~crowdstudy.body.joint_names.match_names`). ``parent``: (nodes,)
    parent node of every node. Raises InvalidInputError when a required joint has no
    counterpart or the mapped joints' hierarchy differs from the skeleton's."""
    _check_skin(doc, skin, path)
    nodes = doc.get("nodes", [])
    skin_joints = [int(j) for j in doc["skins"][skin]["joints"]]
    joint_set = set(skin_joints)
    names = {j: str(nodes[j].get("name", f"node{j}")) for j in skin_joints}
    node_map = _vrm_map(doc)
    node_map = {k: v for k, v in node_map.items() if k in joint_set}
    convention = "vrm-extension" if len(node_map) >= 15 else ""
    if not convention:
        convention, node_map = match_names(names)
    found = set(node_map.values())
    missing = [j for j in JOINT_NAMES if j not in found]
    required = [j for j in missing if j not in OPTIONAL_JOINTS]
    if required:
        raise InvalidInputError(
            f"glTF file {path}: skin {skin} has no joint for {', '.join(required)} (best naming match: "
            f"{convention or 'none'}; joint names seen: {', '.join(list(names.values())[:12])}...)"
        )
    unmapped = {names[j]: _nearest_mapped(j, node_map, parent) for j in skin_joints if j not in node_map}
    check_hierarchy(node_map, parent, f"glTF file {path}")
    return SkinJointMap(
        skin=skin,
        nodes=tuple(skin_joints),
        parent=parent,
        names=names,
        node_map=node_map,
        convention=convention,
        missing=tuple(missing),
        unmapped=unmapped,
    )


@dataclasses.dataclass(frozen=True)
class SkinBind:
    """The bind pose of one glTF skin.

    Attributes:
        joints: the skin's joint node indices (K), in skin order.
        ibm: (K, 4, 4) float64 inverse bind matrices.
        to_world: (4, 4) float64 bind space -> the file's world: ``J_r IBM_r`` of the skin's
            pelvis joint r (its first joint when the pelvis is not in it).
        target: (K,) int64 our joint index that takes each skin joint's weights.
    """

    joints: list[int]
    ibm: np.ndarray
    to_world: np.ndarray
    target: np.ndarray


def read_skin_binds(gltf: GltfFile, joint_map: SkinJointMap, world: np.ndarray, path: Path) -> dict[int, SkinBind]:
    """{skin index: :class:`SkinBind`} of the mapped skin and of every other skin whose joints
    all belong to its skeleton (Blender and Ready Player Me write one skin per mesh over
    the same bones). ``world``: (nodes, 4, 4) world matrices of the file's default pose.

    Bind-space vertices and joints are carried to the file's world by ``J_r IBM_r``, so a
    default pose that differs from the bind pose (an animated file) does not deform the
    character."""
    joint_set = set(joint_map.nodes)
    pelvis_node = next(k for k, val in joint_map.node_map.items() if val == "pelvis")
    out = {}
    for s_idx, sk in enumerate(gltf.doc["skins"]):
        sj = [int(j) for j in sk["joints"]]
        if s_idx != joint_map.skin and not set(sj) <= joint_set:
            continue
        ibm = (
            gltf.accessor(sk["inverseBindMatrices"]).astype(np.float64)
            if "inverseBindMatrices" in sk
            else np.tile(np.eye(4), (len(sj), 1, 1))
        )
        if len(ibm) != len(sj):
            raise InvalidInputError(
                f"glTF file {path}: skin {s_idx} has {len(sj)} joints but {len(ibm)} inverse bind matrices"
            )
        r = sj.index(pelvis_node) if pelvis_node in sj else 0
        out[s_idx] = SkinBind(
            joints=sj,
            ibm=ibm,
            to_world=world[sj[r]] @ ibm[r],
            target=np.array([JOINT_INDEX[joint_map.weight_joint(j)] for j in sj]),
        )
    return out


@dataclasses.dataclass
class SkinnedMesh:
    """The triangle meshes bound to a set of skins, merged, in the file's world (glTF axes).

    Attributes:
        vertices: (V, 3) float64 metres; faces: (F, 3) int32.
        weights: (V, 24) float64 skin weights of our joints, rows summing to 1.
        uvs: per primitive, its (V_p, 2) TEXCOORD_0 or None; images: per primitive, the
            index of its base-colour image or None.
    """

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    uvs: list
    images: list


def read_skinned_mesh(gltf: GltfFile, binds: dict[int, SkinBind], skin: int, path: Path) -> SkinnedMesh:
    """Every triangle primitive of the meshes whose node uses one of the skins ``binds``,
    in the bind pose; ``skin`` names the chosen skin in the error when there is none."""
    doc = gltf.doc
    verts, faces, weights, uvs, images = [], [], [], [], []
    offset = 0
    for node in doc.get("nodes", []):
        if "mesh" not in node or node.get("skin") not in binds:
            continue
        bind = binds[node["skin"]]
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            if prim.get("mode", 4) != 4:
                continue
            p, w = _primitive_vertices(gltf, prim, node["mesh"], bind, path)
            verts.append(p @ bind.to_world[:3, :3].T + bind.to_world[:3, 3])
            weights.append(w)
            idx = gltf.accessor(prim["indices"]).astype(np.int64) if "indices" in prim else np.arange(len(p))
            faces.append(idx.reshape(-1, 3) + offset)
            offset += len(p)
            attrs = prim["attributes"]
            uvs.append(gltf.accessor(attrs["TEXCOORD_0"]).astype(np.float64) if "TEXCOORD_0" in attrs else None)
            images.append(_base_color_image(doc, prim))
    if not verts:
        raise InvalidInputError(f"glTF file {path}: no triangle mesh bound to skin {skin}")
    return SkinnedMesh(
        vertices=np.concatenate(verts),
        faces=np.concatenate(faces).astype(np.int32),
        weights=np.concatenate(weights),
        uvs=uvs,
        images=images,
    )


def _primitive_vertices(
    gltf: GltfFile, prim: dict, mesh: int, bind: SkinBind, path: Path
) -> tuple[np.ndarray, np.ndarray]:
    """A primitive's bind-space positions (V, 3) float64 and its weights (V, 24) of our
    joints (every JOINTS_k / WEIGHTS_k set summed onto the joints that take them), rows
    normalised to sum 1."""
    attrs = prim["attributes"]
    if "JOINTS_0" not in attrs or "WEIGHTS_0" not in attrs:
        raise InvalidInputError(f"glTF file {path}: mesh {mesh} has no JOINTS_0/WEIGHTS_0")
    p = gltf.accessor(attrs["POSITION"]).astype(np.float64)
    wsum = np.zeros((len(p), NUM_JOINTS))
    k = 0
    while f"JOINTS_{k}" in attrs:
        ji = gltf.accessor(attrs[f"JOINTS_{k}"]).astype(np.int64)
        wi = gltf.accessor(attrs[f"WEIGHTS_{k}"]).astype(np.float64)
        if ji.max(initial=0) >= len(bind.target):
            raise InvalidInputError(f"glTF file {path}: JOINTS_{k} refers past the skin's {len(bind.target)} joints")
        for c in range(ji.shape[1]):
            np.add.at(wsum, (np.arange(len(p)), bind.target[ji[:, c]]), wi[:, c])
        k += 1
    total = wsum.sum(axis=1, keepdims=True)
    if np.any(total <= 0):
        raise InvalidInputError(f"glTF file {path}: vertices of mesh {mesh} without skin weights")
    return p, wsum / total


def _straighten_rest_pose(
    vertices: np.ndarray, joints: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rest pose with arms near horizontal and legs near vertical (:func:`_rest_fix`),
    the mesh following by linear blend skinning: vertices (V, 3), joints (24, 3) m and
    weights (V, 24) -> ``(vertices, joints, global rotations (24, 3, 3) of the fix)``."""
    local = np.tile(np.eye(3), (NUM_JOINTS, 1, 1))
    for jname, child, kind in _STRAIGHTEN:
        j, c = JOINT_INDEX[jname], JOINT_INDEX[child]
        glob, p = forward_kinematics(joints, local, np.zeros(3), rotations_are_matrices=True)
        d = p[c] - p[j]
        fix = _rest_fix(d, kind)
        par = glob[int(PARENTS[j])]
        local[j] = par.T @ fix @ par @ local[j]
    glob, new_joints = forward_kinematics(joints, local, np.zeros(3), rotations_are_matrices=True)
    lbs = np.zeros((NUM_JOINTS, 3, 4))
    lbs[:, :, :3] = glob
    lbs[:, :, 3] = new_joints - np.einsum("jab,jb->ja", glob, joints)
    blended = np.einsum("vj,jab->vab", weights, lbs)
    return np.einsum("vab,vb->va", blended[:, :, :3], vertices) + blended[:, :, 3], new_joints, glob


def _upright_frame(pos: dict[str, np.ndarray]) -> np.ndarray:
    """(3, 3) rotation: pelvis->head snapped to the nearest axis becomes +z, then a turn
    about z sends the hips' right->left direction to -x (the character faces +y)."""
    up = pos["head"] - pos["pelvis"]
    k = int(np.argmax(np.abs(up)))
    snap = np.zeros(3)
    snap[k] = math.copysign(1.0, up[k])
    if snap[2] == 1.0:
        first = np.eye(3)
    elif snap[2] == -1.0:
        first = np.diag([1.0, -1.0, -1.0])
    else:
        first = rotation_between(snap, np.array([0.0, 0.0, 1.0]))
        first = np.round(first)  # an exact axis permutation
    left = first @ (pos["left_hip"] - pos["right_hip"])
    if math.hypot(left[0], left[1]) < 1e-9:
        raise InvalidInputError("glTF character: the hips have no left-right extent (cannot tell its facing)")
    turn = math.remainder(math.pi - math.atan2(left[1], left[0]), 2.0 * math.pi)
    c, s = math.cos(turn), math.sin(turn)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ first


def _base_color_image(doc: dict, prim: dict):
    mat_idx = prim.get("material")
    if mat_idx is None:
        return None
    info = doc["materials"][mat_idx].get("pbrMetallicRoughness", {}).get("baseColorTexture")
    if info is None:
        return None
    return doc["textures"][info["index"]].get("source")


def _merge_uv(path: Path, gltf: GltfFile, uvs: list, images: list):
    """One UV set and one texture when every primitive shares the same base-colour image."""
    if any(u is None for u in uvs) or len(set(images)) != 1 or images[0] is None:
        return None, None
    import io

    from PIL import Image

    try:
        img = Image.open(io.BytesIO(gltf.image_bytes(images[0]))).convert("RGB")
    except OSError as exc:
        raise InvalidInputError(f"glTF file {path}: cannot decode image {images[0]} ({exc})") from None
    uv = np.concatenate(uvs)
    return np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1).astype(np.float32), np.asarray(img, dtype=np.uint8)


def load_gltf_body(record: dict):
    """The :class:`~crowdstudy.body.model.Body` of a ``{"model": "gltf"}`` record: ``skin``
    (default 0) or ``node`` (a rigid-parts character's root) selects the character,
    ``map`` ({physics joint: joint name or index}) forces joints of its mapping."""
    check_fields(record, str(record.get("model", "gltf")), RECORD_FIELDS)
    path = record.get("path")
    if not isinstance(path, str) or not path:
        raise InvalidInputError(f"body record field 'path': expected a glTF file path, got {path!r}")
    node = record.get("node")
    if node is not None and (isinstance(node, bool) or not isinstance(node, int)):
        raise InvalidInputError(f"body record field 'node': expected an integer node index, got {node!r}")
    skin = record.get("skin", 0 if node is None else None)
    if node is None and (isinstance(skin, bool) or not isinstance(skin, int)):
        raise InvalidInputError(f"body record field 'skin': expected an integer index, got {skin!r}")
    overrides = record.get("map")
    if overrides is not None and not isinstance(overrides, dict):
        raise InvalidInputError(f"body record field 'map': expected {{physics joint: joint}}, got {overrides!r}")
    height = record.get("height")
    if height is not None:
        try:
            height = float(height)
        except (TypeError, ValueError):
            raise InvalidInputError(f"body record field 'height': expected a number, got {height!r}") from None
        if not 0.3 <= height <= 2.5:
            raise InvalidInputError(f"body record field 'height': expected 0.3 to 2.5 m, got {height}")
    return body_from_character(record, read_character(path, skin=skin, node=node, height=height, overrides=overrides))


def body_from_character(record: dict, ch: GltfCharacter) -> Body:
    """The :class:`~crowdstudy.body.model.Body` of a read character. Rest positions are
    rounded to 0.1 um, so copies of one character placed anywhere in a file get the same
    bytes (and share their capsule fit); bodies with the same faces and weights share a
    template."""
    digest = hashlib.sha256(np.ascontiguousarray(ch.faces).tobytes() + ch.weights.tobytes()).hexdigest()
    verts = np.round(ch.vertices, 7) + 0.0
    return Body(
        record=dict(record),
        rest_joints=np.round(ch.joints, 7) + 0.0,
        rest_vertices=verts,
        faces=ch.faces,
        weights=ch.weights,
        pelvis_height=float(-verts[:, 2].min()),
        template_key=f"gltf-{digest[:16]}",
    )

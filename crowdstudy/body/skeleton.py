"""The 24-joint kinematic tree (SMPL-compatible) and forward kinematics.

Rest pose conventions (the toolkit's frame: metres, radians, Z up):

* Z up, floor at z = 0 in world space; in the *rest* (T-pose) the character faces **+y**,
  so its right-hand side is **+x** and its left-hand side **-x**; arms are horizontal.
* Rest joint positions ``rest_joints`` (J, 3) are given relative to the pelvis (joint 0 at
  the origin); ``root_translation`` places the pelvis in the world.
* ``joint_rotations[..., 0, :]`` is the global root orientation; every other joint's
  rotation is relative to its parent. With all rotations zero the character stands in the
  rest pose.
* Forward kinematics: ``G_0 = R_0``, ``G_j = G_parent(j) R_j``;
  ``p_0 = root_translation``, ``p_j = p_parent(j) + G_parent(j) (rest_j - rest_parent(j))``.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.rotations import rodrigues_rows
from crowdstudy.errors import InvalidInputError

__all__ = [
    "JOINT_NAMES",
    "PARENTS",
    "NUM_JOINTS",
    "JOINT_INDEX",
    "ARM_JOINTS",
    "LEG_JOINTS",
    "TRUNK_JOINTS",
    "BODY_PARTS",
    "DEFAULT_REST_JOINTS",
    "DEFAULT_PELVIS_HEIGHT",
    "forward_kinematics",
    "joint_index",
    "children",
    "MIRROR_JOINTS",
    "mirror_pose",
]

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
)
PARENTS: np.ndarray = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21], dtype=np.int64
)
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}
ARM_JOINTS: tuple[str, ...] = (
    "left_collar",
    "right_collar",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hand",
    "right_hand",
)
LEG_JOINTS: tuple[str, ...] = (
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_foot",
    "right_foot",
)
TRUNK_JOINTS: tuple[str, ...] = ("pelvis", "spine1", "spine2", "spine3", "neck", "head")
#: the tree split into three parts (each joint in exactly one), for reports of where a
#: correction moves a character: ``(name, joint names)``
BODY_PARTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("legs", LEG_JOINTS),
    ("trunk", TRUNK_JOINTS),
    ("arms", ARM_JOINTS),
)

# An average adult (about 1.70 m) in the T-pose, metres, relative to the pelvis. Only a
# default for shape-independent work (clip authoring, tests): body models provide the rest
# joints of each shape.
_HALF = {  # left-side joints; the right side mirrors x
    "left_hip": (-0.060, -0.010, -0.090),
    "left_knee": (-0.105, -0.005, -0.475),
    "left_ankle": (-0.088, -0.040, -0.880),
    "left_foot": (-0.115, 0.080, -0.935),
    "left_collar": (-0.075, -0.020, 0.440),
    "left_shoulder": (-0.165, -0.025, 0.485),
    "left_elbow": (-0.420, -0.045, 0.475),
    "left_wrist": (-0.675, -0.050, 0.475),
    "left_hand": (-0.760, -0.055, 0.470),
}
_MID = {
    "pelvis": (0.0, 0.0, 0.0),
    "spine1": (0.0, -0.020, 0.115),
    "spine2": (0.0, -0.005, 0.255),
    "spine3": (0.0, 0.000, 0.315),
    "neck": (0.0, -0.020, 0.525),
    "head": (0.0, 0.020, 0.615),
}


def _default_rest() -> np.ndarray:
    out = np.zeros((NUM_JOINTS, 3))
    for name, pos in _MID.items():
        out[JOINT_INDEX[name]] = pos
    for name, (x, y, z) in _HALF.items():
        out[JOINT_INDEX[name]] = (x, y, z)
        out[JOINT_INDEX[name.replace("left_", "right_")]] = (-x, y, z)
    return out


DEFAULT_REST_JOINTS: np.ndarray = _default_rest()
DEFAULT_REST_JOINTS.flags.writeable = False
#: Height of the pelvis above the floor for DEFAULT_REST_JOINTS standing (sole ~4 cm below the foot joint).
DEFAULT_PELVIS_HEIGHT = 0.975


def joint_index(name: str) -> int:
    """Index of a joint by name; unknown names raise an error listing the valid ones."""
    try:
        return JOINT_INDEX[name]
    except KeyError:
        raise InvalidInputError(f"unknown joint name {name!r}; expected one of {', '.join(JOINT_NAMES)}") from None


def children(parents: np.ndarray = PARENTS) -> list[list[int]]:
    """Children of each joint, in index order."""
    out: list[list[int]] = [[] for _ in range(len(parents))]
    for j, p in enumerate(parents):
        if p >= 0:
            out[int(p)].append(j)
    return out


#: Joint index -> its mirror image (left <-> right), for :func:`mirror_pose`.
MIRROR_JOINTS: np.ndarray = np.array(
    [JOINT_INDEX[n.replace("left_", "#").replace("right_", "left_").replace("#", "right_")] for n in JOINT_NAMES]
)


def mirror_pose(quat: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pose mirrored left <-> right across the character's sagittal plane (x -> -x):
    quaternions (..., 24, 4) xyzw (joint 0 global, the others local) and root positions
    (..., 3) metres. A reflection M = diag(-1, 1, 1) turns a rotation R into M R M, i.e. the
    quaternion (x, y, z, w) into (x, -y, -z, w), and each joint takes its mirror joint's."""
    q = np.array(quat, dtype=np.float64, copy=True)[..., MIRROR_JOINTS, :]
    q[..., 1:3] *= -1.0
    r = np.array(root, dtype=np.float64, copy=True)
    r[..., 0] *= -1.0
    return q, r


def forward_kinematics(
    rest_joints: np.ndarray,
    joint_rotations: np.ndarray,
    root_translation: np.ndarray,
    parents: np.ndarray = PARENTS,
    *,
    rotations_are_matrices: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Global joint rotations and positions.

    Args:
        rest_joints: (..., J, 3) float, metres; rest-pose joint positions (any origin).
        joint_rotations: (..., J, 3) axis-angle radians, or (..., J, 3, 3) matrices when
            ``rotations_are_matrices``; joint 0 global, the others parent-relative.
        root_translation: (..., 3) metres, world position of joint 0.
        parents: (J,) parent indices with ``parents[j] < j`` and -1 for the root.

    Returns:
        ``(global_rotations (..., J, 3, 3), joint_positions (..., J, 3))``, the leading
        shapes broadcast together.
    """
    rest = np.asarray(rest_joints, dtype=np.float64)
    rot = np.asarray(joint_rotations, dtype=np.float64)
    n_j = len(parents)
    if rest.shape[-2:] != (n_j, 3):
        raise InvalidInputError(f"rest_joints: expected shape (..., {n_j}, 3), got {rest.shape}")
    if rotations_are_matrices and rot.shape[-3:] != (n_j, 3, 3):
        raise InvalidInputError(f"joint_rotations: expected (..., {n_j}, 3, 3) matrices, got {rot.shape}")
    if not rotations_are_matrices and rot.shape[-2:] != (n_j, 3):
        raise InvalidInputError(f"joint_rotations: expected (..., {n_j}, 3) axis-angle, got {rot.shape}")
    root = np.asarray(root_translation, dtype=np.float64)
    if root.shape[-1:] != (3,):
        raise InvalidInputError(f"root_translation: expected shape (..., 3), got {root.shape}")
    rot_batch = rot.shape[:-3] if rotations_are_matrices else rot.shape[:-2]
    batch = np.broadcast_shapes(rest.shape[:-2], rot_batch, root.shape[:-1])
    parents = np.asarray(parents)
    offsets = rest - rest[..., np.maximum(parents, 0), :]
    glob = np.empty(batch + (n_j, 3, 3))
    pos = np.empty(batch + (n_j, 3))
    # Poses are taken in blocks of about _FK_BLOCK along the leading batch axis, each laid out
    # component-major ((J, 3, 3, M) arrays, M poses): every joint is then a few dozen
    # ufunc calls on contiguous cache-sized rows instead of M batched 3x3 products, and no
    # temporary grows with the whole batch (fresh memory is dear on a virtual machine).
    lead = batch[0] if batch else 1
    per_row = int(np.prod(batch[1:], dtype=np.int64)) if len(batch) > 1 else 1
    rows = max(1, _FK_BLOCK // max(per_row, 1))
    full_rot = np.broadcast_to(rot, batch + rot.shape[len(rot_batch) :])
    full_off = np.broadcast_to(offsets, batch + (n_j, 3))
    full_root = np.broadcast_to(root, batch + (3,))
    flat_glob = glob.reshape(-1, n_j, 3, 3)
    flat_pos = pos.reshape(-1, n_j, 3)
    for r0 in range(0, lead, rows):
        r1 = min(lead, r0 + rows)
        pick = (slice(r0, r1),) if batch else ()
        block_rot = full_rot[pick].reshape((-1,) + rot.shape[len(rot_batch) :])
        m0, m1 = r0 * per_row, r1 * per_row if batch else 1
        block_off, block_root = full_off[pick].reshape(-1, n_j, 3), full_root[pick].reshape(-1, 3)
        if m1 - m0 <= _FK_FEW:
            _fk_few(
                block_rot, block_off, block_root, parents, rotations_are_matrices, flat_glob[m0:m1], flat_pos[m0:m1]
            )
            continue
        g, p = _fk_block(block_rot, block_off, block_root, parents, rotations_are_matrices)
        flat_glob[m0:m1] = g.transpose(3, 0, 1, 2)
        flat_pos[m0:m1] = p.transpose(2, 0, 1)
    return glob, pos


#: poses per block of :func:`forward_kinematics` (about 2 MB of rotations per block)
_FK_BLOCK = 4096


#: up to this many poses a block is computed pose-major (:func:`_fk_few`): fewer, larger
#: ufunc calls; the same sums in the same order, so the same bits
_FK_FEW = 16


def _fk_few(
    rot: np.ndarray,
    offsets: np.ndarray,
    root: np.ndarray,
    parents: np.ndarray,
    matrices: bool,
    glob: np.ndarray,
    pos: np.ndarray,
) -> None:
    """Forward kinematics of a few poses into ``glob`` (M, J, 3, 3) and ``pos`` (M, J, 3)
    (arguments as :func:`_fk_block`)."""
    if matrices:
        local = rot
    else:
        rows = rodrigues_rows(rot[..., 0], rot[..., 1], rot[..., 2], np.empty((3, 3) + rot.shape[:2]))
        local = rows.transpose(2, 3, 0, 1)
    glob[:, 0] = local[:, 0]
    pos[:, 0] = root
    for j in range(1, len(parents)):
        p = int(parents[j])
        gp = glob[:, p]
        # (g0 l0 + g1 l1) + g2 l2 per entry, as _fk_block sums them
        glob[:, j] = (gp[:, :, :, None] * local[:, j, None, :, :]).sum(axis=2)
        pos[:, j] = (gp * offsets[:, j, None, :]).sum(axis=2) + pos[:, p]


def _fk_block(
    rot: np.ndarray, offsets: np.ndarray, root: np.ndarray, parents: np.ndarray, matrices: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics of M poses, component-major: rot (M, J, 3) axis-angle or (M, J, 3, 3),
    offsets (M, J, 3) from each joint's parent at rest, root (M, 3) -> ``(glob (J, 3, 3, M),
    pos (J, 3, M))``."""
    n_j = len(parents)
    m = rot.shape[0]
    if matrices:
        local = np.ascontiguousarray(rot.transpose(1, 2, 3, 0))
    else:
        comp = np.ascontiguousarray(rot.transpose(2, 1, 0))  # (3, J, M)
        local = rodrigues_rows(comp[0], comp[1], comp[2], np.empty((3, 3, n_j, m))).transpose(2, 0, 1, 3)
    off = np.ascontiguousarray(offsets.transpose(1, 2, 0))  # (J, 3, M)
    glob = np.empty((n_j, 3, 3, m))
    pos = np.empty((n_j, 3, m))
    glob[0] = local[0]
    pos[0] = root.T
    tmp = np.empty(m)
    for j in range(1, n_j):
        gp, lj, gj, oj = glob[int(parents[j])], local[j], glob[j], off[j]
        pj, pp = pos[j], pos[int(parents[j])]
        for a in range(3):
            for b in range(3):
                np.multiply(gp[a, 0], lj[0, b], out=gj[a, b])
                np.multiply(gp[a, 1], lj[1, b], out=tmp)
                gj[a, b] += tmp
                np.multiply(gp[a, 2], lj[2, b], out=tmp)
                gj[a, b] += tmp
            np.multiply(gp[a, 0], oj[0], out=pj[a])
            np.multiply(gp[a, 1], oj[1], out=tmp)
            pj[a] += tmp
            np.multiply(gp[a, 2], oj[2], out=tmp)
            pj[a] += tmp
            pj[a] += pp[a]
    return glob, pos


# --- Name maps from common BVH skeletons (for retargeting) -------------------------------
# Keys are the BVH joint names, values our joint names. BVH joints that are missing from a
# map (CMU's LHipJoint/RHipJoint/Neck1/finger and thumb joints, Mixamo's *_End and finger
# joints) have no counterpart: a retargeter folds their rotation into the nearest mapped
# joint (the parent for a fixed offset, the mapped child for an intermediate one).
_CMU_SIDE = {
    "UpLeg": "hip",
    "Leg": "knee",
    "Foot": "ankle",
    "ToeBase": "foot",
    "Shoulder": "collar",
    "Arm": "shoulder",
    "ForeArm": "elbow",
    "Hand": "wrist",
    "FingerBase": "hand",
}
_MIXAMO_SIDE = {
    "UpLeg": "hip",
    "Leg": "knee",
    "Foot": "ankle",
    "ToeBase": "foot",
    "Shoulder": "collar",
    "Arm": "shoulder",
    "ForeArm": "elbow",
    "Hand": "wrist",
    "HandMiddle1": "hand",
}


def _side_map(table: dict[str, str], prefix: str = "") -> dict[str, str]:
    out = {}
    for bvh, ours in table.items():
        out[f"{prefix}Left{bvh}"] = f"left_{ours}"
        out[f"{prefix}Right{bvh}"] = f"right_{ours}"
    return out


#: ``{"cmu": {bvh_name: joint_name}, "mixamo": {...}}``. CMU (the mocap database's BVH
#: conversion, e.g. ``12_01.bvh``): Hips, LowerBack, Spine, Spine1, Neck, Head and the
#: Left/Right chains. Mixamo: the same names with the ``mixamorig:`` prefix (Spine, Spine1,
#: Spine2 for our spine1..3; the middle finger's first joint stands for ``*_hand``).
BVH_NAME_MAPS: dict[str, dict[str, str]] = {
    "cmu": {
        "Hips": "pelvis",
        "LowerBack": "spine1",
        "Spine": "spine2",
        "Spine1": "spine3",
        "Neck": "neck",
        "Head": "head",
        **_side_map(_CMU_SIDE),
    },
    "daz": {
        "hip": "pelvis",
        "abdomen": "spine1",
        "chest": "spine2",
        "neck": "neck",
        "head": "head",
        **{
            f"{c}{bvh}": f"{side}_{ours}"
            for c, side in (("l", "left"), ("r", "right"))
            for bvh, ours in {
                "Thigh": "hip",
                "Shin": "knee",
                "Foot": "ankle",
                "Collar": "collar",
                "Shldr": "shoulder",
                "ForeArm": "elbow",
                "Hand": "wrist",
                "Mid1": "hand",
            }.items()
        },
    },
    "mixamo": {
        "mixamorig:Hips": "pelvis",
        "mixamorig:Spine": "spine1",
        "mixamorig:Spine1": "spine2",
        "mixamorig:Spine2": "spine3",
        "mixamorig:Neck": "neck",
        "mixamorig:Head": "head",
        **_side_map(_MIXAMO_SIDE, "mixamorig:"),
    },
}
#: Joints a naming lacks, derived from the ones it has: ``{convention: {joint: (anchor BVH
#: joint, end BVH joint or None for the anchor's end site, fraction)}}``. A derived joint
#: rotates with its anchor (its local rotation is then the identity) and rests at
#: ``anchor + fraction * (end - anchor)``. The Daz-friendly CMU skeleton (B. Hahne's BVH
#: release: ``hip, abdomen, chest, neck, head, lButtock, lThigh, lShin, lFoot, lCollar,
#: lShldr, lForeArm, lHand`` and fingers) has two spine joints and no toes: ``spine3`` sits
#: halfway up the chest, the toe joint at the foot's end site.
BVH_DERIVED_JOINTS: dict[str, dict[str, tuple[str, str | None, float]]] = {
    "daz": {"spine3": ("chest", "neck", 0.5), "left_foot": ("lFoot", None, 1.0), "right_foot": ("rFoot", None, 1.0)},
}
__all__ += ["BVH_NAME_MAPS", "BVH_DERIVED_JOINTS", "bvh_name_map", "bvh_convention"]


def bvh_convention(bvh_joint_names) -> str:
    """The naming (a key of :data:`BVH_NAME_MAPS`) that matches most of the joint names."""
    names = set(bvh_joint_names)

    def score(conv: str) -> int:
        table = BVH_NAME_MAPS[conv]
        if conv == "mixamo":
            keys = {"mixamorig:" + (n.split(":", 1)[1] if ":" in n else n) for n in names}
            return len(keys & set(table))
        return len(names & set(table))

    return max(BVH_NAME_MAPS, key=score)


def bvh_name_map(bvh_joint_names, convention: str | None = None) -> dict[str, str]:
    """The map ``{bvh_name: joint_name}`` that applies to a BVH file's joint names.

    Args:
        bvh_joint_names: the joint names of the file (any iterable of str).
        convention: ``"cmu"``, ``"daz"``, ``"mixamo"`` or None to pick the one that matches
            most names. Mixamo names are matched with any ``mixamorig*:`` namespace prefix or none.

    Returns:
        Only the entries for names present in the file; joints the naming derives
        (:data:`BVH_DERIVED_JOINTS`) are not in it. Raises InvalidInputError naming the
        missing joints when the file lacks one of the 24 joints' counterparts.
    """
    names = list(bvh_joint_names)
    if convention is not None and convention not in BVH_NAME_MAPS:
        raise InvalidInputError(
            f"convention: unknown BVH naming {convention!r}; expected one of {sorted(BVH_NAME_MAPS)}"
        )

    def strip(name: str) -> str:
        return "mixamorig:" + name.split(":", 1)[1] if ":" in name else name

    def candidates(conv: str) -> dict[str, str]:
        table = BVH_NAME_MAPS[conv]
        if conv == "mixamo":
            found = {}
            for n in names:
                key = strip(n) if ":" in n else "mixamorig:" + n
                if key in table:
                    found[n] = table[key]
            return found
        return {n: table[n] for n in names if n in table}

    convs = [convention] if convention else list(BVH_NAME_MAPS)
    conv = max(convs, key=lambda c: len(candidates(c)))
    best = candidates(conv)
    derived = {
        j
        for j, (anchor, end, _) in BVH_DERIVED_JOINTS.get(conv, {}).items()
        if anchor in names and (end is None or end in names)
    }
    missing = sorted(set(JOINT_NAMES) - set(best.values()) - derived)
    if missing:
        raise InvalidInputError(
            f"BVH joint names: no counterpart for joints {', '.join(missing)} (conventions tried: {', '.join(convs)})"
        )
    return best

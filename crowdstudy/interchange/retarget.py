"""A rig's joint motion <-> the 24 physics joints' rotations, for any file format.

Notation (per character): ``W_s(t)`` world matrix of rig joint s at frame t and ``B_s`` at
bind time, in the file's world; ``C`` (3, 3) rotation from the file's axes to the
toolkit's (Z up); ``frame`` (3, 3) the rest frame's turn (facing +y) and ``S_j`` (3, 3) the
rest-pose fix of physics joint j (:class:`~crowdstudy.body.gltf_model.GltfCharacter`).
A vertex skinned to rig joint s moves by ``W_s(t) B_s^-1``; on the toolkit's body it moves
with physics joint j = map(s), whose global rotation is therefore

    G_j(t) = C R(W_s(t)) R(B_s)^T C^T frame^T S_j^T

(``R(.)``: the rotation part, scale removed). Physics joints without a source turn with
their parent. The root translation is the pelvis source's world origin, ``C W_p(t)[:3, 3]``.

Back (:func:`rig_targets`): the corrected ``G'_j`` gives each mapped rig joint the world
rotation ``C^T G'_j S_j frame C R(B_s)``; :func:`rewrite_rig` turns that into local
rotations down the rig's tree, so the joints between mapped ones keep their own motion,
unmapped joints keep theirs relative to their parents, the pelvis source takes the
corrected root position, and a joint beside the mapped tree whose parts follow a physics
joint (an IK foot target) moves rigidly with that joint's correction.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.rig_map import RigMap
from crowdstudy.body.rotations import matrix_to_axis_angle, matrix_to_quaternion
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS, forward_kinematics

__all__ = [
    "RetargetFrames",
    "rotation_part",
    "to_physics",
    "rig_targets",
    "rewrite_rig",
    "RigMotion",
    "fold_missing",
]


@dataclasses.dataclass(frozen=True)
class RetargetFrames:
    """The fixed frames of one character: ``conv`` (3, 3) file axes -> toolkit axes;
    ``frame`` (3, 3) and ``rest_fix`` (24, 3, 3) of its rest pose; ``bind`` (K, 4, 4) its
    rig joints' bind-time world matrices; ``rig_map`` the joint mapping; ``rest_joints``
    (24, 3) the body's rest joints, m."""

    conv: np.ndarray
    frame: np.ndarray
    rest_fix: np.ndarray
    bind: np.ndarray
    rig_map: RigMap
    rest_joints: np.ndarray


def rotation_part(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation of (..., 4, 4) or (..., 3, 3) matrices (columns normalised:
    uniform or axis-aligned scale removed)."""
    r = np.asarray(m)[..., :3, :3]
    return r / np.linalg.norm(r, axis=-2, keepdims=True)


def _globals(world: np.ndarray, fr: RetargetFrames) -> np.ndarray:
    """(T, 24, 3, 3) global rotations of the physics joints; ``world`` (T, K, 4, 4)."""
    t = world.shape[0]
    g = np.empty((t, NUM_JOINTS, 3, 3))
    rb = rotation_part(fr.bind)
    post = fr.conv.T @ fr.frame.T  # C^T frame^T
    for j, name in enumerate(JOINT_NAMES):
        m = fr.rig_map.joints.get(name)
        if m is None:
            g[:, j] = g[:, int(PARENTS[j])] if j else np.eye(3)
            continue
        rw = rotation_part(world[:, m.source])
        g[:, j] = fr.conv @ rw @ (rb[m.source].T @ post @ fr.rest_fix[j].T)
    return g


def to_physics(world: np.ndarray, fr: RetargetFrames) -> tuple[np.ndarray, np.ndarray]:
    """The 24 joints' motion of a rig: ``world`` (T, K, 4, 4) its joints' world matrices ->
    ``(joint_rotations (T, 24, 3) axis-angle, joint 0 global; root_translation (T, 3) m)``."""
    g = _globals(world, fr)
    local = np.empty_like(g)
    local[:, 0] = g[:, 0]
    par = PARENTS[1:]
    local[:, 1:] = np.swapaxes(g[:, par], -1, -2) @ g[:, 1:]
    pelvis = fr.rig_map.joints["pelvis"].source
    root = world[:, pelvis, :3, 3] @ fr.conv.T
    return matrix_to_axis_angle(local), root


def fold_missing(rotations: np.ndarray, missing) -> np.ndarray:
    """The 24 joints' rotations (T, 24, 3) with the joints a rig lacks (``missing``, placed
    from their neighbours) turned back to rest and their turn passed to their children, so
    every joint the rig has keeps its global rotation: the motion the rig can show (the
    joints below a missing one move by the missing joint's offset only)."""
    from crowdstudy.body.rotations import axis_angle_to_matrix

    if not missing:
        return rotations
    local = axis_angle_to_matrix(rotations)
    kids: list[list[int]] = [[] for _ in JOINT_NAMES]
    for c, p in enumerate(PARENTS):
        if p >= 0:
            kids[int(p)].append(c)
    for j in sorted(JOINT_INDEX[m] for m in missing):
        for c in kids[j]:
            local[:, c] = local[:, j] @ local[:, c]
        local[:, j] = np.eye(3)
    return matrix_to_axis_angle(local)


def rig_targets(rotations: np.ndarray, root: np.ndarray, fr: RetargetFrames) -> dict[int, np.ndarray]:
    """{mapped rig joint: (T, 3, 3) world rotation (file axes)} for the 24 joints' motion
    ``rotations`` (T, 24, 3) and ``root`` (T, 3)."""
    g, _ = forward_kinematics(fr.rest_joints, rotations, root)
    rb = rotation_part(fr.bind)
    pre = fr.frame @ fr.conv  # frame C
    out = {}
    for j, name in enumerate(JOINT_NAMES):
        m = fr.rig_map.joints.get(name)
        if m is not None:
            out[m.source] = fr.conv.T @ g[:, j] @ (fr.rest_fix[j] @ pre @ rb[m.source])
    return out


def _lbs(rotations: np.ndarray, root: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """(T, 24, 4, 4) toolkit skinning matrices."""
    g, p = forward_kinematics(rest, rotations, root)
    m = np.zeros(g.shape[:-2] + (4, 4))
    m[..., :3, :3] = g
    m[..., :3, 3] = p - np.einsum("tjab,jb->tja", g, rest)
    m[..., 3, 3] = 1.0
    return m


@dataclasses.dataclass
class RigMotion:
    """The rewritten motion of a rig: per rig joint whose channels change, its new local
    ``rotation`` (T, 4) quaternions (x, y, z, w) and/or ``translation`` (T, 3)."""

    rotation: dict[int, np.ndarray]
    translation: dict[int, np.ndarray]


def _followers(rm: RigMap) -> dict[int, str]:
    """{rig joint: physics joint} for the top rig joints beside the mapped tree whose parts
    follow a physics joint (not under a mapped joint, not above the pelvis)."""
    mapped = rm.source_to_joint
    above = set()
    k = int(rm.parents[rm.joints["pelvis"].source])
    while k >= 0:
        above.add(k)
        k = int(rm.parents[k])
    out = {}
    for k in range(len(rm.names)):
        if k in mapped or k in above:
            continue
        a, inside = k, False
        while a >= 0:
            if a in mapped:
                inside = True
                break
            a = int(rm.parents[a])
        if not inside and int(rm.parents[k]) in above | {-1}:
            out[k] = rm.weight_joint(k)
    return out


def rewrite_rig(
    local: np.ndarray,
    parent_world: np.ndarray,
    base: tuple[np.ndarray, np.ndarray],
    new: tuple[np.ndarray, np.ndarray],
    fr: RetargetFrames,
) -> RigMotion:
    """New local motion of a rig's joints.

    Args:
        local: (T, K, 4, 4) the rig joints' local matrices (relative to their node parent).
        parent_world: (T, K, 4, 4) world matrices of each rig joint's node parent when that
            parent is not a rig joint (unchanged by the rewrite); identity rows otherwise.
        base: the 24 joints' input motion ``(rotations (T, 24, 3), root (T, 3))``.
        new: the corrected motion, same shapes.
        fr: the character's frames.
    """
    rm = fr.rig_map
    targets = rig_targets(*new, fr)
    pelvis = rm.joints["pelvis"].source
    root_file = new[1] @ fr.conv  # corrected pelvis, file axes
    follow = _followers(rm)
    delta = {}
    if follow:
        conv4 = np.eye(4)
        conv4[:3, :3] = fr.conv
        m_new, m_old = _lbs(*new, fr.rest_joints), _lbs(*base, fr.rest_joints)
        for k, j in follow.items():
            jj = JOINT_INDEX[j]
            delta[k] = conv4.T @ m_new[:, jj] @ np.linalg.inv(m_old[:, jj]) @ conv4
    order = sorted(range(len(rm.names)), key=lambda k: _depth(k, rm.parents))
    world_new = np.empty_like(local)
    out = RigMotion({}, {})
    for k in order:
        p = int(rm.parents[k])
        wp = world_new[:, p] if p >= 0 else parent_world[:, k]
        lk = local[:, k].copy()
        if k in targets:
            lk[:, :3, :3] = np.swapaxes(rotation_part(wp), -1, -2) @ targets[k] * _scales(lk)[:, None, :]
            out.rotation[k] = matrix_to_quaternion(rotation_part(lk))
            if k == pelvis:
                hom = np.concatenate([root_file, np.ones((len(root_file), 1))], axis=1)
                lk[:, :3, 3] = np.einsum("tab,tb->ta", np.linalg.inv(wp), hom)[:, :3]
                out.translation[k] = lk[:, :3, 3].copy()
        elif k in delta:
            lk = np.linalg.inv(wp) @ delta[k] @ (wp @ local[:, k])
            out.rotation[k] = matrix_to_quaternion(rotation_part(lk))
            out.translation[k] = lk[:, :3, 3].copy()
        world_new[:, k] = wp @ lk
    return out


def _scales(m: np.ndarray) -> np.ndarray:
    """(T, 3) column norms (per-axis scale) of (T, 4, 4) local matrices."""
    return np.linalg.norm(m[:, :3, :3], axis=-2)


def _depth(k: int, parents: np.ndarray) -> int:
    d = 0
    while parents[k] >= 0:
        k = int(parents[k])
        d += 1
    return d

"""Assemble a full 24-joint pose from high-level controls (used by the clip generators).

The procedural clips describe a motion by its pelvis trajectory, torso and head angles,
the wanted wrist positions (relative to the shoulders, in the chest frame, in units of
the arm's reach) and the wanted ankle positions and orientations on the floor. This
module turns those controls into joint rotations with analytic two-bone IK for the arms
and the legs, on the authoring skeleton :data:`~crowdstudy.body.skeleton.DEFAULT_REST_JOINTS`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.posing import two_bone_ik
from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle, rot_y
from crowdstudy.body.skeleton import (
    DEFAULT_PELVIS_HEIGHT,
    DEFAULT_REST_JOINTS,
    JOINT_INDEX,
    NUM_JOINTS,
    forward_kinematics,
)

__all__ = [
    "PoseControls",
    "assemble_pose",
    "max_pelvis_height",
    "REST",
    "ANKLE_HEIGHT",
    "FOOT_HEIGHT",
    "LEG_LENGTH",
    "ARM_REACH",
]

REST = np.array(DEFAULT_REST_JOINTS)
_J = JOINT_INDEX

#: Height of the ankle joint above the floor in the rest pose (m).
ANKLE_HEIGHT = float(DEFAULT_PELVIS_HEIGHT + REST[_J["left_ankle"], 2])
#: Height of the foot (toe) joint above the floor in the rest pose (m).
FOOT_HEIGHT = float(DEFAULT_PELVIS_HEIGHT + REST[_J["left_foot"], 2])
#: Thigh + shank length of the authoring skeleton (m).
LEG_LENGTH = float(
    np.linalg.norm(REST[_J["left_knee"]] - REST[_J["left_hip"]])
    + np.linalg.norm(REST[_J["left_ankle"]] - REST[_J["left_knee"]])
)
#: Upper arm + forearm length of the authoring skeleton (m).
ARM_REACH = float(
    np.linalg.norm(REST[_J["left_elbow"]] - REST[_J["left_shoulder"]])
    + np.linalg.norm(REST[_J["left_wrist"]] - REST[_J["left_elbow"]])
)


@dataclasses.dataclass
class PoseControls:
    """Per-frame controls (T frames). Rotations are (T, 3, 3) matrices.

    Attributes:
        root_pos: (T, 3) pelvis position, metres (z from :func:`max_pelvis_height`).
        root_rot: (T, 3, 3) global pelvis rotation.
        spine: three (T, 3, 3) local rotations of spine1, spine2, spine3.
        neck, head: (T, 3, 3) local rotations.
        collar_raise: (T, 2) radians lifting the left / right shoulder girdle.
        wrist_target: (T, 2, 3) wanted wrist position minus the shoulder, in the chest
            (spine3) frame, as a fraction of ARM_REACH; side-agnostic (out, forward, up)
            coordinates: ``out`` > 0 points away from the body's midline.
        elbow_pole: (T, 2, 3) direction the elbow points to, same coordinates.
        wrist_flex: (T, 2) radians bending the wrists (palm side).
        ankle_target: (T, 2, 3) world ankle positions (left, right), metres.
        foot_rot: (T, 2, 3, 3) global ankle rotations (left, right).
        knee_pole: (T, 2, 3) world direction each knee points to.
        toe_bend: (T, 2) radians bending the toes up.
    """

    root_pos: np.ndarray
    root_rot: np.ndarray
    spine: tuple
    neck: np.ndarray
    head: np.ndarray
    collar_raise: np.ndarray
    wrist_target: np.ndarray
    elbow_pole: np.ndarray
    wrist_flex: np.ndarray
    ankle_target: np.ndarray
    foot_rot: np.ndarray
    knee_pole: np.ndarray
    toe_bend: np.ndarray


def _side_to_world(vec: np.ndarray, side: int) -> np.ndarray:
    """(out, forward, up) -> (x, y, z) for the left (side 0, out = -x) or right (side 1) arm."""
    out = np.array(vec, dtype=np.float64, copy=True)
    if side == 0:
        out[..., 0] *= -1.0
    return out


def max_pelvis_height(
    root_xy: np.ndarray,
    root_rot: np.ndarray,
    ankle_target: np.ndarray,
    reach: float = 0.975,
    active: np.ndarray | None = None,
) -> np.ndarray:
    """(T,) highest pelvis z for which both ankles are within ``reach`` of the leg length.

    root_xy: (T, 2) metres; root_rot: (T, 3, 3); ankle_target: (T, 2, 3) metres;
    active: (T, 2) bool, the legs that constrain the height (default both; e.g. only
    the legs on the ground).
    """
    limit = reach * LEG_LENGTH
    best = np.full(root_xy.shape[0], np.inf)
    for side, hip in enumerate(("left_hip", "right_hip")):
        off = root_rot @ REST[_J[hip]]
        dxy = root_xy + off[:, :2] - ankle_target[:, side, :2]
        horiz = np.sum(dxy * dxy, axis=-1)
        z = ankle_target[:, side, 2] - off[:, 2] + np.sqrt(np.maximum(limit * limit - horiz, 0.0))
        if active is not None:
            z = np.where(active[:, side], z, np.inf)
        best = np.minimum(best, z)
    return best


def assemble_pose(c: PoseControls) -> tuple[np.ndarray, np.ndarray]:
    """Joint rotations (T, 24, 3) axis-angle and root translation (T, 3) from controls."""
    t = c.root_pos.shape[0]
    local = np.broadcast_to(np.eye(3), (t, NUM_JOINTS, 3, 3)).copy()
    local[:, 0] = c.root_rot
    for name, rot in zip(("spine1", "spine2", "spine3"), c.spine, strict=True):
        local[:, _J[name]] = rot
    local[:, _J["neck"]] = c.neck
    local[:, _J["head"]] = c.head
    local[:, _J["left_collar"]] = rot_y(c.collar_raise[:, 0])
    local[:, _J["right_collar"]] = rot_y(-c.collar_raise[:, 1])
    glob, pos = forward_kinematics(REST, local, c.root_pos, rotations_are_matrices=True)

    chest = glob[:, _J["spine3"]]
    for side, prefix in enumerate(("left", "right")):
        sh, el, wr = (_J[f"{prefix}_{n}"] for n in ("shoulder", "elbow", "wrist"))
        collar = _J[f"{prefix}_collar"]
        target = pos[:, sh] + np.einsum("tab,tb->ta", chest, _side_to_world(c.wrist_target[:, side], side) * ARM_REACH)
        pole = np.einsum("tab,tb->ta", chest, _side_to_world(c.elbow_pole[:, side], side))
        rest_pole = np.array([0.0, -1.0, 0.0])
        loc_a, loc_b, glob_b = two_bone_ik(
            pos[:, sh], target, pole, glob[:, collar], REST[sh], REST[el], REST[wr], rest_pole
        )
        local[:, sh], local[:, el] = loc_a, loc_b
        # Wrist flexion: palm towards the forearm's flexion side (about the elbow hinge).
        flex = c.wrist_flex[:, side] * (1.0 if side == 0 else -1.0)
        local[:, wr] = _about_axis(np.array([0.0, 0.0, -1.0]), flex)

    pelvis = glob[:, 0]
    for side, prefix in enumerate(("left", "right")):
        hip, knee, ankle, foot = (_J[f"{prefix}_{n}"] for n in ("hip", "knee", "ankle", "foot"))
        loc_a, loc_b, glob_b = two_bone_ik(
            pos[:, hip],
            c.ankle_target[:, side],
            c.knee_pole[:, side],
            pelvis,
            REST[hip],
            REST[knee],
            REST[ankle],
            np.array([0.0, 1.0, 0.0]),
        )
        local[:, hip], local[:, knee] = loc_a, loc_b
        local[:, ankle] = np.swapaxes(glob_b, -1, -2) @ c.foot_rot[:, side]
        local[:, foot] = _about_axis(np.array([1.0, 0.0, 0.0]), c.toe_bend[:, side])
    return matrix_to_axis_angle(local), np.array(c.root_pos, dtype=np.float64)


def _about_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    return axis_angle_to_matrix(np.asarray(angle, dtype=np.float64)[..., None] * axis)

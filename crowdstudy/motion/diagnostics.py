"""Quality measures of an animation's feet: contacts and foot skate.

A foot joint (ankle or ball of the foot) is *in contact* while it is within
``height_tol`` of its lowest height in the animation (and, optionally, moves horizontally
slower than ``speed_tol``); the skate of a contact is the horizontal distance the joint
travels during it. Rolling the foot (heel rise, toe landing) moves the joints by a few
millimetres before they leave this band, so a clean animation shows about 1 cm per
contact. Without a speed criterion (the default) a foot dragged fast along the floor
counts in full.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.scene import CrowdAnimation

__all__ = ["FOOT_JOINTS", "joint_positions", "foot_skate"]

FOOT_JOINTS = ("left_ankle", "right_ankle", "left_foot", "right_foot")


def joint_positions(anim: CrowdAnimation, rest_joints: np.ndarray | None = None) -> np.ndarray:
    """(T, N, 24, 3) world joint positions (m) of every character, on its body's rest joints
    (``load_body(anim.bodies[i])``) unless ``rest_joints`` (N, 24, 3) is given."""
    if rest_joints is None:
        from crowdstudy.body import load_body

        rest_joints = np.stack([load_body(b).rest_joints for b in anim.bodies])
    rest = np.asarray(rest_joints, dtype=np.float64)
    if rest.shape != (anim.n_characters, anim.n_joints, 3):
        raise InvalidInputError(
            f"rest_joints: expected shape ({anim.n_characters}, {anim.n_joints}, 3), got {rest.shape}"
        )
    return forward_kinematics(rest[None], anim.joint_rotations, anim.root_translation, anim.parents)[1]


def foot_skate(
    anim: CrowdAnimation,
    *,
    height_tol: float = 0.01,
    speed_tol: float | None = None,
    rest_joints: np.ndarray | None = None,
) -> np.ndarray:
    """Horizontal travel (m) of every foot contact: a 1-D array, one entry per contact
    (all characters, the 4 foot joints). See the module docstring for the definition."""
    pos = joint_positions(anim, rest_joints)
    out = []
    for name in FOOT_JOINTS:
        p = pos[:, :, JOINT_INDEX[name]]  # (T, N, 3)
        z = p[..., 2]
        step = np.linalg.norm(np.diff(p[..., :2], axis=0), axis=-1)  # (T-1, N)
        contact = (z[:-1] < z.min(axis=0) + height_tol) & (z[1:] < z.min(axis=0) + height_tol)
        if speed_tol is not None:
            contact &= step * anim.fps < speed_tol
        for i in range(p.shape[1]):
            c = contact[:, i]
            if not c.any():
                continue
            edges = np.diff(np.concatenate([[0], c.astype(np.int8), [0]]))
            starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
            sums = np.add.reduceat(np.where(c, step[:, i], 0.0), starts) if len(starts) else []
            out.extend(float(v) for v, a, b in zip(sums, starts, stops, strict=True) if b > a)
    return np.asarray(out)

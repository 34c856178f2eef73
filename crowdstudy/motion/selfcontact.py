"""Self-contact of a retargeted clip: how far its own limbs interpenetrate, and keeping the
hands out of the body.

Motion capture is performed by one person and played on bodies of other widths: a
performer's hands on her hips or clasped in front of his chest end up inside a wider
body, an arm waved overhead passes through a taller head. The physics layer would then
have to push a character out of itself (its intra-body contacts are measured relative to
the animation, so it does not; the hands stay inside the mesh in both Baseline and Ours).

* :func:`self_penetration` measures it with the capsules the physics uses: every pair of
  bones it tests (not parent and child, not touching in the T-pose), depth ``r_i + r_j -
  distance``. Capsules are fatter than the mesh: a person standing with the arms hanging
  already overlaps by about 5 cm between forearm and waist, so the measure reports the
  depth *beyond* what :data:`SLACK` allows, for the hand capsules against the torso and head.
* :func:`clear_hands` moves each hand out of its own body's torso and head capsules
  (beyond the slack) with analytic arm IK (shoulder-elbow-wrist, the elbow keeping its
  direction, the hand its global orientation), smoothed in time, on each character's own
  body (:func:`~crowdstudy.motion.baseline.animate_stationary` calls it after
  ``plant_legs``). Hand-to-hand contact (claps) is left as captured.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.capsules import closest_points_on_segments, posed_capsules, segment_distance, touching_pairs
from crowdstudy.body.posing import hold_peaks, smoothstep5, two_bone_ik
from crowdstudy.body.rotations import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quat_blend,
    quaternion_to_matrix,
)
from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, forward_kinematics

__all__ = ["SLACK", "HAND_BONES", "BODY_BONES", "hand_penetration", "self_penetration", "clear_hands"]

#: Capsule overlap (m) allowed between a hand and the torso or head (capsules are fatter
#: than the mesh; a hand resting on the hip overlaps by about this much).
SLACK = 0.02
#: The hand capsules of each side (bone of the wrist joint: the palm; of the hand joint:
#: the fingers).
HAND_BONES = {side: (JOINT_INDEX[f"{side}_wrist"], JOINT_INDEX[f"{side}_hand"]) for side in ("left", "right")}
#: The bones a hand must stay out of: pelvis, spine, head.
BODY_BONES = tuple(JOINT_INDEX[n] for n in ("pelvis", "spine1", "spine2", "spine3", "head"))
_SMOOTH = 0.06  # s, Gaussian smoothing of the hand offsets
_HOLD = 0.1  # s, an offset is held this long around its peak before it is smoothed
_ITERATIONS = 3


def _pushes(start: np.ndarray, end: np.ndarray, radius: np.ndarray, slack: float) -> tuple[np.ndarray, np.ndarray]:
    """Per side, the hand displacement (T, 2, 3) that clears the body bones by ``slack``, and
    the deepest excess overlap (T, 2) m. start, end: (T, 24, 3) posed capsules; radius (24,)."""
    n = start.shape[0]
    push = np.zeros((n, 2, 3))
    depth = np.zeros((n, 2))
    body = np.array(BODY_BONES)
    for k, side in enumerate(("left", "right")):
        for h in HAND_BONES[side]:
            s, t, dist = closest_points_on_segments(start[:, h, None], end[:, h, None], start[:, body], end[:, body])
            cp = start[:, h, None] + s[..., None] * (end[:, h, None] - start[:, h, None])
            cq = start[:, body] + t[..., None] * (end[:, body] - start[:, body])
            over = radius[h] + radius[body][None, :] - dist - slack  # (T, B)
            normal = (cp - cq) / np.maximum(dist, 1e-9)[..., None]
            vec = np.where((over > 0)[..., None], normal * over[..., None], 0.0).sum(axis=1)  # (T, 3)
            bigger = np.linalg.norm(vec, axis=-1) > np.linalg.norm(push[:, k], axis=-1)
            push[:, k] = np.where(bigger[:, None], vec, push[:, k])
            depth[:, k] = np.maximum(depth[:, k], np.maximum(over, 0.0).max(axis=1))
    return push, depth


def hand_penetration(
    body, joint_rotations: np.ndarray, root_translation: np.ndarray, slack: float = SLACK
) -> np.ndarray:
    """(T, 2) deepest overlap (m) of each (left, right) hand with the torso and head capsules
    of ``body`` beyond ``slack``, for poses (T, 24, 3) / (T, 3)."""
    start, end = posed_capsules(body, joint_rotations, root_translation)
    return _pushes(start, end, np.asarray(body.capsules.radius, dtype=np.float64), slack)[1]


def self_penetration(
    body, joint_rotations: np.ndarray, root_translation: np.ndarray, *, tolerance: float = 0.01
) -> dict:
    """How far a clip's own capsules interpenetrate on ``body``.

    Counts the pairs the physics tests (not parent-child, not within ``r_i + r_j +
    tolerance`` in the T-pose). Returns ``{"max_depth": m, "p95_depth": m (95th percentile
    over frames of the deepest pair), "worst_pair": (joint, joint), "worst_frame": int,
    "hands_max": m, "hands_p95": m (the hands against torso and head beyond SLACK)}``.
    """
    caps = body.capsules
    i, j = np.triu_indices(NUM_JOINTS, k=1)
    skip = {tuple(p) for p in touching_pairs(caps, margin=tolerance)}
    keep = np.array([(a, b) not in skip for a, b in zip(i, j, strict=True)])
    i, j = i[keep], j[keep]
    start, end = posed_capsules(body, joint_rotations, root_translation)
    dist = segment_distance(start[:, i], end[:, i], start[:, j], end[:, j])
    depth = np.maximum(0.0, caps.radius[i] + caps.radius[j] - dist)
    worst = depth.max(axis=1)
    f = int(np.argmax(worst))
    p = int(np.argmax(depth[f]))
    hands = _pushes(start, end, np.asarray(caps.radius, dtype=np.float64), SLACK)[1].max(axis=1)
    return {
        "max_depth": float(worst.max()),
        "p95_depth": float(np.percentile(worst, 95)),
        "worst_pair": (JOINT_NAMES[i[p]], JOINT_NAMES[j[p]]),
        "worst_frame": f,
        "hands_max": float(hands.max()),
        "hands_p95": float(np.percentile(hands, 95)),
    }


def _smooth(push: np.ndarray, fps: float) -> np.ndarray:
    """Offsets (T, ..., 3) held around their peaks (per component, the value of largest
    magnitude within +-_HOLD) and Gaussian smoothed: on before contact, off after it."""
    from scipy.ndimage import gaussian_filter1d

    held = hold_peaks(push, max(1, int(round(_HOLD * fps))), "nearest")
    return gaussian_filter1d(held, _SMOOTH * fps, axis=0, mode="nearest")


def clear_hands(
    joint_rotations: np.ndarray, root_translation: np.ndarray, bodies: list, fps: float, *, slack: float = SLACK
) -> np.ndarray:
    """(T, N, 24, 3) rotations with each character's hands moved out of its own torso and
    head (see the module docstring). ``bodies``: N loaded bodies (``rest_joints``,
    ``capsules``); ``root_translation`` (T, N, 3) m."""
    out = np.array(joint_rotations, dtype=np.float64, copy=True)
    for c, body in enumerate(bodies):
        rest = np.asarray(body.rest_joints, dtype=np.float64)
        radius = np.asarray(body.capsules.radius, dtype=np.float64)
        rot = out[:, c]
        root = root_translation[:, c]
        total = np.zeros((rot.shape[0], 2, 3))
        orig = rot.copy()
        for _ in range(_ITERATIONS):
            start, end = posed_capsules(body, rot, root)
            push, _depth = _pushes(start, end, radius, slack)
            if not np.any(push):
                break
            total = total + push
            rot = _solve_arms(orig, root, rest, _smooth(total, fps))
        out[:, c] = rot
    return out


def _solve_arms(rot: np.ndarray, root: np.ndarray, rest: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Axis-angle rotations (T, 24, 3): ``rot`` with each wrist moved by ``offset`` (T, 2, 3) m
    (arm IK), blended in where the offset is non-zero; other joints and frames unchanged."""
    orig = axis_angle_to_matrix(rot)
    glob, pos = forward_kinematics(rest, orig, root, rotations_are_matrices=True)
    out = np.array(rot, copy=True)
    for k, side in enumerate(("left", "right")):
        sh, el, wr, co = (JOINT_INDEX[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist", "collar"))
        size = np.linalg.norm(offset[:, k], axis=-1)
        if not np.any(size > 0):
            continue
        target = pos[:, wr] + offset[:, k]
        pole = pos[:, el] - pos[:, sh]
        loc_a, loc_b, glob_b = two_bone_ik(
            pos[:, sh],
            target,
            pole,
            glob[:, co],
            rest[sh],
            rest[el],
            rest[wr],
            np.array([0.0, -1.0, 0.0]),
            max_reach=0.995,
        )
        loc_c = np.swapaxes(glob_b, -1, -2) @ glob[:, wr]  # keep the hand's orientation
        w = smoothstep5(size / 0.01)[:, None, None]  # 0 without offset, 1 beyond 1 cm
        moved = size > 0
        for j, new in ((sh, loc_a), (el, loc_b), (wr, loc_c)):
            out[moved, j] = matrix_to_axis_angle(_blend(orig[moved, j], new[moved], w[moved]))
    return out


def _blend(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotation matrices (T, 3, 3) from ``a`` (w = 0) to ``b`` (w = 1), through quaternion nlerp."""
    return quaternion_to_matrix(quat_blend(matrix_to_quaternion(a), matrix_to_quaternion(b), w[..., 0]))

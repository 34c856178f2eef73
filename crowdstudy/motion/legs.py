"""Legs re-solved by analytic IK so the feet go where the clip (or a lock) puts them.

:func:`plant_legs` is shared by the Baseline (bodies of other proportions than the
authoring skeleton; foot locking in the corridor's speed blends) and the motion-capture
cleaning (:mod:`crowdstudy.motion.mocap`, :mod:`crowdstudy.motion.mocap_walks`: planted
feet held where their contact began).
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.posing import smoothstep5, two_bone_ik
from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from crowdstudy.body.skeleton import JOINT_INDEX
from crowdstudy.motion.rig import ANKLE_HEIGHT, REST

__all__ = ["plant_legs"]

#: Fraction of the swing over which a foot-lock offset fades out.
_FADE_END = 0.8


def _segment_starts(mask: np.ndarray, wrapped: np.ndarray) -> np.ndarray:
    """(T, N) index of the first frame of the current run of ``mask`` (-1 outside runs); a
    run also restarts where ``wrapped`` (a new gait cycle) is set."""
    frames = np.arange(mask.shape[0])[:, None]
    prev = np.concatenate([np.zeros((1,) + mask.shape[1:], bool), mask[:-1]], axis=0)
    start = mask & (~prev | wrapped)
    idx = np.maximum.accumulate(np.where(start, frames, -1), axis=0)
    return np.where(mask, idx, -1)


def _lock_offsets(
    ankle: np.ndarray,
    ball: np.ndarray,
    foot_phase: np.ndarray,
    flat_end: float | np.ndarray,
    stance_end: float | np.ndarray,
) -> np.ndarray:
    """(T, N, 3) horizontal corrections of an ankle target that pin the foot on the floor.

    ankle, ball: (T, N, 3) the clip's ankle and ball-of-foot positions; foot_phase: (T, N)
    phase since this foot's heel strike. While flat (``phase < flat_end``) the ankle is
    held where the stance began; then, while the heel rises (until ``stance_end``), the
    ball of the foot is held; the offset left at toe-off fades out (quintic smoothstep)
    before the heel comes down (by 80 % of the swing). Without it, a clip blend that changes under a planted foot
    (speed changes) makes the foot slide.
    """
    cols = np.arange(ankle.shape[1])[None, :]
    wrapped = np.concatenate([np.zeros((1,) + foot_phase.shape[1:], bool), foot_phase[1:] < foot_phase[:-1]], 0)
    flat = foot_phase < flat_end
    roll = (foot_phase >= flat_end) & (foot_phase < stance_end)
    offset = np.zeros(ankle.shape)
    start = _segment_starts(flat, wrapped)
    offset[..., :2] = np.where((start >= 0)[..., None], ankle[np.maximum(start, 0), cols, :2] - ankle[..., :2], 0.0)
    # heel rise: hold the ball where it was (with the flat-phase offset it had then)
    flat_start = start
    start = _segment_starts(roll, wrapped)
    s0 = np.maximum(start, 0)
    before = np.maximum(s0 - 1, 0)
    was_flat = flat[before, cols] & (start > 0)
    held = ankle[np.maximum(flat_start[before, cols], 0), cols, :2] - ankle[s0, cols, :2]  # flat offset at s0
    ball_lock = ball[s0, cols, :2] + np.where(was_flat[..., None], held, 0.0)
    offset[..., :2] = np.where((start >= 0)[..., None], ball_lock - ball[..., :2], offset[..., :2])
    # swing: carry the last stance offset, fading out by the next heel strike
    frames = np.arange(ankle.shape[0])[:, None]
    last = np.maximum.accumulate(np.where(flat | roll, frames, -1), axis=0)
    fade = 1.0 - smoothstep5((foot_phase - stance_end) / (_FADE_END * (1.0 - stance_end)))
    swing = ~(flat | roll) & (last >= 0)
    return np.where(swing[..., None], offset[np.maximum(last, 0), cols] * fade[..., None], offset)


def plant_legs(
    joint_rotations: np.ndarray,
    root_translation: np.ndarray,
    rest_joints: np.ndarray,
    scale: np.ndarray,
    ankle_height: np.ndarray,
    foot_phase: np.ndarray | None = None,
    flat_end: float | np.ndarray = 0.0,
    stance_end: float | np.ndarray = 0.0,
    ankle_offsets: np.ndarray | None = None,
) -> np.ndarray:
    """Re-solve the legs so each body puts its ankles where the clip put them.

    The clips are authored on :data:`DEFAULT_REST_JOINTS`; a body with other proportions
    posed with the same rotations would lift, sink or slide its feet. The wanted ankle
    positions are those of the authoring skeleton scaled by ``scale`` (with the ankle
    height above the floor corrected to the body's own), reached by analytic two-bone IK
    on the body's thigh and shank; the feet keep the clip's global orientation.

    Args:
        joint_rotations: (T, N, 24, 3) axis-angle; root_translation: (T, N, 3) metres.
        rest_joints: (N, 24, 3) metres; scale: (N,); ankle_height: (N,) metres.
        foot_phase: optional (T, N, 2) phase since each foot's (left, right) heel strike;
            with it the ankles are also pinned while ``foot_phase < flat_end`` (the clip
            blend changing under a planted foot would otherwise make it slide): the ankle
            while ``foot_phase < flat_end``, the ball of the foot until ``stance_end``.
        flat_end, stance_end: phases since each foot's heel strike, numbers or arrays
            broadcastable to ``foot_phase`` (per frame, character and foot).
        ankle_offsets: optional (T, N, 2, 3) metres added to the (left, right) ankle targets
            (e.g. holding a planted foot where its contact began).

    Returns:
        (T, N, 24, 3) joint rotations with new hip, knee and ankle rotations.
    """
    out = np.array(joint_rotations, dtype=np.float64, copy=True)
    s = scale[None, :, None]
    pelvis = axis_angle_to_matrix(out[:, :, 0])
    for k, side in enumerate(("left", "right")):
        hip, knee, ankle = (JOINT_INDEX[f"{side}_{n}"] for n in ("hip", "knee", "ankle"))
        r_hip, r_knee, r_ankle = (axis_angle_to_matrix(out[:, :, j]) for j in (hip, knee, ankle))
        g_hip = pelvis @ r_hip
        g_knee = g_hip @ r_knee
        g_ankle = g_knee @ r_ankle
        hip_pos = root_translation + s * np.einsum("tnab,b->tna", pelvis, REST[hip])
        knee_pos = hip_pos + s * np.einsum("tnab,b->tna", g_hip, REST[knee] - REST[hip])
        ankle_pos = knee_pos + s * np.einsum("tnab,b->tna", g_knee, REST[ankle] - REST[knee])
        ankle_pos[..., 2] += ankle_height[None, :] - scale[None, :] * ANKLE_HEIGHT
        if foot_phase is not None:
            # the body's own ball of the foot (its ankle-to-toe offset, not the authoring
            # skeleton's): that is the point that must not slide while the heel rises
            ball_pos = ankle_pos + np.einsum("tnab,nb->tna", g_ankle, rest_joints[:, ankle + 3] - rest_joints[:, ankle])
            fe, se = (
                np.broadcast_to(np.asarray(x, dtype=np.float64), foot_phase.shape)[..., k]
                for x in (flat_end, stance_end)
            )
            ankle_pos += _lock_offsets(ankle_pos, ball_pos, foot_phase[..., k], fe, se)
        if ankle_offsets is not None:
            ankle_pos = ankle_pos + ankle_offsets[..., k, :]
        pole = 2.0 * knee_pos - hip_pos - ankle_pos + 0.02 * g_hip[..., :, 1]
        body_hip = root_translation + np.einsum("tnab,nb->tna", pelvis, rest_joints[:, hip] - rest_joints[:, 0])
        loc_a, loc_b, glob_b = two_bone_ik(
            body_hip,
            ankle_pos,
            pole,
            pelvis,
            rest_joints[:, hip],
            rest_joints[:, knee],
            rest_joints[:, ankle],
            np.array([0.0, 1.0, 0.0]),
        )
        out[:, :, hip] = matrix_to_axis_angle(loc_a)
        out[:, :, knee] = matrix_to_axis_angle(loc_b)
        out[:, :, ankle] = matrix_to_axis_angle(np.swapaxes(glob_b, -1, -2) @ g_ankle)
    return out

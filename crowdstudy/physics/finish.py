"""The output stage of the correction: loop seams, a low-pass of the deviation, planted feet.

The physics (:mod:`crowdstudy.physics.solver`) produces, frame by frame, the simulated pose
of every character. Three steps turn it into the "Ours" animation, each on plain arrays:

* :func:`close_loop`: for a periodic input (a concert stimulus that loops), the correction
  was simulated past one period; the first frames of the output are cross-faded from the
  continuation of the last frame, so frame T-1 -> frame 0 continues the motion.
* :func:`smooth_deviation`: a zero-phase Gaussian low-pass (``PhysicsConfig.output_smoothing``
  seconds) of the DEVIATION from the input animation (joint rotations relative to the
  input's, ``R = R^ exp([delta]x)``, and the root offset), never of the animation itself,
  so the input's own motion keeps every detail; circular for periodic clips. The residual
  overlap is measured after it (``crowdstudy bench physics --bars``).
* :func:`lock_planted_feet`: while the input's ankle is planted, the output's ankle is held
  at one place (its mean over the stance) by two-bone IK of the leg, the offset faded in and
  out over a few frames of the swing: a pushed character keeps its feet where they stand
  instead of sliding them.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.rotations import (axis_angle_to_quaternion, matrix_to_axis_angle, matrix_to_quaternion,
                                       quaternion_to_axis_angle, quaternion_to_matrix)
from crowdstudy.body.skeleton import JOINT_INDEX, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.posing import smoothstep5, two_bone_ik
from crowdstudy.motion.quaternions import quat_blend, quat_conjugate, quat_multiply

__all__ = ["close_loop", "smooth_deviation", "lock_planted_feet", "planted_runs"]

LEGS = tuple(tuple(JOINT_INDEX[f"{side}_{name}"] for name in ("hip", "knee", "ankle")) for side in ("left", "right"))


def close_loop(rot: np.ndarray, root: np.ndarray, n_frames: int, warmup: int, blend: int):
    """One period of an output simulated over ``warmup + n_frames + blend`` input frames.

    The input was fed as frames ``[T - warmup, T) + [0, T) + [0, blend)`` of a periodic clip
    (T = ``n_frames``). The result is frames ``warmup .. warmup + T`` of the simulation, its
    first ``blend`` frames cross-faded (quintic smoothstep, nlerp of rotations) from the
    continuation ``warmup + T + k`` to ``warmup + k``: frame T-1 -> frame 0 is then one
    simulated step, and the loop has no seam.

    Args:
        rot: (warmup + T + blend, N, J, 3) axis-angle rad; root: (..., N, 3) m.
    Returns:
        ``(rot (T, N, J, 3), root (T, N, 3))``.
    """
    total = warmup + n_frames + blend
    if rot.shape[0] != total or root.shape[0] != total:
        raise InvalidInputError(f"rot/root: expected {total} frames (warmup + n_frames + blend), "
                                f"got {rot.shape[0]} and {root.shape[0]}")
    if blend > n_frames:
        raise InvalidInputError(f"blend: expected at most n_frames = {n_frames}, got {blend}")
    out_rot = rot[warmup:warmup + n_frames].copy()
    out_root = root[warmup:warmup + n_frames].copy()
    if blend:
        w = smoothstep5((np.arange(blend) + 1.0) / (blend + 1.0))     # weight of the clip's own frame
        cont = slice(warmup + n_frames, total)
        q = quat_blend(axis_angle_to_quaternion(rot[cont]), axis_angle_to_quaternion(out_rot[:blend]),
                       w[:, None, None])
        out_rot[:blend] = quaternion_to_axis_angle(q)
        out_root[:blend] = (1.0 - w)[:, None, None] * root[cont] + w[:, None, None] * out_root[:blend]
    return out_rot, out_root


def smooth_deviation(rot: np.ndarray, root: np.ndarray, ref_rot: np.ndarray, ref_root: np.ndarray,
                     sigma_frames: float, *, periodic: bool = False):
    """Low-pass the deviation of (rot, root) from (ref_rot, ref_root) along time.

    Args:
        rot, ref_rot: (T, N, J, 3) axis-angle rad (joint 0 global, others parent-relative).
        root, ref_root: (T, N, 3) m.
        sigma_frames: standard deviation of the Gaussian kernel, frames (0: unchanged).
        periodic: the clip loops (frame T follows frame T-1): filter circularly.

    Returns:
        ``(rot, root)`` with ``R = R^ exp([g * delta]x)`` and ``root = root^ + g * (root -
        root^)``, g the Gaussian and delta = log(R^^T R) per joint.
    """
    if sigma_frames < 0:
        raise InvalidInputError(f"sigma_frames: expected >= 0, got {sigma_frames!r}")
    if sigma_frames == 0 or rot.shape[0] < 2:
        return rot, root
    from scipy.ndimage import gaussian_filter1d

    mode = "wrap" if periodic else "nearest"
    q_ref = axis_angle_to_quaternion(ref_rot)
    delta = quaternion_to_axis_angle(quat_multiply(quat_conjugate(q_ref), axis_angle_to_quaternion(rot)))
    delta = gaussian_filter1d(delta, sigma_frames, axis=0, mode=mode)
    offset = gaussian_filter1d(root - ref_root, sigma_frames, axis=0, mode=mode)
    out = quaternion_to_axis_angle(quat_multiply(q_ref, axis_angle_to_quaternion(delta)))
    return out, ref_root + offset


def planted_runs(mask: np.ndarray, *, periodic: bool = False) -> list[tuple[int, int]]:
    """Runs ``[start, stop)`` of True in a (T,) mask; for a periodic mask a run may wrap
    (``stop > T``); a mask that is all True is one run ``(0, T)``."""
    mask = np.asarray(mask, bool)
    n = len(mask)
    if not mask.any():
        return []
    if mask.all():
        return [(0, n)]
    shift = int(np.argmin(mask)) if periodic else 0        # start the scan on a free frame
    m = np.roll(mask, -shift)
    edges = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a + shift), int(b + shift)) for a, b in zip(starts, stops)]


def _ankle_offsets(ankle: np.ndarray, ref_ankle: np.ndarray, fps: float, planted_speed: float,
                   planted_height: float, fade: int, periodic: bool) -> np.ndarray:
    """(T, 2) horizontal offsets that hold one ankle at its mean position over each stance of
    the reference (speed below ``planted_speed`` m/s, height within ``planted_height`` m of
    its lowest), faded out over ``fade`` frames on both sides of the stance, and (T,) the
    hold's weight (1 in the stance)."""
    n = len(ankle)
    vel = np.gradient(ref_ankle[:, :2], axis=0) * fps
    if periodic:
        vel = 0.5 * (np.roll(ref_ankle[:, :2], -1, 0) - np.roll(ref_ankle[:, :2], 1, 0)) * fps
    low = ref_ankle[:, 2] <= ref_ankle[:, 2].min() + planted_height
    mask = (np.linalg.norm(vel, axis=1) < planted_speed) & low
    offset = np.zeros((n, 2))
    weight = np.zeros(n)
    for start, stop in planted_runs(mask, periodic=periodic):
        idx = np.arange(start, stop) % n
        lock = ankle[idx, :2].mean(axis=0)
        offset[idx] = lock - ankle[idx, :2]
        weight[idx] = 1.0
        if stop - start >= n:
            continue
        for side, edge in ((-1, start), (1, stop - 1)):
            for k in range(1, fade + 1):
                t = edge + side * k
                if not periodic and not 0 <= t < n:
                    break
                t %= n
                w = 1.0 - smoothstep5(np.array(k / (fade + 1.0)))
                if w > weight[t]:
                    weight[t] = float(w)
                    offset[t] = w * (lock - ankle[t, :2])
    return offset, weight


def lock_planted_feet(rot: np.ndarray, root: np.ndarray, ref_rot: np.ndarray, ref_root: np.ndarray,
                      rest_joints: np.ndarray, fps: float, *, planted_speed: float = 0.02,
                      planted_height: float = 0.03, fade_frames: int = 4, periodic: bool = False) -> np.ndarray:
    """Hold the output's feet still while the reference's are planted (two-bone leg IK).

    The ankle is held while the reference's ankle is planted; while only the ball of the foot
    is (heel rise), the ankle goes where the held ball and the reference's foot orientation
    put it.

    Args:
        rot, ref_rot: (T, N, 24, 3) axis-angle rad; root, ref_root: (T, N, 3) m.
        rest_joints: (N, 24, 3) m, each character's rest joints.
        fps: frame rate, Hz.
        planted_speed: m/s, the reference's ankle counts as planted below this horizontal
            speed (and within ``planted_height`` m of its lowest height).
        fade_frames: frames of the swing over which the hold fades in and out.
        periodic: the clip loops (stances may wrap around the seam).

    Returns:
        (T, N, 24, 3) joint rotations with new hip, knee and ankle rotations (the foot keeps
        its global orientation); the ankle's height is the output's own.
    """
    rest = np.asarray(rest_joints, np.float64)
    glob, pos = forward_kinematics(rest[None], rot, root, parents=PARENTS)
    ref_glob, ref_pos = forward_kinematics(rest[None], ref_rot, ref_root, parents=PARENTS)
    out = np.array(rot, dtype=np.float64, copy=True)
    n_chars = rot.shape[1]
    for hip, knee, ankle in LEGS:
        toe = ankle + 3                                  # the ball of the foot (left_foot / right_foot)
        target = pos[:, :, ankle].copy()
        toe_target = pos[:, :, toe].copy()
        weight = np.zeros(target.shape[:2])
        toe_weight = np.zeros(target.shape[:2])
        for i in range(n_chars):
            offset, weight[:, i] = _ankle_offsets(pos[:, i, ankle], ref_pos[:, i, ankle], fps, planted_speed,
                                                  planted_height, fade_frames, periodic)
            target[:, i, :2] += offset
            offset, toe_weight[:, i] = _ankle_offsets(pos[:, i, toe], ref_pos[:, i, toe], fps, planted_speed,
                                                      planted_height, fade_frames, periodic)
            toe_target[:, i, :2] += offset
        # heel rise (the ball planted, the ankle not): put the ankle where the held ball and the
        # input's foot orientation want it
        toe_only = toe_weight > weight
        from_toe = toe_target - np.einsum("tnab,nb->tna", ref_glob[:, :, ankle], rest[:, toe] - rest[:, ankle])
        blend_toe = pos[:, :, ankle] + toe_weight[..., None] * (from_toe - pos[:, :, ankle])
        blend_toe[..., 2] = pos[:, :, ankle, 2]
        target = np.where(toe_only[..., None], blend_toe, target)
        weight = np.maximum(weight, toe_weight)
        moved = weight > 0                                                          # (T, N)
        if not moved.any():
            continue
        t_idx, c_idx = np.nonzero(moved)
        pole = (2.0 * pos[t_idx, c_idx, knee] - pos[t_idx, c_idx, hip] - pos[t_idx, c_idx, ankle]
                + 0.02 * glob[t_idx, c_idx, hip][:, :, 1])
        pelvis = glob[t_idx, c_idx, 0]
        loc_a, loc_b, glob_b = two_bone_ik(pos[t_idx, c_idx, hip], target[t_idx, c_idx], pole, pelvis,
                                           rest[c_idx, hip], rest[c_idx, knee], rest[c_idx, ankle],
                                           np.array([0.0, 1.0, 0.0]))
        out[t_idx, c_idx, hip] = matrix_to_axis_angle(loc_a)
        out[t_idx, c_idx, knee] = matrix_to_axis_angle(loc_b)
        # the planted foot keeps the input's world orientation (it does not turn on the floor)
        w = weight[t_idx, c_idx]
        foot = quat_blend(matrix_to_quaternion(glob[t_idx, c_idx, ankle]),
                          matrix_to_quaternion(ref_glob[t_idx, c_idx, ankle]), w)
        ankle_local = np.swapaxes(glob_b, -1, -2) @ quaternion_to_matrix(foot)
        out[t_idx, c_idx, ankle] = matrix_to_axis_angle(ankle_local)
    return out


"""The output stage of the correction: loop seams, a low-pass of the deviation, planted feet.

The physics (:mod:`crowdstudy.physics.solver`) produces, frame by frame, the simulated pose
of every character. Three steps turn it into the "Ours" animation, each on plain arrays:

* :func:`close_loop`: for a periodic input (a concert stimulus that loops), the correction
  was simulated past one period; the first frames of the output are cross-faded from the
  continuation of the last frame, so frame T-1 -> frame 0 continues the motion.
* :func:`smooth_deviation`: a zero-phase Gaussian low-pass (``PhysicsConfig.output.smoothing``
  seconds, ``output.smoothing_root`` for the root) of the DEVIATION from the input
  animation (joint rotations relative to the input's, ``R = R^ exp([delta]x)``, and the
  root offset), never of the animation itself, so the input's own motion keeps every
  detail; each deviation is first held at its peak over +-``output.hold`` kernel widths, so
  the separation a contact needed is kept while the correction eases in and out around it;
  circular for periodic clips. The residual overlap is measured after this stage
  (``crowdstudy bench physics --bars``).
* :func:`lock_planted_feet`: while the input's foot is planted (ankle or ball), the output's
  foot moves as the input's at one constant offset (two-bone IK of the leg, the input's
  foot orientation), the offset handed smoothly through the swing to the next contact: a
  pushed character keeps its feet where they stand instead of sliding them.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.posing import hold_peaks, planted_runs, smoothstep5, two_bone_ik
from crowdstudy.body.rotations import (
    axis_angle_to_quaternion,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    quat_blend,
    quat_conjugate,
    quat_multiply,
    quaternion_to_axis_angle,
    quaternion_to_matrix,
    rotation_between,
)
from crowdstudy.body.skeleton import JOINT_INDEX, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError

__all__ = ["close_loop", "smooth_deviation", "lock_planted_feet", "planted_frames"]

#: a held leg's reach is compressed smoothly beyond this fraction of the leg's length
#: (:func:`_soft_reach`: no knee pops near full extension)
SOFT_REACH = 0.97
#: the fraction of a swing at each end over which a held foot's offset eases out to / in
#: from the foot's own corrected path (:func:`_foot_hold`)
SWING_EASE = 0.25
#: a held foot may stretch the leg freely up to this fraction of its length; beyond it no
#: further than the output's own leg (:func:`_soft_reach`)
STRAIGHT_HOLD = 0.95
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
        raise InvalidInputError(
            f"rot/root: expected {total} frames (warmup + n_frames + blend), got {rot.shape[0]} and {root.shape[0]}"
        )
    if blend > n_frames:
        raise InvalidInputError(f"blend: expected at most n_frames = {n_frames}, got {blend}")
    out_rot = rot[warmup : warmup + n_frames].copy()
    out_root = root[warmup : warmup + n_frames].copy()
    if blend:
        w = smoothstep5((np.arange(blend) + 1.0) / (blend + 1.0))  # weight of the clip's own frame
        cont = slice(warmup + n_frames, total)
        q = quat_blend(axis_angle_to_quaternion(rot[cont]), axis_angle_to_quaternion(out_rot[:blend]), w[:, None, None])
        out_rot[:blend] = quaternion_to_axis_angle(q)
        out_root[:blend] = (1.0 - w)[:, None, None] * root[cont] + w[:, None, None] * out_root[:blend]
    return out_rot, out_root


def smooth_deviation(
    rot: np.ndarray,
    root: np.ndarray,
    ref_rot: np.ndarray,
    ref_root: np.ndarray,
    sigma_frames: float,
    *,
    periodic: bool = False,
    root_sigma_frames: float | None = None,
    hold: float = 0.0,
):
    """Low-pass the deviation of (rot, root) from (ref_rot, ref_root) along time.

    Args:
        rot, ref_rot: (T, N, J, 3) axis-angle rad (joint 0 global, others parent-relative).
        root, ref_root: (T, N, 3) m.
        sigma_frames: standard deviation of the Gaussian kernel, frames (0: unchanged).
        periodic: the clip loops (frame T follows frame T-1): filter circularly.
        root_sigma_frames: the root offset's own kernel width (frames; None = sigma_frames).
        hold: before the low-pass, each deviation component is held at its largest
            magnitude within +-``hold * sigma`` frames (:func:`hold_peaks`), so the low-pass
            does not shave the deviation a contact needed: the correction starts a little
            before the contact and ends a little after it instead of being flattened.

    Returns:
        ``(rot, root)`` with ``R = R^ exp([g * delta]x)`` and ``root = root^ + g * (root -
        root^)``, g the Gaussian and delta = log(R^^T R) per joint.
    """
    root_sigma = sigma_frames if root_sigma_frames is None else root_sigma_frames
    if sigma_frames < 0 or root_sigma < 0:
        raise InvalidInputError(
            f"sigma_frames, root_sigma_frames: expected >= 0, got {sigma_frames!r}, {root_sigma_frames!r}"
        )
    if (sigma_frames == 0 and root_sigma == 0) or rot.shape[0] < 2:
        return rot, root
    from scipy.ndimage import gaussian_filter1d

    mode = "wrap" if periodic else "nearest"
    q_ref = axis_angle_to_quaternion(ref_rot)
    delta = quaternion_to_axis_angle(quat_multiply(quat_conjugate(q_ref), axis_angle_to_quaternion(rot)))
    if sigma_frames > 0:
        if hold > 0:
            delta = hold_peaks(delta, int(round(hold * sigma_frames)), mode)
        delta = gaussian_filter1d(delta, sigma_frames, axis=0, mode=mode)
    offset = root - ref_root
    if root_sigma > 0:
        if hold > 0:
            offset = hold_peaks(offset, int(round(hold * root_sigma)), mode)
        offset = gaussian_filter1d(offset, root_sigma, axis=0, mode=mode)
    out = quaternion_to_axis_angle(quat_multiply(q_ref, axis_angle_to_quaternion(delta)))
    return out, ref_root + offset


def planted_frames(
    ref_joint: np.ndarray, fps: float, planted_speed: float, planted_height: float, periodic: bool
) -> np.ndarray:
    """(T,) frames at which a reference joint (T, 3) is planted.

    A STEP t -> t + 1 is planted when slow (below ``planted_speed`` m/s horizontally) and
    low (mean height of its two frames within ``planted_height`` m of the joint's lowest),
    as :func:`crowdstudy.metrics.smoothness.foot_slide` counts steps; a frame is planted
    when a step on either side of it is, so no planted step has a free end."""
    nxt = np.roll(ref_joint, -1, axis=0)
    speed = np.linalg.norm(nxt[:, :2] - ref_joint[:, :2], axis=1) * fps
    height = 0.5 * (nxt[:, 2] + ref_joint[:, 2])
    step = (speed < planted_speed) & (height <= ref_joint[:, 2].min() + planted_height)
    if not periodic:
        step[-1] = False  # no step from the last frame to the first
    return step | np.roll(step, 1)


def _foot_hold(ankle: np.ndarray, ref_ankle: np.ndarray, contact: np.ndarray, periodic: bool):
    """Ankle targets that hold one foot of one character on the floor.

    Args:
        ankle: (T, 3) the output's ankle, m.
        ref_ankle: (T, 3) the reference's ankle, m.
        contact: (T,) the reference's ankle or ball of the foot planted.

    One contact is a run of frames where the ankle or the ball is planted. Over the whole
    run the output's ankle follows the reference's ankle at one constant horizontal offset,
    the mean of the output's offset from the reference over the run (the leg reaches it
    from either end of the stance: holding the offset of the frame that needed the most,
    as before, stretched pushed walkers' legs beyond reach at the other end, and the feet
    slid, p99 4.2 cm/s against 2.4 at corridor D4). With the
    reference's foot orientation (the caller's) the whole foot then moves as the reference's
    does while it stands: its heel rise and roll over the ball, and its own slow creep below
    the planted speed, so a planted foot of Ours slides exactly as much as the Baseline's.
    (Holding the ankle still on flat frames and the ball still on heel-rise frames, as before,
    moved the foot by the reference's creep in the single frames where a mocap foot flickers
    between the two: 1-3 mm, 6-18 cm/s.) Between two contacts (a swing) the offset goes over
    from the end of the one to the start of the next along a quintic smoothstep, eased out
    to zero over the first and in over the last ``SWING_EASE`` of the swing: the foot keeps
    its own corrected swing path, displaced smoothly near the contacts, so its velocity stays
    continuous (fading towards the held place instead drags the swinging foot back and
    shows as high-frequency knee and ankle motion; carrying the offset straight through
    pushes swinging legs into the neighbours' the physics kept them clear of). In a clip that
    does not loop the swings cut by the clip's ends ease the offset in before the first
    contact and out after the last over the ``SWING_EASE`` of a whole swing of that foot.

    Returns:
        ``(pull (T, 2) m, weight (T,))``: horizontal offsets to add to the output's ankle,
        and the weight with which the foot takes the reference's orientation (1 wherever a
        foot has a contact in the clip).
    """
    n = len(ankle)
    pull = np.zeros((n, 2))
    weight = np.zeros(n)
    runs = planted_runs(contact, periodic=periodic)
    ends = []  # (start, stop, offset at the start, offset at the end)
    for start, stop in runs:
        idx = np.arange(start, stop) % n
        dev = ankle[idx, :2] - ref_ankle[idx, :2]
        offset = dev.mean(axis=0)
        pull[idx] = ref_ankle[idx, :2] + offset - ankle[idx, :2]
        weight[idx] = 1.0
        ends.append((start, stop, pull[idx[0]].copy(), pull[idx[-1]].copy()))
    if not ends or ends[0][1] - ends[0][0] >= n:
        return pull, weight
    # swings: the OFFSET (not the held place) goes over from the end of one contact to the
    # start of the next along a quintic smoothstep, so the foot keeps its own swing path and
    # its velocity stays continuous; before the first / after the last contact of a clip that
    # does not loop, the offset eases in from / out to zero
    # (start, stop, offset there, offset at the end, hold weight at the start / end)
    gaps = [(ends[k][1], ends[k + 1][0], ends[k][3], ends[k + 1][2], 1.0, 1.0) for k in range(len(ends) - 1)]
    if periodic:
        gaps.append((ends[-1][1], ends[0][0] + n, ends[-1][3], ends[0][2], 1.0, 1.0))
    else:
        # before the first / after the last contact of a clip that does not loop, the swing
        # is cut by the clip's end: the offset eases in / out over the SWING_EASE of a whole
        # swing of this foot (the median one) and the foot is on its own path beyond
        # (easing over the cut piece made the last swing snap; a corridor clip's last
        # frames are dissolved into its first)
        swings = [g1 - g0 for g0, g1, *_ in gaps]
        ease = max(1.0, SWING_EASE * (float(np.median(swings)) if swings else 0.4 * n))
        tail = np.arange(ends[-1][1], n)
        pull[tail] = ends[-1][3] * (1.0 - smoothstep5((tail - ends[-1][1] + 1.0) / (ease + 1.0)))[:, None]
        head = np.arange(0, ends[0][0])
        pull[head] = ends[0][2] * (1.0 - smoothstep5((ends[0][0] - head) / (ease + 1.0)))[:, None]
        weight[tail] = weight[head] = 1.0
    for g0, g1, off0, off1, w0, w1 in gaps:
        t = np.arange(g0, g1)
        if not len(t):
            continue
        u = (t - g0 + 1.0) / (g1 - g0 + 1.0)
        s = smoothstep5(u)
        keep = slice(None) if periodic else (t >= 0) & (t < n)
        t, u, s = t[keep] % n, u[keep], s[keep]
        # ... and eases back to the foot's own (corrected) path over the first and last
        # SWING_EASE of the swing: the physics kept the swinging leg clear of the neighbours'
        back = 1.0 - smoothstep5(np.clip(np.minimum(u, 1.0 - u) / SWING_EASE, 0.0, 1.0))
        pull[t] = back[:, None] * ((1.0 - s)[:, None] * off0 + s[:, None] * off1)
        weight[t] = (1.0 - s) * w0 + s * w1
    return pull, weight


def _ankle_about_ball(
    hip: np.ndarray, reach: np.ndarray, ball: np.ndarray, foot: np.ndarray, target: np.ndarray
) -> np.ndarray:
    """Ankles (M, 3) at ``reach`` m from the hip and ``foot`` m from the ball (both (M,)),
    the point of that circle nearest the ``target`` ankle; straight from the hip towards
    the ball where the two spheres do not meet."""
    axis = ball - hip
    dist = np.maximum(np.linalg.norm(axis, axis=-1), 1e-9)
    e = axis / dist[:, None]
    along = np.clip((dist**2 + reach**2 - foot**2) / (2.0 * dist), -reach, reach)
    radius = np.sqrt(np.maximum(reach**2 - along**2, 0.0))
    side = target - hip
    side = side - np.sum(side * e, axis=-1, keepdims=True) * e
    side /= np.maximum(np.linalg.norm(side, axis=-1, keepdims=True), 1e-9)
    return hip + along[:, None] * e + radius[:, None] * side


def _soft_reach(hip: np.ndarray, ankle: np.ndarray, target: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Ankle goals (M, 3) for the leg IK: ``target`` with its hip distance changed only by
    the soft-clamped change from the output's own ankle.

    Near full extension a small change of the ankle's distance from the hip swings the knee
    far (the pops of a hard-clamped two-bone IK). Distances beyond ``SOFT_REACH * length``
    are compressed exponentially towards ``length``, s(d), and the goal's distance is
    d0 + s(d) - s(d0) (d0 the output's own ankle distance, d the target's): a leg whose
    ankle is not moved keeps its pose exactly, a straight standing leg stays straight.
    """
    lo, hi = SOFT_REACH * length, 0.999 * length

    def soft(d):
        over = np.maximum(d - lo, 0.0)
        return np.where(d > lo, lo + (hi - lo) * (1.0 - np.exp(-over / (hi - lo))), d)

    d0 = np.linalg.norm(ankle - hip, axis=-1)
    v = target - hip
    d = np.linalg.norm(v, axis=-1)
    new = np.maximum(d0 + soft(d) - soft(d0), 1e-6)
    # near full extension a hold may not straighten the leg further than the output's own
    # leg (+1 % of its length): the foot gives way instead of the knee snapping back after
    new = np.minimum(new, np.maximum(d0 + 0.01 * length, STRAIGHT_HOLD * length))
    return hip + v * (new / np.maximum(d, 1e-9))[:, None]


def lock_planted_feet(
    rot: np.ndarray,
    root: np.ndarray,
    ref_rot: np.ndarray,
    ref_root: np.ndarray,
    rest_joints: np.ndarray,
    fps: float,
    *,
    planted_speed: float = 0.02,
    planted_height: float = 0.03,
    periodic: bool = False,
    ref_kinematics: tuple | None = None,
) -> np.ndarray:
    """Hold the output's feet where they stand while the reference's are planted (two-bone
    leg IK).

    While the reference's ankle or ball of the foot is planted the output's ankle follows
    the reference's at one constant offset per contact (see ``_foot_hold``) and the foot
    takes the reference's world orientation: a still reference foot is held still, a heel
    rise rolls over the ball as in the reference.

    Args:
        rot, ref_rot: (T, N, 24, 3) axis-angle rad; root, ref_root: (T, N, 3) m.
        rest_joints: (N, 24, 3) m, each character's rest joints.
        fps: frame rate, Hz.
        planted_speed: m/s, a reference joint (ankle, ball) counts as planted below this
            horizontal speed (and within ``planted_height`` m of its lowest height).
        periodic: the clip loops (contacts may wrap around the seam).
        ref_kinematics: ``forward_kinematics(rest_joints[None], ref_rot, ref_root)`` when the
            caller has it already (None: computed here).

    Returns:
        (T, N, 24, 3) joint rotations with new hip, knee and ankle rotations; the ankle's
        height is the output's own.
    """
    rest = np.asarray(rest_joints, np.float64)
    glob, pos = forward_kinematics(rest[None], rot, root, parents=PARENTS)
    if ref_kinematics is None:
        ref_kinematics = forward_kinematics(rest[None], ref_rot, ref_root, parents=PARENTS)
    ref_glob, ref_pos = ref_kinematics
    out = np.array(rot, dtype=np.float64, copy=True)
    n_chars = rot.shape[1]
    for hip, knee, ankle in LEGS:
        toe = ankle + 3  # the ball of the foot (left_foot / right_foot)
        target = pos[:, :, ankle].copy()
        weight = np.zeros(target.shape[:2])
        ball_only = np.zeros(target.shape[:2], bool)  # heel rise: the ball planted alone
        for i in range(n_chars):
            flat = planted_frames(ref_pos[:, i, ankle], fps, planted_speed, planted_height, periodic)
            ball = planted_frames(ref_pos[:, i, toe], fps, planted_speed, planted_height, periodic)
            ball_only[:, i] = ball & ~flat
            pull, weight[:, i] = _foot_hold(pos[:, i, ankle], ref_pos[:, i, ankle], flat | ball, periodic)
            target[:, i, :2] += pull
        moved = weight > 0  # (T, N)
        if not moved.any():
            continue
        t_idx, c_idx = np.nonzero(moved)
        pole = (
            2.0 * pos[t_idx, c_idx, knee]
            - pos[t_idx, c_idx, hip]
            - pos[t_idx, c_idx, ankle]
            + 0.02 * glob[t_idx, c_idx, hip][:, :, 1]
        )
        pelvis = glob[t_idx, c_idx, 0]
        hip_pos = pos[t_idx, c_idx, hip]
        goal = _soft_reach(
            hip_pos,
            pos[t_idx, c_idx, ankle],
            target[t_idx, c_idx],
            np.linalg.norm(rest[c_idx, knee] - rest[c_idx, hip], axis=-1)
            + np.linalg.norm(rest[c_idx, ankle] - rest[c_idx, knee], axis=-1),
        )
        # in a heel rise the ball stays where the target puts it: where the leg cannot reach
        # the target, the heel rises further (the foot turns about the ball) instead of the
        # ball sliding
        aim = target[t_idx, c_idx]
        lift = np.flatnonzero(ball_only[t_idx, c_idx] & (np.linalg.norm(goal - aim, axis=-1) > 1e-5))
        if len(lift):
            tl, cl = t_idx[lift], c_idx[lift]
            arm = np.einsum("mab,mb->ma", ref_glob[tl, cl, ankle], rest[cl, toe] - rest[cl, ankle])
            ball_at = aim[lift] + arm
            goal[lift] = _ankle_about_ball(
                hip_pos[lift],
                np.linalg.norm(goal[lift] - hip_pos[lift], axis=-1),
                ball_at,
                np.linalg.norm(arm, axis=-1),
                aim[lift],
            )
            turn = rotation_between(arm, ball_at - goal[lift])
        loc_a, loc_b, glob_b = two_bone_ik(
            hip_pos,
            goal,
            pole,
            pelvis,
            rest[c_idx, hip],
            rest[c_idx, knee],
            rest[c_idx, ankle],
            np.array([0.0, 1.0, 0.0]),
        )
        out[t_idx, c_idx, hip] = matrix_to_axis_angle(loc_a)
        out[t_idx, c_idx, knee] = matrix_to_axis_angle(loc_b)
        # the held foot takes the reference's world orientation (it does not turn on the floor)
        w = weight[t_idx, c_idx]
        foot = quat_blend(
            matrix_to_quaternion(glob[t_idx, c_idx, ankle]), matrix_to_quaternion(ref_glob[t_idx, c_idx, ankle]), w
        )
        foot_rot = quaternion_to_matrix(foot)
        if len(lift):
            foot_rot[lift] = turn @ foot_rot[lift]
        ankle_local = np.swapaxes(glob_b, -1, -2) @ foot_rot
        out[t_idx, c_idx, ankle] = matrix_to_axis_angle(ankle_local)
    return out

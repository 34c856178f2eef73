"""The last step of the output stage: no joint faster than the Baseline crowd's fastest.

A limb that a contact held back rejoins its animation after the contact, and the physics'
stiff PD control brings it back within a few frames: for those frames the hand moves faster
than any hand of the captured performance (concert D1: 7.3 m/s where the Baseline's fastest
joint moves at 6.0 m/s). :func:`limit_joint_speed` finds the frames where a joint of the
corrected animation moves faster than ``limit`` (by default the reference crowd's fastest
joint plus ``margin``) and spreads the correction of that joint's upper-body chain over
more frames there: the chain's deviation from the reference (``R = R^ exp([delta]x)`` per
joint, as in :func:`crowdstudy.physics.finish.smooth_deviation`) is blended, in a smooth
window around the fast frames, towards a Gaussian low-pass of itself, with a wider kernel
each round until no joint is too fast (or ``max_rounds`` is reached). The reference's own
motion is never slowed: only the deviation is re-timed, so a joint can only be slowed
where the correction made it faster than its animation allows.

The chain of an arm or the head runs up to spine2 (spine2, spine3, neck, head, collar,
shoulder, elbow, wrist, hand); the root, pelvis and spine1 are never changed. A fast leg
joint re-times its leg (hip, knee, ankle, ball) only on the frames where the reference's
foot swings, so the feet held by :func:`~crowdstudy.physics.finish.lock_planted_feet`
stay where they are (a held foot's offset handed back to the swing too quickly is what
makes a leg fast). The overlap is measured after this step, like the rest of the output
stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdstudy.body.rotations import axis_angle_to_quaternion, quat_conjugate, quat_multiply, quaternion_to_axis_angle
from crowdstudy.body.skeleton import JOINT_INDEX, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics import joint_speeds
from crowdstudy.physics.finish import planted_frames

__all__ = ["SpeedLimitReport", "limit_joint_speed", "fastest_reference_joint", "UPPER_CHAIN_STOP"]

#: an upper-body chain is re-timed up to, not including, these joints (the root and the
#: lower spine carry the legs and the held feet)
UPPER_CHAIN_STOP = frozenset(JOINT_INDEX[n] for n in ("pelvis", "spine1"))
#: hip, knee, ankle, ball of the foot, per side (left, right)
_LEGS = tuple(tuple(JOINT_INDEX[f"{s}_{n}"] for n in ("hip", "knee", "ankle", "foot")) for s in ("left", "right"))


@dataclass(frozen=True)
class SpeedLimitReport:
    """What :func:`limit_joint_speed` did.

    Attributes:
        limit_m_s: the speed limit, m/s.
        fast_samples: (frame step, character, joint) samples above the limit before, count.
        characters: indices of the characters whose chains were re-timed.
        rounds: the most rounds any character needed.
        max_speed_before_m_s, max_speed_after_m_s: the fastest joint of the output, m/s.
        unresolved: samples still above the limit after (leg joints, or ``max_rounds``).
    """

    limit_m_s: float
    fast_samples: int
    characters: tuple[int, ...]
    rounds: int
    max_speed_before_m_s: float
    max_speed_after_m_s: float
    unresolved: int

    def as_dict(self) -> dict:
        return {
            "limit_m_s": self.limit_m_s,
            "fast_samples": self.fast_samples,
            "characters": list(self.characters),
            "rounds": self.rounds,
            "max_speed_before_m_s": self.max_speed_before_m_s,
            "max_speed_after_m_s": self.max_speed_after_m_s,
            "unresolved": self.unresolved,
        }


def _leg_side(joint: int) -> int:
    """0 / 1 for a joint of the left / right leg (hip to foot), else -1."""
    for side, leg in enumerate(_LEGS):
        if joint in leg:
            return side
    return -1


def _chain(joint: int) -> list[int]:
    """The joints whose deviation a fast ``joint`` re-times: a leg joint's whole leg (hip,
    knee, ankle, foot), otherwise ``joint`` and its ancestors up to (not including) the
    pelvis group; [] for the pelvis and spine1."""
    side = _leg_side(joint)
    if side >= 0:
        return list(_LEGS[side])
    out = []
    j = joint
    while j >= 0 and j not in UPPER_CHAIN_STOP:
        out.append(j)
        j = int(PARENTS[j])
    return out


def _window(fast_steps: np.ndarray, n_frames: int, width: float, periodic: bool) -> np.ndarray:
    """(T,) blend weight in [0, 1]: 1 on the frames around each fast step, falling off as a
    Gaussian of standard deviation ``width`` frames (circular distance when periodic)."""
    t = np.arange(n_frames, dtype=np.float64)
    w = np.zeros(n_frames)
    for s in np.unique(fast_steps):
        for centre in (s, s + 1):  # a step s joins frames s and s + 1
            d = np.abs(t - (centre % n_frames))
            if periodic:
                d = np.minimum(d, n_frames - d)
            w = np.maximum(w, np.exp(-0.5 * (np.maximum(d - 1.0, 0.0) / width) ** 2))
    return w


def fastest_reference_joint(ref_pos: np.ndarray, fps: float, periodic_length: float | None = None) -> float:
    """The reference's fastest joint, m/s, over its own steps (positions (T, ..., J, 3) m):
    a clip cut from a longer loop need not meet its first frame smoothly, and its seam is
    no motion of the reference, so the seam does not count (0 for a single frame)."""
    speed = joint_speeds(ref_pos, fps, periodic_length=periodic_length)
    return float(speed.max()) if speed.size else 0.0


def limit_joint_speed(
    rot: np.ndarray,
    root: np.ndarray,
    ref_rot: np.ndarray,
    ref_root: np.ndarray,
    rest_joints: np.ndarray,
    fps: float,
    *,
    margin: float = 0.3,
    limit: float | None = None,
    periodic: bool = False,
    sigma0: float = 1.0,
    growth: float = 1.5,
    max_rounds: int = 12,
    planted_speed: float = 0.02,
    planted_height: float = 0.03,
    periodic_length: float | None = None,
    ref_kinematics: tuple | None = None,
) -> tuple[np.ndarray, SpeedLimitReport]:
    """Re-time the correction where it makes a joint faster than ``limit``.

    Args:
        rot, ref_rot: (T, N, 24, 3) axis-angle rad (the output and the reference it corrects).
        root, ref_root: (T, N, 3) m (the root is not changed; it enters the speeds).
        rest_joints: (N, 24, 3) m, each character's rest joints.
        fps: frame rate, Hz.
        margin: m/s above the reference crowd's fastest joint (any character, joint, step
            within the clip) that the output may reach; ignored when ``limit`` is given.
        limit: m/s, an explicit limit.
        periodic: the clip loops (the output's last-to-first step counts, windows wrap).
        periodic_length: m, the scene's period along x (``CrowdAnimation.periodic_length``:
            steps take the minimum image, as the smoothness metrics measure them), or None.
        sigma0: frames, the first round's low-pass kernel; ``growth`` widens it each round.
        max_rounds: rounds per character at most.
        planted_speed, planted_height: m/s and m, when the reference's ankle or ball counts
            as planted (:func:`~crowdstudy.physics.finish.planted_frames`): a leg is re-timed
            only on the frames where neither is.
        ref_kinematics: ``forward_kinematics(rest_joints[None], ref_rot, ref_root)`` when the
            caller has it already (None: computed here).

    Returns:
        ``(rot, report)``: new joint rotations (the input's where nothing was too fast) and a
        :class:`SpeedLimitReport`.
    """
    rot, root, ref_rot, ref_root = _checked_motions(rot, root, ref_rot, ref_root)
    if fps <= 0 or margin < 0 or sigma0 <= 0 or growth <= 1.0 or max_rounds < 1:
        raise InvalidInputError(
            f"fps > 0, margin >= 0, sigma0 > 0, growth > 1 and max_rounds >= 1 expected: got "
            f"{fps!r}, {margin!r}, {sigma0!r}, {growth!r}, {max_rounds!r}"
        )
    rest = np.asarray(rest_joints, np.float64)
    n_frames = rot.shape[0]
    if ref_kinematics is None:
        ref_kinematics = forward_kinematics(rest[None], ref_rot, ref_root, parents=PARENTS)
    ref_pos = ref_kinematics[1]
    if limit is None:
        limit = fastest_reference_joint(ref_pos, fps, periodic_length) + float(margin)
    _, pos = forward_kinematics(rest[None], rot, root, parents=PARENTS)
    speed = joint_speeds(pos, fps, periodic_length=periodic_length, seam=periodic)
    before = float(speed.max()) if speed.size else 0.0
    fast = speed > limit
    n_fast = int(fast.sum())
    out = rot.copy()
    if not n_fast or n_frames < 3:
        return out, SpeedLimitReport(float(limit), n_fast, (), 0, before, before, n_fast)
    settings = _Retiming(
        fps=fps,
        limit=limit,
        sigma0=sigma0,
        growth=growth,
        max_rounds=max_rounds,
        periodic=periodic,
        periodic_length=periodic_length,
    )
    q_ref = axis_angle_to_quaternion(ref_rot)
    touched, most_rounds = [], 0
    for c in np.unique(np.nonzero(fast)[1]):
        # a leg is re-timed only while its foot swings: planted frames keep the foot hold
        free = _swing_frames(ref_pos[:, c], fps, planted_speed, planted_height, periodic)
        rounds, spd = _retime_character(out, int(c), q_ref[:, c], speed[:, c], free, rest[c], root[:, c], settings)
        if rounds:
            touched.append(int(c))
            most_rounds = max(most_rounds, rounds)
            speed[:, c] = spd
    after = float(speed.max())
    return out, SpeedLimitReport(
        float(limit), n_fast, tuple(touched), most_rounds, before, after, int((speed > limit).sum())
    )


def _checked_motions(
    rot: np.ndarray, root: np.ndarray, ref_rot: np.ndarray, ref_root: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The output and reference motions of :func:`limit_joint_speed` as float64, their
    shapes checked: rotations (T, N, J, 3) rad, roots (T, N, 3) m."""
    rot = np.asarray(rot, np.float64)
    ref_rot = np.asarray(ref_rot, np.float64)
    root = np.asarray(root, np.float64)
    ref_root = np.asarray(ref_root, np.float64)
    if (
        rot.shape != ref_rot.shape
        or rot.ndim != 4
        or root.shape != rot.shape[:2] + (3,)
        or ref_root.shape != root.shape
    ):
        raise InvalidInputError(
            f"rot, ref_rot (T, N, J, 3) and root, ref_root (T, N, 3): got {rot.shape}, "
            f"{ref_rot.shape}, {root.shape}, {ref_root.shape}"
        )
    return rot, root, ref_rot, ref_root


@dataclass(frozen=True)
class _Retiming:
    """The settings of :func:`limit_joint_speed`'s rounds: ``fps`` Hz, ``limit`` m/s, the
    first low-pass kernel ``sigma0`` frames widened by ``growth`` each round, at most
    ``max_rounds``; ``periodic`` clip and the scene's ``periodic_length`` m (or None)."""

    fps: float
    limit: float
    sigma0: float
    growth: float
    max_rounds: int
    periodic: bool
    periodic_length: float | None


def _swing_frames(
    ref_pos: np.ndarray, fps: float, planted_speed: float, planted_height: float, periodic: bool
) -> list[np.ndarray]:
    """Per leg (left, right), the (T,) frames where neither the reference's ankle nor its
    ball is planted; ``ref_pos`` (T, 24, 3) m, one character's joints."""
    return [
        ~(
            planted_frames(ref_pos[:, leg[2]], fps, planted_speed, planted_height, periodic)
            | planted_frames(ref_pos[:, leg[3]], fps, planted_speed, planted_height, periodic)
        )
        for leg in _LEGS
    ]


def _retime_character(
    out: np.ndarray,
    c: int,
    q_ref: np.ndarray,
    speed: np.ndarray,
    free: list[np.ndarray],
    rest: np.ndarray,
    root: np.ndarray,
    settings: _Retiming,
) -> tuple[int, np.ndarray]:
    """Re-time character ``c``'s deviation from its reference (quaternions ``q_ref`` (T, 24,
    4)) in ``out`` (T, N, 24, 3) rad, in place, round by round with a wider kernel until no
    joint is faster than the limit. ``speed`` (T', 24) m/s its joint speeds now, ``free``
    its legs' swing frames, ``rest`` (24, 3) and ``root`` (T, 3) m. Returns the rounds
    used and the joint speeds after them."""
    delta = quaternion_to_axis_angle(quat_multiply(quat_conjugate(q_ref), axis_angle_to_quaternion(out[:, c])))
    n_frames = out.shape[0]
    sigma, rounds = settings.sigma0, 0
    while rounds < settings.max_rounds:
        steps, joints = np.nonzero(speed > settings.limit)
        if not steps.size:
            break
        w = _window(steps, n_frames, 2.0 * sigma, settings.periodic)
        groups: dict[int, set[int]] = {}  # chain joints by their window
        for jt in np.unique(joints):
            side = _leg_side(int(jt))
            groups.setdefault(side, set()).update(_chain(int(jt)))
        if not _retime_chains(out, c, delta, q_ref, w, groups, free, sigma, settings.periodic):
            break  # only the root, pelvis or spine1, or planted legs, are fast
        rounds += 1
        _, pc = forward_kinematics(rest[None], out[:, c], root, parents=PARENTS)
        speed = joint_speeds(pc, settings.fps, periodic_length=settings.periodic_length, seam=settings.periodic)
        sigma *= settings.growth
    return rounds, speed


def _retime_chains(
    out: np.ndarray,
    c: int,
    delta: np.ndarray,
    q_ref: np.ndarray,
    w: np.ndarray,
    groups: dict[int, set[int]],
    free: list[np.ndarray],
    sigma: float,
    periodic: bool,
) -> bool:
    """One round for character ``c``: each chain of ``groups`` ({leg side or -1: joints})
    has its deviation ``delta`` (T, 24, 3) rad blended, by the window ``w`` (T,) (times its
    leg's swing frames), towards its Gaussian low-pass of ``sigma`` frames; ``delta`` and
    the re-timed rotations of ``out`` are updated in place. Returns whether any moved."""
    from scipy.ndimage import gaussian_filter1d

    mode = "wrap" if periodic else "nearest"
    moved = False
    for side, chain in groups.items():
        idx = np.array(sorted(chain), dtype=np.int64)
        wk = w if side < 0 else w * free[side]
        frames = np.nonzero(wk > 0)[0]
        if not idx.size or not frames.size:
            continue
        moved = True
        low = gaussian_filter1d(delta[:, idx], sigma, axis=0, mode=mode)[frames]
        blend = wk[frames, None, None]
        delta[np.ix_(frames, idx)] = (1.0 - blend) * delta[np.ix_(frames, idx)] + blend * low
        # only what was re-timed is written back (elsewhere the input, bit for bit)
        q_new = quat_multiply(q_ref[np.ix_(frames, idx)], axis_angle_to_quaternion(delta[np.ix_(frames, idx)]))
        out[frames[:, None], c, idx[None, :]] = quaternion_to_axis_angle(q_new)
    return moved

"""Cleaning motion-capture takes for a crowd: facing, drift, trims, planted feet, self-contact.

A take imported by :func:`~crowdstudy.motion.bvh.load_bvh` is on our skeleton but faces
wherever the performer faced, wanders around the capture volume and has feet that slide a
little (marker noise, retargeting). For a dancer who must stay on its spot facing the
stage, :func:`clean_take`:

1. cuts the frames outside ``[trim_start, trim_end)`` (set per take) and the calibration or
   glitch frames at either end (:func:`outlier_ends`: a frame step far above the take's own);
2. turns the take so the performer faces +y on average (circular mean of the pelvis's
   heading) and removes the slow part of its wandering and turning: the pelvis's
   horizontal path and heading, Gaussian-smoothed over ``drift_sigma`` seconds, are
   subtracted (what is left is the sway, steps and twists of the dance);
3. shrinks the steps of a dancer who wanders far (:func:`shrink_steps`: the feet's centre
   and the pelvis wander less, planted feet stay planted, stance width kept), so a dense
   crowd's dancers step in place;
4. finds each foot's contacts (:func:`foot_contacts`: ankle or toe near its lowest
   height and the ankle nearly still, runs of at least 0.12 s) and holds a planted foot
   where its contact began, heading included; the offset left at lift-off fades out over the swing
   (quintic), and the legs are re-solved by analytic IK
   (:func:`~crowdstudy.motion.legs.plant_legs`);
5. levels the gaze (:func:`level_head`): the captured performers hold their heads 12-33
   degrees up on average (the capture skeleton's head bone is not the face's direction),
   so a constant correction, shared by neck and head, brings the take's mean gaze to
   :data:`GAZE_PITCH` relative to the chest (a crowd watching a stage looks ahead).

Self-contact (hands inside a wider body) is measured and fixed per character at animation
time, on its own body: :mod:`crowdstudy.motion.selfcontact`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.posing import planted_runs, smoothstep5
from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle, rot_z
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.legs import plant_legs
from crowdstudy.motion.rig import ANKLE_HEIGHT

__all__ = [
    "clean_take",
    "outlier_ends",
    "turn_about_z",
    "face_forward",
    "remove_drift",
    "shrink_steps",
    "foot_contacts",
    "lock_feet",
    "lock_loop_feet",
    "MAX_EXCURSION",
]

_MIN_CONTACT = 0.12  # s, shortest contact kept
_MAX_GAP = 0.08  # s, shorter gaps inside a contact are filled
_FADE = 0.3  # s, longest fade-out of a lock offset after lift-off
#: Default largest wander (m, 95th percentile) of a dancer's feet centre around its spot.
MAX_EXCURSION = 0.12


def _headings(clip: MotionClip) -> np.ndarray:
    """(T,) heading (rad about z, 0 = facing +y) of the pelvis, unwrapped."""
    fwd = axis_angle_to_matrix(clip.joint_rotations[:, 0])[:, :, 1]
    return np.unwrap(np.arctan2(-fwd[:, 0], fwd[:, 1]))


def turn_about_z(clip: MotionClip, yaw, centre, name: str | None = None) -> MotionClip:
    """``clip`` with frame t turned by ``yaw[t]`` rad about +z around the point ``centre[t]``
    (m), which goes to the origin; ``yaw`` (T,) or a number, ``centre`` (T, 2) or (2,)."""
    n = clip.n_frames
    rz = rot_z(np.broadcast_to(np.asarray(yaw, dtype=np.float64), (n,)))
    rot = np.array(clip.joint_rotations, copy=True)
    rot[:, 0] = matrix_to_axis_angle(rz @ axis_angle_to_matrix(rot[:, 0]))
    root = np.array(clip.root_translation, copy=True)
    root[:, :2] = np.einsum("tab,tb->ta", rz[:, :2, :2], root[:, :2] - np.asarray(centre, dtype=np.float64))
    return dataclasses.replace(clip, name=name or clip.name, joint_rotations=rot, root_translation=root)


def face_forward(clip: MotionClip) -> MotionClip:
    """``clip`` turned about z so its mean heading is +y, its mean pelvis position at x = y = 0."""
    h = _headings(clip)
    mean = float(np.angle(np.mean(np.exp(1j * h))))
    return turn_about_z(clip, -mean, clip.root_translation[:, :2].mean(axis=0))


def remove_drift(clip: MotionClip, sigma: float) -> MotionClip:
    """``clip`` without the slow part (Gaussian, ``sigma`` seconds) of its horizontal pelvis
    path and heading: a dancer who wanders or turns slowly stays on its spot facing +y."""
    from scipy.ndimage import gaussian_filter1d

    s = float(sigma) * clip.fps
    h = _headings(clip)
    slow_h = gaussian_filter1d(h, s, mode="nearest")
    slow_xy = gaussian_filter1d(clip.root_translation[:, :2], s, axis=0, mode="nearest")
    return turn_about_z(clip, -slow_h, slow_xy)


def foot_contacts(clip: MotionClip, *, height_tol: float = 0.035, speed_tol: float = 0.6) -> np.ndarray:
    """(T, 2) bool, the (left, right) foot planted: its ankle within ``height_tol`` m of the
    ankle's lowest height or its toe within 0.025 m of the toe's, and the ankle moving
    slower than ``speed_tol`` m/s horizontally; gaps under 0.08 s filled, runs under
    0.12 s dropped."""
    from scipy.ndimage import gaussian_filter1d

    pos = clip.joint_positions()
    out = np.zeros((clip.n_frames, 2), bool)
    for k, side in enumerate(("left", "right")):
        ankle = pos[:, JOINT_INDEX[f"{side}_ankle"]]
        toe = pos[:, JOINT_INDEX[f"{side}_foot"]]
        vel = gaussian_filter1d(np.gradient(ankle[:, :2], axis=0) * clip.fps, 0.03 * clip.fps, axis=0, mode="nearest")
        low_a = np.percentile(ankle[:, 2], 2)
        low_t = np.percentile(toe[:, 2], 2)
        planted = ((ankle[:, 2] < low_a + height_tol) | (toe[:, 2] < low_t + 0.025)) & (
            np.linalg.norm(vel, axis=1) < speed_tol
        )
        gaps = planted_runs(~planted)
        for a, b in gaps:
            if 0 < a and b < len(planted) and (b - a) < _MAX_GAP * clip.fps:
                planted[a:b] = True
        for a, b in planted_runs(planted):
            if (b - a) < _MIN_CONTACT * clip.fps:
                planted[a:b] = False
        out[:, k] = planted
    return out


def _held(values: np.ndarray, contacts: np.ndarray, fps: float) -> np.ndarray:
    """(T, D) offsets that hold ``values`` (T, D) at their value where each contact began,
    faded out after lift-off over the swing (at most 0.3 s, quintic)."""
    n = len(values)
    off = np.zeros(values.shape)
    runs = planted_runs(contacts)
    for r, (a, b) in enumerate(runs):
        off[a:b] = values[a] - values[a:b]
        nxt = runs[r + 1][0] if r + 1 < len(runs) else n
        fade = max(1, min(int(round(_FADE * fps)), int(0.8 * (nxt - b))))
        u = np.arange(1, fade + 1) / fade
        end = min(b + fade, n)
        off[b:end] = off[b - 1] * (1.0 - smoothstep5(u[: end - b]))[:, None]
    return off


def _step_lift(offset: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """(T,) ankle lift (m) while a held foot catches up with the take after lift-off: a
    sine bump of 40 % of the distance it travels (at most 4 cm), so the catch-up is a small
    step, not a slide (a take whose foot shuffles along the floor)."""
    lift = np.zeros(len(offset))
    runs = planted_runs(contacts)
    for r, (_, b) in enumerate(runs):
        nxt = runs[r + 1][0] if r + 1 < len(runs) else len(offset)
        span = np.flatnonzero(np.linalg.norm(offset[b:nxt], axis=1) > 1e-9)
        if b == 0 or not span.size:
            continue
        end = b + int(span[-1]) + 2
        u = (np.arange(b, min(end, len(offset))) - b + 1) / (end - b + 1)
        lift[b : b + len(u)] = min(0.04, 0.4 * float(np.linalg.norm(offset[b - 1]))) * np.sin(np.pi * u) ** 2
    return lift


def _approach_lift(height: np.ndarray, contacts: np.ndarray, fps: float) -> np.ndarray:
    """(T,) ankle lift (m) that keeps a foot coming in to land at least 1.5 cm above its floor
    height until its contact begins (low frame-rate takes bring the heel down while it still
    moves fast: it would slide in), eased out over the last 0.05 s."""
    lift = np.zeros(len(height))
    floor = float(np.percentile(height, 2)) + 0.015
    ease = max(1, int(round(0.05 * fps)))
    runs = planted_runs(contacts)
    for r, (a, _b) in enumerate(runs):
        prev = runs[r - 1][1] if r else 0
        j = np.arange(max(prev, a - int(round(0.25 * fps))), a)
        if not j.size:
            continue
        w = smoothstep5((a - j) / ease)
        lift[j] = np.maximum(floor - height[j], 0.0) * w
    return lift


def lock_feet(clip: MotionClip, contacts: np.ndarray) -> MotionClip:
    """``clip`` with each planted foot held where its contact began, ankle position and foot
    heading (a foot turning about its planted ankle would sweep its toes over the floor);
    the legs re-solved by IK on the authoring skeleton, the feet keeping their pitch and roll."""
    glob, pos = forward_kinematics(DEFAULT_REST_JOINTS, clip.joint_rotations, clip.root_translation)
    rot = np.array(clip.joint_rotations, copy=True)
    offsets = np.zeros((clip.n_frames, 2, 3))
    for k, side in enumerate(("left", "right")):
        ja, jt = JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]
        offsets[:, k, :2] = _held(pos[:, ja, :2], contacts[:, k], clip.fps)
        offsets[:, k, 2] = _step_lift(offsets[:, k, :2], contacts[:, k]) + _approach_lift(
            pos[:, ja, 2], contacts[:, k], clip.fps
        )
        toe = pos[:, jt] - pos[:, ja]
        yaw = np.unwrap(np.arctan2(toe[:, 1], toe[:, 0]))
        turn = rot_z(_held(yaw[:, None], contacts[:, k], clip.fps)[:, 0])
        rot[:, ja] = matrix_to_axis_angle(np.swapaxes(glob[:, PARENTS[ja]], -1, -2) @ turn @ glob[:, ja])
    rot = plant_legs(
        rot[:, None],
        clip.root_translation[:, None],
        DEFAULT_REST_JOINTS[None],
        np.ones(1),
        np.array([ANKLE_HEIGHT]),
        ankle_offsets=offsets[:, None],
    )[:, 0]
    return dataclasses.replace(clip, joint_rotations=rot)


def _contact_offsets(values: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """(T, D): the mean of ``values`` (T, D) over each contact, held through it, eased from
    one contact's value to the next over the swing between them (quintic)."""
    n = len(values)
    runs = planted_runs(contacts)
    if not runs:
        return np.broadcast_to(values.mean(axis=0), values.shape).copy()
    held = [values[a:b].mean(axis=0) for a, b in runs]
    out = np.empty(values.shape)
    out[: runs[0][0]] = held[0]
    for r, (a, b) in enumerate(runs):
        out[a:b] = held[r]
        end = runs[r + 1][0] if r + 1 < len(runs) else n
        if r + 1 < len(runs):
            u = smoothstep5((np.arange(b, end) - b + 1) / (end - b + 1))[:, None]
            out[b:end] = (1.0 - u) * held[r] + u * held[r + 1]
        else:
            out[b:end] = held[r]
    return out


def _feet_centre(clip: MotionClip) -> np.ndarray:
    """(T, 2) the midpoint of the two ankles, smoothed over 0.25 s: where the dancer stands."""
    from scipy.ndimage import gaussian_filter1d

    pos = clip.joint_positions()
    mid = 0.5 * (pos[:, JOINT_INDEX["left_ankle"], :2] + pos[:, JOINT_INDEX["right_ankle"], :2])
    return gaussian_filter1d(mid, 0.25 * clip.fps, axis=0, mode="nearest")


def shrink_steps(clip: MotionClip, factor: float) -> MotionClip:
    """``clip`` with its wandering scaled by ``factor``: the centre of the two feet
    (:func:`_feet_centre`) moves ``factor`` times as far from the spot, the pelvis with it; each foot is
    moved by a constant amount through each of its contacts (so a planted foot stays
    planted) and eases to the next one during its swing; the legs are re-solved by IK. The
    stance width, heights, arms and torso are unchanged: the steps get shorter."""
    if factor >= 1.0:
        return clip
    shift = (factor - 1.0) * _feet_centre(clip)  # (T, 2)
    contacts = foot_contacts(clip)
    new_root = clip.root_translation.copy()
    new_root[:, :2] += shift
    offsets = np.zeros((clip.n_frames, 2, 3))
    for k in range(2):
        offsets[:, k, :2] = _contact_offsets(shift, contacts[:, k]) - shift  # FK already moved by `shift`
    rot = plant_legs(
        clip.joint_rotations[:, None],
        new_root[:, None],
        DEFAULT_REST_JOINTS[None],
        np.ones(1),
        np.array([ANKLE_HEIGHT]),
        ankle_offsets=offsets[:, None],
    )[:, 0]
    return dataclasses.replace(clip, joint_rotations=rot, root_translation=new_root)


def lock_loop_feet(loop: MotionClip) -> MotionClip:
    """A looping (in place) clip with its planted feet held, seam included: contacts are found
    and held on the loop played three times and the middle copy is kept, so a contact that
    runs across the seam is held at the same spot at both ends (the blend of a loop's seam
    would otherwise slide a planted foot from where the loop ends to where it starts)."""
    if not loop.loop:
        raise InvalidInputError(f"lock_loop_feet: clip {loop.name!r} does not loop")
    n = loop.n_frames
    tiled = dataclasses.replace(
        loop,
        loop=False,
        joint_rotations=np.tile(loop.joint_rotations, (3, 1, 1)),
        root_translation=np.tile(loop.root_translation, (3, 1)),
    )
    locked = lock_feet(tiled, foot_contacts(tiled))
    return dataclasses.replace(loop, joint_rotations=locked.joint_rotations[n : 2 * n])


#: mean gaze pitch (degrees, negative = down) of a cleaned take, relative to the chest
GAZE_PITCH = -4.0


def _gaze_pitch(clip: MotionClip) -> np.ndarray:
    """(T,) degrees: the face direction's elevation in the chest's (spine3) frame."""
    glob, _ = forward_kinematics(DEFAULT_REST_JOINTS, clip.joint_rotations, clip.root_translation)
    local = np.einsum(
        "tba,tb->ta", glob[:, JOINT_INDEX["spine3"]], glob[:, JOINT_INDEX["head"]] @ np.array([0, 1.0, 0])
    )
    return np.degrees(np.arctan2(local[:, 2], np.hypot(local[:, 0], local[:, 1])))


def level_head(clip: MotionClip, pitch: float = GAZE_PITCH) -> MotionClip:
    """The clip with a constant nod (half at the neck, half at the head, about their
    lateral axes) that brings its mean gaze pitch relative to the chest to ``pitch`` degrees."""
    delta = np.radians(float(np.mean(_gaze_pitch(clip))) - float(pitch))
    fix = axis_angle_to_matrix(np.array([-0.5 * delta, 0.0, 0.0]))
    rot = np.array(clip.joint_rotations, dtype=np.float64)
    for j in ("neck", "head"):
        k = JOINT_INDEX[j]
        rot[:, k] = matrix_to_axis_angle(axis_angle_to_matrix(rot[:, k]) @ fix)
    return dataclasses.replace(clip, joint_rotations=rot)


def outlier_ends(clip: MotionClip, *, window: float = 0.5, factor: float = 5.0) -> tuple[float, float]:
    """``(start, end)`` seconds of ``clip`` without the calibration or glitch frames at its ends:
    within the first / last ``window`` seconds, a frame step whose largest joint displacement
    exceeds ``factor`` times the take's median (and 3 cm) cuts the take after / before it
    (e.g. a hand that jumps 7 cm between the first two frames of a standing take)."""
    pos = clip.joint_positions()
    step = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1)  # (T-1,) m per frame
    bad = step > max(factor * float(np.median(step)), 0.03)
    k = max(1, int(round(window * clip.fps)))
    head = np.flatnonzero(bad[:k])
    tail = np.flatnonzero(bad[-k:])
    first = int(head[-1]) + 1 if head.size else 0
    last = len(step) - k + int(tail[0]) if tail.size else clip.n_frames - 1
    return first / clip.fps, last / clip.fps


def clean_take(
    clip: MotionClip,
    *,
    trim_start: float = 0.0,
    trim_end: float | None = None,
    drift_sigma: float | None = 1.5,
    max_excursion: float | None = MAX_EXCURSION,
    fps: float = 60.0,
    name: str | None = None,
) -> MotionClip:
    """A dance or idle take ready for the crowd (see the module docstring): trimmed to
    ``[trim_start, trim_end)`` s, resampled to ``fps``, facing +y on its spot (slow drift
    removed over ``drift_sigma`` s; None keeps it), steps shrunk (:func:`shrink_steps`) so
    the feet's centre stays within ``max_excursion`` m of the spot (95th percentile; there is
    no room to step around in a dense crowd; the hips may sway further over the feet),
    feet planted. Meta gains ``trim``, ``drift_sigma``,
    ``step_scale`` and ``contact_share`` (fraction of frames each foot is planted)."""
    if clip.loop:
        raise InvalidInputError(f"clean_take: expected a take (non-looping clip), got looping clip {clip.name!r}")
    auto0, auto1 = outlier_ends(clip)
    t0 = max(float(trim_start), auto0)
    t1 = min(clip.duration if trim_end is None else min(float(trim_end), clip.duration), auto1)
    if not 0.0 <= t0 < t1:
        raise InvalidInputError(
            f"clean_take: trim [{trim_start}, {trim_end}) s is empty for clip {clip.name!r} of {clip.duration:.2f} s"
        )
    n = int(np.floor((t1 - t0) * fps + 1e-9)) + 1
    rot, root = clip.sample(t0 + np.arange(n) / fps)
    take = dataclasses.replace(clip, name=name or clip.name, fps=float(fps), joint_rotations=rot, root_translation=root)
    take = face_forward(take)
    if drift_sigma is not None:
        take = remove_drift(take, drift_sigma)
    scale = 1.0
    if max_excursion is not None:
        reach = float(np.percentile(np.linalg.norm(_feet_centre(take), axis=1), 95))
        scale = min(1.0, float(max_excursion) / max(reach, 1e-9))
        take = shrink_steps(take, scale)
    contacts = foot_contacts(take)
    take = level_head(lock_feet(take, contacts))
    meta = {
        **clip.meta,
        "trim": [t0, t1],
        "drift_sigma": drift_sigma,
        "step_scale": scale,
        "gaze_pitch": GAZE_PITCH,
        "contact_share": [float(x) for x in contacts.mean(axis=0)],
    }
    return dataclasses.replace(take, meta=meta)

"""Looping in-place walks cut from motion capture (CMU walks, ``shared/data/mocap``).

:func:`build_walk_loops` turns each straight walking take into a walking clip of the same
form as the procedural ones (:mod:`crowdstudy.motion.walk`), so that
:func:`crowdstudy.motion.baseline.animate_walking` blends them by speed:

1. :func:`~crowdstudy.motion.bvh.load_bvh` (our 24-joint skeleton, metres, feet grounded),
   resampled to :data:`FPS` (Catmull-Rom on quaternions);
2. foot contacts per foot from the ankle and ball-of-foot heights and horizontal speeds
   with hysteresis (:func:`foot_events`): heel strike (the ankle comes down and stops),
   end of the flat foot (the heel rises), toe-off (the ball leaves); the gait cycle period
   is the median time between left heel strikes;
3. a loop of 2 (else 1) whole gait cycles chosen by :func:`~crowdstudy.motion.loops.find_loop`
   and blended at its seam by :func:`~crowdstudy.motion.loops.make_loop`;
4. turned so the loop's net displacement points along +y, made in place (root relative to a
   point moving along +y at the loop's mean speed, centred on the trajectory);
5. time-normalised: every gait cycle gets the same number of frames and starts at a left
   heel strike (phase 0), so blends of two clips are coherent;
6. the planted feet locked on the authoring skeleton (leg IK of
   :func:`~crowdstudy.motion.legs.plant_legs`): the foot keeps its heading while flat,
   the ankle is held from heel strike to heel rise, then the ball of the foot until
   toe-off; the swinging ankle is kept :data:`HOVER` above the floor until it has slowed
   (24 fps captures bring the heel down while it still moves fast). Foot skate per
   contact on the loops is then below about 1.5 cm (:func:`loop_foot_skate`).

Each clip has ``kind = "walk"``, ``speed`` (m/s, distance per loop over its duration) and
meta ``stride_length`` (m per gait cycle), ``cadence`` (steps/min), ``cycle`` (s per gait
cycle), ``cycles`` (gait cycles in the loop), ``contacts`` (gait phases in [0, 1) of each
foot's ``strike``, ``flat_end`` and ``toe_off``), ``lock_lead`` = :data:`LOCK_LEAD` and
``lock_lag`` = :data:`LOCK_LAG` (cycles before the strike / after the toe-off that
:func:`~crowdstudy.motion.baseline.animate_walking` also holds the foot), ``source`` (file
name) and ``trial`` (CMU trial id). The result depends only on the files (no randomness):
the same input gives the same bytes.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from crowdstudy.body.rotations import quaternion_to_axis_angle
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip, seam_discontinuity
from crowdstudy.motion.mocap import level_head, turn_about_z

__all__ = ["WALK_FILES", "FPS", "build_walk_loops", "build_walk_loop", "foot_events", "loop_foot_skate", "gait_report"]

#: The straight walking takes used (``shared/data/mocap``), about 0.4 to 1.9 m/s.
WALK_FILES = (
    "cmu_142_07_walk_slow_short_steps.bvh.gz",
    "cmu_139_28_walk_slow.bvh.gz",
    "cmu_104_02_walk_neutral.bvh.gz",
    "cmu_81_02_walk_normal.bvh.gz",
    "cmu_82_13_walk_brisk.bvh.gz",
    "cmu_132_20_walk_fast.bvh.gz",
)
#: Working frame rate (frames/s); the loops keep about this rate with an exact period.
FPS = 60.0
#: mean gaze pitch of a walker relative to its chest, degrees: the captured walkers lean their
#: chests 8-24 degrees forward, so a slightly raised head looks a little down the corridor
WALK_GAZE_PITCH = 5.0
#: Seam blend of the loops (s).
BLEND_SECONDS = 0.2
#: Half-width of the window matched at the loop's cut points (s).
MATCH_SECONDS = 0.1
#: Gait cycles before the heel strike from which animate_walking holds the ankle (the
#: foot is then over its landing spot, a centimetre up).
LOCK_LEAD = 0.02
#: Gait cycles past the toe-off during which animate_walking still holds the ball of the
#: foot (the captured ball is still rising through the floor band then).
LOCK_LAG = 0.03
#: Height (m) above its stance height below which a swinging ankle is not let down before
#: its heel strike.
HOVER = 0.015
_SIDES = ("left", "right")


def _heights_speeds(pos: np.ndarray, fps: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per foot joint: height (T,) m and smoothed horizontal speed (T,) m/s of world positions (T, 24, 3)."""
    from scipy.ndimage import gaussian_filter1d

    out = {}
    for side in _SIDES:
        for part in ("ankle", "foot"):
            p = pos[:, JOINT_INDEX[f"{side}_{part}"]]
            v = np.linalg.norm(np.gradient(p[:, :2], 1.0 / fps, axis=0), axis=-1)
            out[f"{side}_{part}"] = (p[:, 2], gaussian_filter1d(v, 0.025 * fps, mode="nearest"))
    return out


def foot_events(pos: np.ndarray, fps: float, speed: float) -> dict[str, dict[str, np.ndarray]]:
    """Heel strikes, heel rises and toe-offs of both feet of a walk.

    Args:
        pos: (T, 24, 3) world joint positions (m), travelling (not in place).
        fps: frames per second; speed: walking speed (m/s), which scales the speed thresholds.

    The captured floor is not level (stance heights drift by centimetres over a take), so
    contacts come from horizontal speeds (smoothed over about 0.04 s) with hysteresis: a
    foot enters its stance when its ankle slows below ``0.1 + 0.45 * speed`` and leaves it
    when the ball of the foot moves faster than ``0.15 + 0.8 * speed``; the toe-off is then
    moved on to where the ball rises 1.2 cm above its lowest height in that stance (by at
    most 0.15 s). The flat foot ends (heel rise) at the last stance frame with the
    ankle within 1 cm of its lowest height in that stance. Stances shorter than 0.1 s are
    dropped, swings shorter than 0.15 s (a planted foot slipping) merged into one stance;
    a stance cut by the start or end of the take is not reported.

    Returns ``{"left": {"strike": frames, "flat_end": frames, "toe_off": frames}, "right": ...}``
    (int arrays; one entry per complete stance, in order).
    """
    hs = _heights_speeds(pos, fps)
    out: dict[str, dict[str, np.ndarray]] = {}
    for side in _SIDES:
        za, va = hs[f"{side}_ankle"]
        zb, vb = hs[f"{side}_foot"]
        enter = va < 0.1 + 0.45 * speed
        leave = vb > 0.15 + 0.8 * speed
        spans: list[list[int]] = []
        state, start = None, 0  # None until the first swing is seen (skip a partial stance)
        for t in range(len(za)):
            if state is None:
                state = False if leave[t] else None
            elif not state and enter[t] and not leave[t]:
                state, start = True, t
            elif state and leave[t]:
                state = False
                if spans and start - spans[-1][1] < 0.15 * fps:
                    spans[-1][1] = t  # a brief slip of a planted foot: one stance
                else:
                    spans.append([start, t])
        spans = [sp for sp in spans if sp[1] - sp[0] >= 0.1 * fps]
        reach = int(0.15 * fps)
        for i, sp in enumerate(spans):  # the toe leaves where the ball rises from its stance height
            low = zb[sp[0] : sp[1]].min() + 0.012
            last = min(spans[i + 1][0] - 1 if i + 1 < len(spans) else len(zb) - 1, sp[1] + reach)
            while sp[1] < last and zb[sp[1]] < low:
                sp[1] += 1
        strikes = [a for a, _ in spans]
        offs = [b for _, b in spans]
        flats = [a + int(np.flatnonzero(za[a:b] < za[a:b].min() + 0.01)[-1]) for a, b in spans]
        out[side] = {
            k: np.asarray(v, dtype=np.int64) for k, v in (("strike", strikes), ("flat_end", flats), ("toe_off", offs))
        }
    return out


def _level_floor(clip: MotionClip, events: dict) -> MotionClip:
    """``clip`` with the floor made level and at the authoring height: the trend over
    time of the flat feet's ankle heights is removed and their 20th percentile brought to
    :data:`~crowdstudy.motion.rig.ANKLE_HEIGHT` (m)."""
    from crowdstudy.motion.rig import ANKLE_HEIGHT

    pos = clip.joint_positions()
    t, z = [], []
    for side in _SIDES:
        for a, b in zip(events[side]["strike"], events[side]["flat_end"], strict=True):
            t.append(np.arange(a, b + 1))
            z.append(pos[a : b + 1, JOINT_INDEX[f"{side}_ankle"], 2])
    t, z = np.concatenate(t), np.concatenate(z)
    slope, icpt = np.polyfit(t.astype(np.float64), z, 1)
    root = clip.root_translation.copy()
    frames = np.arange(clip.n_frames)
    ground = np.percentile(z - slope * t, 20)  # a low flat-foot ankle height, levelled
    root[:, 2] -= slope * frames + ground - ANKLE_HEIGHT
    return dataclasses.replace(clip, root_translation=root)


def _world(clip: MotionClip, repeats: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (R*T, 24, 3) and travelling roots (R*T, 3) of a walking loop played ``repeats`` times."""
    n = clip.n_frames
    t = np.arange(repeats * n) / clip.fps
    root = np.tile(clip.root_translation, (repeats, 1)) + clip.travel(t)
    return np.tile(clip.joint_rotations, (repeats, 1, 1)), root


def _world_positions(clip: MotionClip, repeats: int = 1) -> np.ndarray:
    from crowdstudy.body.skeleton import forward_kinematics

    rot, root = _world(clip, repeats)
    return forward_kinematics(DEFAULT_REST_JOINTS, rot, root)[1]


def _middle_events(clip: MotionClip, pos3: np.ndarray, cycles: int) -> dict[str, dict[str, np.ndarray]]:
    """Events of the loop played 3 times (``pos3``, world joints): every stance, and a check
    that ``cycles`` stances of each foot start in the middle copy."""
    n = clip.n_frames
    ev = foot_events(pos3, clip.fps, clip.walk_speed)
    for side in _SIDES:
        st = ev[side]["strike"]
        k = int(((st >= n) & (st < 2 * n)).sum())
        if k != cycles:
            raise InvalidInputError(f"walk loop {clip.name!r}: found {k} {side} heel strikes in {cycles} gait cycles")
    return ev


def _loop_contacts(ev: dict, n: int, cycles: int) -> dict[str, dict[str, float]]:
    """Mean gait phases (per cycle, in [0, 1)) of each foot's strike, flat_end and toe_off
    from the events ``ev`` of a loop of ``n`` frames played 3 times."""
    per = n / cycles
    out: dict[str, dict[str, float]] = {}
    for side in _SIDES:
        st = ev[side]["strike"]
        sel = (st >= n) & (st < 2 * n)  # stances starting in the middle copy
        ph = (st[sel] - n) / per
        strike = float(np.mod(np.angle(np.mean(np.exp(2j * np.pi * ph))) / (2 * np.pi), 1.0))  # circular mean
        strike = 0.0 if strike > 1.0 - 1e-9 else strike
        out[side] = {"strike": strike}
        for key in ("flat_end", "toe_off"):
            dur = float(np.mean(ev[side][key][sel] - st[sel]) / per)  # cycles since the strike
            out[side][key] = float(np.mod(strike + dur, 1.0))
    return out


def _lock_offsets(pos: np.ndarray, ev: dict, fps: float) -> np.ndarray:
    """(T, 2, 3) corrections (m) of the (left, right) ankle targets that pin the planted feet
    of world joint positions ``pos`` (T, 24, 3) at ``fps`` with stances ``ev``.

    Per stance: the ankle is held at its median position over the flat foot (strike to
    flat_end), then the ball of the foot where it was at the heel rise until toe-off. The
    offset fades in over the last 40 % of the swing before (the foot comes over its
    landing spot before it touches down; 24 fps captures land abruptly) and fades out over
    the first 45 % of the swing after (quintic smoothstep). Before the strike the ankle is
    also kept :data:`HOVER` above its stance height (a captured heel often reaches the
    floor while still moving fast), released over the last 0.05 s before it.
    """
    from crowdstudy.body.posing import smoothstep5

    t_all = pos.shape[0]
    out = np.zeros((t_all, 2, 3))
    for k, side in enumerate(_SIDES):
        ankle, ball = pos[:, JOINT_INDEX[f"{side}_ankle"], :2], pos[:, JOINT_INDEX[f"{side}_foot"], :2]
        za = pos[:, JOINT_INDEX[f"{side}_ankle"], 2]
        lift = np.zeros(t_all)
        st, fl, to = (ev[side][x] for x in ("strike", "flat_end", "toe_off"))
        swings = st[1:] - to[:-1]
        default = int(np.median(swings)) if len(swings) else int(0.4 * (to[0] - st[0]) + 1)
        off = np.zeros((t_all, 2))
        for i, (a, f, e) in enumerate(zip(st, fl, to, strict=True)):
            held = np.median(ankle[a : f + 1], axis=0)
            stance = np.zeros((e + 1 - a, 2))
            stance[: f + 1 - a] = held - ankle[a : f + 1]
            stance[f + 1 - a :] = ball[f] + stance[f - a] - ball[f + 1 : e + 1]
            off[a : e + 1] += stance
            before = st[i] - to[i - 1] if i else default
            after = st[i + 1] - e if i + 1 < len(st) else default
            j = np.arange(1, int(0.4 * before) + 1)
            j = j[a - j >= 0]
            off[a - j] += stance[0] * (1.0 - smoothstep5(j / (0.4 * before)))[:, None]
            # the captured heel often reaches the floor while still moving fast (24 fps takes):
            # keep the ankle HOVER above its stance height until it has slowed down (the strike)
            j = np.arange(1, int(0.5 * before) + 1)
            j = j[a - j >= 0]
            floor = za[a : f + 1].min() + HOVER
            lift[a - j] = np.maximum(floor - za[a - j], 0.0) * smoothstep5(j / (0.05 * fps))
            j = np.arange(1, int(0.45 * after) + 1)
            j = j[e + j < t_all]
            off[e + j] += stance[-1] * (1.0 - smoothstep5(j / (0.45 * after)))[:, None]
        out[:, k, :2] = off
        out[:, k, 2] = lift
    return out


def _hold_foot_yaw(rot: np.ndarray, root: np.ndarray, ev: dict) -> np.ndarray:
    """Rotations (T, 24, 3) whose feet keep, while flat on the floor (strike to flat_end),
    the heading (yaw) they have at the heel rise: a captured foot turning about its planted
    ankle would make the ball of the foot slide. The correction fades in over the last
    40 % of the swing before (quintic smoothstep) and is zero from the heel rise on."""
    from crowdstudy.body.posing import smoothstep5
    from crowdstudy.body.rotations import matrix_to_axis_angle, rot_z
    from crowdstudy.body.skeleton import PARENTS, forward_kinematics

    glob, pos = forward_kinematics(DEFAULT_REST_JOINTS, rot, root)
    out = rot.copy()
    for side in _SIDES:
        ja, jb = JOINT_INDEX[f"{side}_ankle"], JOINT_INDEX[f"{side}_foot"]
        v = pos[:, jb] - pos[:, ja]
        yaw = np.arctan2(v[:, 1], v[:, 0])
        delta = np.zeros(len(yaw))
        st, fl, to = (ev[side][x] for x in ("strike", "flat_end", "toe_off"))
        for i, (a, f) in enumerate(zip(st, fl, strict=True)):
            d = np.angle(np.exp(1j * (yaw[f] - yaw[a : f + 1])))
            delta[a : f + 1] = d
            before = a - to[i - 1] if i else int(0.5 * (f - a)) + 1
            j = np.arange(1, int(0.4 * before) + 1)
            j = j[a - j >= 0]
            delta[a - j] = d[0] * (1.0 - smoothstep5(j / (0.4 * before)))
        turn = rot_z(delta)  # (T, 3, 3)
        local = np.swapaxes(glob[:, PARENTS[ja]], -1, -2) @ turn @ glob[:, ja]
        out[:, ja] = matrix_to_axis_angle(local)
    return out


def _lock_feet(clip: MotionClip, pos3: np.ndarray, ev: dict) -> MotionClip:
    """``clip`` with its planted feet pinned on the authoring skeleton (:func:`_hold_foot_yaw`,
    :func:`_lock_offsets`)."""
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.motion.legs import plant_legs
    from crowdstudy.motion.rig import ANKLE_HEIGHT

    n = clip.n_frames
    rot, root = _world(clip, 3)
    rot = _hold_foot_yaw(rot, root, ev)
    pos3 = forward_kinematics(DEFAULT_REST_JOINTS, rot, root)[1]
    offsets = _lock_offsets(pos3, ev, clip.fps)[:, None]
    new = plant_legs(
        rot[:, None],
        root[:, None],
        DEFAULT_REST_JOINTS[None],
        np.ones(1),
        np.array([ANKLE_HEIGHT]),
        ankle_offsets=offsets,
    )[n : 2 * n, 0]
    return dataclasses.replace(clip, joint_rotations=new)


def _steady_pelvis(clip: MotionClip, cycles: int) -> MotionClip:
    """``clip`` (a loop of ``cycles`` gait cycles) without the slow surge and wander of its
    pelvis: a take is never at exactly constant speed, so after subtracting the mean speed
    the pelvis drifts fore-aft (up to 10-18 cm in a short take) and sideways. The loop's
    Fourier harmonics below the step frequency (``2 cycles`` per loop) are removed from the
    fore-aft position, those that are not whole gait cycles from the lateral one (the sway
    over the stance foot, once per cycle, stays)."""
    root = clip.root_translation.copy()
    spec = np.fft.rfft(root[:, :2], axis=0)
    k = np.arange(spec.shape[0])
    spec[(k >= 1) & (k < 2 * cycles), 1] = 0.0
    spec[(k >= 1) & (k % cycles != 0), 0] = 0.0
    root[:, :2] = np.fft.irfft(spec, n=clip.n_frames, axis=0)
    return dataclasses.replace(clip, root_translation=root)


def build_walk_loop(path: str | Path, *, fps: float = FPS, max_cycles: int = 2) -> MotionClip:
    """One looping in-place walking clip from a straight walking BVH take (see the module docstring).

    Args:
        path: a BVH file (``.bvh`` or ``.bvh.gz``) of a steady straight walk.
        fps: working frame rate (frames/s); max_cycles: most gait cycles in the loop (1 or 2).
    """
    from crowdstudy.motion.bvh import load_bvh
    from crowdstudy.motion.loops import find_loop, in_place_positions, make_loop

    path = Path(path)
    stem = path.name.removesuffix(".gz").removesuffix(".bvh")
    raw = load_bvh(path).resample(fps)
    fps = raw.fps
    root = raw.root_translation
    net = root[-1, :2] - root[0, :2]
    rough_speed = float(np.linalg.norm(net) / raw.duration)
    raw = _level_floor(raw, foot_events(raw.joint_positions(), fps, rough_speed))
    ev = foot_events(raw.joint_positions(), fps, rough_speed)
    left = ev["left"]["strike"]
    if len(left) < 2:
        raise InvalidInputError(f"{path.name}: found {len(left)} left heel strikes, need 2 to measure the gait cycle")
    period = float(np.median(np.diff(left)))  # frames per gait cycle
    blend = int(round(BLEND_SECONDS * fps))
    window = int(round(MATCH_SECONDS * fps))
    choice = None
    for k in range(max(1, max_cycles), 0, -1):
        lengths = np.round(k * period) + np.arange(-3, 4)
        try:
            choice = find_loop(in_place_positions(raw), lengths, window=window, min_start=blend)
        except InvalidInputError:
            continue
        cycles = k
        break
    if choice is None:
        raise InvalidInputError(f"{path.name}: the take is too short for a loop of one gait cycle")
    a, length = choice.start, choice.length
    # turn the take so the loop's net displacement points along +y, then make it in place
    d = root[a + length, :2] - root[a, :2]
    speed = float(np.linalg.norm(d) / (length / fps))
    turned = turn_about_z(raw, float(np.pi / 2 - np.arctan2(d[1], d[0])), root[a, :2])
    rt = turned.root_translation.copy()
    rt[:, 1] -= speed * (np.arange(raw.n_frames) - a) / fps
    rt[:, :2] -= rt[a : a + length, :2].mean(axis=0)
    in_place = dataclasses.replace(turned, root_translation=rt)
    loop = make_loop(in_place, a, length, blend, name=stem, kind="walk", speed=speed)
    # phase 0 = left heel strike; every gait cycle gets the same number of frames
    ev = foot_events(_world_positions(loop, 3), fps, speed)
    s = ev["left"]["strike"]
    s = s[(s >= length) & (s < 2 * length)] - length
    if len(s) != cycles:
        raise InvalidInputError(f"{path.name}: found {len(s)} left heel strikes in a loop of {cycles} gait cycles")
    per_cycle = int(round(length / cycles))
    bounds = np.append(s, s[0] + length).astype(np.float64)
    u = np.arange(per_cycle) / per_cycle
    times = np.concatenate([(bounds[j] + (bounds[j + 1] - bounds[j]) * u) for j in range(cycles)]) / fps
    quat, r = loop.sample_quaternions(times)
    n = per_cycle * cycles
    new_fps = n / loop.duration
    r = r.copy()
    r[:, 1] += speed * (times - (s[0] / fps) - np.arange(n) / new_fps)  # same world path, new clock
    r[:, :2] -= r[:, :2].mean(axis=0)
    trial = "_".join(stem.split("_")[1:3])
    warped = MotionClip(
        name=stem,
        kind="walk",
        fps=new_fps,
        joint_rotations=quaternion_to_axis_angle(quat),
        root_translation=r,
        speed=speed,
        loop=True,
    )
    ev = _middle_events(warped, _world_positions(warped, 3), cycles)  # contact timing from the capture
    warped = _steady_pelvis(warped, cycles)
    pos3 = _world_positions(warped, 3)
    contacts = _loop_contacts(ev, n, cycles)
    locked = level_head(_lock_feet(warped, pos3, ev), WALK_GAZE_PITCH)
    cycle_s = loop.duration / cycles
    meta = {
        "description": f"CMU {trial} motion capture walk",
        "source": path.name,
        "trial": trial,
        "cadence": 120.0 / cycle_s,
        "stride_length": speed * cycle_s,
        "cycle": cycle_s,
        "cycles": cycles,
        "contacts": contacts,
        "lock_lead": LOCK_LEAD,
        "lock_lag": LOCK_LAG,
        "duty_factor": float(np.mean([np.mod(contacts[x]["toe_off"] - contacts[x]["strike"], 1.0) for x in _SIDES])),
        "loop_source": {"start": int(a), "length": int(length), "blend": int(blend), "fps": float(fps)},
    }
    return dataclasses.replace(locked, meta=meta)


def build_walk_loops(mocap_dir: str | Path, files: tuple[str, ...] = WALK_FILES) -> list[MotionClip]:
    """The looping walking clips of ``files`` in ``mocap_dir`` (see the module docstring), slowest first."""
    mocap_dir = Path(mocap_dir)
    missing = [f for f in files if not (mocap_dir / f).is_file()]
    if missing:
        raise InvalidInputError(f"mocap_dir {str(mocap_dir)!r}: missing walk files {', '.join(missing)}")
    return sorted((build_walk_loop(mocap_dir / f) for f in files), key=lambda c: c.walk_speed)


def loop_foot_skate(clip: MotionClip, repeats: int = 3, height_tol: float = 0.01) -> np.ndarray:
    """Horizontal travel (m) of every foot contact of a walking loop played ``repeats`` times
    with its travel, on the authoring skeleton (:func:`crowdstudy.motion.diagnostics.foot_skate`,
    a contact = a foot joint within ``height_tol`` m of its lowest height)."""
    from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
    from crowdstudy.motion.diagnostics import foot_skate
    from crowdstudy.scene import CrowdAnimation

    rot, root = _world(clip, repeats)
    anim = CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root[:, None],
        joint_rotations=rot[:, None],
        fps=clip.fps,
        bodies=({},),
        clips=({"kind": "walk"},),
        meta={"scenario": "corridor"},
    )
    return foot_skate(anim, height_tol=height_tol, rest_joints=DEFAULT_REST_JOINTS[None])


def gait_report(clip: MotionClip) -> dict:
    """Checks that a walking loop looks like a walk: knee angle at each heel strike (deg,
    180 = straight), wrist fore-aft swing (m, peak to peak, relative to the pelvis), head
    height (m, mean), the per-contact foot skate (m, max and median, :func:`loop_foot_skate`)
    and the seam (:func:`~crowdstudy.motion.clip.seam_discontinuity`)."""
    pos = clip.joint_positions()
    n, cyc = clip.n_frames, int(clip.meta.get("cycles", 1))
    out: dict = {
        "speed": clip.speed,
        "cadence": clip.meta["cadence"],
        "stride": clip.meta["stride_length"],
        "cycles": cyc,
    }
    for side in _SIDES:
        hip, knee, ankle = (pos[:, JOINT_INDEX[f"{side}_{j}"]] for j in ("hip", "knee", "ankle"))
        a, b = hip - knee, ankle - knee
        ang = np.degrees(
            np.arccos(np.clip(np.sum(a * b, -1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1), -1, 1))
        )
        f = (np.round((clip.meta["contacts"][side]["strike"] + np.arange(cyc)) * n / cyc).astype(int)) % n
        out[f"{side}_knee_at_strike"] = float(ang[f].mean())
        w = pos[:, JOINT_INDEX[f"{side}_wrist"], 1] - pos[:, 0, 1]
        out[f"{side}_wrist_swing"] = float(w.max() - w.min())
    out["head_height"] = float(pos[:, JOINT_INDEX["head"], 2].mean())
    skate = loop_foot_skate(clip)
    out["skate_max"] = float(skate.max()) if skate.size else 0.0
    out["skate_median"] = float(np.median(skate)) if skate.size else 0.0
    out["seam"] = seam_discontinuity(clip)
    return out

"""The Baseline crowd animation: layouts and trajectories -> full-body characters.

* **Stationary** (concert): every character stands at its Poisson-disk spot facing the
  stage (+y) with a small random yaw, and dances one of the shipped dance clips from a
  random phase. Clips are dealt so each is used about equally often.
* **Walking** (corridor): characters follow their ORCA trajectories. The instantaneous
  speed (smoothed finite differences of the positions) selects a blend of the 4 walking
  clips; the gait phase advances by the *distance travelled* divided by the blended
  stride length, so the planted foot does not slide. Body size enters through the leg
  scale ``s = pelvis_height / DEFAULT_PELVIS_HEIGHT``: a character at speed ``v`` uses the
  clips at speed ``v / s`` with strides scaled by ``s`` (geometric similarity).

Clip root heights are scaled by ``s`` so the soles stay on the floor (z = 0) for every
body. Both functions return a :class:`~crowdstudy.scene.CrowdAnimation`;
:func:`build_baseline` runs the whole cell of a study design.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body import load_body
from crowdstudy.body.rotations import (
    axis_angle_to_quaternion,
    quat_about_z,
    quat_conjugate,
    quat_multiply,
    quat_nearest_sign,
    quaternion_to_axis_angle,
)
from crowdstudy.body.shapes import BodyShapes
from crowdstudy.body.skeleton import DEFAULT_PELVIS_HEIGHT, JOINT_INDEX, JOINT_NAMES, PARENTS, mirror_pose
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.legs import plant_legs
from crowdstudy.motion.library import list_clips, load_clip, walk_clips
from crowdstudy.motion.mocap_library import dance_loop, idle_loop
from crowdstudy.motion.selfcontact import clear_hands
from crowdstudy.provenance import provenance
from crowdstudy.scene import Crowd, CrowdAnimation

__all__ = [
    "build_baseline",
    "bodies_meta",
    "animate_stationary",
    "animate_walking",
    "body_scales",
    "gait_blend",
    "loop_cycles",
    "MAX_LOOP_TEMPO_CHANGE",
    "LOOP_DISSOLVE_SECONDS",
]

#: Standard deviation of the random yaw around facing the stage (rad, about 8 degrees).
YAW_JITTER_SD = 0.14
#: Samples per gait cycle in the walking clips' phase tables (linear interpolation between).
_GAIT_SAMPLES = 512
#: Shortest stride, as a fraction of the slowest clip's, used below the slowest clip's speed.
_MIN_STRIDE_FACTOR = 0.5
#: Speeds below this (m/s) keep the previous facing direction.
_TURN_SPEED = 0.15
#: Largest tempo change (fraction) a dance clip may take so that a whole number of its
#: loops fills the animation (concert stimuli are exactly periodic); the 15
#: shipped clips need at most 11.1 % at 20 s / 30 fps. Beyond it the clip keeps its own
#: length and the animation is not periodic (short test durations).
MAX_LOOP_TEMPO_CHANGE = 0.12
#: The concert's default tempo (bpm; the design's ``[scenarios.concert] tempo``).
DEFAULT_TEMPO = 120.0
#: Default range of the per-dancer scale of upper-body movement.
AMPLITUDE_RANGE = (0.85, 1.15)
#: Joints whose movement ``amplitude`` scales: spine, neck, head, collars and arms.
_UPPER_BODY = np.array(
    [
        JOINT_INDEX[n]
        for n in JOINT_NAMES
        if n.startswith(("spine", "neck", "head"))
        or n.split("_", 1)[-1] in ("collar", "shoulder", "elbow", "wrist", "hand")
    ]
)
#: Seconds of extra corridor animation past the stimulus duration, cross-dissolved into the
#: video's first frames so the loop seam is not seen as a jump (``meta["loop"]`` "dissolve").
LOOP_DISSOLVE_SECONDS = 0.5


def _rng(seed, stream: int) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None:
        raise InvalidInputError("seed: expected an int or numpy Generator, got None")
    return np.random.default_rng([int(seed), stream])


def body_scales(bodies: list[dict]) -> np.ndarray:
    """(N,) leg scale of each body record: its pelvis height over the authoring skeleton's."""
    return _body_geometry(bodies)[1]


def _body_geometry(bodies: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest joints (N, 24, 3), leg scales (N,) and ankle heights above the soles (N,)."""
    loaded = [load_body(rec) for rec in bodies]
    rest = np.stack([b.rest_joints for b in loaded])
    pelvis = np.array([b.pelvis_height for b in loaded], dtype=np.float64)
    ankle = pelvis + 0.5 * (rest[:, JOINT_INDEX["left_ankle"], 2] + rest[:, JOINT_INDEX["right_ankle"], 2])
    return rest, pelvis / DEFAULT_PELVIS_HEIGHT, ankle


def _sampled(n: int, seed, model: str, shapes: BodyShapes = "study") -> list[dict]:
    from crowdstudy.body import sample_bodies

    return sample_bodies(n, seed, model=model, shapes=shapes)


def bodies_meta(shapes: BodyShapes) -> dict:
    """``meta["bodies"]`` of an animation whose bodies were drawn with ``shapes``
    (:data:`~crowdstudy.body.shapes.BodyShapes`): ``{"shapes": ...}``, or ``{}`` for the
    default ``"study"`` draw, whose animations stay the bytes they always were."""
    return {} if shapes == "study" else {"bodies": {"shapes": shapes}}


def _bodies(n: int, seed, bodies):
    if bodies is None:
        from crowdstudy.body import sample_bodies

        bodies = sample_bodies(n, seed)
    bodies = [dict(b) for b in bodies]
    if len(bodies) != n:
        raise InvalidInputError(f"bodies: expected {n} records (one per character), got {len(bodies)}")
    return bodies


def _place(quat: np.ndarray, root_local: np.ndarray, yaw: np.ndarray, xy: np.ndarray, scale: np.ndarray):
    """Turn clip poses (..., 24, 4) / roots (..., 3) to the world: yaw (...,) about z, then
    translate to xy (..., 2); root offsets scaled by ``scale`` (...,)."""
    quat = quat.copy()
    quat[..., 0, :] = quat_multiply(quat_about_z(yaw), quat[..., 0, :])
    c, s = np.cos(yaw), np.sin(yaw)
    local = root_local * scale[..., None]
    root = np.empty(root_local.shape)
    root[..., 0] = xy[..., 0] + c * local[..., 0] - s * local[..., 1]
    root[..., 1] = xy[..., 1] + s * local[..., 0] + c * local[..., 1]
    root[..., 2] = local[..., 2]
    return quaternion_to_axis_angle(quat), root


def _check_timing(duration, fps) -> tuple[float, int]:
    try:
        duration, fps = float(duration), float(fps)
    except (TypeError, ValueError):
        raise InvalidInputError(f"duration/fps: expected numbers, got {duration!r}, {fps!r}") from None
    if not np.isfinite(fps) or fps <= 0:
        raise InvalidInputError(f"fps: expected a positive frame rate, got {fps!r}")
    if not np.isfinite(duration) or duration <= 0:
        raise InvalidInputError(f"duration: expected a positive number of seconds, got {duration!r}")
    return fps, max(1, int(round(duration * fps)))


def loop_cycles(natural_frames: float, n_frames: int, max_change: float = MAX_LOOP_TEMPO_CHANGE) -> int:
    """Whole loops of a clip of ``natural_frames`` frames that fill ``n_frames`` frames with
    the smallest tempo change (log ratio), or 0 when that change exceeds ``max_change``
    (e.g. an animation shorter than about one loop). The loop then lasts ``n_frames / k``
    frames (a divisor of ``n_frames`` whenever one is nearest) at tempo ``natural_frames * k / n_frames``."""
    ratio = float(n_frames) / float(natural_frames)
    best = 0
    for k in {max(1, int(np.floor(ratio))), max(1, int(np.ceil(ratio)))}:
        if (
            best == 0
            or abs(np.log(ratio / k)) < abs(np.log(ratio / best))
            or (abs(np.log(ratio / k)) == abs(np.log(ratio / best)) and k < best)
        ):
            best = k
    tempo = natural_frames * best / n_frames
    return best if abs(tempo - 1.0) <= max_change + 1e-12 else 0


def animate_stationary(
    crowd: Crowd,
    *,
    duration: float = 20.0,
    fps: float = 30.0,
    seed=0,
    bodies: list[dict] | None = None,
    clip_names: list[str] | None = None,
    yaw_jitter: float = YAW_JITTER_SD,
    tempo: float | None = DEFAULT_TEMPO,
    mirror: float = 0.5,
    amplitude: tuple[float, float] = AMPLITUDE_RANGE,
    clear_self_contact: bool = True,
    meta: dict | None = None,
) -> CrowdAnimation:
    """A dancing crowd on the layout ``crowd`` (its first frame).

    Args:
        crowd: positions (T, N, 2) metres; frame 0 gives each character's spot and, when
            the crowd has headings, its facing (default +y, the stage).
        duration, fps: length (s) and frame rate of the animation.
        seed: int or Generator for clip choice, phase, mirroring, amplitude and yaw; also
            seeds ``sample_bodies`` when ``bodies`` is None.
        bodies: N body records (default ``sample_bodies(N, seed)``).
        clip_names: dance clips to deal from (default the motion-captured dances of the
            default concert, :func:`~crowdstudy.motion.library.list_clips`); procedural
            clip names (``list_clips("dance", source="procedural")``) work too.
        yaw_jitter: standard deviation (rad) of the random yaw around that facing.
        tempo: the music's beat (bpm) for motion-captured dances: each take is time-warped
            so its bounce falls on the beats and loops over whole bars
            (:func:`~crowdstudy.motion.mocap_library.dance_loop`); each dancer starts on a
            random whole beat of its loop, so neighbours differ but share the beat. None
            plays every take at its own tempo from a random frame (no shared beat: the
            "before" of :func:`~crowdstudy.motion.beat.bounce_phase`).
        mirror: probability that a dancer plays its clip mirrored left <-> right.
        amplitude: (low, high) range of a per-dancer scale of the upper body's movement
            around the clip's mean pose (legs and pelvis untouched, feet stay planted).
        clear_self_contact: move each character's hands out of its own torso and head
            (:func:`~crowdstudy.motion.selfcontact.clear_hands`: a performer's hands on the
            hips end up inside a wider body).

    Motion-captured loops last whole bars that divide the animation when it holds whole
    bars (then it is exactly periodic). Procedural clips play a whole number ``k`` of loops
    in the T frames (:func:`loop_cycles`: time-warped by at most
    :data:`MAX_LOOP_TEMPO_CHANGE`). Either way the animation is exactly periodic with period
    T when every clip's loop divides T: frame T would equal frame 0 and the step T-1 -> 0
    is an ordinary frame step (the videos loop).

    Returns:
        CrowdAnimation with root_translation (T, N, 3) m and joint_rotations (T, N, 24, 3);
        ``clips[i] = {"kind": "dance", "clips": [name], "weights": [1.0], "phase": s,
        "yaw": rad, "scale": leg scale, "tempo": played / natural speed, "loop_frames":
        frames per loop, "mirrored": bool, "amplitude": upper-body scale, "beat_offset":
        whole beats into the loop (motion capture)}``; ``meta["loop"] = {"mode":
        "periodic", "frames": T}`` or ``{"mode": "none"}``; ``meta["tempo"]`` (bpm).
    """
    if not isinstance(crowd, Crowd):
        raise InvalidInputError(f"crowd: expected a Crowd, got {type(crowd).__name__}")
    fps, n_frames = _check_timing(duration, fps)
    amplitude = _check_dance_options(amplitude, mirror)
    n = crowd.n_agents
    names = list(clip_names) if clip_names is not None else list_clips("dance", default_only=True)
    clips = _dance_clips(names, tempo, fps, n_frames)
    rng = _rng(seed, 1)
    dancers = _draw_dancers(rng, clips, n, yaw_jitter, mirror, amplitude)
    if crowd.headings is not None:  # face the crowd's headings (the stage: +y)
        dancers.yaw = dancers.yaw + crowd.headings[0] - np.pi / 2
    bodies = _bodies(n, seed, bodies)
    rest, scale, ankle_height = _body_geometry(bodies)
    xy = crowd.positions[0]
    rot = np.empty((n_frames, n, len(JOINT_NAMES), 3))
    root = np.empty((n_frames, n, 3))
    periodic = True
    for k, clip in enumerate(clips):
        members = np.flatnonzero(dancers.choice == k)
        if members.size == 0:
            continue
        loop = _dance_schedule(clip, dancers.phase[members], rng, fps, n_frames)
        periodic &= loop.periodic
        dancers.tempo_ratio[members] = loop.tempo_ratio
        if loop.beat_offset is not None:
            dancers.beat_offset[members] = loop.beat_offset
        dancers.loop_frames[members] = loop.n_loop / loop.step
        rot[:, members], root[:, members] = _dance_poses(
            clip, loop, n_frames, dancers, members, xy[members], scale[members]
        )
        dancers.phase[members] = loop.start * clip.duration / loop.n_loop
    rot = plant_legs(rot, root, rest, scale, ankle_height)
    if clear_self_contact:  # hands out of each character's own (wider) body
        rot = clear_hands(rot, root, [load_body(b) for b in bodies], fps)
    out_meta = {
        "method": "Baseline",
        "scenario": crowd.meta.get("scenario", "concert"),
        "tempo": None if tempo is None else float(tempo),
        "provenance": provenance(seed if not isinstance(seed, np.random.Generator) else None),
    }
    out_meta.update(
        {k: crowd.meta[k] for k in ("floor", "stage_distance", "stage_front", "obstacles") if k in crowd.meta}
    )  # the scene's static geometry, for the later stages
    out_meta.update(meta or {})
    loop_meta = {"mode": "periodic", "frames": int(n_frames)} if periodic else {"mode": "none"}
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=rot,
        fps=fps,
        bodies=tuple(bodies),
        clips=_dance_records(names, dancers, scale),
        meta={"loop": loop_meta, **out_meta},
    )


def _check_dance_options(amplitude: tuple[float, float], mirror: float) -> tuple[float, float]:
    """The (low, high) upper-body amplitude range of :func:`animate_stationary`, checked
    together with its mirroring probability."""
    lo_amp, hi_amp = (float(a) for a in amplitude)
    if not (0.0 < lo_amp <= hi_amp <= 2.0):
        raise InvalidInputError(f"amplitude: expected 0 < low <= high <= 2, got {amplitude!r}")
    if not 0.0 <= float(mirror) <= 1.0:
        raise InvalidInputError(f"mirror: expected a probability in [0, 1], got {mirror!r}")
    return lo_amp, hi_amp


def _dance_clips(names: list[str], tempo: float | None, fps: float, n_frames: int) -> list[MotionClip]:
    """The clips called ``names``, motion-captured ones made into loops of ``n_frames`` at
    ``fps``: idle takes (and every take when ``tempo`` is None) at their own tempo, dances
    time-warped onto the beat of ``tempo`` bpm."""
    if not names:
        raise InvalidInputError("clip_names: expected at least one dance clip")
    clips = []
    for name in names:
        clip = load_clip(name)
        if clip.meta.get("mocap"):
            clip = (
                idle_loop(name, fps, n_frames)
                if clip.meta.get("idle") or tempo is None
                else dance_loop(name, float(tempo), fps, n_frames / fps)
            )
        clips.append(clip)
    return clips


@dataclasses.dataclass
class _Dancers:
    """Per-dancer choices of :func:`animate_stationary`, (N,) arrays: the random draws
    (``choice`` clip index, ``phase`` s into the clip, ``yaw`` rad about +z from facing +y,
    ``mirrored``, ``amp`` upper-body scale) and what the clip's loop makes of them
    (``tempo_ratio`` played / natural speed, ``loop_frames`` frames per loop,
    ``beat_offset`` whole beats into the loop, -1 without beats)."""

    choice: np.ndarray
    phase: np.ndarray
    yaw: np.ndarray
    mirrored: np.ndarray
    amp: np.ndarray
    tempo_ratio: np.ndarray
    loop_frames: np.ndarray
    beat_offset: np.ndarray


def _draw_dancers(
    rng: np.random.Generator,
    clips: list[MotionClip],
    n: int,
    yaw_jitter: float,
    mirror: float,
    amplitude: tuple[float, float],
) -> _Dancers:
    """The random draws of ``n`` dancers, in this order: clips dealt so each is used about
    equally often, phases, yaws (clipped at 2.5 ``yaw_jitter``), mirroring, amplitudes."""
    choice = rng.permutation(np.resize(np.arange(len(clips)), n))
    phase = rng.uniform(0.0, 1.0, n) * np.array([clips[c].duration for c in choice])
    yaw = (
        np.clip(rng.normal(0.0, yaw_jitter, n), -2.5 * yaw_jitter, 2.5 * yaw_jitter) if yaw_jitter > 0 else np.zeros(n)
    )
    mirrored = rng.uniform(0.0, 1.0, n) < float(mirror)
    amp = rng.uniform(amplitude[0], amplitude[1], n)
    return _Dancers(
        choice=choice,
        phase=phase,
        yaw=yaw,
        mirrored=mirrored,
        amp=amp,
        tempo_ratio=np.ones(n),
        loop_frames=np.ones(n),
        beat_offset=np.full(n, -1, dtype=np.int64),
    )


@dataclasses.dataclass(frozen=True)
class _DanceLoop:
    """How M dancers play one clip: a table of ``n_loop`` phases of the loop advanced
    ``step`` entries per frame from ``start`` (M,) int64; ``tempo_ratio`` played / natural
    speed; ``beat_offset`` (M,) whole beats into the loop (None without beats);
    ``periodic``: whether the loop divides the animation's frames."""

    n_loop: int
    step: int
    start: np.ndarray
    tempo_ratio: float
    beat_offset: np.ndarray | None
    periodic: bool


def _dance_schedule(
    clip: MotionClip, phase: np.ndarray, rng: np.random.Generator, fps: float, n_frames: int
) -> _DanceLoop:
    """The loop of ``clip`` for its M dancers at ``phase`` (M,) seconds: a motion-captured
    loop is played frame by frame from a random whole beat (drawn from ``rng``); a
    procedural one is time-warped so a whole number of loops fills ``n_frames``."""
    if clip.meta.get("mocap"):
        # a loop of whole frames (whole bars for dances), each dancer from its own beat
        n_loop = clip.n_frames
        bf = int(clip.meta.get("beat_frames", 1))
        start = bf * rng.integers(0, max(1, n_loop // bf), phase.size)
        return _DanceLoop(
            n_loop=n_loop,
            step=1,
            start=start,
            tempo_ratio=clip.meta.get("tempo_ratio", 1.0),
            beat_offset=start // bf if "beat_frames" in clip.meta else None,
            periodic=n_frames % n_loop == 0,
        )
    # A whole number of loops in the T frames (time-warped to fit: frame T would be
    # frame 0), sampled on a table of n_loop phases advanced `step` entries per frame.
    cycles = loop_cycles(clip.duration * fps, n_frames)
    if cycles:
        g = int(np.gcd(n_frames, cycles))
        n_loop, step = n_frames // g, cycles // g  # n_loop / step = T / cycles
    else:  # shorter than a loop: the natural length
        n_loop, step = max(4, int(round(clip.duration * fps))), 1
    return _DanceLoop(
        n_loop=n_loop,
        step=step,
        start=np.floor(phase / clip.duration * n_loop).astype(np.int64),
        tempo_ratio=clip.duration * fps * step / n_loop,
        beat_offset=None,
        periodic=bool(cycles),
    )


def _dance_poses(
    clip: MotionClip,
    loop: _DanceLoop,
    n_frames: int,
    dancers: _Dancers,
    members: np.ndarray,
    xy: np.ndarray,
    scale: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The M dancers ``members`` of ``clip`` over ``n_frames`` frames: joint rotations
    (T, M, 24, 3) axis-angle and pelvis positions (T, M, 3) m, mirrored and amplitude-scaled
    as drawn, turned by their yaw and standing at ``xy`` (M, 2) m; ``scale`` (M,) leg scales."""
    quat_table, root_table = clip.loop_table(loop.n_loop)
    idx = (loop.start[None, :] + loop.step * np.arange(n_frames)[:, None]) % loop.n_loop  # (T, M)
    quat = quat_table[idx]  # (T, M, 24, 4)
    local = root_table[idx]
    flip = dancers.mirrored[members]
    if flip.any():
        quat[:, flip], local[:, flip] = mirror_pose(quat[:, flip], local[:, flip])
    quat = _scale_upper_body(quat, quat_table, dancers.amp[members])
    rot = quaternion_to_axis_angle(quat)
    y = np.broadcast_to(dancers.yaw[members], idx.shape)
    q0 = quat_multiply(quat_about_z(y), quat[..., 0, :])
    rot[:, :, 0] = quaternion_to_axis_angle(q0)
    local = local * scale[None, :, None]
    c, s_ = np.cos(y), np.sin(y)
    root = np.empty(local.shape)
    root[..., 0] = xy[:, 0] + c * local[..., 0] - s_ * local[..., 1]
    root[..., 1] = xy[:, 1] + s_ * local[..., 0] + c * local[..., 1]
    root[..., 2] = local[..., 2]
    return rot, root


def _dance_records(names: list[str], dancers: _Dancers, scale: np.ndarray) -> tuple[dict, ...]:
    """``CrowdAnimation.clips`` of the dancers (see :func:`animate_stationary`)."""
    d = dancers
    return tuple(
        {
            "kind": "dance",
            "clips": [names[c]],
            "weights": [1.0],
            "phase": float(ph),
            "yaw": float(y),
            "scale": float(s),
            "tempo": float(tp),
            "loop_frames": float(lf),
            "mirrored": bool(mi),
            "amplitude": float(am),
            "beat_offset": int(bo),
        }
        for c, ph, y, s, tp, lf, mi, am, bo in zip(
            d.choice, d.phase, d.yaw, scale, d.tempo_ratio, d.loop_frames, d.mirrored, d.amp, d.beat_offset, strict=True
        )
    )


def _scale_upper_body(quat: np.ndarray, table: np.ndarray, amp: np.ndarray) -> np.ndarray:
    """(T, M, 24, 4) poses whose upper-body joints move ``amp`` (M,) times as far from the
    loop's mean pose (per joint, the normalised mean of ``table`` (S, 24, 4))."""
    if np.allclose(amp, 1.0):
        return quat
    mean = np.sum(quat_nearest_sign(table, table[:1]), axis=0)
    mean /= np.linalg.norm(mean, axis=-1, keepdims=True)  # (24, 4)
    out = quat.copy()
    j = _UPPER_BODY
    rel = quat_multiply(quat_conjugate(mean[j]), quat[..., j, :])
    aa = quaternion_to_axis_angle(rel) * amp[None, :, None, None]
    out[..., j, :] = quat_multiply(mean[j], axis_angle_to_quaternion(aa))
    return out


def _check_walks(walks) -> list[MotionClip]:
    """The walking clips sorted by speed, checked for what :func:`animate_walking` needs."""
    walks = sorted(walks, key=lambda c: c.speed if c.speed is not None else -1.0)
    if len(walks) < 2:
        raise InvalidInputError(f"walks: expected at least 2 walking clips, got {len(walks)}")
    for c in walks:
        if not isinstance(c, MotionClip) or not c.loop or c.speed is None or "stride_length" not in c.meta:
            raise InvalidInputError(
                f"walks: clip {getattr(c, 'name', c)!r} is not a looping walking clip with a "
                "speed and meta 'stride_length'"
            )
    speeds = [c.speed for c in walks]
    if len(set(speeds)) != len(speeds):
        raise InvalidInputError(f"walks: clip speeds must differ, got {speeds}")
    return walks


def _contact_table(walks: list[MotionClip]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K, 2) arrays of the walking clips' foot-lock timing, left and right foot, in gait
    cycles: the phase where each foot's lock starts (its heel strike less ``lock_lead``,
    given as an offset from the nominal 0 / 0.5 so clips blend across phase 0), and the
    durations from there to the end of the flat foot and to the end of the stance
    (toe-off plus ``lock_lag``).

    ``meta["contacts"] = {"left": {"strike", "flat_end", "toe_off"}, "right": {...}}`` are
    gait phases in [0, 1); a clip without it gets those of the procedural walks
    (:mod:`crowdstudy.motion.walk`).
    """
    from crowdstudy.motion.walk import procedural_contacts

    default = procedural_contacts()
    out = np.zeros((3, len(walks), 2))
    for i, c in enumerate(walks):
        src = c.meta if "contacts" in c.meta else default
        lead, lag = float(src.get("lock_lead", 0.0)), float(src.get("lock_lag", 0.0))
        for k, (side, nominal) in enumerate((("left", 0.0), ("right", 0.5))):
            ev = src["contacts"][side]
            strike = float(ev["strike"])
            out[0, i, k] = nominal + np.mod(strike - nominal + 0.5, 1.0) - 0.5 - lead
            out[1, i, k] = np.mod(float(ev["flat_end"]) - strike, 1.0) + lead
            out[2, i, k] = np.mod(float(ev["toe_off"]) - strike, 1.0) + lag + lead
    return out[0], out[1], out[2]


def gait_blend(speed: np.ndarray, clip_speeds: np.ndarray) -> np.ndarray:
    """(..., K) blend weights of K walking clips (speeds ascending) for ``speed`` (...,) m/s:
    linear between the two nearest clip speeds, clamped to the slowest / fastest clip."""
    speeds = np.asarray(clip_speeds, dtype=np.float64)
    v = np.clip(np.asarray(speed, dtype=np.float64), speeds[0], speeds[-1])
    hi = np.clip(np.searchsorted(speeds, v, side="right"), 1, len(speeds) - 1)
    lo = hi - 1
    frac = (v - speeds[lo]) / (speeds[hi] - speeds[lo])
    w = np.zeros(v.shape + (len(speeds),))
    np.put_along_axis(w, lo[..., None], (1.0 - frac)[..., None], axis=-1)
    np.put_along_axis(w, hi[..., None], frac[..., None], axis=-1)
    return w


def _resample_track(positions: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    t_in = np.arange(positions.shape[0]) / fps_in
    n_out = int(np.floor(t_in[-1] * fps_out + 1e-9)) + 1
    t_out = np.arange(n_out) / fps_out
    idx = (
        np.clip(np.searchsorted(t_in, t_out, side="right") - 1, 0, len(t_in) - 2)
        if len(t_in) > 1
        else np.zeros(n_out, dtype=int)
    )
    if len(t_in) == 1:
        return np.repeat(positions, n_out, axis=0)
    frac = ((t_out - t_in[idx]) * fps_in)[:, None, None]
    return positions[idx] * (1.0 - frac) + positions[idx + 1] * frac


def _headings(vel: np.ndarray, speed: np.ndarray, initial: np.ndarray, fps: float, smooth_s: float) -> np.ndarray:
    """(T, N) facing angles from the motion direction, held while slow, unwrapped and smoothed."""
    from scipy.ndimage import gaussian_filter1d

    ang = np.arctan2(vel[..., 1], vel[..., 0])
    ang = np.where(speed > _TURN_SPEED, ang, np.nan)
    ang[0] = np.where(np.isnan(ang[0]), initial, ang[0])
    # forward fill the slow frames
    idx = np.where(np.isnan(ang), 0, np.arange(ang.shape[0])[:, None])
    np.maximum.accumulate(idx, axis=0, out=idx)
    ang = np.take_along_axis(ang, idx, axis=0)
    ang = np.unwrap(ang, axis=0)
    if smooth_s > 0 and ang.shape[0] > 1:
        ang = gaussian_filter1d(ang, smooth_s * fps, axis=0, mode="nearest")
    return ang


def animate_walking(
    crowd: Crowd,
    *,
    fps: float | None = None,
    seed=0,
    bodies: list[dict] | None = None,
    facing: str = "auto",
    velocity_smoothing: float = 0.12,
    heading_smoothing: float = 0.25,
    dissolve_frames: int = 0,
    meta: dict | None = None,
    walks: list[MotionClip] | None = None,
) -> CrowdAnimation:
    """Walking characters along the trajectories of ``crowd``.

    Args:
        crowd: positions (T, N, 2) metres at ``crowd.fps`` (unwrapped when periodic) and
            optionally headings (T, N) radians.
        facing: "crowd" (the crowd's headings), "motion" (the direction of the smoothed
            velocity, held while standing) or "auto" (the headings when the crowd has
            them). The gait is a forward walk: headings far from the direction of motion
            would make the feet slide sideways.
        fps: output frame rate (default the crowd's); positions are linearly resampled.
        seed: int or Generator for the initial gait phases; seeds ``sample_bodies`` too.
        bodies: N body records (default ``sample_bodies(N, seed)``).
        velocity_smoothing, heading_smoothing: Gaussian smoothing (s) of the speed used to
            pick the clips and of the facing direction ("motion"; "crowd" headings are
            smoothed over a third of it).
        dissolve_frames: D > 0 when the crowd's last D frames lie past the video: the
            video is the first T = n_frames - D frames and its seam is a cross-dissolve
            of frames T..T+D-1 into its first D frames (``render_video``).
        walks: the in-place looping walking clips to blend (default
            :func:`~crowdstudy.motion.library.walk_clips`), at least 2 of different
            ``speed``; each with meta ``stride_length`` (m per gait cycle), optionally
            ``cycles`` (gait cycles in the loop, default 1; phase 0 of every cycle = the
            left heel strike), ``contacts`` (see :func:`_contact_table`), ``lock_lead``
            and ``lock_lag``.

    Returns:
        CrowdAnimation; ``clips[i] = {"kind": "walk", "clips": [4 names], "weights":
        time-averaged blend weights, "phase": initial gait phase (0..1), "scale",
        "mean_speed"}``; ``meta["periodic"]`` copied from the crowd; ``meta["loop"] =
        {"mode": "dissolve", "frames": D, "video_frames": T}`` (``{"mode": "none"}`` when D = 0).
    """
    fps_out, pos = _walking_track(crowd, fps)
    n_frames, n = pos.shape[:2]
    if (
        isinstance(dissolve_frames, bool)
        or not isinstance(dissolve_frames, (int, np.integer))
        or not 0 <= dissolve_frames <= n_frames // 2
    ):
        raise InvalidInputError(
            f"dissolve_frames: expected an integer in [0, {n_frames // 2}] (at most half of "
            f"the {n_frames} frames), got {dissolve_frames!r}"
        )
    rng = _rng(seed, 2)
    phase0 = rng.uniform(0.0, 1.0, n)
    bodies = _bodies(n, seed, bodies)
    rest, scale, ankle_height = _body_geometry(bodies)
    vel, speed = _walking_velocity(pos, fps_out, velocity_smoothing)
    heading = _walking_heading(crowd, facing, vel, speed, fps_out, heading_smoothing)
    walks = _check_walks(walk_clips() if walks is None else walks)
    weights, phase = _gait_phase(pos, speed, scale, walks, phase0)
    quat, root_local = _blend_gaits(walks, weights, phase)
    rot, root = _place(quat, root_local, heading - np.pi / 2, pos, np.broadcast_to(scale, (n_frames, n)))
    # Foot locking holds each foot from its heel strike (less the clips' ``lock_lead``: a
    # procedural foot is over its landing spot before it comes down) through the flat
    # stance, then the ball through the heel rise and toe-off (plus ``lock_lag``); the
    # contact timing of the clips (meta "contacts") is blended by the pose weights.
    strike, flat_len, stance_len = (np.einsum("tnk,kf->tnf", weights, x) for x in _contact_table(walks))
    foot_phase = np.mod(phase[..., None] - strike, 1.0)
    rot = plant_legs(rot, root, rest, scale, ankle_height, foot_phase, flat_len, stance_len)
    records = tuple(
        {
            "kind": "walk",
            "clips": [c.name for c in walks],
            "weights": [float(x) for x in weights[:, i].mean(axis=0)],
            "phase": float(phase0[i]),
            "scale": float(scale[i]),
            "mean_speed": float(speed[:, i].mean()),
        }
        for i in range(n)
    )
    out_meta = {
        "method": "Baseline",
        "scenario": crowd.meta.get("scenario", "corridor"),
        "provenance": provenance(seed if not isinstance(seed, np.random.Generator) else None),
    }
    if crowd.meta.get("periodic"):
        out_meta["periodic"] = dict(crowd.meta["periodic"])
    out_meta.update(
        {
            k: crowd.meta[k]
            for k in ("floor", "corridor_width", "corridor_length", "plaza", "obstacles")
            if k in crowd.meta
        }
    )  # the scene's static geometry, for the later stages
    out_meta.update(meta or {})
    loop = (
        {"mode": "dissolve", "frames": int(dissolve_frames), "video_frames": int(n_frames - dissolve_frames)}
        if dissolve_frames
        else {"mode": "none"}
    )
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=rot,
        fps=fps_out,
        bodies=tuple(bodies),
        clips=records,
        meta={"loop": loop, **out_meta},
    )


def _walking_track(crowd: Crowd, fps: float | None) -> tuple[float, np.ndarray]:
    """The output frame rate (default the crowd's) and the crowd's positions (T, N, 2) m
    linearly resampled to it."""
    if not isinstance(crowd, Crowd):
        raise InvalidInputError(f"crowd: expected a Crowd, got {type(crowd).__name__}")
    if crowd.n_frames < 2:
        raise InvalidInputError("crowd: walking needs trajectories with at least 2 frames, got a layout (T = 1)")
    fps_out = crowd.fps if fps is None else float(fps)
    if not np.isfinite(fps_out) or fps_out <= 0:
        raise InvalidInputError(f"fps: expected a positive frame rate, got {fps!r}")
    pos = crowd.positions if fps_out == crowd.fps else _resample_track(crowd.positions, crowd.fps, fps_out)
    return fps_out, pos


def _walking_velocity(pos: np.ndarray, fps: float, smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocities (T, N, 2) m/s of the positions ``pos`` (T, N, 2) m at ``fps`` (central
    differences, Gaussian-smoothed over ``smoothing`` s) and their speeds (T, N) m/s."""
    from scipy.ndimage import gaussian_filter1d

    n_frames = pos.shape[0]
    vel = np.gradient(pos, 1.0 / fps, axis=0) if n_frames > 2 else np.repeat(np.diff(pos, axis=0) * fps, 2, 0)
    if smoothing > 0:
        vel = gaussian_filter1d(vel, smoothing * fps, axis=0, mode="nearest")
    return vel, np.linalg.norm(vel, axis=-1)


def _walking_heading(
    crowd: Crowd, facing: str, vel: np.ndarray, speed: np.ndarray, fps: float, smoothing: float
) -> np.ndarray:
    """(T, N) facing angles (rad from +x) at ``fps``: the crowd's headings (``facing``
    "crowd", or "auto" when it has them) smoothed over ``smoothing / 3`` s, else the
    direction of the velocity ``vel`` (T, N, 2) smoothed over ``smoothing`` s."""
    from scipy.ndimage import gaussian_filter1d

    if facing not in ("auto", "crowd", "motion"):
        raise InvalidInputError(f"facing: expected 'auto', 'crowd' or 'motion', got {facing!r}")
    if facing == "crowd" and crowd.headings is None:
        raise InvalidInputError("facing: 'crowd' needs a crowd with headings; this one has none")
    n_frames, n = speed.shape
    if facing != "motion" and crowd.headings is not None:
        heads = np.unwrap(crowd.headings, axis=0)
        if fps != crowd.fps:
            heads = _resample_track(heads[..., None], crowd.fps, fps)[..., 0]
        return (
            gaussian_filter1d(heads, smoothing / 3 * fps, axis=0, mode="nearest")
            if smoothing > 0 and n_frames > 1
            else heads
        )
    initial = crowd.headings[0] if crowd.headings is not None else np.full(n, np.pi / 2)
    return _headings(vel, speed, initial, fps, smoothing)


def _gait_phase(
    pos: np.ndarray, speed: np.ndarray, scale: np.ndarray, walks: list[MotionClip], phase0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Blend weights (T, N, K) of the K walking clips at each character's speed (T, N) m/s
    over its leg scale (N,), and the gait phase (T, N) in cycles from ``phase0`` (N,): the
    distance walked (from the positions ``pos`` (T, N, 2) m) over the blended stride."""
    clip_speeds = np.array([c.speed for c in walks])
    strides = np.array([c.meta["stride_length"] for c in walks])
    weights = gait_blend(speed / scale, clip_speeds)  # (T, N, K)
    stride = (weights @ strides) * scale  # (T, N) metres per cycle
    # Below the slowest clip, strides shorten (as in slow human walking: about 75 steps
    # per minute at 0.5 m/s rather than a slow-motion 0.8 m/s gait); the foot locking in
    # plant_legs keeps the planted feet still while the legs take the shorter steps.
    stride = stride * np.sqrt(np.clip(speed / scale / clip_speeds[0], _MIN_STRIDE_FACTOR**2, 1.0))
    step = np.linalg.norm(np.diff(pos, axis=0), axis=-1)  # (T-1, N)
    dphase = step / (0.5 * (stride[1:] + stride[:-1]))
    n = pos.shape[1]
    return weights, phase0 + np.concatenate([np.zeros((1, n)), np.cumsum(dphase, axis=0)], axis=0)


def _blend_gaits(walks: list[MotionClip], weights: np.ndarray, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The in-place walking pose at gait ``phase`` (T, N) cycles blending the clips by
    ``weights`` (T, N, K): quaternions (T, N, 24, 4) and clip root positions (T, N, 3) m.

    Dense per-phase tables of the clips; each frame blends the two active clips, each
    linearly interpolated between neighbouring table entries (nlerp, signs taken nearest
    the first term's)."""
    tables = [c.loop_table(_GAIT_SAMPLES) for c in walks]
    quat_tab = np.stack([q for q, _ in tables])  # (K, S, J, 4)
    root_tab = np.stack([r for _, r in tables])  # (K, S, 3)
    lo = np.clip(np.argmax(weights > 0, axis=-1), 0, len(walks) - 2)
    w_hi = np.take_along_axis(weights, (lo + 1)[..., None], axis=-1)[..., 0]
    # a clip of c gait cycles spans c units of the gait phase (every cycle starts at a left heel strike)
    cycles = np.array([float(c.meta.get("cycles", 1)) for c in walks])
    terms = []
    for k, w_k in ((lo, 1.0 - w_hi), (lo + 1, w_hi)):
        u = np.mod(phase, cycles[k]) / cycles[k] * _GAIT_SAMPLES
        i0 = np.floor(u).astype(np.int64) % _GAIT_SAMPLES
        f = u - np.floor(u)
        terms += [((k, i0), w_k * (1.0 - f)), ((k, (i0 + 1) % _GAIT_SAMPLES), w_k * f)]
    ref = quat_tab[terms[0][0]]
    quat = np.zeros_like(ref)
    root_local = np.zeros(phase.shape + (3,))
    for n_term, ((k, i), w) in enumerate(terms):
        q = quat_tab[k, i]
        if n_term:
            q = np.where((np.einsum("...c,...c->...", q, ref) < 0.0)[..., None], -q, q)
        quat += w[..., None, None] * q
        root_local += w[..., None] * root_tab[k, i]
    quat /= np.sqrt(np.einsum("...c,...c->...", quat, quat))[..., None]
    return quat, root_local


def build_baseline(
    design,
    stage,
    level: str,
    *,
    duration: float | None = None,
    fps: float | None = None,
    seed: int | None = None,
    dissolve: float | None = None,
    body_model: str = "makehuman",
    body_shapes: BodyShapes | None = None,
) -> CrowdAnimation:
    """The Baseline animation of one (stage, density) cell of a study design.

    Args:
        design: a :class:`~crowdstudy.design.StudyDesign` (or a path to its TOML file).
        stage: "stationary" / "walking" (or 1 / 2, or the scenario name).
        level: density level, e.g. "D3".
        duration, fps: default the design's video duration and frame rate.
        seed: default the design's seed of the cell (``design.cell_seed``).
        dissolve: walking scenarios (corridor, crossing) only, seconds of animation generated past ``duration`` for the
            video's loop cross-dissolve (default :data:`LOOP_DISSOLVE_SECONDS`; 0 = none).
        body_model: the bodies' model for ``sample_bodies`` ("makehuman", or "open" for the
            generated mannequins).
        body_shapes: the bodies' shape draw for ``sample_bodies``
            (:data:`~crowdstudy.body.shapes.BodyShapes`; default the design's ``[bodies] shapes``).

    The concert is exactly periodic over ``duration`` (``meta["loop"]["mode"] ==
    "periodic"``); the corridor and the crossing have T + D frames (T = duration * fps, D = dissolve * fps,
    at most T / 2) and ``meta["loop"] = {"mode": "dissolve", "frames": D, "video_frames": T}``.

    Returns:
        CrowdAnimation with meta {stage, stage_number, scenario, density_level, density,
        n_characters, seed, method "Baseline", provenance, loop, periodic (corridor)}, and
        ``bodies`` {"shapes"} when the shapes are not the default ``"study"`` draw.
    """
    from crowdstudy.design import StudyDesign, load_design

    if not isinstance(design, StudyDesign):
        design = load_design(design)
    st = design.stage(str(stage))
    if level not in design.densities:
        raise InvalidInputError(
            f"level: unknown density level {level!r}; expected one of {', '.join(design.densities)}"
        )
    seed = design.cell_seed(st, level) if seed is None else int(seed)
    duration = float(design.duration if duration is None else duration)
    fps = float(design.fps if fps is None else fps)
    scenario = design.scenarios[st.scenario]
    meta = {
        "stage": st.key,
        "stage_number": st.number,
        "scenario": scenario.kind,
        "density_level": level,
        "density": design.densities[level],
        "n_characters": design.n_characters(level),
        "seed": seed,
        "method": "Baseline",
        "provenance": provenance(seed, design=design.source),
    }
    shapes = design.body_shapes if body_shapes is None else body_shapes
    meta.update(bodies_meta(shapes))
    if scenario.name != scenario.kind:  # a design's own name for a scenario of a known kind
        meta["scenario_name"] = scenario.name
    if scenario.kind == "concert":
        from crowdstudy.layout import concert_layout

        crowd = concert_layout(design, level, seed, scenario=scenario.name)
        sc = scenario.params
        names = list_clips("dance", "procedural") if sc.get("motion", "mocap") == "procedural" else None
        bodies = _sampled(crowd.n_agents, seed, body_model, shapes)
        return animate_stationary(
            crowd,
            duration=duration,
            fps=fps,
            seed=seed,
            clip_names=names,
            tempo=sc.get("tempo", DEFAULT_TEMPO),
            meta=meta,
            bodies=bodies,
        )
    if scenario.kind in ("corridor", "crossing"):
        return _walking_cell(design, scenario, level, seed, duration, fps, dissolve, (body_model, shapes), meta)
    raise InvalidInputError(f"stage {st.key!r}: scenario {st.scenario!r} ({scenario.kind}) has no Baseline animation")


def _walking_cell(
    design,
    scenario,
    level: str,
    seed: int,
    duration: float,
    fps: float,
    dissolve,
    body: tuple[str, BodyShapes],
    meta: dict,
) -> CrowdAnimation:
    """The Baseline of a walking cell (a corridor or a crossing scenario): its navigation
    run ``dissolve`` s (default :data:`LOOP_DISSOLVE_SECONDS`) past ``duration``, then
    :func:`animate_walking` with those frames dissolved into the video's start; ``body`` is
    the bodies' (model, shapes)."""
    from crowdstudy.navigation import corridor_crowd, crossing_crowd

    dissolve = LOOP_DISSOLVE_SECONDS if dissolve is None else float(dissolve)
    if not np.isfinite(dissolve) or dissolve < 0:
        raise InvalidInputError(f"dissolve: expected a non-negative number of seconds, got {dissolve!r}")
    fps, n_video = _check_timing(duration, fps)
    n_dissolve = min(int(round(dissolve * fps)), n_video // 2)
    # the navigation runs D frames past the video: they are dissolved into its start
    navigate = corridor_crowd if scenario.kind == "corridor" else crossing_crowd
    crowd = navigate(design, level, seed, duration=(n_video + n_dissolve) / fps, fps=fps, scenario=scenario.name)
    walks = walk_clips("procedural") if scenario.params.get("motion", "mocap") == "procedural" else None
    return animate_walking(
        crowd,
        fps=fps,
        seed=seed,
        dissolve_frames=n_dissolve,
        walks=walks,
        meta=meta,
        bodies=_sampled(crowd.n_agents, seed, *body),
    )

"""Procedural concert dances: 15 distinct looping clips for the 24-joint skeleton.

Each dance is a :class:`DanceSpec`, a combination of periodic moves timed on the beat
(bpm 90..140): knee bounces, lateral sways, hip twists, head nods, side tilts, jumps,
step-touches, and one of several arm patterns (relaxed swing, elbow groove, fist pumps,
V raise, hands up swaying, clapping in front or overhead, one-arm waving, slow raises).
Every move is a smooth periodic function of the beat whose period divides the loop
length, so the clip loops seamlessly (pose and velocity continuous across the seam).

The feet stay planted with analytic leg IK (except during jumps and step-touches) and
the pelvis height comes from the legs (:func:`~crowdstudy.motion.rig.max_pelvis_height`,
knees never fully locked); the arms are posed by IK towards wrist targets in the chest
frame.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.posing import lift_profile, smoothstep5
from crowdstudy.body.rotations import rot_z, yaw_roll_pitch
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.rig import ANKLE_HEIGHT, REST, PoseControls, assemble_pose, max_pelvis_height

__all__ = ["DanceSpec", "DANCES", "generate_dance", "ARM_PATTERNS"]

ARM_PATTERNS = (
    "relaxed",
    "groove",
    "pump_right",
    "pump_alternate",
    "pump_both",
    "raise_both",
    "hands_up_sway",
    "clap",
    "clap_overhead",
    "wave_right",
    "raise_slow",
)
_GRAVITY = 9.81


@dataclasses.dataclass(frozen=True)
class DanceSpec:
    """One dance: tempo and the amplitude of each move (zero: move absent).

    Attributes:
        name, description: identifiers.
        bpm: tempo, beats per minute (the loop length is rounded to whole frames and the
            bpm adjusted to it).
        beats: loop length in beats (every move's period divides it).
        bounce: pelvis drop on the beat (m); ``bounce_every`` beats per bounce.
        sway: lateral pelvis shift (m); ``sway_beats`` beats per left-right cycle.
        twist: pelvis yaw amplitude (rad); ``twist_beats`` beats per cycle.
        lean: forward lean of the trunk (rad, negative leans back).
        nod: head nod (rad, chin down on the beat); ``nod_every`` beats per nod.
        head_tilt: side tilt of the head with the sway (rad).
        arms: one of :data:`ARM_PATTERNS`; ``arm_beats`` beats per arm cycle.
        jump: jump height (m); ``jump_every`` beats per jump (0: no jumps).
        step: step-touch width (m), a 4-beat side-to-side step pattern.
    """

    name: str
    bpm: float
    description: str
    beats: int = 8
    bounce: float = 0.0
    bounce_every: int = 1
    sway: float = 0.0
    sway_beats: int = 2
    twist: float = 0.0
    twist_beats: int = 2
    lean: float = 0.0
    nod: float = 0.0
    nod_every: int = 1
    head_tilt: float = 0.0
    arms: str = "relaxed"
    arm_beats: int = 1
    jump: float = 0.0
    jump_every: int = 0
    step: float = 0.0


DANCES: tuple[DanceSpec, ...] = (
    DanceSpec("dance_nod_bounce", 92, "easy knee bounce with head nods, arms hanging", bounce=0.035, nod=0.22),
    DanceSpec(
        "dance_sway_relaxed",
        96,
        "slow side-to-side sway with a side tilt of the head",
        sway=0.05,
        sway_beats=4,
        head_tilt=0.10,
        bounce=0.012,
        bounce_every=2,
    ),
    DanceSpec(
        "dance_fist_pump_right",
        128,
        "right fist pumping on every beat, bounce and nod",
        bounce=0.03,
        nod=0.10,
        arms="pump_right",
    ),
    DanceSpec(
        "dance_fist_pump_alternate",
        124,
        "alternating fist pumps, slight sway",
        bounce=0.025,
        arms="pump_alternate",
        arm_beats=2,
        sway=0.02,
        sway_beats=2,
    ),
    DanceSpec(
        "dance_clap_front", 110, "clapping in front of the chest on every beat", bounce=0.02, nod=0.08, arms="clap"
    ),
    DanceSpec(
        "dance_clap_overhead",
        120,
        "overhead claps on 2 and 4 with a sway",
        arms="clap_overhead",
        arm_beats=2,
        sway=0.03,
        sway_beats=4,
        bounce=0.015,
    ),
    DanceSpec(
        "dance_jump_arms_v",
        136,
        "jumping every second beat with both arms up in a V",
        jump=0.11,
        jump_every=2,
        arms="raise_both",
        arm_beats=4,
    ),
    DanceSpec(
        "dance_pogo_pump",
        140,
        "small pogo hops on every beat with both fists pumping",
        jump=0.05,
        jump_every=1,
        arms="pump_both",
    ),
    DanceSpec(
        "dance_hands_up_sway",
        100,
        "hands up, swaying left and right over four beats",
        arms="hands_up_sway",
        arm_beats=4,
        sway=0.04,
        sway_beats=4,
        head_tilt=0.06,
    ),
    DanceSpec(
        "dance_step_touch_clap",
        116,
        "side step-touch with claps on the beat",
        step=0.18,
        arms="clap",
        arm_beats=2,
        bounce=0.015,
    ),
    DanceSpec(
        "dance_twist_groove",
        104,
        "hip twist with bent-elbow groove",
        twist=0.22,
        twist_beats=2,
        arms="groove",
        bounce=0.02,
    ),
    DanceSpec(
        "dance_wave_right",
        108,
        "right arm waving overhead, head tilting with it",
        arms="wave_right",
        arm_beats=4,
        sway=0.025,
        sway_beats=4,
        head_tilt=0.08,
        nod=0.05,
        nod_every=2,
    ),
    DanceSpec(
        "dance_headbang",
        132,
        "forward lean and strong head-banging, pumping bounce",
        lean=0.15,
        nod=0.38,
        bounce=0.03,
        arms="groove",
        arm_beats=2,
    ),
    DanceSpec(
        "dance_slow_raise",
        90,
        "both arms rising and falling over four beats, leaning back slightly",
        lean=-0.05,
        arms="raise_slow",
        arm_beats=4,
        sway=0.03,
        sway_beats=4,
    ),
    DanceSpec(
        "dance_jump_clap",
        126,
        "a jump every four beats, overhead claps in between",
        jump=0.14,
        jump_every=4,
        arms="clap_overhead",
        arm_beats=1,
        bounce=0.015,
    ),
)


def _pulse(phase: np.ndarray, power: float = 3.0) -> np.ndarray:
    """Smooth periodic pulse in [0, 1] peaking at integer ``phase``."""
    return ((1.0 + np.cos(2.0 * np.pi * phase)) / 2.0) ** power


def _lerp(a, b, w):
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a + (b - a) * np.asarray(w, dtype=np.float64)[..., None]


def _arm_controls(spec: DanceSpec, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wrist targets (T, 2, 3), elbow poles (T, 2, 3), wrist flex (T, 2) in (out, fwd, up) units."""
    t = b.shape[0]
    a = b / spec.arm_beats
    swing = np.sin(np.pi * b)  # 2-beat arm swing for relaxed arms
    relaxed = np.stack([np.full(t, 0.10), 0.10 + 0.05 * swing, np.full(t, -0.985)], axis=-1)
    relaxed_pole = np.array([0.1, -1.0, 0.0])
    target = np.stack([relaxed, relaxed * [1, -1, 1] + [0, 0.2, 0]], axis=1)
    pole = np.broadcast_to(relaxed_pole, (t, 2, 3)).copy()
    flex = np.full((t, 2), 0.1)
    mode = spec.arms
    up_low, up_high = np.array([0.35, 0.45, 0.15]), np.array([0.18, 0.3, 0.9])
    pump_pole = np.array([1.0, -0.3, -0.5])
    if mode == "groove":
        for s in range(2):
            target[:, s] = np.stack(
                [np.full(t, 0.05), 0.5 + 0.12 * np.sin(2 * np.pi * a + np.pi * s), -0.45 + 0.08 * _pulse(b)], axis=-1
            )
        pole[:] = [0.4, -1.0, -0.4]
        flex[:] = 0.2
    elif mode in ("pump_right", "pump_alternate", "pump_both"):
        sides = {"pump_right": (1,), "pump_alternate": (0, 1), "pump_both": (0, 1)}[mode]
        for s in sides:
            shift = 0.5 if (mode == "pump_alternate" and s == 1) else 0.0
            target[:, s] = _lerp(up_low, up_high, _pulse(a - shift))
            pole[:, s] = pump_pole
            flex[:, s] = 0.0
    elif mode == "raise_both":
        s_ = np.sin(2 * np.pi * a)
        for s, sign in ((0, 1.0), (1, -1.0)):
            target[:, s] = np.stack([0.45 + 0.12 * sign * s_, np.full(t, 0.15), np.full(t, 0.85)], axis=-1)
        pole[:] = [1.0, 0.1, -0.2]
        flex[:] = -0.2
    elif mode == "hands_up_sway":
        s_ = np.sin(2 * np.pi * a)
        for s, sign in ((0, 1.0), (1, -1.0)):
            target[:, s] = np.stack([0.15 + 0.3 * sign * s_, np.full(t, 0.1), np.full(t, 0.88)], axis=-1)
        pole[:] = [1.0, 0.0, -0.3]
        flex[:] = -0.1
    elif mode in ("clap", "clap_overhead"):
        c = _pulse(a, 4.0)
        if mode == "clap":
            open_, closed = np.array([0.2, 0.6, -0.3]), np.array([-0.235, 0.65, -0.3])
            pole[:] = [0.5, -0.4, -1.0]
        else:
            open_, closed = np.array([0.35, 0.2, 0.75]), np.array([-0.235, 0.25, 0.82])
            pole[:] = [1.0, 0.0, -0.3]
        target[:, 0] = target[:, 1] = _lerp(open_, closed, c)
        flex[:] = -0.15
    elif mode == "wave_right":
        s_ = np.sin(2 * np.pi * a)
        target[:, 1] = np.stack([0.3 + 0.35 * s_, np.full(t, 0.2), np.full(t, 0.8)], axis=-1)
        pole[:, 1] = [1.0, 0.0, -0.3]
        flex[:, 1] = 0.35 * np.sin(4 * np.pi * a)
    elif mode == "raise_slow":
        # The straight arm sweeps up sideways: a great-circle arc at a constant reach.
        r = (1.0 - np.cos(2 * np.pi * a)) / 2.0
        angle = np.radians(-80.0) + np.radians(150.0) * r  # elevation above the horizontal
        for s in range(2):
            target[:, s] = 0.95 * np.stack([np.cos(angle) * 0.97, np.full(t, 0.2), np.sin(angle)], axis=-1)
            pole[:, s] = _lerp(relaxed_pole, [0.3, -1.0, 0.0], r)
        flex[:] = 0.1 - 0.3 * r[:, None]
    elif mode != "relaxed":
        raise InvalidInputError(f"DanceSpec {spec.name!r}: field 'arms' is {mode!r}, expected one of {ARM_PATTERNS}")
    return target, pole, flex


def _windows(b: np.ndarray, period: float, start: float, width: float) -> np.ndarray:
    """Position (0..1 inside) of beat time ``b`` in a window [start, start + width) repeating every ``period``."""
    return np.mod(b - start, period) / width


def generate_dance(spec: DanceSpec, fps: float = 60.0) -> MotionClip:
    """Build the looping clip of one dance at about ``fps`` frames per second.

    The loop holds ``spec.beats`` beats; the frame count is rounded and the frame rate
    adjusted so the period is exact (``clip.meta["bpm"]`` is the tempo).
    """
    for field in ("bounce_every", "sway_beats", "twist_beats", "nod_every", "arm_beats"):
        value = getattr(spec, field)
        if value < 1 or spec.beats % value:
            raise InvalidInputError(
                f"DanceSpec {spec.name!r}: field {field!r} = {value} must divide beats = {spec.beats}"
            )
    if spec.jump_every and spec.beats % spec.jump_every:
        raise InvalidInputError(f"DanceSpec {spec.name!r}: field 'jump_every' must divide beats = {spec.beats}")
    if not 40 <= spec.bpm <= 220:
        raise InvalidInputError(f"DanceSpec {spec.name!r}: field 'bpm' = {spec.bpm} is outside 40..220")
    period = spec.beats * 60.0 / spec.bpm
    n = int(round(period * fps))
    fps = n / period
    t = np.arange(n) / fps
    b = t * spec.bpm / 60.0
    two_pi = 2.0 * np.pi

    drop = spec.bounce * _pulse(b / spec.bounce_every, 2.0)
    sway_s = np.sin(two_pi * b / spec.sway_beats)
    yaw = spec.twist * np.sin(two_pi * b / spec.twist_beats)
    x = spec.sway * sway_s
    flight = np.zeros(n)
    feet_lift = np.zeros(n)
    if spec.jump_every and spec.jump > 0:
        per = float(spec.jump_every)
        dur = min(0.9 * np.sqrt(8.0 * spec.jump / _GRAVITY), 0.7 * per * 60.0 / spec.bpm) * spec.bpm / 60.0
        margin = min(0.35, 0.45 * (per - dur))
        flight = spec.jump * lift_profile(_windows(b, per, 0.0, dur))
        drop = drop + 0.35 * spec.jump * lift_profile(_windows(b, per, -margin, dur + 2 * margin))
        feet_lift = 0.55 * spec.jump * lift_profile(_windows(b, per, 0.15 * dur, 0.7 * dur))

    # Feet: planted in a relaxed stance, toes slightly out; step-touch moves them sideways.
    toe_out = 0.12
    ankle = np.zeros((n, 2, 3))
    ankle[:, 0] = [-0.10, REST[7, 1] + 0.01, ANKLE_HEIGHT]
    ankle[:, 1] = [0.10, REST[8, 1] + 0.01, ANKLE_HEIGHT]
    ankle[:, :, 2] += feet_lift[:, None]
    if spec.step > 0:
        q = np.mod(b, 4.0)
        moves = [smoothstep5((q - k) / 0.5) for k in range(4)]
        lifts = [0.05 * lift_profile((q - k) / 0.5) for k in range(4)]
        # beat 0: right steps out; 1: left closes; 2: left steps back; 3: right closes
        ankle[:, 1, 0] += spec.step * (moves[0] - moves[3])
        ankle[:, 0, 0] += spec.step * (moves[1] - moves[2])
        ankle[:, 1, 2] += lifts[0] + lifts[3]
        ankle[:, 0, 2] += lifts[1] + lifts[2]
        x = x + 0.5 * spec.step * (moves[0] + moves[1] - moves[2] - moves[3])
        # centre the pattern on the character's spot
        ankle[:, :, 0] -= 0.5 * spec.step
        x = x - 0.5 * spec.step
    foot_rot = np.stack([rot_z(np.full(n, toe_out)), rot_z(np.full(n, -toe_out))], axis=1)
    knee_pole = np.zeros((n, 2, 3))
    knee_pole[:, 0] = [-np.sin(toe_out) - 0.1, np.cos(toe_out), 0.0]
    knee_pole[:, 1] = [np.sin(toe_out) + 0.1, np.cos(toe_out), 0.0]

    pelvis_pitch = 0.3 * spec.lean + 1.5 * drop  # forward tilt (rad) when the knees bend
    pelvis_roll = -0.8 * x  # the loaded hip rises (rad per m of shift)
    root_rot = yaw_roll_pitch(yaw, pelvis_roll, -pelvis_pitch)
    root_xy = np.stack([x, np.full(n, 0.0)], axis=-1)
    zmax = max_pelvis_height(root_xy, root_rot, ankle)
    grounded = feet_lift < 1e-6
    base = np.min((zmax + drop - flight)[grounded]) if np.any(grounded) else np.min(zmax + drop - flight)
    root_pos = np.concatenate([root_xy, (base - drop + flight)[:, None]], axis=-1)

    trunk_pitch = 0.7 * spec.lean + 1.0 * drop  # forward flexion of the spine (rad)
    trunk_roll = 1.6 * x
    trunk_yaw = -1.3 * yaw
    spine = tuple(yaw_roll_pitch(w * trunk_yaw, w * trunk_roll, -w * trunk_pitch) for w in (0.35, 0.35, 0.3))
    nod = spec.nod * _pulse(b / spec.nod_every, 2.0)
    tilt = spec.head_tilt * sway_s
    head_yaw = 0.6 * (yaw + trunk_yaw) * -1.0  # keep looking at the stage
    neck = yaw_roll_pitch(0.5 * head_yaw, 0.4 * tilt - 0.2 * trunk_roll, -(0.4 * nod - 0.3 * spec.lean))
    head = yaw_roll_pitch(0.5 * head_yaw, 0.6 * tilt - 0.2 * trunk_roll, -(0.6 * nod - 0.3 * spec.lean))

    wrist, pole, flex = _arm_controls(spec, b)
    collar = 0.25 * np.clip(wrist[:, :, 2], 0.0, 1.0)
    controls = PoseControls(
        root_pos=root_pos,
        root_rot=root_rot,
        spine=spine,
        neck=neck,
        head=head,
        collar_raise=collar,
        wrist_target=wrist,
        elbow_pole=pole,
        wrist_flex=flex,
        ankle_target=ankle,
        foot_rot=foot_rot,
        knee_pole=knee_pole,
        toe_bend=np.zeros((n, 2)),
    )
    rot, root = assemble_pose(controls)
    meta = {
        "bpm": spec.bpm,
        "beats": spec.beats,
        "description": spec.description,
        "arms": spec.arms,
        "moves": [
            m for m in ("bounce", "sway", "twist", "lean", "nod", "head_tilt", "jump", "step") if getattr(spec, m)
        ],
    }
    return MotionClip(
        name=spec.name, kind="dance", fps=fps, joint_rotations=rot, root_translation=root, loop=True, meta=meta
    )

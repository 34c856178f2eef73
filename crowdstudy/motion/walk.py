"""Procedural walking: 4 looping in-place gait clips (about 0.8, 1.1, 1.4, 1.8 m/s).

A gait cycle (phase 0..1 from the left heel strike) is built from foot trajectories and
analytic two-bone leg IK:

* each ankle is planted during its stance (a duty factor of 0.62, the right foot half a
  cycle later) and, in the clip's frame moving forward at ``speed``, slides back at
  exactly ``speed``: on the ground it does not move;
* in swing the foot's ground displacement follows a quintic smoothstep (zero velocity and
  acceleration at lift-off and touch-down) and it lifts along ``sin^2``, so positions and
  velocities are continuous everywhere, the loop seam included;
* the pelvis bobs twice per cycle (highest at mid-stance), sways over the stance foot,
  rotates and tilts with the legs; its height comes from the legs (never fully locked);
  the thorax counter-rotates, the head keeps looking ahead and the arms swing opposite
  to the legs, more and with more elbow flexion at higher speed.

Cadences follow typical adult values (about 96 to 132 steps per minute from slow to
fast walking), which fixes the stride length ``speed * 120 / cadence``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.posing import lift_profile, smoothstep5
from crowdstudy.body.rotations import rot_x, rot_z, yaw_roll_pitch
from crowdstudy.body.skeleton import JOINT_INDEX
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.rig import ANKLE_HEIGHT, REST, PoseControls, assemble_pose, max_pelvis_height

__all__ = [
    "WalkSpec",
    "WALKS",
    "generate_walk",
    "DUTY_FACTOR",
    "FLAT_STANCE_END",
    "FOOT_PHASE_OFFSET",
    "LANDING_HOVER",
    "LIFT_OFF",
    "procedural_contacts",
]

#: Fraction of the gait cycle each foot is on the ground (same for every clip so blends
#: of clips keep their contacts aligned).
DUTY_FACTOR = 0.62
#: Phase since heel strike before which every clip's foot is flat on the floor (the heel
#: rises later: at ``DUTY_FACTOR - 0.20 - 0.03 * speed``).
FLAT_STANCE_END = 0.36
#: Fraction of the swing, at its end, during which the foot only comes down (no horizontal
#: travel in the clip): the foot is over its landing spot.
LANDING_HOVER = 0.16
#: Fraction of the swing, at its start, during which the foot only lifts (the ball clears
#: the floor before the foot travels).
LIFT_OFF = 0.06
#: Gait phase of each foot's heel strike (left, right).
FOOT_PHASE_OFFSET = (0.0, 0.5)


def procedural_contacts() -> dict:
    """The foot-contact timing shared by the procedural walks, in the form of the clips'
    meta (gait phases in [0, 1), phase 0 = the left heel strike): ``contacts`` =
    ``{"left": {"strike", "flat_end", "toe_off"}, "right": ...}``, ``lock_lead`` (the
    foot is over its landing spot :data:`LANDING_HOVER` of the swing before the strike)
    and ``lock_lag`` (it only lifts for :data:`LIFT_OFF` of the swing after toe-off)."""
    contacts = {
        side: {"strike": off, "flat_end": (off + FLAT_STANCE_END) % 1.0, "toe_off": (off + DUTY_FACTOR) % 1.0}
        for side, off in zip(("left", "right"), FOOT_PHASE_OFFSET, strict=True)
    }
    return {
        "contacts": contacts,
        "lock_lead": LANDING_HOVER * (1.0 - DUTY_FACTOR),
        "lock_lag": LIFT_OFF * (1.0 - DUTY_FACTOR),
        "cycles": 1,
    }


@dataclasses.dataclass(frozen=True)
class WalkSpec:
    """One gait: ``speed`` m/s at ``cadence`` steps per minute."""

    name: str
    speed: float
    cadence: float
    description: str

    @property
    def cycle(self) -> float:
        """Seconds per gait cycle (two steps)."""
        return 120.0 / self.cadence

    @property
    def stride(self) -> float:
        """Metres per gait cycle (two steps) for the authoring skeleton."""
        return self.speed * self.cycle


WALKS: tuple[WalkSpec, ...] = (
    WalkSpec("walk_slow", 0.8, 96.0, "slow stroll, short steps, little arm swing"),
    WalkSpec("walk_normal", 1.1, 106.0, "comfortable walk"),
    WalkSpec("walk_brisk", 1.4, 116.0, "brisk walk, longer steps"),
    WalkSpec("walk_fast", 1.8, 132.0, "fast walk, long strides, bent swinging arms"),
)


_TOE_OUT = 0.10
#: Foot vector from the ankle to the ball of the foot (the ``foot`` joint), left side, m.
_ANKLE_TO_BALL = REST[JOINT_INDEX["left_foot"]] - REST[JOINT_INDEX["left_ankle"]]


def _flat_ankle(p, x: float, y_strike: float, stride: float) -> np.ndarray:
    """(..., 3) ankle of a flat foot at stance phase ``p`` (the shape of ``p``): at ``x`` across,
    ``y_strike`` ahead of the hip at the heel strike, moving back ``stride`` (m) per cycle."""
    p = np.asarray(p, dtype=np.float64)
    return np.stack([np.full(p.shape, x), y_strike - stride * p, np.full(p.shape, ANKLE_HEIGHT)], axis=-1)


def _pitched(yaw_m: np.ndarray, p) -> np.ndarray:
    """(..., 3, 3) foot rotation at pitch ``p`` (rad, the shape of ``p``) after the toe-out ``yaw_m``."""
    return yaw_m @ rot_x(np.asarray(p, dtype=np.float64))


def _foot_trajectories(phase: np.ndarray, v: float, stride: float, beta: float, lead: float = 0.6):
    """Ankle targets (T, 2, 3), global foot rotations (T, 2, 3, 3) and toe bends (T, 2).

    Per foot, with ``ph`` the phase since its heel strike: the foot lands toes up and
    flattens about the ankle (ph < 0.1), stays flat, then rolls over the ball of the foot
    (the heel rises, the ball stays planted) until toe-off at ``beta``; in swing the
    foot first lifts, then its ground displacement follows a quintic smoothstep (between 6 %
    and 84 % of the swing; the heel then comes down vertically). Every
    piece starts and ends with zero velocity on the ground, so the whole curve is C1.
    ``lead``: the fraction of the flat-foot travel spent ahead of the hip.
    """
    n = phase.shape[0]
    heel_off = beta - (0.20 + 0.03 * v)  # start of the roll over the ball
    roll_max = 0.75 + 0.15 * v  # foot pitch at toe-off (rad, heel up)
    strike = 0.20  # toes-up pitch at heel strike (rad)
    clearance = 0.05 + 0.01 * v  # extra ankle lift in early swing (m)
    width = 0.095 - 0.006 * v
    y_strike = lead * stride * heel_off  # ankle ahead of the hip at heel strike (m)
    ankle = np.zeros((n, 2, 3))
    foot_rot = np.zeros((n, 2, 3, 3))
    toe_bend = np.zeros((n, 2))
    for side, (offset, sign) in enumerate(((0.0, -1.0), (0.5, 1.0))):
        yaw_m = rot_z(-sign * _TOE_OUT)
        ball = np.array([sign * abs(_ANKLE_TO_BALL[0]), _ANKLE_TO_BALL[1], _ANKLE_TO_BALL[2]])
        flat_ball = yaw_m @ ball
        ph = np.mod(phase - offset, 1.0)
        u = np.clip((ph - beta) / (1.0 - beta), 0.0, 1.0)
        in_swing = ph >= beta
        x = sign * width  # the foot's distance across from the hip line (m)

        flatten = strike * (1.0 - smoothstep5(ph / 0.1))
        rolling = -roll_max * smoothstep5((ph - heel_off) / (beta - heel_off))
        swing_pitch = -roll_max + (roll_max + strike) * smoothstep5(u / 0.7)
        pitch = np.where(in_swing, swing_pitch, np.where(ph < heel_off, flatten, rolling))
        foot_rot[:, side] = _pitched(yaw_m, pitch)

        flat = _flat_ankle(ph, x, y_strike, stride)
        rolled = flat + flat_ball - np.einsum("tab,b->ta", _pitched(yaw_m, rolling), ball)
        stance = np.where((ph >= heel_off)[:, None], rolled, flat)
        toe_off = _flat_ankle(beta, x, y_strike, stride) + flat_ball - _pitched(yaw_m, -roll_max) @ ball
        land = _flat_ankle(0.0, x, y_strike, stride) + np.array([0.0, stride * (1.0 - beta), 0.0])
        # The foot first lifts (the ball clears the floor), travels between 6 % and 84 % of
        # the swing, and the heel comes straight down at the end.
        swing = toe_off + (land - toe_off) * smoothstep5((u - LIFT_OFF) / (1.0 - LIFT_OFF - LANDING_HOVER))[:, None]
        swing[:, 2] = toe_off[2] + (land[2] - toe_off[2]) * smoothstep5(u)
        swing[:, 1] -= stride * (ph - beta)  # ground -> the frame moving at v
        swing[:, 2] += clearance * lift_profile(u / 0.7) + 0.025 * lift_profile((u - 0.5) / 0.5)
        ankle[:, side] = np.where(in_swing[:, None], swing, stance)
        toe_bend[:, side] = np.where(
            in_swing, roll_max * (1.0 - smoothstep5(u / 0.5)), np.where(ph < heel_off, 0.0, -rolling)
        )
    return ankle, foot_rot, toe_bend


def generate_walk(spec: WalkSpec, fps: float = 60.0) -> MotionClip:
    """Build the in-place looping clip of one gait at about ``fps`` frames per second."""
    if not 0.3 <= spec.speed <= 2.5:
        raise InvalidInputError(f"WalkSpec {spec.name!r}: field 'speed' = {spec.speed} is outside 0.3..2.5 m/s")
    if not 60 <= spec.cadence <= 160:
        raise InvalidInputError(f"WalkSpec {spec.name!r}: field 'cadence' = {spec.cadence} is outside 60..160")
    v, period, stride = spec.speed, spec.cycle, spec.stride
    n = int(round(period * fps))
    fps = n / period
    phase = np.arange(n) / n
    beta = DUTY_FACTOR
    two_pi = 2.0 * np.pi

    ankle, foot_rot, toe_bend = _foot_trajectories(phase, v, stride, beta)
    toe_out = _TOE_OUT
    knee_pole = np.stack(
        [np.stack([np.full(n, s * (np.sin(toe_out) + 0.05)), np.full(n, 1.0), np.zeros(n)], -1) for s in (-1.0, 1.0)],
        axis=1,
    )

    mid = beta / 2.0
    bob = (0.008 + 0.01 * v) * np.cos(2.0 * two_pi * (phase - mid))
    sway = -(0.03 - 0.008 * v) * np.cos(two_pi * (phase - mid))
    yaw = -(0.05 + 0.03 * v) * np.cos(two_pi * phase)
    roll = 0.05 * np.cos(two_pi * (phase - mid))
    pitch_fwd = 0.05 + 0.03 * v
    root_rot = yaw_roll_pitch(yaw, roll, np.full(n, -pitch_fwd))
    root_xy = np.stack([sway, np.zeros(n)], axis=-1)
    on_ground = np.stack([np.mod(phase, 1.0) < beta, np.mod(phase - 0.5, 1.0) < beta], axis=1)
    zmax = max_pelvis_height(root_xy, root_rot, ankle, reach=0.985, active=on_ground)
    base = np.min(zmax - bob)
    root_pos = np.concatenate([root_xy, (base + bob)[:, None]], axis=-1)

    trunk_yaw = -1.8 * yaw
    trunk_roll = -0.7 * roll
    lean = 0.02 + 0.03 * v - pitch_fwd  # net forward lean of the thorax
    spine = tuple(yaw_roll_pitch(w * trunk_yaw, w * trunk_roll, np.full(n, -w * lean)) for w in (0.35, 0.35, 0.3))
    head_yaw = -(yaw + trunk_yaw)
    neck = yaw_roll_pitch(0.5 * head_yaw, -0.15 * roll, np.full(n, 0.5 * (pitch_fwd + lean) - 0.02))
    head = yaw_roll_pitch(0.5 * head_yaw, -0.15 * roll, np.full(n, 0.5 * (pitch_fwd + lean) - 0.02))

    swing_amp = 0.22 + 0.14 * v
    wrist = np.zeros((n, 2, 3))
    for side, sign in ((0, -1.0), (1, 1.0)):
        alpha = sign * swing_amp * np.cos(two_pi * phase)  # upper arm angle, forward > 0
        elbow = 0.2 + 0.22 * v + 0.5 * np.maximum(alpha, 0.0)
        upper = np.stack([np.full(n, 0.12), np.sin(alpha), -np.cos(alpha)], axis=-1)
        fore = np.stack([np.full(n, 0.02), np.sin(alpha + elbow), -np.cos(alpha + elbow)], axis=-1)
        wrist[:, side] = 0.5 * (upper / np.linalg.norm(upper, axis=-1, keepdims=True) + fore)
    pole = np.broadcast_to([0.15, -1.0, 0.0], (n, 2, 3)).copy()
    controls = PoseControls(
        root_pos=root_pos,
        root_rot=root_rot,
        spine=spine,
        neck=neck,
        head=head,
        collar_raise=np.zeros((n, 2)),
        wrist_target=wrist,
        elbow_pole=pole,
        wrist_flex=np.full((n, 2), 0.1),
        ankle_target=ankle,
        foot_rot=foot_rot,
        knee_pole=knee_pole,
        toe_bend=toe_bend,
    )
    rot, root = assemble_pose(controls)
    meta = {
        "description": spec.description,
        "cadence": spec.cadence,
        "stride_length": stride,
        "duty_factor": beta,
        "cycle": period,
        **procedural_contacts(),
    }
    return MotionClip(
        name=spec.name, kind="walk", fps=fps, joint_rotations=rot, root_translation=root, speed=v, loop=True, meta=meta
    )

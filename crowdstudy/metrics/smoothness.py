"""Smoothness of crowd animations: is "Ours" as smooth as its Baseline?

The physics layer corrects a Baseline animation into "Ours"; the perception study needs
the only visible difference to be the contacts, so Ours must be as smooth as its input.
This module measures, on world joint positions (forward kinematics with each character's
rest joints):

* :func:`joint_jerk`: mean norm of the third time derivative of joint positions, m/s^3.
* :func:`high_frequency_share`: share of joint-velocity energy above ``cutoff_hz`` (6 Hz).
* :func:`peak_joint_speed`: the largest single-frame joint speed, m/s, and where it is.
* :func:`pelvis_acceleration_p99`: 99th percentile of the pelvis horizontal acceleration,
  m/s^2, from the root translation.
* :func:`foot_slide`: horizontal speed (m/s) of planted feet, the mask of planted samples
  taken from a reference animation (the Baseline) when given.
* :func:`seam_jump`: the jump between the last and the first frame of a looping clip,
  against the median frame-to-frame step (a ratio of about 1 = a seamless loop).

The core functions take plain arrays, positions ``pos`` (T, N, J, 3) float64 metres (Z up,
floor at z = 0) and ``fps`` (Hz). :func:`smoothness` measures a
:class:`~crowdstudy.scene.CrowdAnimation` (optionally against its reference) and returns a
:class:`SmoothnessResult`; :func:`smoothness_ratios` compares two results.

In periodic scenes (``meta["periodic"]["length"]``) every difference along x is taken by
the minimum image, so a wrapped coordinate never reads as a jump.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX
from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics.overlap import resolve_bodies
from crowdstudy.metrics.tracking import check_reference, joint_positions
from crowdstudy.scene_meta import loop_mode

__all__ = [
    "FOOT_JOINTS",
    "SLIDE_THRESHOLD_M_S",
    "PeakSpeed",
    "FootSlide",
    "SeamJump",
    "SmoothnessResult",
    "joint_jerk",
    "high_frequency_share",
    "joint_speeds",
    "peak_joint_speed",
    "pelvis_acceleration_p99",
    "foot_slide",
    "seam_jump",
    "mean_jerk",
    "smoothness",
    "smoothness_from_positions",
    "smoothness_ratios",
]

#: Foot joints of the 24-joint SMPL-order skeleton: left/right ankle and left/right foot
#: (toe), (7, 8, 10, 11).
FOOT_JOINTS: tuple[int, ...] = tuple(
    JOINT_INDEX[name] for name in ("left_ankle", "right_ankle", "left_foot", "right_foot")
)
#: Planted-foot speed above which a sample counts as sliding, m/s (5 cm/s).
SLIDE_THRESHOLD_M_S = 0.05

_FRAME_CHUNK = 64  # frames per forward-kinematics chunk


# ------------------------------------------------------------------------ validation
def _positions(pos: Any, name: str, min_frames: int, ndim: int = 4) -> np.ndarray:
    arr = np.asarray(pos, dtype=np.float64)
    if arr.ndim != ndim or arr.shape[-1] != 3:
        want = "(T, N, J, 3)" if ndim == 4 else "(T, N, 3)"
        raise InvalidInputError(f"{name}: expected shape {want}, got {arr.shape}")
    if arr.shape[0] < min_frames:
        raise InvalidInputError(f"{name}: needs at least {min_frames} frames, got {arr.shape[0]}")
    if arr.shape[1] < 1:
        raise InvalidInputError(f"{name}: needs at least one character, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError(f"{name}: contains NaN or infinite values")
    return arr


def _positive(value: Any, name: str, *, allow_zero: bool = False) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(out) or out < 0 or (out == 0 and not allow_zero):
        raise InvalidInputError(
            f"{name}: expected a {'non-negative' if allow_zero else 'positive'} finite number, got {value!r}"
        )
    return out


def _length(periodic_length: Any) -> float | None:
    return None if periodic_length is None else _positive(periodic_length, "periodic_length")


def _min_image(diff: np.ndarray, length: float | None) -> np.ndarray:
    """``diff`` with its x component (index 0 of the last axis) wrapped to [-L/2, L/2]."""
    if length is not None:
        diff = diff.copy()
        diff[..., 0] -= length * np.round(diff[..., 0] / length)
    return diff


def _steps(pos: np.ndarray, length: float | None) -> np.ndarray:
    """First differences along time p[t+1] - p[t] (minimum image along x), metres."""
    return _min_image(np.diff(pos, axis=0), length)


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else float("nan")


# ----------------------------------------------------------------------- core metrics
def joint_jerk(pos: Any, fps: float, *, periodic_length: float | None = None) -> tuple[float, np.ndarray]:
    """Mean joint jerk, m/s^3.

    The norm of the third finite difference of the positions times ``fps^3``, averaged over
    frames, characters and joints. For ``x = A sin(2 pi f t)`` it is close to
    ``(2/pi) A (2 pi f)^3`` (the mean of ``|cos|`` is 2/pi).

    Args:
        pos: (T, N, J, 3) joint positions, metres; T >= 4.
        fps: frame rate, Hz.
        periodic_length: period along x, metres, or None.

    Returns:
        (overall, per_character): the mean over everything (m/s^3) and the (N,) mean of
        each character.
    """
    pos = _positions(pos, "pos", 4)
    fps = _positive(fps, "fps")
    jerk = np.diff(_steps(pos, _length(periodic_length)), n=2, axis=0) * fps**3
    norm = np.linalg.norm(jerk, axis=-1)  # (T-3, N, J)
    per = norm.mean(axis=(0, 2))
    return float(norm.mean()), per


def high_frequency_share(
    pos: Any, fps: float, *, cutoff_hz: float = 6.0, periodic_length: float | None = None
) -> tuple[float, np.ndarray]:
    """Share of joint-velocity energy above ``cutoff_hz`` (dimensionless, 0..1).

    Velocity = first difference times ``fps`` (m/s, T-1 samples). For every (character,
    joint, axis) its mean over time is removed, a Hann window applied and the one-sided
    power spectrum taken by ``rfft`` along time. The share is the energy at frequencies
    above ``cutoff_hz`` over the energy of all bins but DC; per character the sums run over
    its joints and axes, overall over everything. A motionless signal (no energy) has share 0.

    Args:
        pos: (T, N, J, 3) joint positions, metres; T >= 3.
        fps: frame rate, Hz.
        cutoff_hz: in (0, fps/2), Hz.
        periodic_length: period along x, metres, or None.

    Returns:
        (overall, per_character (N,)).
    """
    pos = _positions(pos, "pos", 3)
    fps = _positive(fps, "fps")
    cutoff_hz = _positive(cutoff_hz, "cutoff_hz")
    if cutoff_hz >= fps / 2:
        raise InvalidInputError(f"cutoff_hz: must be below the Nyquist frequency {fps / 2:g} Hz, got {cutoff_hz:g}")
    vel = _steps(pos, _length(periodic_length)) * fps  # (T-1, N, J, 3)
    n = vel.shape[0]
    vel = vel - vel.mean(axis=0, keepdims=True)
    vel = vel * np.hanning(n)[:, None, None, None] if n > 2 else vel
    power = np.abs(np.fft.rfft(vel, axis=0)) ** 2  # (n//2 + 1, N, J, 3)
    weight = np.full(power.shape[0], 2.0)  # one-sided spectrum: the negative frequencies fold in
    weight[0] = 0.0  # DC excluded
    if n % 2 == 0:
        weight[-1] = 1.0  # the Nyquist bin has no mirror
    freq = np.fft.rfftfreq(n, d=1.0 / fps)
    per_bin = power.sum(axis=(2, 3)) * weight[:, None]  # (bins, N)
    high = per_bin[freq > cutoff_hz].sum(axis=0)
    total = per_bin.sum(axis=0)
    per = np.divide(high, total, out=np.zeros_like(total), where=total > 0)
    overall = float(high.sum() / total.sum()) if total.sum() > 0 else 0.0
    return overall, per


@dataclasses.dataclass(frozen=True)
class PeakSpeed:
    """The largest single-frame joint speed.

    Attributes:
        value: m/s, ``max |p[t+1] - p[t]| * fps`` over frames, characters and joints.
        frame: t of that step (the step from frame t to frame t+1).
        character, joint: where it happened (joint index of the skeleton).
        per_character: (N,) m/s, the largest speed of each character.
    """

    value: float
    frame: int
    character: int
    joint: int
    per_character: np.ndarray


def joint_speeds(
    pos: np.ndarray, fps: float, *, periodic_length: float | None = None, seam: bool = False
) -> np.ndarray:
    """Single-frame joint speeds, m/s: (T-1, ..., J) from positions (T, ..., J, 3) m, the
    steps taking the minimum image along x when ``periodic_length`` (m) is given; with
    ``seam`` the step from the last frame to the first (a loop) is appended (T steps)."""
    steps = _steps(pos, periodic_length)
    if seam:
        steps = np.concatenate([steps, _min_image(pos[:1] - pos[-1:], periodic_length)], axis=0)
    return np.linalg.norm(steps, axis=-1) * fps


def peak_joint_speed(pos: Any, fps: float, *, periodic_length: float | None = None) -> PeakSpeed:
    """The largest single-frame joint speed (m/s) and where it happened.

    Args:
        pos: (T, N, J, 3) joint positions, metres; T >= 2.
        fps: frame rate, Hz.
        periodic_length: period along x, metres, or None.
    """
    pos = _positions(pos, "pos", 2)
    fps = _positive(fps, "fps")
    speed = joint_speeds(pos, fps, periodic_length=_length(periodic_length))  # (T-1, N, J)
    t, i, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
    return PeakSpeed(
        value=float(speed[t, i, j]), frame=int(t), character=int(i), joint=int(j), per_character=speed.max(axis=(0, 2))
    )


def pelvis_acceleration_p99(root: Any, fps: float, *, periodic_length: float | None = None) -> tuple[float, np.ndarray]:
    """99th percentile of the pelvis horizontal acceleration, m/s^2.

    The second difference of the root's x, y times ``fps^2``, its norm, and the 99th
    percentile over (frames, characters) overall and over frames per character.

    Args:
        root: (T, N, 3) root (pelvis) translation, metres; T >= 3.
        fps: frame rate, Hz.
        periodic_length: period along x, metres, or None.

    Returns:
        (overall, per_character (N,)).
    """
    root = _positions(root, "root", 3, ndim=3)
    fps = _positive(fps, "fps")
    acc = np.diff(_steps(root, _length(periodic_length))[..., :2], axis=0) * fps**2
    norm = np.linalg.norm(acc, axis=-1)  # (T-2, N)
    return _percentile(norm, 99.0), np.percentile(norm, 99.0, axis=0)


@dataclasses.dataclass(frozen=True)
class FootSlide:
    """Horizontal speed of planted feet.

    Samples are the frame steps t -> t+1 of each (character, foot joint). A sample is
    planted when the reference's horizontal speed in that step is below ``planted_speed``
    and its height (mean of frames t and t+1) is within ``planted_height`` of that joint's
    lowest reference height for that character over the clip. The slide of a sample is the
    measured animation's horizontal speed in that step. Statistics are NaN without planted
    samples.

    Attributes:
        p50, p90, p99, mean: m/s, over all planted samples.
        fraction_over_threshold: share of planted samples faster than ``threshold`` (0.05 m/s).
        samples: number of planted samples.
        per_character_p99: (N,) m/s (NaN for a character without planted samples).
        per_character_samples: (N,) planted samples of each character.
        threshold: m/s.
    """

    p50: float
    p90: float
    p99: float
    mean: float
    fraction_over_threshold: float
    samples: int
    per_character_p99: np.ndarray
    per_character_samples: np.ndarray
    threshold: float = SLIDE_THRESHOLD_M_S


def _horizontal_speed(pos: np.ndarray, fps: float, length: float | None) -> np.ndarray:
    return np.linalg.norm(_steps(pos, length)[..., :2], axis=-1) * fps


def foot_slide(
    pos: Any,
    fps: float,
    *,
    reference: Any = None,
    foot_joints: Sequence[int] = FOOT_JOINTS,
    planted_speed: float = 0.02,
    planted_height: float = 0.03,
    periodic_length: float | None = None,
) -> FootSlide:
    """Distribution of the horizontal speed (m/s) of planted feet (see :class:`FootSlide`).

    Args:
        pos: (T, N, J, 3) measured joint positions, metres; T >= 2.
        fps: frame rate, Hz.
        reference: (T, N, J, 3) positions that decide which samples are planted (e.g. the
            Baseline of an "Ours"); None = ``pos`` itself.
        foot_joints: joint indices of the feet (default ankles and toes, :data:`FOOT_JOINTS`).
        planted_speed: reference horizontal speed below which a foot is planted, m/s.
        planted_height: height above the joint's lowest height within which it is planted, m.
        periodic_length: period along x, metres, or None.
    """
    pos = _positions(pos, "pos", 2)
    ref = pos if reference is None else _positions(reference, "reference", 2)
    if ref.shape != pos.shape:
        raise InvalidInputError(f"reference: expected the shape of pos {pos.shape}, got {ref.shape}")
    fps = _positive(fps, "fps")
    planted_speed = _positive(planted_speed, "planted_speed")
    planted_height = _positive(planted_height, "planted_height", allow_zero=True)
    length = _length(periodic_length)
    feet = np.asarray(list(foot_joints), dtype=np.int64)
    if feet.ndim != 1 or feet.size == 0 or feet.min() < 0 or feet.max() >= pos.shape[2]:
        raise InvalidInputError(f"foot_joints: expected joint indices in [0, {pos.shape[2]}), got {list(foot_joints)}")
    ref_feet = ref[:, :, feet]
    height = ref_feet[..., 2]  # (T, N, F)
    mid_height = 0.5 * (height[1:] + height[:-1])
    planted = (_horizontal_speed(ref_feet, fps, length) < planted_speed) & (
        mid_height <= height.min(axis=0, keepdims=True) + planted_height
    )  # (T-1, N, F)
    slide_all = _horizontal_speed(pos[:, :, feet], fps, length)
    slide = slide_all[planted]
    per_samples = planted.sum(axis=(0, 2)).astype(np.int64)
    per_p99 = np.array([_percentile(slide_all[:, i][planted[:, i]], 99.0) for i in range(pos.shape[1])])
    nan = float("nan")
    return FootSlide(
        p50=_percentile(slide, 50.0),
        p90=_percentile(slide, 90.0),
        p99=_percentile(slide, 99.0),
        mean=float(slide.mean()) if slide.size else nan,
        fraction_over_threshold=float((slide > SLIDE_THRESHOLD_M_S).mean()) if slide.size else nan,
        samples=int(slide.size),
        per_character_p99=per_p99,
        per_character_samples=per_samples,
    )


@dataclasses.dataclass(frozen=True)
class SeamJump:
    """The loop seam (last frame -> first frame) against the ordinary frame step.

    Attributes:
        seam: metres, mean over characters and joints of ``|p[0] - p[T-1]|``.
        frame_step: metres, median over t of the mean over characters and joints of
            ``|p[t+1] - p[t]|``.
        ratio: ``seam / frame_step`` (about 1 for a clip that loops seamlessly; 1 when
            nothing moves, inf when only the seam moves).
        per_character: (N,) ``seam_i / median_t step_i``.
        max_character: the largest per-character ratio.
    """

    seam: float
    frame_step: float
    ratio: float
    per_character: np.ndarray
    max_character: float


def _ratio(num: np.ndarray | float, den: np.ndarray | float) -> np.ndarray:
    num, den = np.asarray(num, dtype=np.float64), np.asarray(den, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = num / den
    return np.where(den > 0, out, np.where(num > 0, np.inf, 1.0))


def seam_jump(pos: Any, *, periodic_length: float | None = None) -> SeamJump:
    """The jump at the loop seam of a clip against its median frame step (see :class:`SeamJump`).

    Args:
        pos: (T, N, J, 3) joint positions, metres; T >= 3.
        periodic_length: period along x, metres, or None.
    """
    pos = _positions(pos, "pos", 3)
    length = _length(periodic_length)
    seam_i = np.linalg.norm(_min_image(pos[0] - pos[-1], length), axis=-1).mean(axis=-1)  # (N,)
    step = np.linalg.norm(_steps(pos, length), axis=-1).mean(axis=-1)  # (T-1, N)
    seam = float(seam_i.mean())
    frame_step = float(np.median(step.mean(axis=1)))
    per = _ratio(seam_i, np.median(step, axis=0))
    return SeamJump(
        seam=seam,
        frame_step=frame_step,
        ratio=float(_ratio(seam, frame_step)),
        per_character=per,
        max_character=float(per.max()),
    )


# --------------------------------------------------------------------- on animations
def _joint_positions(anim, body_objs: Sequence) -> np.ndarray:
    """(T, N, J, 3) world joint positions of every frame, computed in frame chunks."""
    out = np.empty((anim.n_frames, anim.n_characters, anim.n_joints, 3))
    for c0 in range(0, anim.n_frames, _FRAME_CHUNK):
        chunk = np.arange(c0, min(c0 + _FRAME_CHUNK, anim.n_frames))
        out[chunk] = joint_positions(anim, bodies=body_objs, frames=chunk)
    return out


def _check_animation(value, name: str) -> None:
    if not hasattr(value, "joint_rotations"):
        raise InvalidInputError(f"{name}: expected a CrowdAnimation, got {type(value).__name__}")


def mean_jerk(anim, *, bodies: Sequence | None = None) -> float:
    """Mean norm of the joint jerk (third derivative of joint positions), m/s^3.

    Third finite differences of the world joint positions times ``fps^3``, averaged over
    frames, characters and joints (:func:`joint_jerk` on the animation's forward
    kinematics, minimum image along x in periodic scenes). Needs at least 4 frames.
    """
    _check_animation(anim, "anim")
    if anim.n_frames < 4:
        raise InvalidInputError(f"anim: mean_jerk needs at least 4 frames, got {anim.n_frames}")
    body_objs = resolve_bodies(anim, bodies)
    total = 0.0
    count = 0
    for c0 in range(0, anim.n_frames - 3, _FRAME_CHUNK):
        chunk = np.arange(c0, min(c0 + _FRAME_CHUNK + 3, anim.n_frames))
        pos = joint_positions(anim, bodies=body_objs, frames=chunk)
        value, _ = joint_jerk(pos, anim.fps, periodic_length=anim.periodic_length)
        n = (len(chunk) - 3) * anim.n_characters * anim.n_joints
        total += value * n
        count += n
    return total / count


def _num(value: Any) -> float | None:
    """A float for JSON: None when NaN or infinite."""
    value = float(value)
    return value if np.isfinite(value) else None


@dataclasses.dataclass(frozen=True)
class SmoothnessResult:
    """Smoothness of one animation (see the module docstring for each measure).

    Attributes:
        fps: frame rate, Hz.
        n_frames, n_characters: sizes of the measured clip.
        cutoff_hz: the high-frequency cutoff, Hz.
        jerk_m_s3: mean joint jerk, m/s^3; ``jerk_per_character`` (N,).
        hf_share: share of joint-velocity energy above ``cutoff_hz`` (0..1);
            ``hf_share_per_character`` (N,).
        max_joint_speed_m_s: largest single-frame joint speed, m/s, in the step from
            ``max_joint_speed_frame`` to the next, of character ``max_joint_speed_character``
            and joint ``max_joint_speed_joint``; ``max_joint_speed_per_character`` (N,).
        pelvis_accel_p99_m_s2: 99th percentile of the pelvis horizontal acceleration,
            m/s^2; ``pelvis_accel_p99_per_character`` (N,).
        foot_slide_p50_m_s, foot_slide_p90_m_s, foot_slide_p99_m_s, foot_slide_mean_m_s:
            planted-foot horizontal speed, m/s (NaN without planted samples);
            ``foot_slide_p99_per_character`` (N,).
        foot_slide_fraction_over_5cm_s: share of planted samples sliding faster than 5 cm/s.
        foot_planted_samples: number of planted (step, character, foot joint) samples;
            ``foot_planted_samples_per_character`` (N,).
        foot_mask_from: "reference" when the planted mask came from a reference animation,
            else "self".
        seam_jump_m: loop seam, metres; seam_frame_step_m: median frame step, metres;
            seam_ratio: their ratio (about 1 = seamless); seam_ratio_per_character (N,) and
            its maximum seam_ratio_max_character.
    """

    fps: float
    n_frames: int
    n_characters: int
    cutoff_hz: float
    jerk_m_s3: float
    jerk_per_character: np.ndarray
    hf_share: float
    hf_share_per_character: np.ndarray
    max_joint_speed_m_s: float
    max_joint_speed_frame: int
    max_joint_speed_character: int
    max_joint_speed_joint: int
    max_joint_speed_per_character: np.ndarray
    pelvis_accel_p99_m_s2: float
    pelvis_accel_p99_per_character: np.ndarray
    foot_slide_p50_m_s: float
    foot_slide_p90_m_s: float
    foot_slide_p99_m_s: float
    foot_slide_mean_m_s: float
    foot_slide_fraction_over_5cm_s: float
    foot_planted_samples: int
    foot_slide_p99_per_character: np.ndarray
    foot_planted_samples_per_character: np.ndarray
    foot_mask_from: str
    seam_jump_m: float
    seam_frame_step_m: float
    seam_ratio: float
    seam_ratio_max_character: float
    seam_ratio_per_character: np.ndarray

    #: Keys of :meth:`as_dict` besides ``per_character`` (fixed, in this order).
    KEYS = (
        "jerk_m_s3",
        "hf_share",
        "hf_cutoff_hz",
        "max_joint_speed_m_s",
        "max_joint_speed_frame",
        "max_joint_speed_character",
        "max_joint_speed_joint",
        "pelvis_accel_p99_m_s2",
        "foot_slide_p50_m_s",
        "foot_slide_p90_m_s",
        "foot_slide_p99_m_s",
        "foot_slide_mean_m_s",
        "foot_slide_fraction_over_5cm_s",
        "foot_planted_samples",
        "foot_mask_from",
        "seam_jump_m",
        "seam_frame_step_m",
        "seam_ratio",
        "seam_ratio_max_character",
    )
    #: Keys of ``as_dict()["per_character"]``: lists of N values.
    PER_CHARACTER_KEYS = (
        "jerk_m_s3",
        "hf_share",
        "max_joint_speed_m_s",
        "pelvis_accel_p99_m_s2",
        "foot_slide_p99_m_s",
        "foot_planted_samples",
        "seam_ratio",
    )

    def as_dict(self, *, per_character: bool = True) -> dict:
        """A JSON-serialisable dict with the keys :attr:`KEYS` (NaN and inf become None)
        and, when ``per_character``, ``per_character``: {key: list of N values} for
        :attr:`PER_CHARACTER_KEYS`."""
        out: dict = {
            "jerk_m_s3": _num(self.jerk_m_s3),
            "hf_share": _num(self.hf_share),
            "hf_cutoff_hz": float(self.cutoff_hz),
            "max_joint_speed_m_s": _num(self.max_joint_speed_m_s),
            "max_joint_speed_frame": int(self.max_joint_speed_frame),
            "max_joint_speed_character": int(self.max_joint_speed_character),
            "max_joint_speed_joint": int(self.max_joint_speed_joint),
            "pelvis_accel_p99_m_s2": _num(self.pelvis_accel_p99_m_s2),
            "foot_slide_p50_m_s": _num(self.foot_slide_p50_m_s),
            "foot_slide_p90_m_s": _num(self.foot_slide_p90_m_s),
            "foot_slide_p99_m_s": _num(self.foot_slide_p99_m_s),
            "foot_slide_mean_m_s": _num(self.foot_slide_mean_m_s),
            "foot_slide_fraction_over_5cm_s": _num(self.foot_slide_fraction_over_5cm_s),
            "foot_planted_samples": int(self.foot_planted_samples),
            "foot_mask_from": self.foot_mask_from,
            "seam_jump_m": _num(self.seam_jump_m),
            "seam_frame_step_m": _num(self.seam_frame_step_m),
            "seam_ratio": _num(self.seam_ratio),
            "seam_ratio_max_character": _num(self.seam_ratio_max_character),
        }
        if per_character:
            columns = (  # (N,) values and their JSON form, in the order of PER_CHARACTER_KEYS
                (self.jerk_per_character, _num),
                (self.hf_share_per_character, _num),
                (self.max_joint_speed_per_character, _num),
                (self.pelvis_accel_p99_per_character, _num),
                (self.foot_slide_p99_per_character, _num),
                (self.foot_planted_samples_per_character, int),
                (self.seam_ratio_per_character, _num),
            )
            out["per_character"] = {
                key: [convert(v) for v in values]
                for key, (values, convert) in zip(self.PER_CHARACTER_KEYS, columns, strict=True)
            }
        return out


def smoothness_from_positions(
    pos: Any,
    root: Any,
    fps: float,
    *,
    reference_pos: Any = None,
    periodic_length: float | None = None,
    cutoff_hz: float = 6.0,
    planted_speed: float = 0.02,
    planted_height: float = 0.03,
    foot_joints: Sequence[int] = FOOT_JOINTS,
) -> SmoothnessResult:
    """Every smoothness measure on plain arrays.

    Args:
        pos: (T, N, J, 3) joint positions, metres; T >= 4.
        root: (T, N, 3) root (pelvis) translation, metres.
        fps: frame rate, Hz.
        reference_pos: (T, N, J, 3) positions of the reference that decide the planted
            feet (see :func:`foot_slide`), or None.
        periodic_length: period along x, metres, or None.
        cutoff_hz, planted_speed, planted_height, foot_joints: see
            :func:`high_frequency_share` and :func:`foot_slide`.
    """
    pos = _positions(pos, "pos", 4)
    root = _positions(root, "root", 4, ndim=3)
    if root.shape[:2] != pos.shape[:2]:
        raise InvalidInputError(f"root: expected (frames, characters) {pos.shape[:2]}, got {root.shape[:2]}")
    jerk, jerk_i = joint_jerk(pos, fps, periodic_length=periodic_length)
    hf, hf_i = high_frequency_share(pos, fps, cutoff_hz=cutoff_hz, periodic_length=periodic_length)
    peak = peak_joint_speed(pos, fps, periodic_length=periodic_length)
    acc, acc_i = pelvis_acceleration_p99(root, fps, periodic_length=periodic_length)
    feet = foot_slide(
        pos,
        fps,
        reference=reference_pos,
        foot_joints=foot_joints,
        planted_speed=planted_speed,
        planted_height=planted_height,
        periodic_length=periodic_length,
    )
    seam = seam_jump(pos, periodic_length=periodic_length)
    return SmoothnessResult(
        fps=float(fps),
        n_frames=int(pos.shape[0]),
        n_characters=int(pos.shape[1]),
        cutoff_hz=float(cutoff_hz),
        jerk_m_s3=jerk,
        jerk_per_character=jerk_i,
        hf_share=hf,
        hf_share_per_character=hf_i,
        max_joint_speed_m_s=peak.value,
        max_joint_speed_frame=peak.frame,
        max_joint_speed_character=peak.character,
        max_joint_speed_joint=peak.joint,
        max_joint_speed_per_character=peak.per_character,
        pelvis_accel_p99_m_s2=acc,
        pelvis_accel_p99_per_character=acc_i,
        foot_slide_p50_m_s=feet.p50,
        foot_slide_p90_m_s=feet.p90,
        foot_slide_p99_m_s=feet.p99,
        foot_slide_mean_m_s=feet.mean,
        foot_slide_fraction_over_5cm_s=feet.fraction_over_threshold,
        foot_planted_samples=feet.samples,
        foot_slide_p99_per_character=feet.per_character_p99,
        foot_planted_samples_per_character=feet.per_character_samples,
        foot_mask_from="self" if reference_pos is None else "reference",
        seam_jump_m=seam.seam,
        seam_frame_step_m=seam.frame_step,
        seam_ratio=seam.ratio,
        seam_ratio_max_character=seam.max_character,
        seam_ratio_per_character=seam.per_character,
    )


def smoothness(
    anim,
    reference=None,
    *,
    bodies: Sequence | None = None,
    cutoff_hz: float = 6.0,
    planted_speed: float = 0.02,
    planted_height: float = 0.03,
) -> SmoothnessResult:
    """Smoothness of a :class:`~crowdstudy.scene.CrowdAnimation` (every frame).

    Joint positions come from forward kinematics with each character's rest joints; the
    pelvis acceleration from ``root_translation``; periodic scenes use the minimum image
    along x. A corridor clip that loops by a cross-dissolve (``meta["loop"]["mode"] ==
    "dissolve"``) has no joint-space seam (NaN; its seam is measured in pixels by
    :mod:`crowdstudy.render.seam`).

    Args:
        anim: the animation to measure (e.g. "Ours"); at least 4 frames.
        reference: its input (e.g. the Baseline, same frames, characters and joints): the
            planted-foot mask comes from it. None = from ``anim`` itself.
        bodies: optional body objects overriding ``load_body`` (shared with the reference).
        cutoff_hz: high-frequency cutoff, Hz (6).
        planted_speed: reference horizontal foot speed below which a foot is planted, m/s
            (0.02: a foot its animation holds still; the Baseline's locked feet move under
            2 cm/s).
        planted_height: height above the foot joint's lowest height within which it is
            planted, metres (0.03).
    """
    _check_animation(anim, "anim")
    if anim.n_frames < 4:
        raise InvalidInputError(f"anim: smoothness needs at least 4 frames, got {anim.n_frames}")
    body_objs = resolve_bodies(anim, bodies)
    ref_pos = None
    if reference is not None:
        _check_animation(reference, "reference")
        check_reference(anim, reference)
        ref_pos = _joint_positions(reference, body_objs)
    pos = _joint_positions(anim, body_objs)
    result = smoothness_from_positions(
        pos,
        anim.root_translation,
        anim.fps,
        reference_pos=ref_pos,
        periodic_length=anim.periodic_length,
        cutoff_hz=cutoff_hz,
        planted_speed=planted_speed,
        planted_height=planted_height,
    )
    if loop_mode(anim.meta) == "dissolve":
        # the video loops by a cross-dissolve of frames [T, T + D) into its first frames
        # (crowdstudy.render.video): a fading ghost, not a joint trajectory, so its seam is
        # measured in pixels (crowdstudy.render.seam), not here
        nan = float("nan")
        result = dataclasses.replace(
            result,
            seam_jump_m=nan,
            seam_frame_step_m=nan,
            seam_ratio=nan,
            seam_ratio_per_character=np.full(anim.n_characters, nan),
            seam_ratio_max_character=nan,
        )
    return result


def smoothness_ratios(result: SmoothnessResult, reference_result: SmoothnessResult) -> dict:
    """Compare "Ours" (``result``) with its Baseline (``reference_result``).

    Returns:
        A JSON-serialisable dict. Ratios Ours / Baseline (1 = as smooth; None when the
        Baseline's value is 0 or undefined): ``jerk_ratio``, ``hf_share_ratio``,
        ``pelvis_accel_p99_ratio``. Differences Ours - Baseline (0 = as smooth; None when
        undefined): ``max_joint_speed_diff_m_s`` (m/s) and ``foot_slide_p99_diff_m_s`` (m/s).
    """
    for name, value in (("result", result), ("reference_result", reference_result)):
        if not isinstance(value, SmoothnessResult):
            raise InvalidInputError(f"{name}: expected a SmoothnessResult, got {type(value).__name__}")

    def ratio(a: float, b: float) -> float | None:
        return _num(a / b) if np.isfinite(b) and b > 0 and np.isfinite(a) else None

    def diff(a: float, b: float) -> float | None:
        return _num(a - b) if np.isfinite(a) and np.isfinite(b) else None

    return {
        "jerk_ratio": ratio(result.jerk_m_s3, reference_result.jerk_m_s3),
        "hf_share_ratio": ratio(result.hf_share, reference_result.hf_share),
        "pelvis_accel_p99_ratio": ratio(result.pelvis_accel_p99_m_s2, reference_result.pelvis_accel_p99_m_s2),
        "max_joint_speed_diff_m_s": diff(result.max_joint_speed_m_s, reference_result.max_joint_speed_m_s),
        "foot_slide_p99_diff_m_s": diff(result.foot_slide_p99_m_s, reference_result.foot_slide_p99_m_s),
    }

"""Motion clips for the 24-joint skeleton: container, looping and resampling.

A :class:`MotionClip` holds one motion sampled at ``fps``: joint rotations
``(T, 24, 3)`` axis-angle (joint 0 global, the others relative to their parent, as in
:mod:`crowdstudy.body.skeleton`) and the pelvis position ``(T, 3)`` in metres for the
authoring skeleton (:data:`~crowdstudy.body.skeleton.DEFAULT_REST_JOINTS`, pelvis
:data:`~crowdstudy.body.skeleton.DEFAULT_PELVIS_HEIGHT` above the floor).

Looping clips (``loop=True``) are periodic: frame ``T`` equals frame 0 and is not stored,
so the period is ``T / fps`` seconds. Sampling between frames uses a Catmull-Rom spline
on quaternions (C1 in time, exact at the stored frames), wrapping around for loops.
Walking clips are *in place*: ``root_translation`` holds the pelvis relative to a point
moving along +y at ``speed`` m/s; :meth:`MotionClip.travel` gives that forward progress.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from crowdstudy.body.rotations import (
    axis_angle_to_quaternion,
    quat_align_signs,
    quat_nearest_sign,
    quaternion_to_axis_angle,
)
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, NUM_JOINTS, forward_kinematics
from crowdstudy.errors import InvalidInputError

__all__ = ["MotionClip", "catmull_rom_weights", "seam_discontinuity"]

_KINDS = ("dance", "walk", "mocap")


def catmull_rom_weights(frac: np.ndarray) -> np.ndarray:
    """Weights (..., 4) of the samples i-1, i, i+1, i+2 for a uniform Catmull-Rom spline
    evaluated at ``i + frac`` (frac (...,) in [0, 1)); C1 across samples, exact at them."""
    u = np.asarray(frac, dtype=np.float64)
    u2, u3 = u * u, u * u * u
    return np.stack(
        [-0.5 * u3 + u2 - 0.5 * u, 1.5 * u3 - 2.5 * u2 + 1.0, -1.5 * u3 + 2.0 * u2 + 0.5 * u, 0.5 * u3 - 0.5 * u2],
        axis=-1,
    )


@dataclasses.dataclass(frozen=True, eq=False)
class MotionClip:
    """One motion for the 24-joint skeleton.

    Attributes:
        name: clip name (unique within the library).
        kind: ``"dance"``, ``"walk"`` or ``"mocap"`` (imported).
        fps: samples per second (> 0).
        joint_rotations: (T, 24, 3) float64 axis-angle radians.
        root_translation: (T, 3) float64 metres, pelvis position (in place for walks).
        speed: forward speed in m/s for in-place walking clips, else None.
        loop: True when the clip is periodic (frame T == frame 0, not stored).
        meta: free-form description (bpm, stride length, source file ...).
    """

    name: str
    kind: str
    fps: float
    joint_rotations: np.ndarray
    root_translation: np.ndarray
    speed: float | None = None
    loop: bool = True
    meta: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        where = f"MotionClip {self.name!r}"
        if not isinstance(self.name, str) or not self.name:
            raise InvalidInputError("MotionClip.name: expected a non-empty string")
        if self.kind not in _KINDS:
            raise InvalidInputError(f"{where}: field 'kind' is {self.kind!r}, expected one of {_KINDS}")
        try:
            fps = float(self.fps)
        except (TypeError, ValueError):
            raise InvalidInputError(f"{where}: field 'fps' must be a number, got {self.fps!r}") from None
        if not np.isfinite(fps) or fps <= 0:
            raise InvalidInputError(f"{where}: field 'fps' must be positive, got {self.fps!r}")
        rot = np.asarray(self.joint_rotations, dtype=np.float64)
        root = np.asarray(self.root_translation, dtype=np.float64)
        if rot.ndim != 3 or rot.shape[1:] != (NUM_JOINTS, 3) or rot.shape[0] < 1:
            raise InvalidInputError(
                f"{where}: field 'joint_rotations' must have shape (T, {NUM_JOINTS}, 3), got {rot.shape}"
            )
        if root.shape != (rot.shape[0], 3):
            raise InvalidInputError(
                f"{where}: field 'root_translation' must have shape ({rot.shape[0]}, 3) "
                f"to match joint_rotations, got {root.shape}"
            )
        for field, arr in (("joint_rotations", rot), ("root_translation", root)):
            if not np.all(np.isfinite(arr)):
                raise InvalidInputError(f"{where}: field {field!r} holds non-finite values")
        speed = self.speed
        if speed is not None:
            speed = float(speed)
            if not np.isfinite(speed) or speed < 0:
                raise InvalidInputError(f"{where}: field 'speed' must be a non-negative number, got {self.speed!r}")
        if self.loop and rot.shape[0] < 4:
            raise InvalidInputError(f"{where}: a looping clip needs at least 4 frames, got {rot.shape[0]}")
        rot.flags.writeable = False
        root.flags.writeable = False
        object.__setattr__(self, "fps", fps)
        object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "loop", bool(self.loop))
        object.__setattr__(self, "joint_rotations", rot)
        object.__setattr__(self, "root_translation", root)
        object.__setattr__(self, "meta", dict(self.meta))

    # -- sizes ---------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return self.joint_rotations.shape[0]

    @property
    def duration(self) -> float:
        """Seconds: the period ``T / fps`` for loops, ``(T - 1) / fps`` otherwise."""
        return self.n_frames / self.fps if self.loop else (self.n_frames - 1) / self.fps

    @property
    def walk_speed(self) -> float:
        """``speed`` (m/s) of a walking clip; asking a clip without one is an error."""
        if self.speed is None:
            raise InvalidInputError(f"MotionClip {self.name!r}: not a walk (no field 'speed')")
        return self.speed

    @functools.cached_property
    def quaternions(self) -> np.ndarray:
        """(T, 24, 4) unit quaternions, signs aligned frame to frame."""
        return quat_align_signs(axis_angle_to_quaternion(self.joint_rotations), axis=0)

    # -- sampling ------------------------------------------------------------------------
    def _neighbours(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        pos = np.asarray(times, dtype=np.float64) * self.fps
        n = self.n_frames
        if self.loop:
            pos = np.mod(pos, n)
            base = np.floor(pos)
            frac = pos - base
            idx = (base.astype(np.int64)[..., None] + np.arange(-1, 3)) % n
        else:
            pos = np.clip(pos, 0.0, n - 1)
            base = np.minimum(np.floor(pos), max(n - 2, 0))
            frac = pos - base
            idx = np.clip(base.astype(np.int64)[..., None] + np.arange(-1, 3), 0, n - 1)
        return idx, frac

    def sample_quaternions(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pose at ``times`` (..., ) seconds (wrapped for loops, clamped otherwise).

        Returns ``(quaternions (..., 24, 4), root_translation (..., 3) metres)``.
        """
        idx, frac = self._neighbours(times)
        weights = catmull_rom_weights(frac)  # (..., 4)
        q = self.quaternions[idx]  # (..., 4, J, 4)
        q = quat_nearest_sign(q, q[..., 1:2, :, :])
        quat = np.einsum("...k,...kjc->...jc", weights, q)
        quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
        root = np.einsum("...k,...kc->...c", weights, self.root_translation[idx])
        return quat, root

    def loop_table(self, samples: int) -> tuple[np.ndarray, np.ndarray]:
        """The loop sampled at ``samples`` evenly spaced phases: ``(quaternions (S, 24, 4)
        aligned frame to frame, root_translation (S, 3))`` (cached; read-only)."""
        if not self.loop:
            raise InvalidInputError(f"loop_table: clip {self.name!r} does not loop")
        cache = self.__dict__.setdefault("_tables", {})
        if samples not in cache:
            quat, root = self.sample_quaternions(np.arange(samples) * (self.duration / samples))
            quat = quat_align_signs(quat, axis=0)
            quat.flags.writeable = False
            root.flags.writeable = False
            cache[samples] = (quat, root)
        return cache[samples]

    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`sample_quaternions` with axis-angle rotations (..., 24, 3)."""
        quat, root = self.sample_quaternions(times)
        return quaternion_to_axis_angle(quat), root

    def travel(self, times: np.ndarray) -> np.ndarray:
        """(..., 3) forward progress of an in-place walking clip at ``times`` (zero otherwise)."""
        t = np.asarray(times, dtype=np.float64)
        out = np.zeros(t.shape + (3,))
        if self.speed is not None and self.kind == "walk":
            out[..., 1] = self.speed * t
        return out

    def resample(self, fps: float) -> MotionClip:
        """The same motion at another frame rate (a loop keeps its period, rounded to frames)."""
        fps = float(fps)
        if not np.isfinite(fps) or fps <= 0:
            raise InvalidInputError(f"resample: fps must be positive, got {fps!r}")
        if self.loop:
            n = max(4, int(round(self.duration * fps)))
            new_fps = n / self.duration
        else:
            n = int(np.floor(self.duration * fps + 1e-9)) + 1
            new_fps = fps
        rot, root = self.sample(np.arange(n) / new_fps)
        return dataclasses.replace(self, fps=new_fps, joint_rotations=rot, root_translation=root)

    def joint_positions(self, rest_joints: np.ndarray | None = None) -> np.ndarray:
        """(T, 24, 3) world joint positions in metres (forward kinematics on ``rest_joints``,
        default the authoring skeleton); in place for walking clips."""
        rest = DEFAULT_REST_JOINTS if rest_joints is None else rest_joints
        return forward_kinematics(rest, self.joint_rotations, self.root_translation)[1]


def seam_discontinuity(clip: MotionClip, rest_joints: np.ndarray | None = None) -> dict:
    """How smooth a looping clip is across its seam, from joint positions.

    Velocities are finite differences of world joint positions (in place); the report
    compares the changes across the seam (last frame -> first frame) with the largest
    ones inside the clip.

    Returns a dict: ``step_seam`` / ``step_max`` (m, largest joint displacement per
    frame at the seam / anywhere inside), ``accel_seam`` / ``accel_max`` (m, largest
    second difference at the two seam frames / inside).
    """
    if not clip.loop:
        raise InvalidInputError(f"seam_discontinuity: clip {clip.name!r} does not loop")
    pos = clip.joint_positions(rest_joints)
    ext = np.concatenate([pos[-2:], pos, pos[:2]], axis=0)  # frames -2 .. T+1
    step = np.linalg.norm(np.diff(ext, axis=0), axis=-1).max(axis=-1)  # T+3 steps
    accel = np.linalg.norm(np.diff(ext, 2, axis=0), axis=-1).max(axis=-1)  # T+2 second differences
    # step k of ext spans ext[k] -> ext[k+1]; the seam step is T-1 -> 0, i.e. ext[T+1] -> ext[T+2]
    n = clip.n_frames
    seam_steps = [n + 1]
    inner_steps = np.arange(2, n + 1)
    # second difference k is centred on ext[k+1]; frames T-1 and 0 sit at ext[T+1], ext[T+2]
    seam_acc = [n, n + 1]
    inner_acc = np.arange(2, n)
    return {
        "step_seam": float(step[seam_steps].max()),
        "step_max": float(step[inner_steps].max()),
        "accel_seam": float(accel[seam_acc].max()),
        "accel_max": float(accel[inner_acc].max()),
    }

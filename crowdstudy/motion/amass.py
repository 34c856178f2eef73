"""SMPL / AMASS-style pose files (``.npz``) -> :class:`~crowdstudy.motion.clip.MotionClip`.

The file holds ``poses`` (T, 72) SMPL axis-angle (24 joints x 3, root first), or the
body part of larger layouts: (T, 156) SMPL-H and (T, 165) SMPL-X, whose first 22 joints
are SMPL's (the hands then stay at rest), or (T, 66) body only; ``trans`` (T, 3) metres;
``mocap_framerate`` (or ``mocap_frame_rate``) frames per second.

SMPL's canonical body frame is Y up, facing +z, left at +x; ours is Z up, facing +y, left
at -x. Joint rotations are conjugated by that change of frame. The world frame of the
file is Y up by default (``up="y"``, as in most SMPL renderings and exports); AMASS's own
archives are Z up (``up="z"``). The motion is lowered or raised so the feet touch the
floor (z = 0).
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, JOINT_INDEX, NUM_JOINTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.rig import ANKLE_HEIGHT

__all__ = ["load_amass", "SMPL_MEAN_PELVIS"]

#: Pelvis joint of SMPL's mean template in its canonical frame (m): ``trans`` moves this point.
SMPL_MEAN_PELVIS = np.array([-0.0022, -0.2408, 0.0286])
#: SMPL canonical (x left, y up, z forward) -> ours (x right, y forward, z up).
_CANONICAL = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
#: File world -> ours: a Y-up world is turned like the canonical frame; a Z-up one is kept.
_WORLD = {"y": _CANONICAL, "z": np.eye(3)}


def _field(data, key: str, path) -> np.ndarray:
    if key not in data.files:
        has = ", ".join(data.files) or "nothing"
        raise InvalidInputError(f"AMASS file {path}: field {key!r} is missing (has {has})")
    try:
        return np.asarray(data[key], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"AMASS file {path}: field {key!r} is not numeric ({exc})") from None


def load_amass(
    path: str | Path, *, up: str = "y", name: str | None = None, rest_joints: np.ndarray | None = None
) -> MotionClip:
    """Read an SMPL/AMASS pose file as a non-looping clip (kind "mocap").

    Args:
        path: the ``.npz`` file.
        up: the file's world up axis, "y" (default) or "z" (AMASS archives).
        name: clip name (default the file stem).
        rest_joints: (24, 3) skeleton used to put the feet on the floor (default the
            authoring skeleton).
    """
    from crowdstudy.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
    from crowdstudy.body.skeleton import forward_kinematics

    if up not in _WORLD:
        raise InvalidInputError(f"up: expected 'y' or 'z', got {up!r}")
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"AMASS file {str(path)!r} does not exist")
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InvalidInputError(f"AMASS file {path}: not a readable .npz archive ({exc})") from None
    with data:
        try:
            poses = _field(data, "poses", path)
            trans = _field(data, "trans", path)
            key = "mocap_framerate" if "mocap_framerate" in data.files else "mocap_frame_rate"
            rate = _field(data, key, path)
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            if isinstance(exc, InvalidInputError):
                raise
            raise InvalidInputError(f"AMASS file {path}: truncated or corrupt archive ({exc})") from None
    if poses.ndim != 2 or poses.shape[1] not in (66, 72, 156, 165) or poses.shape[0] < 1:
        raise InvalidInputError(
            f"AMASS file {path}: field 'poses' must have shape (T, 72) (or 66/156/165 columns), got {poses.shape}"
        )
    n = poses.shape[0]
    if trans.shape != (n, 3):
        raise InvalidInputError(
            f"AMASS file {path}: field 'trans' must have shape ({n}, 3) to match 'poses', got {trans.shape}"
        )
    if rate.size != 1 or not np.isfinite(rate).all() or float(rate.reshape(-1)[0]) <= 0:
        raise InvalidInputError(f"AMASS file {path}: field {key!r} must be one positive number, got {rate!r}")
    for field, arr in (("poses", poses), ("trans", trans)):
        if not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise InvalidInputError(f"AMASS file {path}: field {field!r} has a non-finite value at {tuple(bad)}")
    fps = float(rate.reshape(-1)[0])
    aa = np.zeros((n, NUM_JOINTS, 3))
    body = 24 if poses.shape[1] == 72 else 22
    aa[:, :body] = poses[:, : body * 3].reshape(n, body, 3)
    local = axis_angle_to_matrix(aa)
    world = _WORLD[up]
    local[:, 1:] = _CANONICAL @ local[:, 1:] @ _CANONICAL.T
    local[:, 0] = world @ local[:, 0] @ _CANONICAL.T
    # SMPL rotates the body about its pelvis joint J0, then adds trans: pelvis = J0 + trans.
    root = (trans + SMPL_MEAN_PELVIS) @ world.T
    rotations = matrix_to_axis_angle(local)
    rest = np.array(DEFAULT_REST_JOINTS if rest_joints is None else rest_joints, dtype=np.float64)
    if rest.shape != (NUM_JOINTS, 3):
        raise InvalidInputError(f"rest_joints: expected shape ({NUM_JOINTS}, 3), got {rest.shape}")
    _, joints = forward_kinematics(rest, rotations, root)
    feet = float(np.percentile(joints[:, [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]], 2].min(axis=1), 5))
    root = root.copy()
    root[:, 2] += ANKLE_HEIGHT - feet
    meta = {"source": str(path), "format": f"smpl-{poses.shape[1]}", "up": up, "frames": n}
    return MotionClip(
        name=name or path.stem,
        kind="mocap",
        fps=fps,
        joint_rotations=rotations,
        root_translation=root,
        loop=False,
        meta=meta,
    )

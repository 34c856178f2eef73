"""Quaternion helpers for motion clips, vectorised over any leading batch shape.

Quaternions are scalar-last ``(x, y, z, w)`` (docs/concepts/conventions.md). These complement
:mod:`crowdstudy.body.rotations` (conversions between axis-angle, matrices and
quaternions) with what clip sampling and blending need: products, sign alignment and a
C1 periodic Catmull-Rom interpolation.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX, JOINT_NAMES

__all__ = [
    "MIRROR_JOINTS",
    "mirror_pose",
    "quat_multiply",
    "quat_conjugate",
    "quat_align_signs",
    "quat_blend",
    "quat_about_z",
    "catmull_rom_weights",
]


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of (..., 4) quaternions (rotation b first, then a)."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions (..., 4)."""
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., :3] *= -1.0
    return out


def quat_align_signs(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip quaternions along ``axis`` (time) so neighbours lie in the same hemisphere."""
    q = np.moveaxis(np.array(q, dtype=np.float64, copy=True), axis, 0)
    for i in range(1, q.shape[0]):
        flip = np.sum(q[i] * q[i - 1], axis=-1) < 0.0
        q[i][flip] *= -1.0
    return np.moveaxis(q, 0, axis)


def quat_blend(a: np.ndarray, b: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Normalised linear blend (nlerp) ``(1 - w) a + w b`` on the shortest arc.

    a, b: (..., 4); weight: broadcastable to (..., 1) or (...,), in [0, 1].
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    w = np.asarray(weight, dtype=np.float64)
    if w.ndim == a.ndim - 1:
        w = w[..., None]
    b = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0.0, -b, b)
    out = (1.0 - w) * a + w * b
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def quat_about_z(angle: np.ndarray) -> np.ndarray:
    """(...,) yaw angles (radians, about +z) -> (..., 4) quaternions."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    zeros = np.zeros_like(half)
    return np.stack([zeros, zeros, np.sin(half), np.cos(half)], axis=-1)


def catmull_rom_weights(frac: np.ndarray) -> np.ndarray:
    """Weights (..., 4) of the samples i-1, i, i+1, i+2 for a uniform Catmull-Rom spline
    evaluated at ``i + frac`` (frac in [0, 1)); C1 across samples, exact at them."""
    u = np.asarray(frac, dtype=np.float64)
    u2, u3 = u * u, u * u * u
    return np.stack([-0.5 * u3 + u2 - 0.5 * u,
                     1.5 * u3 - 2.5 * u2 + 1.0,
                     -1.5 * u3 + 2.0 * u2 + 0.5 * u,
                     0.5 * u3 - 0.5 * u2], axis=-1)


#: Joint index -> its mirror image (left <-> right), for :func:`mirror_pose`.
MIRROR_JOINTS = np.array([JOINT_INDEX[n.replace("left_", "#").replace("right_", "left_").replace("#", "right_")]
                          for n in JOINT_NAMES])


def mirror_pose(quat: np.ndarray, root: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pose mirrored left <-> right across the character's sagittal plane (x -> -x):
    quaternions (..., 24, 4) xyzw (joint 0 global, the others local) and root positions
    (..., 3). A reflection M = diag(-1, 1, 1) turns a rotation R into M R M, i.e. the
    quaternion (x, y, z, w) into (x, -y, -z, w), and each joint takes its mirror joint's."""
    q = np.array(quat, dtype=np.float64, copy=True)[..., MIRROR_JOINTS, :]
    q[..., 1:3] *= -1.0
    r = np.array(root, dtype=np.float64, copy=True)
    r[..., 0] *= -1.0
    return q, r

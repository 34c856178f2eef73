"""Quaternion helpers for motion clips, vectorised over any leading batch shape.

Quaternions are scalar-last ``(x, y, z, w)`` (DESIGN.md). These complement
:mod:`crowdstudy.body.rotations` (matrices) with what clip sampling and blending need:
products, axis-angle conversions without a matrix round trip, sign alignment and a
C1 periodic Catmull-Rom interpolation.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "quat_multiply",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_to_axis_angle",
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


def quat_from_axis_angle(rotvec: np.ndarray) -> np.ndarray:
    """(..., 3) axis * angle (radians) -> (..., 4) unit quaternions."""
    v = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(half)/angle with its Taylor expansion near zero.
    small = angle < 1e-8
    scale = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([v * scale, np.cos(half)], axis=-1)


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (normalised here) -> (..., 3) axis-angle with angle in [0, pi]."""
    q = np.asarray(q, dtype=np.float64)
    vec = np.where(q[..., 3:4] < 0.0, -q[..., :3], q[..., :3])
    w = np.abs(q[..., 3:4])
    sin_half = np.sqrt(np.einsum("...c,...c->...", vec, vec))[..., None]
    angle = 2.0 * np.arctan2(sin_half, w)     # scale-free: no normalisation needed
    small = sin_half < 1e-12
    scale = np.where(small, 2.0 / np.maximum(w, 1e-12), angle / np.where(small, 1.0, sin_half))
    return vec * scale


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

"""Every rotation and quaternion helper of the toolkit, vectorised over any leading batch shape.

Conventions: quaternions are scalar-last ``(x, y, z, w)``; files store rotations as
axis-angle vectors (the angle is the norm, in radians); matrices act on column vectors
(``v_world = R @ v_local``); the Hamilton product ``a * b`` applies ``b`` first.

The module holds the conversions between axis-angle, matrices and quaternions, the
elementary rotations about the coordinate axes (:func:`rot_x`, :func:`rot_y`,
:func:`rot_z`, :func:`yaw_roll_pitch`), and the quaternion algebra that clip sampling,
blending and the physics output need (:func:`quat_multiply`, :func:`quat_conjugate`,
:func:`quat_rotate`, :func:`quat_nearest_sign`, :func:`quat_align_signs`,
:func:`quat_blend`, :func:`quat_about_z`). It imports nothing else of the package but
its error type, so every layer can use it.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = [
    "axis_angle_to_matrix",
    "matrix_to_axis_angle",
    "quaternion_to_matrix",
    "matrix_to_quaternion",
    "axis_angle_to_quaternion",
    "quaternion_to_axis_angle",
    "rotation_between",
    "rodrigues_rows",
    "skew",
    "rot_x",
    "rot_y",
    "rot_z",
    "yaw_roll_pitch",
    "quat_multiply",
    "quat_conjugate",
    "quat_rotate",
    "quat_nearest_sign",
    "quat_align_signs",
    "quat_blend",
    "quat_about_z",
]


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v]x`` so that ``skew(v) @ u == cross(v, u)``; (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def axis_angle_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues' formula. ``rotvec``: (..., 3) axis * angle in radians -> (..., 3, 3).

    R = I + a K + b K^2 with K = [v]x, a = sin(t)/t, b = (1 - cos(t))/t^2, t = |v|, written
    out entry by entry (:func:`rodrigues_rows`) on blocks of rotations laid out
    component-major: no batched 3x3 products and no temporary as large as the batch."""
    v = np.asarray(rotvec, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise InvalidInputError(f"rotvec: expected shape (..., 3), got {v.shape}")
    flat = v.reshape(-1, 3)
    out = np.empty((flat.shape[0], 3, 3))
    for s in range(0, flat.shape[0], _BLOCK):
        block = np.ascontiguousarray(flat[s : s + _BLOCK].T)
        rows = np.empty((3, 3, block.shape[1]))
        rodrigues_rows(block[0], block[1], block[2], rows)
        out[s : s + _BLOCK] = rows.transpose(2, 0, 1)
    return out.reshape(v.shape[:-1] + (3, 3))


#: rotations per block of the component-major conversions
_BLOCK = 8192


def rodrigues_rows(x: np.ndarray, y: np.ndarray, z: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Rodrigues' formula component-major: the axis-angle components ``x, y, z`` (...) rad
    -> ``out`` (3, 3, ...), entry [a, b] of every matrix one array (the small-angle branch
    by its Taylor expansion, exact to double precision); returns ``out``."""
    xx, yy, zz = x * x, y * y, z * z
    theta2 = xx + yy + zz
    small = theta2 < 1e-12
    theta = np.sqrt(np.where(small, 1.0, theta2))
    a = np.sin(theta)
    a /= theta
    b = 1.0 - np.cos(theta)
    b /= theta * theta
    if small.any():
        a[small] = 1.0 - theta2[small] / 6.0
        b[small] = 0.5 - theta2[small] / 24.0
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    ax, ay, az = a * x, a * y, a * z
    np.subtract(1.0, b * (yy + zz), out=out[0, 0])
    np.subtract(bxy, az, out=out[0, 1])
    np.add(bxz, ay, out=out[0, 2])
    np.add(bxy, az, out=out[1, 0])
    np.subtract(1.0, b * (xx + zz), out=out[1, 1])
    np.subtract(byz, ax, out=out[1, 2])
    np.subtract(bxz, ay, out=out[2, 0])
    np.add(byz, ax, out=out[2, 1])
    np.subtract(1.0, b * (xx + yy), out=out[2, 2])
    return out


def matrix_to_quaternion(matrix: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions ``(x, y, z, w)`` with w >= 0."""
    m = np.asarray(matrix, dtype=np.float64)
    batch = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = np.trace(m, axis1=1, axis2=2)
    # Shepperd's method: pick the largest of w, x, y, z to divide by.
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    pick = np.argmax(cand, axis=1)
    q = np.empty((m.shape[0], 4))
    for case in range(4):
        sel = pick == case
        if not np.any(sel):
            continue
        r = m[sel]
        if case == 0:
            s = np.sqrt(1.0 + tr[sel]) * 2.0
            q[sel] = np.stack(
                [(r[:, 2, 1] - r[:, 1, 2]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s, (r[:, 1, 0] - r[:, 0, 1]) / s, 0.25 * s],
                axis=1,
            )
        elif case == 1:
            s = np.sqrt(1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2]) * 2.0
            q[sel] = np.stack(
                [0.25 * s, (r[:, 0, 1] + r[:, 1, 0]) / s, (r[:, 0, 2] + r[:, 2, 0]) / s, (r[:, 2, 1] - r[:, 1, 2]) / s],
                axis=1,
            )
        elif case == 2:
            s = np.sqrt(1.0 + r[:, 1, 1] - r[:, 0, 0] - r[:, 2, 2]) * 2.0
            q[sel] = np.stack(
                [(r[:, 0, 1] + r[:, 1, 0]) / s, 0.25 * s, (r[:, 1, 2] + r[:, 2, 1]) / s, (r[:, 0, 2] - r[:, 2, 0]) / s],
                axis=1,
            )
        else:
            s = np.sqrt(1.0 + r[:, 2, 2] - r[:, 0, 0] - r[:, 1, 1]) * 2.0
            q[sel] = np.stack(
                [(r[:, 0, 2] + r[:, 2, 0]) / s, (r[:, 1, 2] + r[:, 2, 1]) / s, 0.25 * s, (r[:, 1, 0] - r[:, 0, 1]) / s],
                axis=1,
            )
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1.0
    return q.reshape(batch + (4,))


def quaternion_to_matrix(quat: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions ``(x, y, z, w)`` (normalised here) -> (..., 3, 3)."""
    q = np.asarray(quat, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - z * w)
    out[..., 0, 2] = 2 * (x * z + y * w)
    out[..., 1, 0] = 2 * (x * y + z * w)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - x * w)
    out[..., 2, 0] = 2 * (x * z - y * w)
    out[..., 2, 1] = 2 * (y * z + x * w)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def axis_angle_to_quaternion(rotvec: np.ndarray) -> np.ndarray:
    """(..., 3) axis * angle (radians) -> (..., 4) unit quaternions ``(x, y, z, w)``
    (no matrix round trip; w = cos(angle / 2), so w < 0 for angles beyond pi). Computed in
    blocks of rotations, component-major, as :func:`axis_angle_to_matrix`."""
    v = np.asarray(rotvec, dtype=np.float64)
    if v.shape[-1:] != (3,):
        raise InvalidInputError(f"rotvec: expected shape (..., 3), got {v.shape}")
    flat = v.reshape(-1, 3)
    out = np.empty((flat.shape[0], 4))
    for s in range(0, flat.shape[0], _BLOCK):
        x, y, z = np.ascontiguousarray(flat[s : s + _BLOCK].T)
        angle = np.sqrt(x * x + y * y + z * z)
        half = 0.5 * angle
        # sin(half)/angle with its Taylor expansion near zero
        small = angle < 1e-8
        scale = np.sin(half)
        scale /= np.where(small, 1.0, angle)
        if small.any():
            scale[small] = 0.5 - angle[small] ** 2 / 48.0
        rows = np.empty((4, x.shape[0]))
        np.multiply(x, scale, out=rows[0])
        np.multiply(y, scale, out=rows[1])
        np.multiply(z, scale, out=rows[2])
        np.cos(half, out=rows[3])
        out[s : s + _BLOCK] = rows.T
    return out.reshape(v.shape[:-1] + (4,))


def quaternion_to_axis_angle(quat: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions ``(x, y, z, w)`` (any norm, either sign) -> (..., 3) axis-angle
    with angle in [0, pi]; accurate near 0 and pi (arctan2 of the half-angle sine and cosine)."""
    q = np.asarray(quat, dtype=np.float64)
    vec = np.where(q[..., 3:4] < 0.0, -q[..., :3], q[..., :3])
    w = np.abs(q[..., 3:4])
    sin_half = np.sqrt(np.einsum("...c,...c->...", vec, vec))[..., None]
    angle = 2.0 * np.arctan2(sin_half, w)  # scale-free: no normalisation needed
    small = sin_half < 1e-12
    scale = np.where(small, 2.0 / np.maximum(w, 1e-12), angle / np.where(small, 1.0, sin_half))
    return vec * scale


def matrix_to_axis_angle(matrix: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 3) axis-angle with angle in [0, pi] (through the quaternion,
    which stays accurate near 0 and pi)."""
    return quaternion_to_axis_angle(matrix_to_quaternion(matrix))


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``a`` onto direction ``b``: (..., 3) twice ->
    (..., 3, 3); the identity where the two are parallel or opposite (|a x b| < 1e-12 for
    the unit directions)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    cross = np.cross(a, b)
    sin = np.linalg.norm(cross, axis=-1, keepdims=True)
    angle = np.arctan2(sin, np.sum(a * b, axis=-1, keepdims=True))
    return axis_angle_to_matrix(np.where(sin >= 1e-12, cross / np.maximum(sin, 1e-12) * angle, 0.0))


# -- elementary rotations -------------------------------------------------------------


def _rot(axis: int, angle: np.ndarray | float) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about coordinate axis ``axis`` (0 x, 1 y, 2 z)."""
    a = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(angle: np.ndarray) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about +x."""
    return _rot(0, angle)


def rot_y(angle: np.ndarray) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about +y."""
    return _rot(1, angle)


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about +z."""
    return _rot(2, angle)


def yaw_roll_pitch(yaw: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """``Rz(yaw) Ry(roll) Rx(pitch)`` (..., 3, 3) for a body facing +y, angles (...,) in
    radians (broadcast together): pitch leans forward/back about the lateral x axis, roll
    tilts sideways about the forward y axis, yaw turns about z."""
    yaw, roll, pitch = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (yaw, roll, pitch)))
    return rot_z(yaw) @ rot_y(roll) @ rot_x(pitch)


# -- quaternion algebra ---------------------------------------------------------------


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of (..., 4) quaternions (rotation b first, then a)."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate of (..., 4) quaternions: the inverse rotation of unit quaternions."""
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., :3] *= -1.0
    return out


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors ``v`` (..., 3) rotated by unit quaternions ``q`` (..., 4): ``q v q*`` with v
    taken as the pure quaternion ``(v, 0)``; returns (..., 3)."""
    v = np.asarray(v, dtype=np.float64)
    vq = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], -1)
    return quat_multiply(quat_multiply(q, vq), quat_conjugate(q))[..., :3]


def quat_nearest_sign(q: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """``q`` or ``-q`` (the same rotation), whichever lies in the hemisphere of ``ref``
    (non-negative dot product): (..., 4) and (..., 4) broadcast together -> (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    return np.where(np.sum(q * ref, axis=-1, keepdims=True) < 0.0, -q, q)


def quat_align_signs(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """(..., 4) quaternions with signs flipped along ``axis`` (time) so that neighbours lie
    in the same hemisphere (each takes the sign nearest its already aligned predecessor)."""
    q = np.moveaxis(np.array(q, dtype=np.float64, copy=True), axis, 0)
    if q.shape[0] < 2:
        return np.moveaxis(q, 0, axis)
    # q[i] flips when its dot with the aligned q[i - 1] is negative: the sign is the running
    # product of the neighbours' dot signs, started afresh (+1) where a dot is exactly 0
    dot = np.sum(q[1:] * q[:-1], axis=-1)
    step = np.concatenate([np.ones((1,) + dot.shape[1:]), np.where(dot < 0.0, -1.0, 1.0)])
    sign = np.cumprod(step, axis=0)
    if np.any(dot == 0.0):
        index = np.arange(q.shape[0]).reshape((-1,) + (1,) * (dot.ndim - 1))
        fresh = np.concatenate([np.ones((1,) + dot.shape[1:], bool), dot == 0.0])
        start = np.maximum.accumulate(np.where(fresh, index, 0), axis=0)
        sign = sign * np.take_along_axis(sign, start, axis=0)
    return np.moveaxis(q * sign[..., None], 0, axis)


def quat_blend(a: np.ndarray, b: np.ndarray, weight: np.ndarray | float) -> np.ndarray:
    """Normalised linear blend (nlerp) ``(1 - w) a + w b`` on the shortest arc.

    a, b: (..., 4); weight: broadcastable to (..., 1) or (...,), in [0, 1] (a weight with
    one dimension less than ``a`` gets a trailing axis).
    """
    a = np.asarray(a, dtype=np.float64)
    w = np.asarray(weight, dtype=np.float64)
    if w.ndim == a.ndim - 1:
        w = w[..., None]
    b = quat_nearest_sign(b, a)
    out = (1.0 - w) * a + w * b
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def quat_about_z(angle: np.ndarray) -> np.ndarray:
    """(...,) yaw angles (radians, about +z) -> (..., 4) quaternions."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    zeros = np.zeros_like(half)
    return np.stack([zeros, zeros, np.sin(half), np.cos(half)], axis=-1)

"""Building blocks for clips: analytic two-bone IK and time profiles.

All functions are vectorised over a leading batch (frames). Rotation matrices act on
column vectors; a joint's *local* rotation is relative to its parent's global frame. The
time-signal helpers (:func:`planted_runs`, :func:`hold_peaks`) serve the motion-capture
cleaning and the physics output stage alike.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hinge_frame", "two_bone_ik", "smoothstep5", "lift_profile", "planted_runs", "hold_peaks"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def hinge_frame(direction: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """Orthonormal frame (..., 3, 3) with columns ``[d, h x d, h]``: ``d`` the unit bone
    direction and ``h`` the hinge axis made orthogonal to it."""
    d = _unit(direction)
    h = hinge - np.sum(hinge * d, axis=-1, keepdims=True) * d
    h = _unit(h)
    return np.stack([d, np.cross(h, d), h], axis=-1)


def two_bone_ik(
    root_pos: np.ndarray,
    target: np.ndarray,
    pole: np.ndarray,
    parent_rot: np.ndarray,
    rest_a: np.ndarray,
    rest_b: np.ndarray,
    rest_c: np.ndarray,
    rest_pole: np.ndarray,
    *,
    max_reach: float = 0.999,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Analytic IK of a chain a -> b -> c (hip-knee-ankle, shoulder-elbow-wrist).

    Args:
        root_pos: (T, 3) world position of joint a (metres).
        target: (T, 3) wanted world position of joint c; pulled in to ``max_reach`` of the
            chain length when out of reach.
        pole: (T, 3) world direction the middle joint b should point to (the knee's front,
            the elbow's back).
        parent_rot: (T, 3, 3) global rotation of a's parent.
        rest_a, rest_b, rest_c: (3,) rest positions of a, b, c (any common origin), or
            (..., 3) broadcasting with the batch (one skeleton per character).
        rest_pole: (3,) the direction b points to in the rest pose.

    Returns:
        ``(local_a (T, 3, 3), local_b (T, 3, 3), global_b (T, 3, 3))``: the rotation of a
        relative to its parent, of b relative to a, and b's global rotation. The chain
        bends about a single hinge axis (b's local rotation is a rotation about it).
    """
    rest_a, rest_b, rest_c = (np.asarray(v, dtype=np.float64) for v in (rest_a, rest_b, rest_c))
    u1, u2 = rest_b - rest_a, rest_c - rest_b
    l1 = np.linalg.norm(u1, axis=-1, keepdims=True)
    l2 = np.linalg.norm(u2, axis=-1, keepdims=True)
    hinge_rest = _unit(np.cross(rest_c - rest_a, np.asarray(rest_pole, dtype=np.float64)))
    rest1 = hinge_frame(u1, hinge_rest)
    rest2 = hinge_frame(u2, hinge_rest)

    d = np.asarray(target, dtype=np.float64) - root_pos
    dist = np.linalg.norm(d, axis=-1, keepdims=True)
    d_hat = d / np.maximum(dist, 1e-9)
    dist = np.clip(dist, np.abs(l1 - l2) + 1e-4, max_reach * (l1 + l2))
    along = (l1 * l1 - l2 * l2 + dist * dist) / (2.0 * dist)
    height = np.sqrt(np.maximum(l1 * l1 - along * along, 0.0))
    bend = np.asarray(pole, dtype=np.float64) - np.sum(pole * d_hat, axis=-1, keepdims=True) * d_hat
    bend = _unit(bend)
    knee = root_pos + d_hat * along + bend * height
    ankle = root_pos + d_hat * dist
    hinge = _unit(np.cross(d_hat, bend))
    glob_a = hinge_frame(knee - root_pos, hinge) @ np.swapaxes(rest1, -1, -2)
    glob_b = hinge_frame(ankle - knee, hinge) @ np.swapaxes(rest2, -1, -2)
    local_a = np.swapaxes(parent_rot, -1, -2) @ glob_a
    local_b = np.swapaxes(glob_a, -1, -2) @ glob_b
    return local_a, local_b, glob_b


def smoothstep5(u: np.ndarray) -> np.ndarray:
    """Quintic smoothstep on [0, 1] (zero first and second derivative at both ends)."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * u * (u * (6.0 * u - 15.0) + 10.0)


def lift_profile(u: np.ndarray) -> np.ndarray:
    """A bump on [0, 1]: ``sin^2(pi u)`` inside, zero outside; C1 at the ends."""
    u = np.asarray(u, dtype=np.float64)
    return np.where((u > 0) & (u < 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0)


def planted_runs(mask: np.ndarray, *, periodic: bool = False) -> list[tuple[int, int]]:
    """Runs ``[start, stop)`` of True in a (T,) mask; for a periodic mask a run may wrap
    (``stop > T``); a mask that is all True is one run ``(0, T)``."""
    mask = np.asarray(mask, bool)
    n = len(mask)
    if not mask.any():
        return []
    if mask.all():
        return [(0, n)]
    shift = int(np.argmin(mask)) if periodic else 0  # start the scan on a free frame
    m = np.roll(mask, -shift)
    edges = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a + shift), int(b + shift)) for a, b in zip(starts, stops, strict=True)]


def hold_peaks(x: np.ndarray, half_width: int, mode: str) -> np.ndarray:
    """Each sample replaced by the sample of largest magnitude (with its sign) within
    +-``half_width`` frames along axis 0: a morphological dilation of |x| that keeps signs."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    size = 2 * half_width + 1
    hi = maximum_filter1d(x, size, axis=0, mode=mode)
    lo = minimum_filter1d(x, size, axis=0, mode=mode)
    return np.where(np.abs(hi) >= np.abs(lo), hi, lo)

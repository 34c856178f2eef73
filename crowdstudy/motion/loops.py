"""Seamless loops cut from motion capture: loop points by pose-and-velocity matching, the seam blended.

A take is not periodic. A loop ``[a, a + L)`` of it plays well when the pose *and* the
motion around frame ``a + L`` resemble those around ``a``: :func:`find_loop` scores every
candidate by the summed squared distance of in-place joint positions over a window of
frames centred on the two cut points (matching a window matches velocities and
accelerations too, not just one pose) and takes the longest allowed length whose score is
close to the best one (more of the take, less repetition).

:func:`make_loop` then cuts the loop and blends its seam: over the last ``W`` frames the
motion cross-fades (quintic smoothstep, per joint quaternion nlerp; positions lerp) into
the frames that *precede* ``a`` in the take, which continue smoothly into frame ``a``; so
the loop's last frame flows into its first as any other frame step does. It needs
``a >= W``, which :func:`find_loop` enforces through ``min_start``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.posing import smoothstep5
from crowdstudy.body.rotations import quat_align_signs, quat_blend, quaternion_to_axis_angle
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip

__all__ = ["LoopChoice", "find_loop", "make_loop", "in_place_positions"]


@dataclasses.dataclass(frozen=True)
class LoopChoice:
    """A loop ``[start, start + length)`` (frames) and its match score (m^2 per joint and frame)."""

    start: int
    length: int
    score: float
    best_score: float


def in_place_positions(clip: MotionClip) -> np.ndarray:
    """(T, 24, 3) joint positions of ``clip`` with the pelvis's horizontal position removed."""
    pos = clip.joint_positions()
    pos = pos.copy()
    pos[..., :2] -= pos[:, :1, :2]
    return pos


def find_loop(
    positions: np.ndarray,
    lengths,
    *,
    window: int,
    min_start: int,
    tolerance: float = 1.3,
    end_margin: int = 0,
    start_step: int = 1,
    accept: float = 0.0,
) -> LoopChoice:
    """The loop ``[a, a + L)`` of a take whose two cut points match best.

    Args:
        positions: (T, J, 3) in-place joint positions (metres), e.g. :func:`in_place_positions`.
        lengths: candidate loop lengths L (frames), e.g. whole bars or whole gait cycles.
        window: half-width (frames) of the matched window around the cut points.
        min_start: smallest ``a`` (the seam blend reads ``a - W .. a``; use ``W``).
        tolerance, accept: the longest L whose best score is within ``tolerance`` x the
            overall best, or below ``accept`` (m^2), is chosen.
        end_margin: frames that must remain after ``a + L`` (beyond the window).
        start_step: ``a`` is a multiple of it (e.g. the frames of a beat, so a loop starts on
            a beat).

    Raises InvalidInputError when no candidate fits in the take.
    """
    pos = np.asarray(positions, dtype=np.float64)
    n = pos.shape[0]
    flat = pos.reshape(n, -1)
    offsets = np.arange(-window, window + 1)
    results: dict[int, tuple[float, int]] = {}
    for length in sorted({int(x) for x in lengths}):
        if length < 4:
            continue
        step = max(1, int(start_step))
        lo = -(-max(min_start, window) // step) * step
        hi = n - 1 - length - window - end_margin
        if hi < lo:
            continue
        starts = np.arange(lo, hi + 1, step)
        a = starts[:, None] + offsets[None, :]
        d = flat[a] - flat[a + length]  # (S, 2w+1, J*3)
        score = np.einsum("swc,swc->s", d, d) / (len(offsets) * pos.shape[1])
        k = int(np.argmin(score))
        results[length] = (float(score[k]), int(starts[k]))
    if not results:
        raise InvalidInputError(
            f"find_loop: no loop of lengths {sorted(set(int(x) for x in lengths))} frames fits "
            f"a take of {n} frames (window {window}, start >= {min_start})"
        )
    best = min(s for s, _ in results.values())
    length = max(L for L, (s, _) in results.items() if s <= max(tolerance * best, accept) + 1e-12)
    score, start = results[length]
    return LoopChoice(start=start, length=length, score=score, best_score=best)


def make_loop(
    clip: MotionClip,
    start: int,
    length: int,
    blend: int,
    *,
    name: str | None = None,
    meta: dict | None = None,
    speed: float | None = None,
    kind: str | None = None,
) -> MotionClip:
    """The looping clip of frames ``[start, start + length)`` of ``clip``, its seam blended over
    the last ``blend`` frames into the frames before ``start`` (see the module docstring)."""
    n = clip.n_frames
    if not (0 < length and blend >= 0 and start >= blend and start + length <= n and blend < length):
        raise InvalidInputError(
            f"make_loop: loop [{start}, {start + length}) with a {blend}-frame blend does not fit "
            f"clip {clip.name!r} of {n} frames (needs start >= blend)"
        )
    quat = clip.quaternions[start : start + length].copy()
    root = clip.root_translation[start : start + length].copy()
    if blend:
        i = np.arange(length - blend, length)
        w = smoothstep5((i - (length - blend) + 1) / (blend + 1))  # -> 1 at the seam
        src = i - length + start  # frames before `start`
        quat[i] = quat_blend(quat[i], clip.quaternions[src], w[:, None])
        root[i] = (1.0 - w)[:, None] * root[i] + w[:, None] * clip.root_translation[src]
    quat = quat_align_signs(quat, axis=0)
    info = {"loop_source": {"start": int(start), "length": int(length), "blend": int(blend)}}
    return MotionClip(
        name=name or clip.name,
        kind=kind or clip.kind,
        fps=clip.fps,
        joint_rotations=quaternion_to_axis_angle(quat),
        root_translation=root,
        speed=clip.speed if speed is None else speed,
        loop=True,
        meta={**clip.meta, **info, **(meta or {})},
    )

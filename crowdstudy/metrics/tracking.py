"""Motion-quality metrics: tracking error and intra-body penetration.

* :func:`tracking_error`: how far the corrected animation strays from its input (mean
  joint-position deviation, cm), with each character's own ``rest_joints``.
* :func:`tracking_parts`: the same error split into a placement (each character's
  constant horizontal shift over the clip, as when a dense crowd spreads out) and the
  motion's own deviation around it, and per character and body part (legs, trunk, arms:
  :data:`crowdstudy.body.skeleton.BODY_PARTS`), to see where a correction moves whom.
* :func:`intra_penetration`: how deep a character's own bone capsules sink into each other,
  over pairs that do not already touch in the rest pose (adjacent bones are skipped, as
  the physics layer skips them).

Smoothness (``mean_jerk``, high-frequency energy, speed spikes, foot sliding, loop seams)
is measured in :mod:`crowdstudy.metrics.smoothness`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdstudy.body.capsules import segment_distance
from crowdstudy.body.skeleton import BODY_PARTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics.overlap import capsules_world, frame_indices, resolve_bodies

__all__ = [
    "joint_positions",
    "check_reference",
    "tracking_error",
    "tracking_parts",
    "TrackingParts",
    "intra_penetration",
    "IntraPenetrationResult",
    "intra_pairs",
]

_FRAME_CHUNK = 64


def joint_positions(anim, *, bodies: Sequence | None = None, frames: Any = None) -> np.ndarray:
    """World joint positions by forward kinematics with each body's ``rest_joints``.

    Returns:
        (F, N, J, 3) float64 metres for the selected ``frames`` (all by default).
    """
    from crowdstudy.body.skeleton import forward_kinematics

    idx = frame_indices(frames, anim.n_frames)
    body_objs = resolve_bodies(anim, bodies)
    rest = np.stack([np.asarray(b.rest_joints, dtype=np.float64) for b in body_objs])  # (N, J, 3)
    if rest.shape[1] != anim.n_joints:
        raise InvalidInputError(f"bodies: rest_joints have {rest.shape[1]} joints, the animation has {anim.n_joints}")
    _, pos = forward_kinematics(rest[None], anim.joint_rotations[idx], anim.root_translation[idx], parents=anim.parents)
    return pos


def check_reference(anim, reference) -> None:
    """Raise unless ``reference`` has the same (frames, characters, joints) as ``anim``."""
    if reference.root_translation.shape != anim.root_translation.shape or reference.n_joints != anim.n_joints:
        raise InvalidInputError(
            f"reference: expected the same (frames, characters, joints) as anim "
            f"{anim.root_translation.shape[:2] + (anim.n_joints,)}, got "
            f"{reference.root_translation.shape[:2] + (reference.n_joints,)}"
        )


def tracking_error(anim, reference, *, bodies: Sequence | None = None) -> float:
    """Mean joint-position deviation of ``anim`` from ``reference`` (its input), cm.

    Args:
        anim: the corrected :class:`~crowdstudy.scene.CrowdAnimation`.
        reference: the animation it should follow (same frames, characters, joints).
        bodies: optional body objects overriding ``load_body`` (same for both).

    Joint positions come from forward kinematics with each character's rest joints; in
    periodic scenes the x difference is taken by the minimum image.
    """
    _check_pair(anim, reference)
    total = 0.0
    count = 0
    for diff in _deviations(anim, reference, resolve_bodies(anim, bodies)):
        dist = np.linalg.norm(diff, axis=-1)
        total += float(dist.sum())
        count += dist.size
    return 100.0 * total / count


def _check_pair(anim, reference) -> None:
    for name, value in (("anim", anim), ("reference", reference)):
        if not hasattr(value, "joint_rotations"):
            raise TypeError(f"{name}: expected a CrowdAnimation, got {type(value).__name__}")
    check_reference(anim, reference)


def _deviations(anim, reference, body_objs):
    """The joint-position deviation ``anim - reference`` in chunks of frames, (F, N, J, 3)
    m each (x by the minimum image in periodic scenes)."""
    length = anim.periodic_length
    for c0 in range(0, anim.n_frames, _FRAME_CHUNK):
        chunk = np.arange(c0, min(c0 + _FRAME_CHUNK, anim.n_frames))
        diff = joint_positions(anim, bodies=body_objs, frames=chunk) - joint_positions(
            reference, bodies=body_objs, frames=chunk
        )
        if length is not None:
            diff[..., 0] -= length * np.round(diff[..., 0] / length)
        yield diff


@dataclasses.dataclass(frozen=True)
class TrackingParts:
    """Tracking error and its two parts (cm).

    Attributes:
        total_cm: :func:`tracking_error`, the mean joint-position deviation.
        placement_cm: mean over characters of |s_n|, s_n the character's mean horizontal
            joint deviation over all frames and joints: a constant shift of where it
            stands, which a viewer sees as a slightly different layout.
        motion_cm: mean |d - s_n| over frames, characters and joints: the deviation of the
            motion itself once the character's placement is taken out.
        per_character_placement_cm: (N,) |s_n|.
        per_character_cm: (N,) mean joint deviation of each character.
        per_character_part_cm: body part name (``legs``, ``trunk``, ``arms``) -> (N,) mean
            deviation of that part's joints (NaN where the skeleton has none of them).
        per_joint_cm: (J,) mean deviation of each joint over frames and characters.
    """

    total_cm: float
    placement_cm: float
    motion_cm: float
    per_character_placement_cm: np.ndarray
    per_character_cm: np.ndarray
    per_character_part_cm: dict = dataclasses.field(default_factory=dict)
    per_joint_cm: np.ndarray | None = None

    def as_dict(self, per_character: bool = False) -> dict:
        """Totals as ``tracking_*_cm`` (the parts' ``tracking_legs_cm`` ... are means over
        characters); ``per_character``: also ``tracking_per_character`` (lists)."""
        out: dict[str, Any] = {
            "tracking_error_cm": self.total_cm,
            "tracking_placement_cm": self.placement_cm,
            "tracking_motion_cm": self.motion_cm,
        }
        for part, values in self.per_character_part_cm.items():
            out[f"tracking_{part}_cm"] = float(np.mean(values)) if np.all(np.isfinite(values)) else None
        if per_character:
            per = {
                "tracking_cm": self.per_character_cm.tolist(),
                "placement_cm": self.per_character_placement_cm.tolist(),
            }
            for part, values in self.per_character_part_cm.items():
                per[f"{part}_cm"] = [float(v) if np.isfinite(v) else None for v in values]
            out["tracking_per_character"] = per
        return out


def tracking_parts(anim, reference, *, bodies: Sequence | None = None) -> TrackingParts:
    """:func:`tracking_error` split into placement and motion (:class:`TrackingParts`).

    The total is never more than the sum of the two parts (triangle inequality); a crowd
    that spreads out to make room shows a large placement and a small motion part.
    """
    _check_pair(anim, reference)
    n = anim.n_characters
    body_objs = resolve_bodies(anim, bodies)
    # two passes over the chunks (the placement first), so that little is held in memory
    shift = np.zeros((n, 3))
    for diff in _deviations(anim, reference, body_objs):
        shift[:, :2] += diff[..., :2].sum(axis=(0, 2))
    shift /= anim.n_frames * anim.n_joints
    per_joint = np.zeros((n, anim.n_joints))
    rest = np.zeros(n)
    for diff in _deviations(anim, reference, body_objs):
        per_joint += np.linalg.norm(diff, axis=-1).sum(axis=0)
        rest += np.linalg.norm(diff - shift[None, :, None], axis=-1).sum(axis=(0, 2))
    dist = per_joint.sum(axis=1)
    count = anim.n_frames * anim.n_joints
    place = np.linalg.norm(shift, axis=1)
    index = {name: j for j, name in enumerate(anim.joint_names)}
    parts = {}
    for part, names in BODY_PARTS:
        cols = [index[name] for name in names if name in index]
        parts[part] = (100.0 * per_joint[:, cols].mean(axis=1) / anim.n_frames) if cols else np.full(n, np.nan)
    return TrackingParts(
        total_cm=100.0 * float(dist.sum() / (count * n)),
        placement_cm=100.0 * float(place.mean()),
        motion_cm=100.0 * float(rest.sum() / (count * n)),
        per_character_placement_cm=100.0 * place,
        per_character_cm=100.0 * dist / count,
        per_character_part_cm=parts,
        per_joint_cm=100.0 * per_joint.sum(axis=0) / (anim.n_frames * n),
    )


def intra_pairs(body, *, parents: np.ndarray | None = None) -> np.ndarray:
    """Capsule pairs (P, 2) of one body that are checked for self-penetration: both radii
    positive, not parent and child, and not touching in the rest pose (the body's
    ``rest_touching_pairs()`` when it has one, which the physics layer also skips, else
    capsules within ``r_a + r_b`` of each other in the rest pose)."""
    from crowdstudy.body.skeleton import PARENTS

    parents = PARENTS if parents is None else np.asarray(parents)
    caps = body.capsules
    start = np.asarray(caps.start, dtype=np.float64)
    end = np.asarray(caps.end, dtype=np.float64)
    radius = np.asarray(caps.radius, dtype=np.float64)
    a, b = np.triu_indices(len(radius), k=1)
    ok = (radius[a] > 0) & (radius[b] > 0) & (parents[b] != a) & (parents[a] != b)
    touching = getattr(body, "rest_touching_pairs", None)
    if callable(touching):
        skip = np.zeros((len(radius), len(radius)), bool)
        pairs = np.asarray(touching(), dtype=np.int64).reshape(-1, 2)
        skip[pairs[:, 0], pairs[:, 1]] = True
        skip[pairs[:, 1], pairs[:, 0]] = True
        ok &= ~skip[a, b]
    else:
        ok &= segment_distance(start[a], end[a], start[b], end[b]) > radius[a] + radius[b]
    return np.stack([a[ok], b[ok]], axis=1)


@dataclasses.dataclass(frozen=True)
class IntraPenetrationResult:
    """Self-penetration between a character's own non-adjacent capsules.

    Attributes:
        per_character: (F, N) float64 metres, the deepest penetration
            ``r_a + r_b - distance`` over the character's checked pairs (0 when none).
        frames: (F,) measured frame indices.
        pairs: (N,) number of capsule pairs checked per character.
    """

    per_character: np.ndarray
    frames: np.ndarray
    pairs: np.ndarray

    @property
    def mean_depth(self) -> float:
        """Mean of the deepest penetration over characters and frames, metres."""
        return float(self.per_character.mean()) if self.per_character.size else 0.0

    @property
    def fraction(self) -> float:
        """Share of (frame, character) samples with any self-penetration."""
        return float((self.per_character > 0).mean()) if self.per_character.size else 0.0


def intra_penetration(anim, *, frames: Any = None, bodies: Sequence | None = None) -> IntraPenetrationResult:
    """Depth of self-penetration between non-adjacent bone capsules of each character.

    Pairs that are parent and child, or that already touch in the rest pose, are skipped
    (:func:`intra_pairs`); the depth of a pair is ``r_a + r_b - distance`` of the two
    capsule segments when positive.
    """
    idx = frame_indices(frames, anim.n_frames)
    body_objs = resolve_bodies(anim, bodies)
    out = np.zeros((len(idx), anim.n_characters))
    n_pairs = np.zeros(anim.n_characters, np.int64)
    for i, body in enumerate(body_objs):
        pairs = intra_pairs(body, parents=anim.parents)
        n_pairs[i] = len(pairs)
        if len(pairs) == 0:
            continue
        start, end, radius = capsules_world(body, anim.joint_rotations[idx, i], anim.root_translation[idx, i])
        a, b = pairs[:, 0], pairs[:, 1]
        dist = segment_distance(start[:, a], end[:, a], start[:, b], end[:, b])
        depth = radius[a] + radius[b] - dist
        out[:, i] = np.maximum(depth.max(axis=1), 0.0)
    return IntraPenetrationResult(per_character=out, frames=idx, pairs=n_pairs)

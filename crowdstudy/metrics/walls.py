"""How far the characters' skin reaches through the scene's walls.

The walls are those of the animation's meta (``meta["obstacles"]``, read by
:func:`crowdstudy.scene_meta.static_walls_from_meta`): vertical walls standing on
floor segments, seen from the side each character's root stands on, as the physics sees
them (``wall_kernel``). A character's depth at a frame is the largest distance by which any
vertex of its posed body mesh lies beyond a wall's face (0 when none does), counted where
the vertex's foot point falls within the segment; in periodic scenes (the corridor) the
character is wrapped into ``[0, L)`` along x by its root and its images at +-L are tried.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics.overlap import frame_indices, resolve_bodies
from crowdstudy.scene_meta import static_walls_from_meta

__all__ = ["WallPenetration", "wall_penetration", "beyond_wall"]


@dataclasses.dataclass(frozen=True)
class WallPenetration:
    """Skin beyond the walls.

    Attributes:
        per_character: (F, N) m, each character's deepest vertex beyond a wall's face.
        frames: (F,) the frames measured.
        n_walls: how many wall segments the animation has.
    """

    per_character: np.ndarray
    frames: np.ndarray
    n_walls: int

    @property
    def mean_cm(self) -> float:
        """Mean over characters and frames, cm (frames without contact count as 0)."""
        return 100.0 * float(self.per_character.mean()) if self.per_character.size else 0.0

    @property
    def p99_cm(self) -> float:
        """99th percentile over characters and frames, cm."""
        return 100.0 * float(np.percentile(self.per_character, 99)) if self.per_character.size else 0.0

    @property
    def max_cm(self) -> float:
        return 100.0 * float(self.per_character.max(initial=0.0))

    @property
    def fraction_through(self) -> float:
        """Share of (character, frame) samples with skin more than 1 cm through a wall."""
        return float((self.per_character > 0.01).mean()) if self.per_character.size else 0.0

    def as_dict(self) -> dict:
        return {
            "n_walls": self.n_walls,
            "frames_measured": int(len(self.frames)),
            "mean_cm": self.mean_cm,
            "p99_cm": self.p99_cm,
            "max_cm": self.max_cm,
            "fraction_over_1cm": self.fraction_through,
        }


def beyond_wall(points: np.ndarray, roots: np.ndarray, wall, period: float | None) -> tuple[np.ndarray, np.ndarray]:
    """How far points lie beyond one wall's face, seen from their character's root.

    Args:
        points: (N, P, 2) m, P floor-plane points of each of N characters.
        roots: (N, 2) m, each character's root (its side of the wall is the free one).
        wall: ((x0, y0), (x1, y1)) m, the wall's floor segment.
        period: the scene's period along x (None: not periodic). The character is taken
            into ``[0, period)`` by its root, and each point counts at its first image
            (0, +period, -period) whose foot point falls within the segment.

    Returns:
        ``(depth (N, P) m, normal (N, 2))``: depth > 0 beyond the face, -inf where no
        image of the point is beside the segment; the wall's unit normal towards each
        root's side (zeros, and depth -inf, for a degenerate segment).
    """
    points = np.asarray(points, np.float64)
    roots = np.asarray(roots, np.float64)
    (x0, y0), (x1, y1) = wall
    d = np.array([x1 - x0, y1 - y0], np.float64)
    ll = float(d @ d)
    depth = np.full(points.shape[:2], -np.inf)
    if ll < 1e-12:
        return depth, np.zeros((len(roots), 2))
    shift = -period * np.floor(roots[:, 0] / period) if period else np.zeros(len(roots))
    images = (shift, shift + period, shift - period) if period else (shift,)
    normal = np.array([-d[1], d[0]]) / np.sqrt(ll)
    side = (roots[:, 0] + shift - x0) * normal[0] + (roots[:, 1] - y0) * normal[1]
    normal = np.where(side[:, None] < 0, -normal, normal)
    todo = np.ones(depth.shape, bool)
    for sx in images:
        rel = points + np.stack([sx - x0, np.full(len(roots), -y0)], axis=1)[:, None, :]
        t = rel @ d / ll
        inside = todo & (t >= 0.0) & (t <= 1.0)
        depth = np.where(inside, -(rel * normal[:, None, :]).sum(-1), depth)
        todo &= ~inside
    return depth, normal


def _depths(verts: np.ndarray, root: np.ndarray, walls: np.ndarray, period: float | None) -> float:
    """Deepest vertex (m) of one posed body (V, 3) beyond any wall, seen from ``root`` (3,)."""
    best = 0.0
    for wall in walls:
        depth, _ = beyond_wall(verts[None, :, :2], np.asarray(root)[None, :2], wall, period)
        best = max(best, float(depth.max(initial=0.0)))
    return best


def wall_penetration(anim, *, frames: Any = None, bodies: Sequence | None = None) -> WallPenetration:
    """How deep each character's body mesh reaches through the scene's walls.

    Args:
        anim: a :class:`~crowdstudy.scene.CrowdAnimation` whose meta records its walls.
        frames: which frames (see :func:`crowdstudy.metrics.frame_indices`); None = all.
        bodies: optional per-character body objects overriding ``load_body(record)``.

    Returns:
        :class:`WallPenetration` (per character and frame, m).
    """
    if not hasattr(anim, "joint_rotations"):
        raise InvalidInputError(f"anim: expected a CrowdAnimation, got {type(anim).__name__}")
    walls = static_walls_from_meta(anim.meta)
    idx = frame_indices(frames, anim.n_frames)
    out = np.zeros((len(idx), anim.n_characters))
    if len(walls) == 0:
        return WallPenetration(per_character=out, frames=idx, n_walls=0)
    body_objs = resolve_bodies(anim, bodies)
    period = anim.periodic_length
    for i, body in enumerate(body_objs):
        verts = np.asarray(body.pose(anim.joint_rotations[idx, i], anim.root_translation[idx, i])[0], np.float64)
        for k, f in enumerate(idx):
            out[k, i] = _depths(verts[k], anim.root_translation[f, i], walls, period)
    return WallPenetration(per_character=out, frames=idx, n_walls=len(walls))

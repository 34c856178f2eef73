"""How little a correction could move the characters: an estimate of the tracking floor.

The tracking error (:func:`crowdstudy.metrics.tracking_error`) of a corrected crowd says how
far it strays from its animation; :func:`separation_floor` says how far it would have to
stray, frame by frame, only to take the characters' capsules (with the physics' mesh skin
and contact margin) apart and out of the scene's walls. Each capsule is free to translate on
its own (no joints, no rotations, no smoothness in time), and from the Baseline's pose the
overlapping pairs are pushed apart half each, all at once, until none overlaps (a Jacobi
projection, which lands close to the least displacement). The mean capsule displacement
stands for the mean joint deviation (one capsule per bone): a correction that keeps joints,
rotations and smooth motion cannot do much better, so a tracking bar below this estimate is
out of reach for any correction, and the gap above it is what the method spends.

It is an estimate, not a proof: Jacobi projection does not find the exact least
displacement, and rotating a bone can move one end less than translating it would.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdstudy.body.capsules import (
    SKIN_HAND_SCALE,
    SKIN_MAX,
    SKIN_PERCENTILE,
    capsule_skin,
    closest_points_on_segments,
)
from crowdstudy.body.skeleton import ARM_JOINTS, JOINT_INDEX
from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics.overlap import capsules_world, frame_indices, resolve_bodies
from crowdstudy.metrics.walls import beyond_wall
from crowdstudy.scene_meta import static_walls_from_meta

__all__ = ["SeparationFloor", "separation_floor"]

_ARMS = [JOINT_INDEX[name] for name in ARM_JOINTS]
_CULL = 0.3  # m: capsule pairs farther apart than this beyond touching are left out until re-checked


@dataclasses.dataclass(frozen=True)
class SeparationFloor:
    """Per-frame least displacement that separates the capsules (:func:`separation_floor`).

    Attributes:
        per_joint: (F, N, J) m, each capsule's displacement at each measured frame.
        frames: (F,) the measured frame indices.
        residual: (F,) m, the deepest overlap left when the projection stopped.
        iterations: (F,) projection rounds used.
        contact_depth: (F, N) m, how deep each character's inflated capsules reach into
            another character's in the measured (unmoved) pose, 0 where they do not touch.
        partner: (F, N) the character it reaches deepest into there, -1 where none.
    """

    per_joint: np.ndarray
    frames: np.ndarray
    residual: np.ndarray
    iterations: np.ndarray
    contact_depth: np.ndarray | None = None
    partner: np.ndarray | None = None

    @property
    def mean_cm(self) -> float:
        """Mean over frames, characters and joints, cm: compare with the tracking error."""
        return 100.0 * float(self.per_joint.mean()) if self.per_joint.size else 0.0

    @property
    def per_frame_cm(self) -> np.ndarray:
        return 100.0 * self.per_joint.mean(axis=(1, 2))

    @property
    def arms_cm(self) -> float:
        """Mean over the arm joints (collars to hands), cm."""
        return 100.0 * float(self.per_joint[..., _ARMS].mean()) if self.per_joint.size else 0.0

    @property
    def per_character_cm(self) -> np.ndarray:
        """(N,) each character's mean capsule displacement, cm."""
        return 100.0 * self.per_joint.mean(axis=(0, 2))

    def contacts_per_character(self) -> dict:
        """Whom each character touches in the measured pose: ``contact_fraction`` (N,)
        share of the measured frames it touches anyone, ``partner`` (N,) the character it
        is most often deepest into (-1: none), ``partner_fraction`` (N,) share of the frames
        that partner is the deepest, ``deepest_cm`` (N,) its deepest reach over the frames."""
        depth, partners = self.contact_depth, self.partner
        n = self.per_joint.shape[1]
        if depth is None or partners is None or not len(depth):
            return {
                "contact_fraction": np.zeros(n),
                "partner": np.full(n, -1),
                "partner_fraction": np.zeros(n),
                "deepest_cm": np.zeros(n),
            }
        touching = depth > 0
        partner = np.full(n, -1)
        share = np.zeros(n)
        for c in range(n):
            found = partners[touching[:, c], c]
            if found.size:
                ids, counts = np.unique(found, return_counts=True)
                partner[c] = int(ids[counts.argmax()])  # ties: the lowest index
                share[c] = counts.max() / len(depth)
        return {
            "contact_fraction": touching.mean(axis=0),
            "partner": partner,
            "partner_fraction": share,
            "deepest_cm": 100.0 * depth.max(axis=0),
        }

    def as_dict(self, per_character: bool = False) -> dict:
        """The estimate and its arms' share; ``per_character``: also
        ``separation_floor_per_character`` (lists: ``floor_cm`` and
        :meth:`contacts_per_character`)."""
        out = {
            "separation_floor_cm": self.mean_cm,
            "separation_floor_arms_cm": self.arms_cm,
            "separation_floor_frames": int(len(self.frames)),
            "separation_floor_residual_mm": 1000.0 * float(self.residual.max(initial=0.0)),
        }
        if per_character:
            per = {"floor_cm": self.per_character_cm.tolist()}
            per.update({k: v.tolist() for k, v in self.contacts_per_character().items()})
            out["separation_floor_per_character"] = per
        return out


def _pairs(root: np.ndarray, period: float | None, reach: float):
    """Character pairs (i < j) whose roots are within ``reach`` m (x by the minimum image in
    periodic scenes) and the x shift that brings j next to i."""
    i, j = np.triu_indices(len(root), k=1)
    d = root[j] - root[i]
    shift = np.zeros(len(i))
    if period is not None:
        shift = -period * np.round(d[:, 0] / period)
        d[:, 0] += shift
    near = np.hypot(d[:, 0], d[:, 1]) < reach
    return i[near], j[near], shift[near]


def separation_floor(
    anim,
    *,
    frames: Any = "every:30",
    bodies: Sequence | None = None,
    skin_percentile: float = SKIN_PERCENTILE,
    skin_max: float = SKIN_MAX,
    hand_skin_scale: float = SKIN_HAND_SCALE,
    margin: float = 0.005,
    walls: bool = True,
    tolerance: float = 1e-4,
    max_iterations: int = 400,
) -> SeparationFloor:
    """Estimate, frame by frame, the least joint displacement that removes every overlap.

    Args:
        anim: a :class:`~crowdstudy.scene.CrowdAnimation` (usually the Baseline).
        frames: which frames (:func:`~crowdstudy.metrics.overlap.frame_indices`; default
            every 30th: one a second at 30 fps).
        bodies: optional body objects (default ``load_body`` of ``anim.bodies``).
        skin_percentile: each capsule is inflated by how far its mesh reaches beyond it
            (:func:`crowdstudy.body.capsules.capsule_skin`, the physics' default 90),
            at most ``skin_max`` m and ``hand_skin_scale`` of it on the palm and finger
            bones (the physics' ``skin.max`` and ``skin.hand_scale`` at the dense end of its
            density profile, which a crowd as dense as concert D5 is corrected with; a
            sparser crowd's skins are thicker, ``PhysicsConfig.for_density``) ...
        margin: ... plus this many metres (the physics' ``contacts.margin``).
        walls: also push capsules back behind the scene's walls (``meta["obstacles"]``), to
            the side of their character's root, as the physics does.
        tolerance: m; the projection stops when no pair overlaps by more than this.
        max_iterations: projection rounds per frame at most.

    Returns:
        :class:`SeparationFloor`; ``mean_cm`` is the estimate to set beside the tracking.
    """
    if not hasattr(anim, "joint_rotations"):
        raise TypeError(f"anim: expected a CrowdAnimation, got {type(anim).__name__}")
    if margin < 0 or tolerance <= 0 or int(max_iterations) < 1:
        raise InvalidInputError(
            f"separation_floor: expected margin >= 0, tolerance > 0 and max_iterations >= 1, "
            f"got {margin!r}, {tolerance!r}, {max_iterations!r}"
        )
    idx = frame_indices(frames, anim.n_frames)
    body_objs = resolve_bodies(anim, bodies)
    n, n_j = anim.n_characters, anim.n_joints
    period = anim.periodic_length
    real, r = _inflated_radii(body_objs, skin_percentile, skin_max, hand_skin_scale, margin)
    segs = static_walls_from_meta(anim.meta) if walls else np.zeros((0, 2, 2))
    out = np.zeros((len(idx), n, n_j))
    residual = np.zeros(len(idx))
    rounds = np.zeros(len(idx), np.int64)
    contact = np.zeros((len(idx), n))
    partner = np.full((len(idx), n), -1, np.int64)
    for k, f in enumerate(idx):
        start, end = _frame_capsules(anim, body_objs, f)
        root = anim.root_translation[f]
        all_pairs = _capsule_pairs(root, period, real, r, n_j)
        # the projection works on the pairs near enough to meet (culled from the Baseline's
        # pose); every pair is checked again, and the set renewed, before it stops
        near, _, depth0 = _near_pairs(all_pairs, start, end, np.zeros((n, n_j, 3)))
        contact[k], partner[k] = _deepest_partner(all_pairs[0], all_pairs[1], depth0, n)
        move, deepest, rounds[k] = _project(
            near, all_pairs, start, end, r, root, segs, period, tolerance, int(max_iterations)
        )
        out[k] = np.linalg.norm(move, axis=-1)
        residual[k] = max(deepest, 0.0)
    return SeparationFloor(
        per_joint=out, frames=idx, residual=residual, iterations=rounds, contact_depth=contact, partner=partner
    )


#: Capsule pairs between characters, parallel (P,) arrays: ``(char_a, char_b, joint_a,
#: joint_b, offset (P, 3) m added to b (the periodic image), reach m (sum of the inflated
#: radii))``.
_Pairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _inflated_radii(
    body_objs: Sequence, skin_percentile: float, skin_max: float, hand_skin_scale: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """(N, J) which capsules take part (radius above 1 mm) and their radii (m) inflated by
    the mesh skin (:func:`~crowdstudy.body.capsules.capsule_skin`) and ``margin``, 0 for
    those left out."""
    radius = np.stack([np.asarray(b.capsules.radius, np.float64) for b in body_objs])
    skin = np.stack(
        [capsule_skin(b, skin_percentile, max_skin=skin_max, hand_scale=hand_skin_scale) for b in body_objs]
    )
    real = radius > 1e-3  # zero-radius capsules take no part
    return real, np.where(real, radius + skin + margin, 0.0)


def _frame_capsules(anim, body_objs: Sequence, f: int) -> tuple[np.ndarray, np.ndarray]:
    """The capsule axes' start and end points (N, J, 3) m of every character at frame ``f``."""
    n, n_j = anim.n_characters, anim.n_joints
    start = np.empty((n, n_j, 3))
    end = np.empty((n, n_j, 3))
    for c, body in enumerate(body_objs):
        s, e, _ = capsules_world(body, anim.joint_rotations[f : f + 1, c], anim.root_translation[f : f + 1, c])
        start[c], end[c] = s[0], e[0]
    return start, end


def _capsule_pairs(root: np.ndarray, period: float | None, real: np.ndarray, r: np.ndarray, n_j: int) -> _Pairs:
    """Every pair of taking-part capsules of two characters whose roots (N, 3) m are
    within 2.5 m (minimum image along x when ``period``); ``r`` (N, J) inflated radii."""
    aj, bj = (a.ravel() for a in np.meshgrid(np.arange(n_j), np.arange(n_j), indexing="ij"))
    ci, cj, shift = _pairs(root[:, :2], period, reach=2.5)
    pa_c, pb_c = np.repeat(ci, len(aj)), np.repeat(cj, len(aj))
    pa_j, pb_j = np.tile(aj, len(ci)), np.tile(bj, len(ci))
    off = np.zeros((len(pa_c), 3))
    off[:, 0] = np.repeat(shift, len(aj))
    keep = real[pa_c, pa_j] & real[pb_c, pb_j]
    pa_c, pb_c, pa_j, pb_j, off = pa_c[keep], pb_c[keep], pa_j[keep], pb_j[keep], off[keep]
    return pa_c, pb_c, pa_j, pb_j, off, r[pa_c, pa_j] + r[pb_c, pb_j]


def _project(
    near: _Pairs,
    all_pairs: _Pairs,
    start: np.ndarray,
    end: np.ndarray,
    r: np.ndarray,
    root: np.ndarray,
    segs: np.ndarray,
    period: float | None,
    tolerance: float,
    max_iterations: int,
) -> tuple[np.ndarray, float, int]:
    """Jacobi projection of one frame: every round, each overlapping pair of ``near`` is
    pushed apart half each and each capsule beyond a wall back, the pushes on a capsule
    averaged; when nothing overlaps, ``all_pairs`` are checked again (the near set renewed)
    and it stops if none overlaps by more than ``tolerance`` m. Capsules (N, J, 3) from
    ``start`` to ``end``. Returns the displacement (N, J, 3) m, the deepest overlap left
    (m) and the rounds used."""
    n, n_j = start.shape[:2]
    move = np.zeros((n, n_j, 3))
    deepest = 0.0
    rounds = 0
    for _ in range(max_iterations):
        rounds += 1
        acc = np.zeros((n, n_j, 3))
        cnt = np.zeros((n, n_j))
        hit, deepest = _push_pairs(near, start, end, move, tolerance, acc, cnt)
        wall_hit, deepest = _push_walls(segs, start + move, end + move, r, root, period, tolerance, acc, cnt, deepest)
        if not hit and not wall_hit:
            near, worst, _ = _near_pairs(all_pairs, start, end, move)
            if worst <= tolerance:
                break
            continue  # a culled pair met: go on with the renewed set
        move += acc / np.maximum(cnt, 1.0)[..., None]
    return move, deepest, rounds


def _push_pairs(
    pairs: _Pairs,
    start: np.ndarray,
    end: np.ndarray,
    move: np.ndarray,
    tolerance: float,
    acc: np.ndarray,
    cnt: np.ndarray,
) -> tuple[bool, float]:
    """Add to ``acc`` (N, J, 3) the half-depth pushes (m) apart of the ``pairs`` overlapping
    by more than ``tolerance`` m with the capsules moved by ``move``, and count them in
    ``cnt`` (N, J); returns whether any did and the deepest overlap (m, 0 when none)."""
    pa_c, pb_c, pa_j, pb_j, off, reach = pairs
    a0, a1 = start[pa_c, pa_j] + move[pa_c, pa_j], end[pa_c, pa_j] + move[pa_c, pa_j]
    b0, b1 = start[pb_c, pb_j] + move[pb_c, pb_j] + off, end[pb_c, pb_j] + move[pb_c, pb_j] + off
    s, t, dist = closest_points_on_segments(a0, a1, b0, b1)
    depth = reach - dist
    hit = depth > tolerance
    if hit.any():
        pa = a0[hit] + s[hit, None] * (a1[hit] - a0[hit])
        pb = b0[hit] + t[hit, None] * (b1[hit] - b0[hit])
        normal = _unit(pa - pb)
        push = 0.5 * depth[hit, None] * normal
        np.add.at(acc, (pa_c[hit], pa_j[hit]), push)
        np.add.at(cnt, (pa_c[hit], pa_j[hit]), 1.0)
        np.add.at(acc, (pb_c[hit], pb_j[hit]), -push)
        np.add.at(cnt, (pb_c[hit], pb_j[hit]), 1.0)
    return bool(hit.any()), float(depth.max(initial=0.0))


def _push_walls(
    segs: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    r: np.ndarray,
    root: np.ndarray,
    period: float | None,
    tolerance: float,
    acc: np.ndarray,
    cnt: np.ndarray,
    deepest: float,
) -> tuple[bool, float]:
    """Add to ``acc`` (N, J, 3) the pushes (m) back behind each wall of ``segs`` (W, 2, 2)
    of the capsules (N, J, 3) from ``start`` to ``end`` reaching beyond it by more than
    ``tolerance`` m, towards their root's side, and count them in ``cnt`` (N, J); returns
    whether any did and ``deepest`` raised to the deepest reach (m)."""
    wall_hit = False
    for wall in segs:
        depth_w, normal = _wall_depth(start, end, r, root, wall, period)
        over = depth_w > tolerance
        if over.any():
            wall_hit = True
            deepest = max(deepest, float(depth_w.max()))
            push = np.zeros((len(root), 1, 3))
            push[:, 0, :2] = normal  # towards the root's side
            acc += np.where(over, depth_w, 0.0)[..., None] * push
            cnt += over
    return wall_hit, deepest


def _near_pairs(pairs: _Pairs, start, end, move) -> tuple[_Pairs, float, np.ndarray]:
    """The capsule pairs within ``_CULL`` of touching with the capsules moved by ``move``,
    the deepest overlap (m) over all ``pairs`` (char_a, char_b, joint_a, joint_b, x offset
    of b, reach), and every pair's depth (m, negative: apart)."""
    ac, bc, aj, bj, off, reach = pairs
    _, _, dist = closest_points_on_segments(
        start[ac, aj] + move[ac, aj],
        end[ac, aj] + move[ac, aj],
        start[bc, bj] + move[bc, bj] + off,
        end[bc, bj] + move[bc, bj] + off,
    )
    depth = reach - dist
    near = depth > -_CULL
    kept: _Pairs = (ac[near], bc[near], aj[near], bj[near], off[near], reach[near])
    return kept, float(depth.max(initial=0.0)), depth


def _deepest_partner(char_a: np.ndarray, char_b: np.ndarray, depth: np.ndarray, n: int):
    """(N,) each character's deepest overlap (m, 0 if none) over the capsule pairs
    (``char_a[p]``, ``char_b[p]``, ``depth[p]``) and (N,) whom it is with (-1: none)."""
    deepest = np.zeros(n)
    partner = np.full(n, -1, np.int64)
    mine = np.concatenate([char_a, char_b])
    other = np.concatenate([char_b, char_a])
    both = np.concatenate([depth, depth])
    touch = both > 0
    mine, other, both = mine[touch], other[touch], both[touch]
    order = np.lexsort((both, mine))  # by character, then depth
    mine, other, both = mine[order], other[order], both[order]
    last = np.flatnonzero(np.r_[mine[1:] != mine[:-1], True]) if len(mine) else np.zeros(0, np.int64)
    deepest[mine[last]] = both[last]
    partner[mine[last]] = other[last]
    return deepest, partner


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    fallback = np.zeros_like(v)
    fallback[..., 2] = 1.0  # coincident axes: part them vertically
    return np.where(norm > 1e-9, v / np.maximum(norm, 1e-12), fallback)


def _wall_depth(start, end, r, root, wall, period):
    """(N, J) m: how far each capsule (its deeper end sphere, radius ``r``) reaches beyond the
    wall's face from its root's side (:func:`crowdstudy.metrics.walls.beyond_wall`), and the
    wall's normal (N, 2) towards each root."""
    best = np.full(r.shape, -np.inf)
    for ends in (start, end):
        depth, normal = beyond_wall(ends[..., :2], root[:, :2], wall, period)
        best = np.maximum(best, np.where(r > 0, r + depth, -np.inf))
    return best, normal

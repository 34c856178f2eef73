"""Clothes and hair with volume: the painted texture decides, the geometry follows.

The albedo painter (``paint.frag``) writes into each texel's alpha what it shows (skin,
hair, shirt, trousers, shoes, eye: :data:`CODES`). :func:`surface_codes` reads that back at
every vertex of the body, and :func:`dress_body` moves the rest surface to match, for
rendering only (the physics keeps the bare body's capsules; cloth adds a few millimetres):

* under a shirt or trousers the body is smoothed (Taubin, volume-preserving; the moves
  along the normal only, so the texture does not slide), so no anatomy shows through the
  fabric, and lifted :data:`CLOTH_LIFT` m along its normal;
* shoes: the toes are smoothed into one shoe shape and lifted :data:`SHOE_LIFT` m;
* hair: the scalp is lifted by the style's volume, the lift tapering to zero across the
  hairline over a few vertex rings, so hair reads as a mass, not as paint.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.render.bodies import vertex_normals
from crowdstudy.render.hands import relax_hands

__all__ = ["CODES", "CLOTH_LIFT", "SHOE_LIFT", "surface_codes", "vertex_codes", "dress_body", "neighbours"]

#: alpha code (round(alpha / 255 * 10)) -> what the texel shows
CODES = {10: "skin", 9: "hair", 8: "shirt", 7: "trousers", 6: "shoes", 5: "eye"}
_PRIORITY = {"hair": 5, "shoes": 4, "trousers": 3, "shirt": 2, "skin": 1, "eye": 0}
CLOTH_LIFT = 0.004  # m, fabric over the skin
SHOE_LIFT = 0.006  # m
_SMOOTH_CLOTH = 12  # Taubin rounds under clothes
_SMOOTH_SHOES = 6  # rounds of spatial averaging that fuse the toes into a shoe tip
_TOE_RADIUS = 0.015  # m
_TAPER = 3  # rings over which the dressing fades in across a garment's edge


def surface_codes(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(R,) uint8 code of each render vertex: the alpha of the painted ``image`` (H, W, 4,
    bottom row first, as OpenGL reads it) at its texture coordinate ``uv`` (R, 2)."""
    h, w = image.shape[:2]
    col = np.clip((np.asarray(uv)[:, 0] * w).astype(np.int64), 0, w - 1)
    row = np.clip((np.asarray(uv)[:, 1] * h).astype(np.int64), 0, h - 1)
    return np.rint(image[row, col, 3].astype(np.float64) / 255.0 * 10.0).astype(np.uint8)


def vertex_codes(body, render_codes: np.ndarray) -> list[str]:
    """Per body vertex: the highest-priority code of its render copies (hair over shoes
    over trousers over shirt over skin)."""
    surface = body.surface
    names = [CODES.get(c, "skin") for c in range(11)]
    rank = np.array([_PRIORITY[n] for n in names])
    best = np.zeros(len(body.rest_vertices), dtype=np.int64)
    np.maximum.at(best, np.asarray(surface.vertex, dtype=np.int64), rank[np.asarray(render_codes, dtype=np.int64)])
    by_rank = {v: k for k, v in _PRIORITY.items()}
    return [by_rank[int(r)] for r in best]


_ADJACENCY: dict = {}


def neighbours(faces: np.ndarray, n_vertices: int):
    """Sparse (V, V) row-normalised adjacency of a triangle mesh (uniform Laplacian weights);
    memoised per topology (every body of a template shares it)."""
    from scipy.sparse import coo_matrix, diags

    f = np.asarray(faces, dtype=np.int64)
    key = (hashlib.sha1(f.tobytes()).hexdigest(), int(n_vertices))
    if key in _ADJACENCY:
        return _ADJACENCY[key]
    rows = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    cols = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    adj = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices)).tocsr()
    adj.data[:] = 1.0
    deg = np.asarray(adj.sum(axis=1)).ravel()
    _ADJACENCY[key] = (diags(1.0 / np.maximum(deg, 1.0)) @ adj).tocsr()
    return _ADJACENCY[key]


def _taubin(points: np.ndarray, avg, mask: np.ndarray, rounds: int, factors=(0.5, -0.53)) -> np.ndarray:
    """Smooth the ``mask`` vertices: Taubin's lambda/mu rounds keep the volume; ``factors``
    (0.6,) is plain Laplacian smoothing, which shrink-wraps (toes into one shoe)."""
    out = points.copy()
    for _ in range(rounds):
        for factor in factors:
            out[mask] += factor * ((avg @ out)[mask] - out[mask])
    return out


_FUSE: dict = {}


def _fuse(points: np.ndarray, mask: np.ndarray, radius: float, rounds: int) -> np.ndarray:
    """Average the ``mask`` vertices over their spatial neighbours within ``radius`` m
    (neighbouring toes included, which mesh smoothing would not reach): toes fuse into
    one rounded shoe tip. The neighbour lists are memoised per mask (bodies of one
    template share their toes' layout)."""
    from scipy.sparse import coo_matrix, diags
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return points
    # the neighbour lists depend on where the points are, not only on which: keyed on both,
    # so a render never depends on the bodies a process dressed before
    where = np.ascontiguousarray(points[idx], dtype=np.float64)
    key = (hashlib.sha1(idx.tobytes() + where.tobytes()).hexdigest(), float(radius))
    if key not in _FUSE:
        if len(_FUSE) > 64:
            _FUSE.clear()
        pairs = cKDTree(points[idx]).query_ball_point(points[idx], radius)
        rows = np.repeat(np.arange(len(idx)), [len(p) for p in pairs])
        cols = np.concatenate([np.asarray(p, dtype=np.int64) for p in pairs])
        mat = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(idx), len(idx))).tocsr()
        _FUSE[key] = (diags(1.0 / np.asarray(mat.sum(axis=1)).ravel()) @ mat).tocsr()
    mat = _FUSE[key]
    out = points.copy()
    sub = out[idx]
    for _ in range(rounds):
        sub = mat @ sub
    out[idx] = sub
    return out


def _ramp(mask: np.ndarray, avg, used: np.ndarray, rounds: int = _TAPER) -> np.ndarray:
    """A 0/1 vertex ``mask`` as a smooth 0..1 weight: averaged over the mesh ``rounds``
    times (about one vertex ring each), so a garment's edge is a gentle ramp across a few
    rings rather than a step along the mesh's edges (a jagged hem in the geometry)."""
    w = mask.astype(np.float64)
    for _ in range(rounds):
        w = np.where(used, avg @ w, w)
    return np.clip(w, 0.0, 1.0)


def dress_body(body, render_codes: np.ndarray, hair_volume: float):
    """A copy of ``body`` (a Body with a surface) whose rest vertices carry its clothes and
    hair (see the module docstring); ``hair_volume`` m, the scalp's lift under the hair.
    The fingers take a relaxed pose (:func:`crowdstudy.render.hands.relax_hands`).

    Under cloth the body is smoothed along its normals only (the surface does not slide
    under its texture), by a weight that ramps smoothly across the garment's edge, so the
    dressed surface has no step along the mesh's edges at a hem, a cuff or a neckline."""
    if body.surface is None:
        raise InvalidInputError("dress_body: the body has no textured surface")
    if not 0.0 <= float(hair_volume) <= 0.05:
        raise InvalidInputError(f"hair_volume: expected 0 to 0.05 m, got {hair_volume!r}")
    codes = np.array(vertex_codes(body, render_codes))
    verts = relax_hands(body.rest_vertices, np.asarray(body.rest_joints, dtype=np.float64), body.weights)
    faces = np.asarray(body.faces, dtype=np.int64)
    avg = neighbours(faces, len(verts))
    used = np.zeros(len(verts), bool)
    used[np.unique(faces)] = True
    cloth = np.isin(codes, ("shirt", "trousers")) & used
    shoes = (codes == "shoes") & used
    hair = (codes == "hair") & used
    normals = vertex_normals(verts, faces)
    # cloth: the smoothed body's offset along the normal, faded in across the garment's edge
    smooth = _taubin(verts, avg, used, _SMOOTH_CLOTH)
    w_cloth = _ramp(cloth, avg, used)
    out = verts + normals * (w_cloth * np.einsum("vk,vk->v", smooth - verts, normals))[:, None]
    # shoes: the toes fused into one shoe tip, then smoothed (these moves are tangential too)
    toes = shoes & (np.asarray(body.weights)[:, [10, 11]].sum(axis=1) > 0.3)
    shod = _taubin(_fuse(out, toes, _TOE_RADIUS, _SMOOTH_SHOES), avg, shoes, 4)
    w_shoes = _ramp(shoes, avg, used)
    out = out + w_shoes[:, None] * (shod - out)
    lift = CLOTH_LIFT * w_cloth + SHOE_LIFT * w_shoes + float(hair_volume) * _ramp(hair, avg, used)
    out = out + vertex_normals(out, faces) * lift[:, None]
    return dataclasses.replace(body, rest_vertices=out, _cache={})

"""Hair with volume: a shell fitted over the scalp of a MakeHuman head, one of a few styles.

The painter colours the scalp (``paint.frag``: the hairline, strands); on its own that reads
as a painted cap. :func:`hair_mesh` builds a sheet of hair standing off the scalp, in a
spherical grid about the skull's centre: each grid direction takes the scalp's radius there
(the farthest head vertex within a few degrees) plus the style's volume, the volume fading
to nothing at the hairline so the sheet meets the painted hair on the scalp without a step.
Below the skull's equator the sheet of a bob or of long hair falls straight down (its own
weight), flaring a little; a ponytail is a tapered tube from the back of the head, a bun a
flattened ball on the crown (every style has the same topology: the characters with hair
share one template group). The sheet is two-sided (an outer layer wound outwards, an
inner one 3 mm under it wound inwards), as the characters are drawn with back faces culled.

Styles (:data:`STYLES`): ``"none"`` (the painted scalp alone: shaved, cropped and bald
heads), ``"short"``, ``"bob"``, ``"long"``, ``"ponytail"``, ``"bun"``. :func:`add_hair`
appends the sheet to a body for rendering only: its vertices are weighted to the head joint
alone (so they move with the head), and take their colour from one texel of the painted
scalp (the crown: hair in every style), so the hair has the character's hair colour and is
lit as hair (the material channel, see ``character.frag``).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX as J
from crowdstudy.errors import InvalidInputError

__all__ = ["STYLES", "Style", "hair_mesh", "add_hair", "crown_uv"]

Style = Literal["none", "short", "bob", "long", "ponytail", "bun"]
STYLES: tuple[str, ...] = ("none", "short", "bob", "long", "ponytail", "bun")

#: per style: (hairline polar angle (deg from the crown) at the front, the sides, the back;
#: drop (m) below the skull's equator at the sides, the back; volume (m) at the crown)
_SHAPES = {
    "short": ((62.0, 84.0, 104.0), (0.0, 0.0), 0.012),
    "bob": ((56.0, 90.0, 90.0), (0.085, 0.095), 0.016),
    "long": ((56.0, 90.0, 90.0), (0.24, 0.30), 0.018),
    "ponytail": ((60.0, 86.0, 104.0), (0.0, 0.0), 0.007),
    "bun": ((60.0, 86.0, 104.0), (0.0, 0.0), 0.007),
}
_COLUMNS, _ROWS = 24, 14
_THICKNESS = 0.003  # m between the sheet's outer and inner layers


def _directions(polar: np.ndarray | float, azimuth: np.ndarray | float) -> np.ndarray:
    """Unit vectors at ``polar`` (from +z) and ``azimuth`` (from +y, the face, towards +x)."""
    s = np.sin(polar)
    return np.stack([s * np.sin(azimuth), s * np.cos(azimuth), np.cos(polar)], axis=-1)


def _scalp_radius(head: np.ndarray, centre: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(...,) distance from ``centre`` to the head's surface along each of ``dirs`` (..., 3)."""
    rel = head - centre
    dist = np.linalg.norm(rel, axis=1)
    unit = rel / dist[:, None]
    flat = dirs.reshape(-1, 3)
    cos = flat @ unit.T  # (D, V)
    near = cos > np.cos(np.radians(9.0))
    r = np.where(near, flat @ rel.T, -np.inf).max(axis=1)
    fallback = np.where(cos > np.cos(np.radians(25.0)), flat @ rel.T, -np.inf).max(axis=1)
    r = np.where(np.isfinite(r), r, fallback)
    return r.reshape(dirs.shape[:-1])


def _grid(shape, head, centre, equator_r):
    """(ROWS, COLUMNS, 3) outer sheet points and the volume's fade (ROWS, COLUMNS)."""
    (front, side, back), (drop_side, drop_back), volume = shape
    az = 2.0 * np.pi * np.arange(_COLUMNS) / _COLUMNS
    c = np.cos(az)  # 1 at the face, -1 at the back
    to_front, to_back = np.clip(c, 0, 1) ** 2, np.clip(-c, 0, 1) ** 2
    edge = np.radians(side + (front - side) * to_front + (back - side) * to_back)
    drop = drop_side * (1 - to_front - to_back) + drop_back * to_back
    drop = drop * np.clip((0.55 - c) / 0.35, 0.0, 1.0) ** 2  # nothing falls over the face
    # each column: the arc over the skull to min(edge, 90 deg), then the drop straight down
    arc = np.where(drop > 0, np.minimum(edge, np.pi / 2), edge)
    length = arc * equator_r + drop
    # m along each column: 60 % of the rows over the skull, the rest down the fall
    u = np.linspace(0.0, 1.0, _ROWS)[:, None]
    over = arc * equator_r
    t = np.where(drop[None] > 0, np.where(u < 0.6, over * u / 0.6, over + drop * (u - 0.6) / 0.4), length * u)
    polar = np.minimum(t / equator_r, arc[None])
    polar = np.maximum(polar, np.radians(4.0))
    below = np.maximum(t - arc[None] * equator_r, 0.0)
    dirs = _directions(polar, np.broadcast_to(az, polar.shape))
    r = _scalp_radius(head, centre, dirs)
    fade = np.clip((length[None] - t) / 0.05, 0.0, 1.0)  # the last 5 cm: down to the scalp
    fade = np.where(drop[None] > 0, np.maximum(fade, np.clip(below / 0.02, 0, 1)), fade)
    lift = volume * (0.35 + 0.65 * np.cos(np.minimum(polar, np.pi / 2))) * fade + 0.002
    points = centre + dirs * (r + lift)[..., None]
    # the falling part: straight down from the equator, flaring out by 10 % of its length
    horiz = np.stack([np.sin(az), np.cos(az), np.zeros_like(az)], axis=-1)
    fall = below > 0
    eq = centre + horiz * (_scalp_radius(head, centre, _directions(np.full_like(az, np.pi / 2), az)) + volume)[:, None]
    hang = eq[None] + horiz[None] * (0.1 * below)[..., None] - np.array([0.0, 0.0, 1.0]) * below[..., None]
    points = np.where(fall[..., None], hang, points)
    return points


def _sheet_faces(rows: int, cols: int, first: int = 0) -> np.ndarray:
    """(T, 3) faces of a ``rows`` x ``cols`` grid closed around its columns, wound outwards
    for a grid whose rows run from the crown down and columns anticlockwise seen from above."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols), indexing="ij")
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    d = (r + 1) * cols + c
    e = (r + 1) * cols + (c + 1) % cols
    return first + np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([b, e, d], -1).reshape(-1, 3)])


def _tube(start: np.ndarray, end: np.ndarray, r0: float, r1: float, sides: int = 10, rings: int = 8):
    """(points, faces) of a closed tapered tube (a ponytail) from ``start`` to ``end``."""
    axis = end - start
    w = axis / np.linalg.norm(axis)
    u = np.cross(w, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    t = np.linspace(0.0, 1.0, rings)
    radius = r0 + (r1 - r0) * t
    radius[0] *= 0.6
    a = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(a)[:, None] * u + np.sin(a)[:, None] * v
    pts = start + t[:, None, None] * axis + radius[:, None, None] * ring[None]
    pts = np.concatenate([pts.reshape(-1, 3), [end + 0.3 * r1 * w]])
    faces = _sheet_faces(rings, sides)
    tip = len(pts) - 1
    last = (rings - 1) * sides + np.arange(sides)
    cap = np.stack([last, np.roll(last, -1), np.full(sides, tip)], -1)
    return pts, np.concatenate([faces, cap])


def _ball(centre: np.ndarray, radii: np.ndarray, n: int = 8):
    """(points, faces) of a closed ellipsoid (a bun), wound outwards."""
    polar = np.linspace(0.0, np.pi, n + 1)[1:-1]
    az = 2 * np.pi * np.arange(2 * n) / (2 * n)
    p, a = np.meshgrid(polar, az, indexing="ij")
    pts = centre + _directions(p, a).reshape(-1, 3) * radii
    cols = 2 * n
    body = _sheet_faces(len(polar), cols)
    top, bottom = len(pts), len(pts) + 1
    pts = np.concatenate([pts, [centre + [0, 0, radii[2]], centre - [0, 0, radii[2]]]])
    ring0, ringn = np.arange(cols), (len(polar) - 1) * cols + np.arange(cols)
    caps = [
        np.stack([np.full(cols, top), np.roll(ring0, -1), ring0], -1),
        np.stack([np.full(cols, bottom), ringn, np.roll(ringn, -1)], -1),
    ]
    return pts, np.concatenate([body, *caps])


def hair_mesh(head: np.ndarray, joints: np.ndarray, style: Style) -> tuple[np.ndarray, np.ndarray]:
    """(points (H, 3) m, faces (T, 3)) of a style's hair over a head.

    Args:
        head: (V, 3) rest positions (m) of the head's vertices (skull, face, ears; T-pose,
            +y forward).
        joints: (24, 3) rest joints.
        style: one of :data:`STYLES` ("none": no points, no faces).
    """
    if style not in STYLES:
        raise InvalidInputError(f"style: expected one of {', '.join(STYLES)}, got {style!r}")
    if style == "none":
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    head = np.asarray(head, dtype=np.float64)
    lo, hi = head.min(axis=0), head.max(axis=0)
    centre = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] - 0.5 * (hi[0] - lo[0])])
    equator_r = 0.5 * (hi[0] - lo[0])
    outer = _grid(_SHAPES[style], head, centre, equator_r).reshape(-1, 3)
    normal = outer - centre
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    inner = outer - _THICKNESS * normal
    faces = _sheet_faces(_ROWS, _COLUMNS)
    n = len(outer)
    # a cap over the crown's opening (row 0 is a small ring around the pole)
    pole = np.array([[outer[:_COLUMNS].mean(axis=0)[0], outer[:_COLUMNS].mean(axis=0)[1], outer[:, 2].max() + 0.001]])
    ring = np.arange(_COLUMNS)
    cap = np.stack([np.full(_COLUMNS, 2 * n), np.roll(ring, -1), ring], -1)
    points = [outer, inner, pole]
    all_faces = [faces, faces[:, [0, 2, 1]] + n, cap]
    # every style has the same topology (sheet, ponytail, bun), so the characters with hair
    # share one template group (one decimation per level of detail, one draw): a style
    # without a ponytail or a bun has those collapsed to a point on its sheet (no area)
    root = centre + np.array([0.0, -1.0, -0.15]) / np.linalg.norm([0.0, -1.0, -0.15]) * (equator_r + 0.01)
    tail = _tube(root, root + np.array([0.0, -0.05, -0.22]), 0.028, 0.012)
    at = centre + _directions(np.radians(50.0), np.pi) * (equator_r + 0.02)
    bun = _ball(at, np.array([0.042, 0.035, 0.036]))
    anchor = outer[np.argmin(np.linalg.norm(outer - root, axis=1))]
    offset = 2 * n + 1
    for extra, used in ((tail, style == "ponytail"), (bun, style == "bun")):
        points.append(extra[0] if used else np.broadcast_to(anchor, extra[0].shape))
        all_faces.append(extra[1] + offset)
        offset += len(extra[0])
    return np.concatenate(points), np.concatenate(all_faces).astype(np.int64)


def add_hair(body, style: Style, crown_uv) -> object:
    """A copy of ``body`` (a Body with a surface) with the hair of ``style`` appended to its
    rest mesh and render surface, weighted to the head joint alone; ``crown_uv`` (2,) the
    texture coordinate its vertices take (a texel of painted hair). The body's closed
    ``faces`` (what the metrics and the physics read) are unchanged."""
    from crowdstudy.body.model import Surface

    if body.surface is None:
        raise InvalidInputError("add_hair: the body has no textured surface")
    verts = np.asarray(body.rest_vertices, dtype=np.float64)
    w = np.asarray(body.weights)
    headish = (w[:, J["head"]] > 0.5) & (np.arange(len(verts)) < _n_skin(body))
    points, faces = hair_mesh(verts[headish], np.asarray(body.rest_joints), style)
    if not len(points):
        return body
    n_v, surf = len(verts), body.surface
    weights = np.zeros((len(points), w.shape[1]), dtype=w.dtype)
    weights[:, J["head"]] = 1.0
    r0 = len(surf.vertex)
    surface = Surface(
        vertex=np.concatenate([surf.vertex, n_v + np.arange(len(points))]).astype(surf.vertex.dtype),
        uv=np.concatenate([surf.uv, np.tile(np.asarray(crown_uv, dtype=surf.uv.dtype), (len(points), 1))]),
        faces=np.concatenate([surf.faces, faces + r0]).astype(surf.faces.dtype),
        part=np.concatenate([surf.part, np.zeros(len(points), surf.part.dtype)]),
    )
    return dataclasses.replace(
        body,
        rest_vertices=np.concatenate([verts, points]),
        weights=np.concatenate([w, weights]),
        surface=surface,
        _cache={},
    )


def crown_uv(body) -> np.ndarray:
    """(2,) texture coordinate of the top of the head (painted hair in every style but bald)."""
    verts = np.asarray(body.rest_vertices)
    vertex = np.asarray(body.surface.vertex)
    skin = vertex < _n_skin(body)
    top = np.argmax(np.where(skin, verts[vertex, 2], -np.inf))
    return np.asarray(body.surface.uv[top], dtype=np.float64)


def _n_skin(body) -> int:
    """Body vertices before the eyes (the skin; MakeHuman stores the eyeballs last)."""
    eye = np.asarray(body.surface.vertex)[np.asarray(body.surface.part) == 1]
    return int(eye.min()) if len(eye) else len(body.rest_vertices)

"""The concert venue around the study's crowd area: a hall, a stage with lights, and a
surrounding audience of low-detail people (decimated MakeHuman bodies,
:mod:`crowdstudy.render.figures`).

Everything is static world-space geometry in the row layout of
:mod:`crowdstudy.render.scene` (``x y z nx ny nz r g b pattern``, linear RGB). The
pattern channel selects the shading in ``shaders/static.*``: 0 lit, 1 floor tiles,
2 emissive (lamp lenses, the LED wall, exit signs: unlit), and 3 + phase (phase in
[0, 1)) a figure of the surrounding audience that bobs on the beat (``static.vert``
lifts its vertices by up to :data:`BOB_AMPLITUDE` times their height fraction, so feet
stay on the floor).

The audience stands outside a keep-out rectangle around the crowd area (the area grown
by :data:`KEEP_OUT` metres: the study's characters, arms included, never reach it), in a
jittered grid drawn from a seeded generator, so the same design gives the same venue.
Figures and stage elements are *cut-away elements*: each comes with its bounding box, and
the renderer leaves out those that stand between the camera and the crowd area, or too
close to the camera (see :func:`occluding`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from crowdstudy.render.palette import srgb_to_linear

__all__ = [
    "Elements",
    "audience",
    "stage",
    "hall",
    "occluding",
    "visible_indices",
    "KEEP_OUT",
    "BOB_AMPLITUDE",
    "PATTERN_EMISSIVE",
    "PATTERN_FIGURE",
]

#: metres added to each side of the crowd area that no audience figure enters (the D5
#: concert's dancers reach 0.58 m beyond the 3 m x 3 m area with their hands)
KEEP_OUT = 0.8
#: vertical bounce of the audience figures at the top of the head (m)
BOB_AMPLITUDE = 0.035
PATTERN_EMISSIVE = 2.0
PATTERN_FIGURE = 3.0


@dataclasses.dataclass
class Elements:
    """Indexed triangles of separately cut-away elements.

    Attributes:
        vertices: (V, 10) float32 rows (see the module doc), element by element.
        indices: (3T,) uint32 triangle corners, rows of ``vertices``, element by element.
        first: (E,) int, first entry of each element in ``indices``.
        count: (E,) int, entries of each element in ``indices``.
        lo, hi: (E, 3) float64 bounding box corners of each element (m).
    """

    vertices: np.ndarray
    indices: np.ndarray
    first: np.ndarray
    count: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @staticmethod
    def join(parts: list) -> Elements:
        """Elements from a list of per-element meshes: (V, 10) rows, 3 per triangle, or a
        ``(rows, faces)`` pair with (T, 3) corner indices into the rows."""
        verts, faces = [], []
        for p in parts:
            rows, f = p if isinstance(p, tuple) else (p, np.arange(len(p)).reshape(-1, 3))
            if len(f):
                verts.append(np.asarray(rows, dtype=np.float32))
                faces.append(np.asarray(f, dtype=np.int64).reshape(-1))
        if not verts:
            z = np.zeros((0, 3))
            return Elements(
                np.zeros((0, 10), np.float32), np.zeros(0, np.uint32), np.zeros(0, int), np.zeros(0, int), z, z.copy()
            )
        offset = np.concatenate([[0], np.cumsum([len(v) for v in verts])[:-1]])
        count = np.array([len(f) for f in faces])
        first = np.concatenate([[0], np.cumsum(count)[:-1]])
        lo = np.array([v[:, :3].min(axis=0) for v in verts], dtype=np.float64)
        hi = np.array([v[:, :3].max(axis=0) for v in verts], dtype=np.float64)
        indices = np.concatenate([f + o for f, o in zip(faces, offset, strict=True)]).astype(np.uint32)
        return Elements(np.concatenate(verts), indices, first, count, lo, hi)

    @staticmethod
    def concat(groups: list[Elements]) -> Elements:
        """The elements of several groups, in order."""
        parts = []
        for g in groups:
            for a, n in zip(g.first, g.count, strict=True):
                idx = g.indices[a : a + n].astype(np.int64)
                used, local = np.unique(idx, return_inverse=True)
                parts.append((g.vertices[used], local.reshape(-1, 3)))
        return Elements.join(parts)

    def __len__(self) -> int:
        return len(self.count)

    def triangles(self) -> np.ndarray:
        """(3T, 10) rows, three per triangle (unindexed), every element."""
        return self.vertices[self.indices]


def _tris(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3, 3) triangles -> (3T, 3) points and their flat (3T, 3) unit normals."""
    n = np.cross(points[:, 1] - points[:, 0], points[:, 2] - points[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return points.reshape(-1, 3), np.repeat(n, 3, axis=0)


def _rows(points, normals, colors, pattern) -> np.ndarray:
    out = np.zeros((len(points), 10), dtype=np.float32)
    out[:, :3], out[:, 3:6], out[:, 6:9], out[:, 9] = points, normals, colors, pattern
    return out


_SHIRTS = (
    (24, 24, 28),
    (40, 40, 46),
    (18, 18, 20),
    (70, 30, 34),
    (30, 44, 80),
    (60, 62, 70),
    (84, 80, 76),
    (40, 66, 52),
    (96, 54, 38),
    (64, 40, 76),
    (104, 96, 82),
    (28, 52, 70),
)
_TROUSERS = ((22, 24, 32), (34, 44, 66), (28, 28, 30), (56, 56, 60), (70, 62, 48), (40, 52, 78))
_SKIN = ((190, 156, 134), (170, 130, 102), (144, 104, 78), (116, 80, 58), (90, 62, 44), (70, 48, 34))
_HAIR = ((22, 18, 16), (44, 32, 24), (78, 56, 36), (130, 100, 64), (110, 110, 110))


_SHOES = ((20, 20, 22), (40, 38, 38), (200, 200, 196), (70, 52, 40))
_POSES = ("none", "one", "both")


def _figure(pose: int, detail: int, sex: int):
    """A figure template (:func:`crowdstudy.render.figures.figure_template`)."""
    from crowdstudy.render.figures import figure_template

    return figure_template(_POSES[pose], detail, ("female", "male")[sex])


def audience(
    area: tuple[float, float],
    hall: tuple[float, float, float, float],
    seed: int,
    *,
    spacing: tuple[float, float] = (0.62, 0.78),
    near: float = 4.0,
    stage_y: float | None = None,
) -> Elements:
    """Low-detail standing figures filling the hall floor around the crowd area.

    Args:
        area: (width along x, depth along y) of the crowd area centred on the origin (m).
        hall: (x0, y0, x1, y1) floor rectangle the figures stand in (m).
        seed: seed of positions, statures, poses and colours.
        spacing: grid spacing (m) within ``near`` metres of the keep-out rectangle (the
            more detailed figures) and beyond; density about 1 / spacing**2 per m^2.
        stage_y: no figure stands beyond this y (the barrier in front of the stage), or None.
    Returns:
        one element per figure; no figure's footprint enters the area grown by
        :data:`KEEP_OUT` on every side.
    """
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = hall
    if stage_y is not None:
        y1 = min(y1, stage_y)
    radius = 0.3  # m, about a figure's footprint around its centre (checked exactly below)
    limit = np.array(area, dtype=np.float64) / 2 + KEEP_OUT
    half = limit + radius
    pos, detail = [], []
    for level, step in enumerate(spacing):
        gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
        p = np.c_[gx.ravel(), gy.ravel()] + rng.uniform(-0.4, 0.4, (gx.size, 2)) * step
        gap = np.linalg.norm(np.maximum(np.abs(p) - half, 0.0), axis=1)  # distance to the keep-out rectangle
        band = (gap > 0) & (gap < near) if level == 0 else gap >= near
        pos.append(p[band])
        detail.append(np.full(int(band.sum()), 1 - level))
    pos, detail = np.concatenate(pos), np.concatenate(detail)
    # no two figures closer than 0.36 m (the grid's jitter would let some stand inside each other)
    d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    crowded = np.triu(d < 0.36, k=1)
    drop = np.zeros(len(pos), bool)
    for i, j in zip(*np.nonzero(crowded), strict=True):
        if not drop[i]:
            drop[j] = True
    pos, detail = pos[~drop], detail[~drop]
    inside = (
        (pos[:, 0] > x0 + radius) & (pos[:, 0] < x1 - radius) & (pos[:, 1] > y0 + radius) & (pos[:, 1] < y1 - radius)
    )
    pos, detail = pos[inside], detail[inside]
    n = len(pos)
    stature = np.clip(rng.normal(1.72, 0.08, n), 1.5, 1.95)
    girth = rng.uniform(0.9, 1.15, n)
    yaw = np.radians(90.0 + rng.normal(0.0, 18.0, n))  # facing +y (the stage), x along the shoulders
    pose = rng.choice(3, n, p=(0.86, 0.11, 0.03)) * detail  # arms down, one or both raised (near figures)
    phase = rng.uniform(0.0, 0.999, n)
    cols = [srgb_to_linear(np.array(p)[rng.integers(len(p), size=n)]) for p in (_TROUSERS, _SHIRTS, _SKIN, _HAIR)]
    cols.append(srgb_to_linear(np.array(_SHOES)[rng.integers(len(_SHOES), size=n)]))
    sex = rng.integers(2, size=n)
    palette = np.stack(cols, axis=1)  # (n, 5 parts: figures.PARTS, 3)
    out = []
    for i in range(n):
        pts, nrm, faces, ids = _figure(int(pose[i]), int(detail[i]), int(sex[i]))
        c, s = math.cos(yaw[i] - math.pi / 2), math.sin(yaw[i] - math.pi / 2)
        rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # row vectors: p @ rot
        scale = np.array([girth[i], girth[i], 1.0]) * stature[i]
        world = (pts * scale) @ rot + np.array([pos[i, 0], pos[i, 1], 0.0])
        normal = (nrm / scale) @ rot
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        lo, hi = world[:, :2].min(axis=0), world[:, :2].max(axis=0)
        if np.all(hi > -limit) and np.all(lo < limit):
            continue  # its footprint would enter the keep-out rectangle
        out.append((_rows(world, normal, palette[i][ids], PATTERN_FIGURE + phase[i]), faces))
    return Elements.join(out)


def _box(lo, hi, color, pattern: float = 0.0) -> np.ndarray:
    """An axis-aligned box, outward faces, no bottom."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    quads = [
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
        [(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)],
        [(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)],
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
    ]
    q = np.array(quads, dtype=np.float64)
    t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    p, n = _tris(t)
    return _rows(p, n, color, pattern)


def _panel(x0, x1, y, z0, z1, color, pattern: float, facing: float) -> np.ndarray:
    """A vertical rectangle in the plane y = const, facing -y (``facing`` < 0) or +y."""
    q = np.array([[(x0, y, z0), (x1, y, z0), (x1, y, z1), (x0, y, z1)]], dtype=np.float64)
    if facing > 0:
        q = q[:, ::-1]
    t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    p, n = _tris(t)
    return _rows(p, n, color, pattern)


def stage(front: float) -> Elements:
    """The stage beyond the crowd area's +y edge: deck, backdrop with an LED wall, a lighting
    truss with lamps aimed at the audience, speaker stacks, truss towers, the crowd barrier.

    Args:
        front: y of the deck's front edge (m).
    """
    lin = lambda rgb: srgb_to_linear(np.asarray(rgb, dtype=np.float64))  # noqa: E731
    w, d, h = 10.0, 5.0, 0.9
    back = front + d
    steel, black = lin((150, 150, 156)), lin((20, 20, 24))
    parts = [
        _box((-w / 2, front, 0), (w / 2, back, h), lin((40, 40, 46))),
        _box((-w / 2, back - 0.3, 0), (w / 2, back, 7.0), lin((16, 16, 22))),
    ]
    # the LED wall: 16 x 6 panels showing a soft blue-violet wave
    xs, zs = np.linspace(-3.6, 3.6, 17), np.linspace(1.6, 5.2, 7)
    for i in range(16):
        for j in range(6):
            wave = 0.5 + 0.5 * math.sin(0.7 * i - 0.9 * j) * math.cos(0.35 * i + 0.5 * j)
            color = lin((30 + 90 * wave, 50 + 40 * wave, 130 + 110 * wave)) * (0.6 + 0.8 * wave)
            parts.append(
                _panel(
                    xs[i] + 0.01,
                    xs[i + 1] - 0.01,
                    back - 0.31,
                    zs[j] + 0.01,
                    zs[j + 1] - 0.01,
                    color,
                    PATTERN_EMISSIVE,
                    -1,
                )
            )
    for sx in (-1, 1):
        x0 = sx * (w / 2 - 0.6)
        parts.append(
            _box((min(x0, x0 + sx * 0.9), front + 0.3, h), (max(x0, x0 + sx * 0.9), front + 1.1, h + 1.8), black)
        )
        parts.append(_box((sx * w / 2 - 0.15, front + 0.4, 0), (sx * w / 2 + 0.15, front + 0.7, 6.5), steel))
    parts.append(_box((-w / 2 - 0.15, front + 0.4, 6.2), (w / 2 + 0.15, front + 0.7, 6.5), steel))
    for k, x in enumerate(np.linspace(-4.0, 4.0, 9)):  # lamps hanging under the truss, lenses toward -y
        tint = ((255, 236, 200), (120, 170, 255), (255, 120, 200))[k % 3]
        parts.append(_box((x - 0.14, front + 0.42, 5.75), (x + 0.14, front + 0.68, 6.2), black))
        parts.append(_panel(x - 0.1, x + 0.1, front + 0.415, 5.82, 6.05, lin(tint) * 4.0, PATTERN_EMISSIVE, -1))
    parts.append(_box((-w / 2, front - 0.35, 0), (w / 2, front - 0.3, 1.1), lin((110, 110, 115))))
    return Elements.join(parts)


def hall(rect: tuple[float, float, float, float], height: float) -> tuple[np.ndarray, Elements]:
    """Walls of a hall around ``rect`` = (x0, y0, x1, y1) metres (one quad each, normals
    inwards) and its fittings (a row of warm house lights along the back wall, exit doors
    with green signs), as cut-away elements.

    Returns:
        (walls (6K, 10) rows, 6 per wall; fittings).
    """
    lin = lambda rgb: srgb_to_linear(np.asarray(rgb, dtype=np.float64))  # noqa: E731
    x0, y0, x1, y1 = rect
    wall = lin((108, 108, 124))  # dim outside the pool of light: a dark blue-grey hall
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    walls = []
    for (ax, ay), (bx, by) in zip(corners, corners[1:] + corners[:1], strict=True):
        q = np.array([[(ax, ay, 0), (bx, by, 0), (bx, by, height), (ax, ay, height)]], dtype=np.float64)
        t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        p, n = _tris(t)
        if np.dot(n[0, :2], -np.array([(ax + bx) / 2 - (x0 + x1) / 2, (ay + by) / 2 - (y0 + y1) / 2])) < 0:
            n = -n  # normals point into the hall
        walls.append(_rows(p, n, wall, 0.0))
    fittings = []
    lamp, sign = lin((255, 200, 140)) * 2.5, lin((40, 220, 90)) * 2.0
    for x in np.linspace(x0 + 2.0, x1 - 2.0, 9):  # house lights along the back wall
        fittings.append(_panel(x - 0.25, x + 0.25, y0 + 0.02, 3.55, 3.7, lamp, PATTERN_EMISSIVE, 1))
    for x in (x0 + 3.0, x1 - 3.0):  # exit doors under the balcony, with green signs
        fittings.append(_panel(x - 0.9, x + 0.9, y0 + 0.01, 0.0, 2.3, lin((62, 60, 70)), 0.0, 1))
        fittings.append(_panel(x - 0.3, x + 0.3, y0 + 0.02, 2.5, 2.75, sign, PATTERN_EMISSIVE, 1))
    return np.concatenate(walls), Elements.join(fittings)


def occluding(
    elements: Elements, eye, extent: tuple[float, float], *, height: float = 2.0, margin: float = 0.3, near: float = 3.5
) -> np.ndarray:
    """(E,) bool: the elements a camera at ``eye`` must leave out (the cutaway): those whose
    bounding box meets a sight line from the eye to the crowd box (the area ``extent``
    grown by ``margin`` metres, from the floor to ``height``), sampled on a 7 x 7 x 4
    grid, and those within ``near`` metres of the eye, which would fill the frame's edge."""
    if not len(elements):
        return np.zeros(0, dtype=bool)
    eye = np.asarray(eye, dtype=np.float64)
    hw, hd = extent[0] / 2 + margin, extent[1] / 2 + margin
    g = np.stack(
        np.meshgrid(np.linspace(-hw, hw, 7), np.linspace(-hd, hd, 7), np.linspace(0.0, height, 4)), axis=-1
    ).reshape(-1, 3)
    direction = g - eye  # (P, 3) segment eye -> point
    inv = 1.0 / np.where(np.abs(direction) < 1e-12, 1e-12, direction)
    t0 = (elements.lo[:, None, :] - eye) * inv[None]  # (E, P, 3)
    t1 = (elements.hi[:, None, :] - eye) * inv[None]
    enter = np.minimum(t0, t1).max(axis=2)
    leave = np.maximum(t0, t1).min(axis=2)
    hit = np.any((enter <= leave) & (leave >= 0.0) & (enter <= 1.0), axis=1)
    gap = np.linalg.norm(np.maximum(np.maximum(elements.lo - eye, eye - elements.hi), 0.0), axis=1)
    return hit | (gap < near)


def visible_indices(elements: Elements, eye, extent: tuple[float, float], view_proj=None) -> np.ndarray:
    """(3T,) uint32: the triangle corners of the elements a camera at ``eye`` keeps (see
    :func:`occluding`) and, given its (4, 4) world-to-clip ``view_proj``, whose boxes
    reach into its view frustum (plus :data:`BOB_AMPLITUDE`), nearest element first, so the
    early depth test skips the shading of the figures hidden behind nearer ones."""
    keep = ~occluding(elements, eye, extent)
    if view_proj is not None and len(elements):
        m = np.asarray(view_proj, dtype=np.float64)
        planes = np.array([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]])
        lo, hi = elements.lo - BOB_AMPLITUDE, elements.hi + BOB_AMPLITUDE
        # the box corner farthest along each plane's normal: the box is outside when it is behind
        far = np.where(planes[None, :, :3] > 0, hi[:, None, :], lo[:, None, :])
        keep &= np.all(np.einsum("epk,pk->ep", far, planes[:, :3]) + planes[:, 3] >= 0, axis=1)
    keep = np.flatnonzero(keep)
    if not len(keep):
        return np.zeros(0, np.uint32)
    centre = 0.5 * (elements.lo[keep] + elements.hi[keep])
    keep = keep[np.argsort(np.linalg.norm(centre - np.asarray(eye, dtype=np.float64), axis=1), kind="stable")]
    return np.concatenate([elements.indices[elements.first[e] : elements.first[e] + elements.count[e]] for e in keep])

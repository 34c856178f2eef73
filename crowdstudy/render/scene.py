"""The environment around the crowd: floor, the concert venue, the corridor walls (the
crossing's plaza: :mod:`crowdstudy.render.plaza`).

Geometry is built as world-space triangle lists (positions, normals, linear-RGB colour
plus a pattern id, see :mod:`crowdstudy.render.venue`). Elements that would stand between
a camera and the crowd area are left out (a cutaway): the concert's stage, hall fittings
and surrounding audience are *cut-away elements* with bounding boxes, and the renderer
drops those that meet a sight line from the camera to the crowd box or stand next to the
camera (:func:`crowdstudy.render.venue.occluding`); walls are drawn with back-face culling
so a wall seen from outside (the corridor's near wall) disappears while the far one stays.

The concert: a 22 m x 21.5 m hall (walls 9 m high, house lights, exit doors), the stage
beyond the area's +y edge (deck, LED wall, a truss of lamps aimed at the audience,
speakers, a barrier) and about 290 low-detail standing figures around the area (darker:
outside the pool of light that falls on the study's crowd; bobbing on the beat; packed
near the area, thinning out towards the back), so every viewpoint sees a crowd in a hall
rather than a block of people in a void.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.render.palette import srgb_to_linear
from crowdstudy.render.venue import Elements, audience, hall, stage

__all__ = ["Environment", "build_environment", "quad_triangles", "split_floor"]


@dataclasses.dataclass
class Environment:
    """Static triangles of one scenario.

    Attributes:
        opaque: (K, 10) float32 rows ``x y z nx ny nz r g b pattern`` (3 rows per triangle);
            the horizontal ground only (drawn with the cheaper floor shader).
        walls: same layout, drawn with back-face culling (normals point inwards).
        cutaway: elements (stage, hall fittings, audience figures) each left out when it
            stands between the camera and the crowd area.
        extent: (x extent, y extent) of the crowd area, metres.
        periodic_length: period along x (m) or None.
        clear_color: linear RGB of the background (and of the distance fog).
        pool: the pool of light on the crowd: (x0, y0, x1, y1, fade, outside): static
            geometry is fully lit inside the rectangle (m) and dims to the factor
            ``outside`` over ``fade`` metres beyond it; None = uniform light.
        beat_hz: bobbing frequency of the audience figures (beats per second).
    """

    opaque: np.ndarray
    walls: np.ndarray
    cutaway: Elements
    extent: tuple[float, float]
    periodic_length: float | None
    clear_color: tuple[float, float, float]
    pool: tuple[float, float, float, float, float, float] | None = None
    beat_hz: float = 0.0


def _rows(points: np.ndarray, normal, color, pattern: float) -> np.ndarray:
    n = len(points)
    out = np.zeros((n, 10), dtype=np.float32)
    out[:, :3] = points
    out[:, 3:6] = normal
    out[:, 6:9] = color
    out[:, 9] = pattern
    return out


def quad_triangles(corners: np.ndarray, color, pattern: float = 0.0, facing=None) -> np.ndarray:
    """Two triangles of a planar quad; ``corners`` (4, 3) counter-clockwise seen from the front.

    ``facing`` (3,): when given, the winding is reversed if needed so the front (and the
    normal) points along it.
    """
    c = np.asarray(corners, dtype=np.float64)
    normal = np.cross(c[1] - c[0], c[2] - c[0])
    if facing is not None and np.dot(normal, facing) < 0:
        c = c[::-1]
        normal = -normal
    normal /= np.linalg.norm(normal)
    return _rows(c[[0, 1, 2, 0, 2, 3]], normal, color, pattern)


def _color(rgb) -> np.ndarray:
    return srgb_to_linear(np.asarray(rgb, dtype=np.float64))


def build_environment(scenario: str, design) -> Environment:
    """The environment of ``scenario`` ("concert" or "corridor") for a study design (a
    crossing's plaza: :func:`crowdstudy.render.plaza.plaza_environment`)."""
    if scenario == "corridor":
        params = design.scenario_of("corridor")
        length, width = float(params["length"]), float(params["width"])
        span = 6.0 * length
        floor = quad_triangles(
            np.array([(-span, -width / 2, 0), (span, -width / 2, 0), (span, width / 2, 0), (-span, width / 2, 0)]),
            _color((176, 160, 140)),
            1.0,
        )
        outside = []
        for sign in (-1, 1):  # ground beyond the walls
            y0, y1 = sorted((sign * (width / 2 + 0.15), sign * 30.0))
            outside.append(
                quad_triangles(
                    np.array([(-span, y0, -0.002), (span, y0, -0.002), (span, y1, -0.002), (-span, y1, -0.002)]),
                    _color((120, 128, 120)),
                )
            )
        wall_h = 2.3
        wall_color = _color((214, 208, 196))
        walls = []
        skirt = _color((90, 84, 78))
        for sign in (-1, 1):  # inner faces look into the corridor (the near one is culled)
            y = sign * width / 2
            inward = (0.0, -float(sign), 0.0)
            walls.append(
                quad_triangles(
                    np.array([(-span, y, 0), (span, y, 0), (span, y, wall_h), (-span, y, wall_h)]),
                    wall_color,
                    facing=inward,
                )
            )
            # skirting boards make the floor/wall junction readable
            y = sign * (width / 2 - 0.005)
            walls.append(
                quad_triangles(
                    np.array([(-span, y, 0), (span, y, 0), (span, y, 0.1), (-span, y, 0.1)]), skirt, facing=inward
                )
            )
        return Environment(
            opaque=np.concatenate([floor, *outside]),
            walls=np.concatenate(walls),
            cutaway=Elements.join([]),
            extent=(length, width),
            periodic_length=length,
            clear_color=tuple(_color((205, 215, 228))),
        )
    if scenario != "concert":
        from crowdstudy.errors import InvalidInputError

        raise InvalidInputError(f"scenario: expected 'concert' or 'corridor', got {scenario!r}")
    width, depth = float(design.floor_width), float(design.floor_depth)
    params = (
        dict(design.scenario_of("concert").params)
        if any(s.kind == "concert" for s in design.scenarios.values())
        else {}
    )
    front = depth / 2 + float(params.get("stage_distance", 1.0))
    tempo = float(params.get("tempo", 120.0))  # bpm
    rect = (-11.0, -13.0, 11.0, front + 6.5)  # the hall: the stage (5 m deep) at its +y end
    x0, y0, x1, y1 = rect
    floor = quad_triangles(np.array([(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)]), _color((112, 112, 118)), 1.0)
    walls, fittings = hall(rect, 9.0)
    # the audience: packed near the crowd area, thinning out towards the back of the hall
    people = audience(
        (width, depth),
        (x0 + 0.5, y0 + 3.0, x1 - 0.5, front),
        int(design.seed),
        near=3.0,
        spacing=(0.62, 0.95),
        stage_y=front - 0.45,
    )
    # the hall's walls are cut-away elements too (lit per vertex like the rest of the venue;
    # a camera outside the hall does not see the crowd through a wall)
    walls = Elements.join([walls[k : k + 6] for k in range(0, len(walls), 6)])
    cut = Elements.concat([walls, stage(front), fittings, people])
    # the stage lights' pool: the crowd area and the floor up to the stage, dimming outside
    pool = (-width / 2 - 0.3, -depth / 2 - 0.3, width / 2 + 0.3, front, 1.6, 0.22)
    return Environment(
        opaque=floor,
        walls=np.zeros((0, 10), np.float32),
        cutaway=cut,
        extent=(width, depth),
        periodic_length=None,
        clear_color=tuple(_color((52, 54, 64))),
        pool=pool,
        beat_hz=tempo / 60.0,
    )


def _floor_cell(quad: np.ndarray, a0: float, b0: float, a1: float, b1: float) -> np.ndarray | None:
    """(6, 10) rows of the rectangle [a0, a1] x [b0, b1] (m) in the plane and with the look of
    ``quad`` ((6, 10) rows of a horizontal quad); None where the rectangle is empty."""
    if not (a1 - a0 > 1e-9 and b1 - b0 > 1e-9):
        return None
    z, normal, color, pattern = quad[0, 2], quad[0, 3:6], quad[0, 6:9], quad[0, 9]
    corners = np.array([(a0, b0, z), (a1, b0, z), (a1, b1, z), (a0, b1, z)], dtype=np.float64)
    return _rows(corners[[0, 1, 2, 0, 2, 3]], normal, color, pattern)


def split_floor(triangles: np.ndarray, rect: tuple[float, float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Split horizontal axis-aligned floor quads at a rectangle.

    Args:
        triangles: (6K, 10) rows as :func:`quad_triangles` writes them for K quads lying in
            planes z = const with edges along x and y (the ground of both scenarios).
        rect: (x0, y0, x1, y1) metres.
    Returns:
        (inside, outside): the parts of the quads inside ``rect`` and the (up to 8 per
        quad) rectangles around it, same row layout. Together they cover exactly the
        input quads, without T-junctions.
    """
    rx0, ry0, rx1, ry1 = (float(v) for v in rect)
    inside, outside = [], []
    for quad in np.asarray(triangles).reshape(-1, 6, 10):
        x0, y0 = quad[:, 0].min(), quad[:, 1].min()
        x1, y1 = quad[:, 0].max(), quad[:, 1].max()
        ix0, iy0, ix1, iy1 = max(x0, rx0), max(y0, ry0), min(x1, rx1), min(y1, ry1)
        if ix0 >= ix1 or iy0 >= iy1:
            outside.append(quad)
            continue
        # a 3 x 3 grid of cells: neighbouring cells share whole edges (no T-junctions, so
        # no cracks between them where the rasteriser rounds differently)
        xs, ys = (x0, ix0, ix1, x1), (y0, iy0, iy1, y1)
        for i in range(3):
            for j in range(3):
                cell = _floor_cell(quad, xs[i], ys[j], xs[i + 1], ys[j + 1])
                if cell is not None:
                    (inside if (i, j) == (1, 1) else outside).append(cell)
    empty = np.zeros((0, 10), dtype=np.float32)
    return (
        np.concatenate(inside).astype(np.float32) if inside else empty,
        np.concatenate(outside).astype(np.float32) if outside else empty,
    )

"""The environment around the crowd: floor, the concert stage, the corridor walls.

Geometry is built as world-space triangle lists (positions, normals, linear-RGB colour
plus a pattern id). Elements that would stand between a camera and the crowd area are left
out (a cutaway): the stage is only drawn when the camera is in front of it (y below the
stage's front edge), and the corridor walls are drawn with back-face culling so the near
wall, seen from outside, disappears while the far wall stays.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.render.palette import srgb_to_linear

__all__ = ["Environment", "build_environment", "box_triangles", "quad_triangles", "split_floor"]


@dataclasses.dataclass
class Environment:
    """Static triangles of one scenario.

    Attributes:
        opaque: (K, 10) float32 rows ``x y z nx ny nz r g b pattern`` (3 rows per triangle);
            the horizontal ground only (drawn with the cheaper floor shader).
        walls: same layout, drawn with back-face culling (normals point into the corridor).
        stage: same layout, drawn only when the camera is in front of the stage.
        stage_front_y: y of the stage's front edge (m), or None.
        extent: (x extent, y extent) of the crowd area, metres.
        periodic_length: period along x (m) or None.
        clear_color: linear RGB of the background.
    """
    opaque: np.ndarray
    walls: np.ndarray
    stage: np.ndarray
    stage_front_y: float | None
    extent: tuple[float, float]
    periodic_length: float | None
    clear_color: tuple[float, float, float]


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


def box_triangles(lo, hi, color) -> np.ndarray:
    """An axis-aligned box from ``lo`` (3,) to ``hi`` (3,) with outward normals (no bottom face)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    faces = [
        [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],  # top
        [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],  # -y
        [(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)],  # +y
        [(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)],  # -x
        [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],  # +x
    ]
    return np.concatenate([quad_triangles(np.array(f), color) for f in faces])


def _color(rgb) -> np.ndarray:
    return srgb_to_linear(np.asarray(rgb, dtype=np.float64))


def build_environment(scenario: str, design) -> Environment:
    """The environment of ``scenario`` ("concert" or "corridor") for a study design."""
    empty = np.zeros((0, 10), dtype=np.float32)
    if scenario == "corridor":
        params = design.scenarios["corridor"]
        length, width = float(params["length"]), float(params["width"])
        span = 6.0 * length
        floor = quad_triangles(np.array([(-span, -width / 2, 0), (span, -width / 2, 0), (span, width / 2, 0),
                                         (-span, width / 2, 0)]), _color((176, 160, 140)), 1.0)
        outside = []
        for sign in (-1, 1):  # ground beyond the walls
            y0, y1 = sorted((sign * (width / 2 + 0.15), sign * 30.0))
            outside.append(quad_triangles(np.array([(-span, y0, -0.002), (span, y0, -0.002), (span, y1, -0.002),
                                                    (-span, y1, -0.002)]), _color((120, 128, 120))))
        wall_h = 2.3
        wall_color = _color((214, 208, 196))
        walls = []
        skirt = _color((90, 84, 78))
        for sign in (-1, 1):  # inner faces look into the corridor (the near one is culled)
            y = sign * width / 2
            inward = (0.0, -float(sign), 0.0)
            walls.append(quad_triangles(np.array([(-span, y, 0), (span, y, 0), (span, y, wall_h), (-span, y, wall_h)]),
                                        wall_color, facing=inward))
            # skirting boards make the floor/wall junction readable
            y = sign * (width / 2 - 0.005)
            walls.append(quad_triangles(np.array([(-span, y, 0), (span, y, 0), (span, y, 0.1), (-span, y, 0.1)]),
                                        skirt, facing=inward))
        return Environment(opaque=np.concatenate([floor, *outside]), walls=np.concatenate(walls),
                           stage=empty, stage_front_y=None, extent=(length, width), periodic_length=length,
                           clear_color=tuple(_color((205, 215, 228))))
    if scenario != "concert":
        from crowdstudy.errors import InvalidInputError
        raise InvalidInputError(f"scenario: expected 'concert' or 'corridor', got {scenario!r}")
    width, depth = float(design.floor_width), float(design.floor_depth)
    params = design.scenarios["concert"] if "concert" in design.scenarios else {"stage_distance": 1.0}
    front = depth / 2 + float(params["stage_distance"])
    span = 40.0
    floor = quad_triangles(np.array([(-span, -span, 0), (span, -span, 0), (span, span, 0), (-span, span, 0)]),
                           _color((112, 112, 118)), 1.0)
    stage_w, stage_d, stage_h = 10.0, 5.0, 0.9
    stage = [box_triangles((-stage_w / 2, front, 0), (stage_w / 2, front + stage_d, stage_h), _color((45, 45, 52))),
             box_triangles((-stage_w / 2, front + stage_d - 0.3, 0), (stage_w / 2, front + stage_d, 6.0),
                           _color((30, 30, 40)))]
    for sx in (-1, 1):  # loudspeaker stacks and truss towers at the sides
        x0 = sx * (stage_w / 2 - 0.6)
        stage.append(box_triangles((min(x0, x0 + sx * 0.9), front + 0.3, stage_h),
                                   (max(x0, x0 + sx * 0.9), front + 1.1, stage_h + 1.6), _color((20, 20, 22))))
        stage.append(box_triangles((sx * stage_w / 2 - 0.15, front + stage_d - 0.6, 0),
                                   (sx * stage_w / 2 + 0.15, front + stage_d - 0.3, 6.0), _color((170, 170, 175))))
    stage.append(box_triangles((-stage_w / 2, front + stage_d - 0.6, 5.7), (stage_w / 2, front + stage_d - 0.3, 6.0),
                               _color((170, 170, 175))))
    # a barrier in front of the stage
    stage.append(box_triangles((-stage_w / 2, front - 0.35, 0), (stage_w / 2, front - 0.3, 1.1), _color((110, 110, 115))))
    return Environment(opaque=floor, walls=empty, stage=np.concatenate(stage), stage_front_y=front - 0.35,
                       extent=(width, depth), periodic_length=None, clear_color=tuple(_color((118, 126, 140))))


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
        z, normal, color, pattern = quad[0, 2], quad[0, 3:6], quad[0, 6:9], quad[0, 9]

        def emit(dest, a0, b0, a1, b1):
            if a1 - a0 > 1e-9 and b1 - b0 > 1e-9:
                corners = np.array([(a0, b0, z), (a1, b0, z), (a1, b1, z), (a0, b1, z)], dtype=np.float64)
                rows = _rows(corners[[0, 1, 2, 0, 2, 3]], normal, color, pattern)
                dest.append(rows)

        ix0, iy0, ix1, iy1 = max(x0, rx0), max(y0, ry0), min(x1, rx1), min(y1, ry1)
        if ix0 >= ix1 or iy0 >= iy1:
            outside.append(quad)
            continue
        # a 3 x 3 grid of cells: neighbouring cells share whole edges (no T-junctions, so
        # no cracks between them where the rasteriser rounds differently)
        xs, ys = (x0, ix0, ix1, x1), (y0, iy0, iy1, y1)
        for i in range(3):
            for j in range(3):
                emit(inside if (i, j) == (1, 1) else outside, xs[i], ys[j], xs[i + 1], ys[j + 1])
    empty = np.zeros((0, 10), dtype=np.float32)
    return (np.concatenate(inside).astype(np.float32) if inside else empty,
            np.concatenate(outside).astype(np.float32) if outside else empty)

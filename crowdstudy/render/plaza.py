"""The environment of a crossing scenario: a paved plaza with its obstacles as solids.

The geometry comes from the animation's ``meta["plaza"]`` (written by
:func:`crowdstudy.navigation.crossing_crowd`: the plaza's size and the design's obstacle
shapes with their heights), else from the design's first crossing scenario. The plaza is
paved with light 0.5 m tiles (the floor pattern of the other scenarios) and lies in darker
paving (the streets the flows come from) that reaches to the horizon (fogged into the sky
colour). Each obstacle is a prism of its
shape and ``height`` (a circle as a smooth 24-sided cylinder), drawn with the walls (lit per
pixel, receiving the characters' shadows; back faces culled, so only its outside is drawn):
planters concrete with a soil-and-green top, a kiosk warm-coloured with a dark roof,
anything else (bollards) dark grey metal, each with a darker plinth that grounds it on the
paving. The obstacles cast no shadows (the shadow map holds the characters only).
"""

from __future__ import annotations

import math

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.render.palette import srgb_to_linear
from crowdstudy.render.scene import Environment, quad_triangles
from crowdstudy.render.venue import Elements

__all__ = ["plaza_environment", "obstacle_solids", "PLAZA_SKY"]

#: The sky and fog colour (sRGB) of the plaza.
PLAZA_SKY = (205, 215, 228)
_PAVING = (188, 180, 168)
_GROUND = (142, 138, 132)  # the streets the flows come from: darker paving
_CYLINDER_SIDES = 24
_PLINTH = 0.06  # m, the darker band at the foot of an obstacle


def _lin(rgb) -> np.ndarray:
    return srgb_to_linear(np.asarray(rgb, dtype=np.float64))


#: (side, top) sRGB colours by the first word of an obstacle's label found here.
_LOOKS = {
    "planter": ((150, 146, 138), (74, 104, 58)),
    "kiosk": ((176, 92, 64), (70, 70, 76)),
    "bench": ((132, 98, 70), (132, 98, 70)),
}
_DEFAULT_LOOK = ((72, 74, 80), (96, 98, 104))


def _look(label: str) -> tuple[np.ndarray, np.ndarray]:
    words = str(label).lower().split()
    for key, (side, top) in _LOOKS.items():
        if key in words:
            return _lin(side), _lin(top)
    return _lin(_DEFAULT_LOOK[0]), _lin(_DEFAULT_LOOK[1])


def _rows(points: np.ndarray, normals: np.ndarray, color: np.ndarray) -> np.ndarray:
    out = np.zeros((len(points), 10), dtype=np.float32)
    out[:, :3], out[:, 3:6], out[:, 6:9] = points, normals, color
    return out


def _ring(shape: dict) -> tuple[np.ndarray, bool]:
    """The obstacle's outline (K, 2) m counter-clockwise, and whether it is round."""
    if shape["shape"] == "circle":
        ang = 2 * math.pi * np.arange(_CYLINDER_SIDES) / _CYLINDER_SIDES
        r = float(shape["radius"])
        return np.asarray(shape["center"], np.float64) + r * np.stack([np.cos(ang), np.sin(ang)], 1), True
    return np.asarray(shape["points"], np.float64), False


def _prism(ring: np.ndarray, round_: bool, z0: float, z1: float, color: np.ndarray) -> np.ndarray:
    """Side faces of the prism over ``ring`` from ``z0`` to ``z1`` m, outward normals
    (radial per vertex when ``round_``: a smooth cylinder)."""
    a, b = ring, np.roll(ring, -1, axis=0)
    centre = ring.mean(axis=0)
    rows = []
    for p, q in zip(a, b, strict=True):
        flat = np.array([q[1] - p[1], -(q[0] - p[0]), 0.0])
        flat /= np.linalg.norm(flat)
        corners = np.array([(p[0], p[1], z0), (q[0], q[1], z0), (q[0], q[1], z1), (p[0], p[1], z1)])
        tri = corners[[0, 1, 2, 0, 2, 3]]
        if round_:
            n = np.concatenate([tri[:, :2] - centre, np.zeros((6, 1))], 1)
            n /= np.linalg.norm(n, axis=1, keepdims=True)
        else:
            n = np.repeat(flat[None], 6, 0)
        rows.append(_rows(tri, n, color))
    return np.concatenate(rows)


def obstacle_solids(shapes: list[dict]) -> np.ndarray:
    """(6K, 10) float32 triangle rows (see :class:`~crowdstudy.render.scene.Environment`) of
    the obstacles ``shapes`` (the design's parsed crossing ``obstacles``: shape, centre and
    radius or points, height m, label) standing on the ground: sides, plinth and top."""
    rows = []
    for shape in shapes:
        ring, round_ = _ring(shape)
        height = float(shape["height"])
        side, top = _look(shape.get("label", ""))
        plinth = min(_PLINTH, 0.3 * height)
        rows.append(_prism(ring, round_, 0.0, plinth, side * 0.55))
        rows.append(_prism(ring, round_, plinth, height, side))
        centre = np.append(ring.mean(axis=0), height)
        fan = []
        for p, q in zip(ring, np.roll(ring, -1, axis=0), strict=True):
            fan += [centre, (p[0], p[1], height), (q[0], q[1], height)]
        rows.append(_rows(np.array(fan), np.array([0.0, 0.0, 1.0]), top))
    return np.concatenate(rows) if rows else np.zeros((0, 10), np.float32)


def _ground(plaza_w: float, plaza_d: float) -> np.ndarray:
    """The paved plaza (tiled) and the darker paving around it out to 60 m (four quads,
    axis-aligned, as :func:`~crowdstudy.render.scene.split_floor` needs)."""
    hw, hd, far = plaza_w / 2, plaza_d / 2, 60.0
    paving = quad_triangles(np.array([(-hw, -hd, 0), (hw, -hd, 0), (hw, hd, 0), (-hw, hd, 0)]), _lin(_PAVING), 1.0)
    z, g = -0.002, _lin(_GROUND)
    around = [
        (-far, -far, far, -hd),  # in front (-y)
        (-far, hd, far, far),  # behind (+y)
        (-far, -hd, -hw, hd),  # left (-x)
        (hw, -hd, far, hd),  # right (+x)
    ]
    quads = [
        quad_triangles(np.array([(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)]), g, 1.0)
        for x0, y0, x1, y1 in around
    ]
    return np.concatenate([paving, *quads])


def plaza_environment(design, meta=None) -> Environment:
    """The :class:`~crowdstudy.render.scene.Environment` of a crossing scenario: the plaza
    of ``meta["plaza"]`` (an animation's), else of the design's first crossing scenario;
    the crowd area (the cameras' framing) is the design's floor (``meta["floor"]`` first)."""
    plaza = (meta or {}).get("plaza")
    if plaza is None:
        if not any(sc.kind == "crossing" for sc in design.scenarios.values()):
            raise InvalidInputError(
                "scenario: this crossing animation has no meta['plaza'] and the design has no crossing scenario"
            )
        sc = design.scenario_of("crossing")
        plaza = {"width": sc["plaza_width"], "depth": sc["plaza_depth"], "obstacles": sc["obstacles"]}
    floor = (meta or {}).get("floor") or {"width": design.floor_width, "depth": design.floor_depth}
    return Environment(
        opaque=_ground(float(plaza["width"]), float(plaza["depth"])),
        walls=obstacle_solids(list(plaza.get("obstacles", []))),
        cutaway=Elements.join([]),
        extent=(float(floor["width"]), float(floor["depth"])),
        periodic_length=None,
        clear_color=tuple(_lin(PLAZA_SKY)),
    )

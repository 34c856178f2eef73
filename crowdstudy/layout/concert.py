"""The stationary concert crowd of study stage 1: a Poisson-disk layout on the floor."""

from __future__ import annotations

import math

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.layout.discs import disc_radius
from crowdstudy.layout.poisson import poisson_disk
from crowdstudy.provenance import provenance
from crowdstudy.scene import Crowd

__all__ = ["concert_layout", "scaled_floor"]


def scaled_floor(design, level: str, n_characters: int) -> tuple[float, float]:
    """(width, depth) in metres of the floor that holds ``n_characters`` at the density of
    ``level``: the design's floor scaled by the same factor on both sides (its aspect ratio
    kept) so that ``n_characters / (width * depth)`` is the level's characters per m^2."""
    if level not in design.densities:
        raise InvalidInputError(
            f"level: unknown density level {level!r}; expected one of {', '.join(design.densities)}"
        )
    if isinstance(n_characters, bool) or not isinstance(n_characters, (int, np.integer)) or n_characters < 1:
        raise InvalidInputError(f"n_characters: expected a positive integer, got {n_characters!r}")
    density = float(design.densities[level])
    scale = math.sqrt(int(n_characters) / (density * float(design.floor_area)))
    return float(design.floor_width) * scale, float(design.floor_depth) * scale


def concert_layout(design, level: str, seed, n_characters: int | None = None, *, scenario: str = "concert") -> Crowd:
    """The concert crowd of one density level as a one-frame :class:`Crowd`.

    ``design.n_characters(level)`` characters on the ``floor_width x floor_depth`` floor
    centred on the origin, ``margin`` metres (of the design's scenario ``scenario``, by
    default its concert) from its edges,
    all facing the stage (+y, heading pi/2).

    ``n_characters`` (a stadium crowd, e.g. 1,000 or 5,000) lays out that many characters
    on a larger floor at the same density (characters per m^2 of the floor):
    :func:`scaled_floor` gives its size; the margin, the stage distance and the disc radius
    stay the design's. The stage front moves with the floor's front edge, and the meta
    records the floor, stage front and wall actually used (later stages read them there).

    Returns:
        Crowd with positions (1, N, 2) metres, radius (N,) from
        :func:`~crowdstudy.layout.discs.disc_radius`, headings (1, N) radians, region the
        floor rectangle (4, 2), meta {scenario, density_level, density, n_characters, seed,
        margin, min_distance, target_distance, provenance} and the scene's static geometry
        (what later stages read instead of a design): ``floor`` {width, depth} m,
        ``stage_distance`` m, ``stage_front`` the y (m) of the stage front
        (``floor_depth / 2 + stage_distance``), and ``obstacles`` [[[x0, y0], [x1, y1]]] m,
        the stage front as one wall segment from x = -floor_width to +floor_width.
    """
    if level not in design.densities:
        raise InvalidInputError(
            f"level: unknown density level {level!r}; expected one of {', '.join(design.densities)}"
        )
    if n_characters is None:
        n = design.n_characters(level)
        width, depth = float(design.floor_width), float(design.floor_depth)
    else:
        width, depth = scaled_floor(design, level, n_characters)
        n = int(n_characters)
    density = float(design.densities[level])
    params = design.scenario_of(scenario)
    margin = float(params["margin"])
    layout = poisson_disk((width, depth), n, seed=seed, margin=margin)
    seed_value = layout.seed
    stage_distance = float(params["stage_distance"])
    stage_front = depth / 2 + stage_distance
    return Crowd(
        positions=layout.points[None],
        radius=np.full(n, disc_radius(density)),
        fps=float(design.fps),
        headings=np.full((1, n), np.pi / 2),
        region=layout.region,
        meta={
            "scenario": "concert",
            "density_level": level,
            "density": density,
            "n_characters": n,
            "seed": seed_value,
            "margin": margin,
            "min_distance": layout.min_distance,
            "target_distance": layout.target_distance,
            "area": layout.area,
            "floor": {"width": width, "depth": depth},
            "stage_distance": stage_distance,
            "stage_front": stage_front,
            "obstacles": [[[-width, stage_front], [width, stage_front]]],
            "provenance": provenance(seed_value, stage="layout"),
        },
    )

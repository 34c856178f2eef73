"""The disc that stands for a character in 2D layouts and navigation.

A walking or standing person occupies about a disc of their shoulder half-width,
``SHOULDER_HALF_WIDTH = 0.22`` m (adult bideltoid breadth is about 0.40-0.48 m). The study's
densest cell has 6.66 characters/m^2, where such discs cannot all fit: 60 discs of
0.22 m cover 9.1 m^2 of a 9 m^2 floor. The disc radius is therefore

    r(rho) = min(0.22, sqrt(MAX_PACKING_FRACTION / (pi * rho)))

so the discs never cover more than ``MAX_PACKING_FRACTION = 0.6`` of the floor (0.22 m up
to 3.95 characters/m^2, 0.207 m at D3, 0.186 m at D4, 0.169 m at D5). 0.6 leaves room to
move: random close packing of discs is about 0.82 and the hexagonal packing 0.907. The
discs are the navigation *core*; the remaining shoulder-to-shoulder contact in dense cells
is what the physics layer resolves on the full bodies.
"""

from __future__ import annotations

import math

from crowdstudy.errors import InvalidInputError

__all__ = ["SHOULDER_HALF_WIDTH", "MAX_PACKING_FRACTION", "disc_radius"]

SHOULDER_HALF_WIDTH = 0.22
MAX_PACKING_FRACTION = 0.6


def disc_radius(density: float) -> float:
    """Disc radius (m) of a character at ``density`` characters per m^2 (see module doc)."""
    try:
        rho = float(density)
    except (TypeError, ValueError):
        raise InvalidInputError(f"density: expected characters per m^2 as a number, got {density!r}") from None
    if not math.isfinite(rho) or rho <= 0:
        raise InvalidInputError(f"density: expected a positive number of characters per m^2, got {density!r}")
    return min(SHOULDER_HALF_WIDTH, math.sqrt(MAX_PACKING_FRACTION / (math.pi * rho)))

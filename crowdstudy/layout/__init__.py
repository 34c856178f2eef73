"""Crowd layouts: Poisson-disk point sets and the stationary concert crowd.

>>> from crowdstudy.layout import poisson_disk
>>> layout = poisson_disk((3.0, 3.0), 60, seed=1, margin=0.2)
>>> layout.points.shape, layout.min_distance >= layout.target_distance
((60, 2), True)
"""

from crowdstudy.layout.concert import concert_layout
from crowdstudy.layout.discs import MAX_PACKING_FRACTION, SHOULDER_HALF_WIDTH, disc_radius
from crowdstudy.layout.poisson import PoissonLayout, poisson_disk

__all__ = [
    "poisson_disk",
    "PoissonLayout",
    "concert_layout",
    "disc_radius",
    "SHOULDER_HALF_WIDTH",
    "MAX_PACKING_FRACTION",
]

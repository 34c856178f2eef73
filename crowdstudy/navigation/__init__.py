"""Crowd navigation: ORCA trajectories of disc agents (the walking corridor of stage 2).

* :class:`ORCASimulator` / :class:`ORCAParams`: RVO2's ORCA as Warp kernels.
* :func:`corridor_crowd`: the study's periodic corridor crowd as a trajectory ``Crowd``.
* :func:`crossing_crowd`: two flows crossing on a plaza with obstacles (``kind = "crossing"``).
* :mod:`crowdstudy.navigation.room`: the closed-room scenario shared with pyrvo (benchmark).
* :mod:`crowdstudy.navigation.plot`: figures of layouts and trajectories.
"""

from crowdstudy.navigation.corridor import (
    MAX_TURN_RATE,
    RHO_JAM,
    SAFETY_MARGIN,
    corridor_crowd,
    smooth_headings,
    speed_factor,
    trajectory_summary,
)
from crowdstudy.navigation.crossing import crossing_crowd, obstacle_clearance, obstacle_polygons, obstacle_segments
from crowdstudy.navigation.orca import ORCAParams, ORCASimulator, segments_to_obstacle_vertices

__all__ = [
    "ORCAParams",
    "ORCASimulator",
    "segments_to_obstacle_vertices",
    "corridor_crowd",
    "crossing_crowd",
    "obstacle_polygons",
    "obstacle_segments",
    "obstacle_clearance",
    "smooth_headings",
    "speed_factor",
    "trajectory_summary",
    "RHO_JAM",
    "MAX_TURN_RATE",
    "SAFETY_MARGIN",
]

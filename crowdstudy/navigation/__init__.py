"""Crowd navigation: ORCA trajectories of disc agents (the walking corridor of stage 2).

* :class:`ORCASimulator` / :class:`ORCAParams`: RVO2's ORCA as Warp kernels.
* :func:`corridor_crowd`: the study's periodic corridor crowd as a trajectory ``Crowd``.
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
from crowdstudy.navigation.orca import ORCAParams, ORCASimulator, segments_to_obstacle_vertices

__all__ = [
    "ORCAParams",
    "ORCASimulator",
    "segments_to_obstacle_vertices",
    "corridor_crowd",
    "smooth_headings",
    "speed_factor",
    "trajectory_summary",
    "RHO_JAM",
    "MAX_TURN_RATE",
    "SAFETY_MARGIN",
]

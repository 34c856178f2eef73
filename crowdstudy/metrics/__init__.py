"""Measurements of crowd animations: inter-character overlap volume (body meshes or
capsules), tracking error, smoothness (jerk, high-frequency energy, speed spikes, pelvis
acceleration, foot sliding, loop seams), intra-body penetration and skin through the scene's
walls, and an estimate of the least displacement that would separate the characters
(the tracking floor); the acceptance bars of a corrected crowd against its Baseline
(:class:`BarTolerances`, :func:`check_bars`); ``crowdstudy metrics``."""

from crowdstudy.metrics.bars import (
    BAR_NAMES,
    BarName,
    BarTolerances,
    check_bars,
    failed_bars,
    loop_mode,
    smoothness_columns,
)
from crowdstudy.metrics.floor import SeparationFloor, separation_floor
from crowdstudy.metrics.neighbourhoods import tile_ratios
from crowdstudy.metrics.overlap import OverlapResult, frame_indices, overlap_volume
from crowdstudy.metrics.smoothness import (
    FootSlide,
    PeakSpeed,
    SeamJump,
    SmoothnessResult,
    foot_slide,
    high_frequency_share,
    joint_jerk,
    joint_speeds,
    mean_jerk,
    peak_joint_speed,
    pelvis_acceleration_p99,
    seam_jump,
    smoothness,
    smoothness_from_positions,
    smoothness_ratios,
)
from crowdstudy.metrics.summary import summarize
from crowdstudy.metrics.tracking import (
    IntraPenetrationResult,
    TrackingParts,
    intra_penetration,
    tracking_error,
    tracking_parts,
)
from crowdstudy.metrics.walls import WallPenetration, wall_penetration

__all__ = [
    "OverlapResult",
    "overlap_volume",
    "frame_indices",
    "tracking_error",
    "tracking_parts",
    "TrackingParts",
    "mean_jerk",
    "intra_penetration",
    "IntraPenetrationResult",
    "summarize",
    "smoothness",
    "smoothness_from_positions",
    "smoothness_ratios",
    "SmoothnessResult",
    "joint_jerk",
    "high_frequency_share",
    "joint_speeds",
    "peak_joint_speed",
    "pelvis_acceleration_p99",
    "foot_slide",
    "seam_jump",
    "PeakSpeed",
    "FootSlide",
    "SeamJump",
    "wall_penetration",
    "WallPenetration",
    "separation_floor",
    "SeparationFloor",
    "BarTolerances",
    "BarName",
    "BAR_NAMES",
    "check_bars",
    "failed_bars",
    "loop_mode",
    "smoothness_columns",
    "tile_ratios",
]

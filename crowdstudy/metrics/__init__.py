"""Measurements of crowd animations: inter-character overlap volume (body meshes or
capsules), tracking error, jerk and intra-body penetration; ``crowdstudy metrics``."""

from crowdstudy.metrics.overlap import OverlapResult, frame_indices, overlap_volume
from crowdstudy.metrics.summary import summarize
from crowdstudy.metrics.tracking import IntraPenetrationResult, intra_penetration, mean_jerk, tracking_error

__all__ = ["OverlapResult", "overlap_volume", "frame_indices", "tracking_error", "mean_jerk",
           "intra_penetration", "IntraPenetrationResult", "summarize"]

"""Motion: shipped clips (15 dances, 4 walks), BVH / AMASS importers, Baseline animation.

Heavy work (clip generation, body loading) happens on first use, not on import.
"""

from crowdstudy.motion.amass import load_amass
from crowdstudy.motion.baseline import animate_stationary, animate_walking, build_baseline
from crowdstudy.motion.bvh import load_bvh, save_bvh
from crowdstudy.motion.clip import MotionClip, seam_discontinuity
from crowdstudy.motion.diagnostics import foot_skate
from crowdstudy.motion.library import list_clips, load_clip

__all__ = [
    "MotionClip",
    "animate_stationary",
    "animate_walking",
    "build_baseline",
    "foot_skate",
    "list_clips",
    "load_amass",
    "load_bvh",
    "load_clip",
    "save_bvh",
    "seam_discontinuity",
]

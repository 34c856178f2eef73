"""Characters: the 24-joint skeleton, body models, body shapes and capsule proxies.

Heavy parts (mesh generation, SMPL loading) run on first use, not on import.
"""

from crowdstudy.body.capsules import Capsules, capsule_mesh_iou, posed_capsules
from crowdstudy.body.loading import load_body
from crowdstudy.body.model import Body, pose_bodies
from crowdstudy.body.shapes import sample_bodies
from crowdstudy.body.skeleton import (
    BVH_NAME_MAPS,
    DEFAULT_PELVIS_HEIGHT,
    DEFAULT_REST_JOINTS,
    JOINT_NAMES,
    NUM_JOINTS,
    PARENTS,
    bvh_name_map,
    forward_kinematics,
    joint_index,
)
from crowdstudy.body.skinning import CrowdSkinner

__all__ = [
    "BVH_NAME_MAPS",
    "Body",
    "Capsules",
    "CrowdSkinner",
    "DEFAULT_PELVIS_HEIGHT",
    "DEFAULT_REST_JOINTS",
    "JOINT_NAMES",
    "NUM_JOINTS",
    "PARENTS",
    "bvh_name_map",
    "capsule_mesh_iou",
    "forward_kinematics",
    "joint_index",
    "load_body",
    "pose_bodies",
    "posed_capsules",
    "sample_bodies",
]

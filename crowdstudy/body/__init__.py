"""Characters: the 24-joint skeleton, body models, body shapes and capsule proxies."""

from crowdstudy.body.skeleton import (
    DEFAULT_PELVIS_HEIGHT,
    DEFAULT_REST_JOINTS,
    JOINT_NAMES,
    NUM_JOINTS,
    PARENTS,
    forward_kinematics,
    joint_index,
)

__all__ = [
    "DEFAULT_PELVIS_HEIGHT",
    "DEFAULT_REST_JOINTS",
    "JOINT_NAMES",
    "NUM_JOINTS",
    "PARENTS",
    "forward_kinematics",
    "joint_index",
]

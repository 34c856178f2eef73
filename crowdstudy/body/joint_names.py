"""Joint-name maps from common rigs to the toolkit's 24-joint skeleton (the glTF character
import, :mod:`crowdstudy.body.gltf_model`). VRoid: the node names of VRoid's VRM 0.x files;
Rigify: Blender's Rigify metarig.

| joint | crowdstudy export | Mixamo / Ready Player Me | VRM humanoid | VRoid | Rigify | CMU BVH |
| --- | --- | --- | --- | --- | --- | --- |
| pelvis | ``cNN_pelvis`` | Hips | hips | J_Bip_C_Hips | spine | Hips |
| spine1 | ``cNN_spine1`` | Spine | spine | J_Bip_C_Spine | spine.001 | LowerBack |
| spine2 | ``cNN_spine2`` | Spine1 | chest | J_Bip_C_Chest | spine.002 | Spine |
| spine3 | ``cNN_spine3`` | Spine2 | upperChest | J_Bip_C_UpperChest | spine.003 | Spine1 |
| neck | ``cNN_neck`` | Neck | neck | J_Bip_C_Neck | spine.004 | Neck |
| head | ``cNN_head`` | Head | head | J_Bip_C_Head | spine.006 | Head |
| left_collar | ... | LeftShoulder | leftShoulder | J_Bip_L_Shoulder | shoulder.L | LeftShoulder |
| left_shoulder | | LeftArm | leftUpperArm | J_Bip_L_UpperArm | upper_arm.L | LeftArm |
| left_elbow | | LeftForeArm | leftLowerArm | J_Bip_L_LowerArm | forearm.L | LeftForeArm |
| left_wrist | | LeftHand | leftHand | J_Bip_L_Hand | hand.L | LeftHand |
| left_hand | | LeftHandMiddle1 | leftMiddleProximal | J_Bip_L_Middle1 | f_middle.01.L | LeftFingerBase |
| left_hip | | LeftUpLeg | leftUpperLeg | J_Bip_L_UpperLeg | thigh.L | LeftUpLeg |
| left_knee | | LeftLeg | leftLowerLeg | J_Bip_L_LowerLeg | shin.L | LeftLeg |
| left_ankle | | LeftFoot | leftFoot | J_Bip_L_Foot | foot.L | LeftFoot |
| left_foot | | LeftToeBase | leftToes | J_Bip_L_ToeBase | toe.L | LeftToeBase |

(right side alike). The ``bcn`` table maps the ``B_Hip_Left``, ``B_Clavicle_Left``,
``B_UpperArm_Left``, ``B_ForeArm_Left`` style (assimp's BCN_Epileptic test model; see
``_B_MID``/``_B_SIDE``). Mixamo and CMU come from ``crowdstudy.body.skeleton.BVH_NAME_MAPS``.
Names are compared after dropping a namespace (``mixamorig:``, ``mixamorig1:``, Blender's
``mixamorig_``), Rigify's ``DEF-``/``ORG-`` prefixes, case, and the characters
``_ . - space``. A VRM file's own humanoid table (``VRM`` or ``VRMC_vrm`` extension) takes
precedence over the node names.
"""

from __future__ import annotations

import re

from crowdstudy.body.skeleton import BVH_NAME_MAPS, JOINT_NAMES

__all__ = ["NAME_MAPS", "normalize_name", "match_names", "VRM_BONES"]

_SIDE_TABLE = {  # our joint suffix -> (VRM, VRoid, Rigify stem)
    "collar": ("Shoulder", "Shoulder", "shoulder"),
    "shoulder": ("UpperArm", "UpperArm", "upper_arm"),
    "elbow": ("LowerArm", "LowerArm", "forearm"),
    "wrist": ("Hand", "Hand", "hand"),
    "hand": ("MiddleProximal", "Middle1", "f_middle.01"),
    "hip": ("UpperLeg", "UpperLeg", "thigh"),
    "knee": ("LowerLeg", "LowerLeg", "shin"),
    "ankle": ("Foot", "Foot", "foot"),
    "foot": ("Toes", "ToeBase", "toe"),
}
_MID_TABLE = {  # our joint -> (VRM, VRoid, Rigify)
    "pelvis": ("hips", "J_Bip_C_Hips", "spine"),
    "spine1": ("spine", "J_Bip_C_Spine", "spine.001"),
    "spine2": ("chest", "J_Bip_C_Chest", "spine.002"),
    "spine3": ("upperChest", "J_Bip_C_UpperChest", "spine.003"),
    "neck": ("neck", "J_Bip_C_Neck", "spine.004"),
    "head": ("head", "J_Bip_C_Head", "spine.006"),
}


# The ``B_*_Left``/``_Right`` style of assimp's BCN_Epileptic test model (tests/data/SOURCES.md):
# the legs hang from ``B_LowerPelvis`` beside the spine, so the pelvis is the root of both;
# no head bone (the face hangs from ``B_Neck``), so the head is ``B_Neck`` and the neck the
# joint below it.
_B_MID = {
    "B_Root_Pelvis_L": "pelvis",
    "B_Spine1": "spine1",
    "B_Spine3": "spine2",
    "B_Spine4": "spine3",
    "B_Root_Neck_T": "neck",
    "B_Neck": "head",
}
_B_SIDE = {
    "collar": "Clavicle",
    "shoulder": "UpperArm",
    "elbow": "ForeArm",
    "wrist": "Hand",
    "hand": "Finger1",
    "hip": "Hip",
    "knee": "Knee",
    "ankle": "Ankle",
    "foot": "Toe",
}


def _tables() -> dict[str, dict[str, str]]:
    vrm, vroid, rigify = {}, {}, {}
    for ours, (a, b, c) in _MID_TABLE.items():
        vrm[a], vroid[b], rigify[c] = ours, ours, ours
    for suffix, (a, b, c) in _SIDE_TABLE.items():
        for side, letter in (("left", "L"), ("right", "R")):
            vrm[f"{side}{a}"] = f"{side}_{suffix}"
            vroid[f"J_Bip_{letter}_{b}"] = f"{side}_{suffix}"
            rigify[f"{c}.{letter}"] = f"{side}_{suffix}"
    mixamo = {k.split(":", 1)[1]: v for k, v in BVH_NAME_MAPS["mixamo"].items()}
    bcn = dict(_B_MID)
    for suffix, stem in _B_SIDE.items():
        for side in ("left", "right"):
            bcn[f"B_{stem}_{side.title()}"] = f"{side}_{suffix}"
    return {
        "crowdstudy": {name: name for name in JOINT_NAMES},
        "mixamo": mixamo,
        "vrm": vrm,
        "vroid": vroid,
        "rigify": rigify,
        "cmu": dict(BVH_NAME_MAPS["cmu"]),
        "bcn": bcn,
    }


#: ``{convention: {file joint name: our joint name}}`` (names as written in the table above).
NAME_MAPS: dict[str, dict[str, str]] = _tables()
#: VRM humanoid bone name -> our joint (for the VRM extensions' own bone tables).
VRM_BONES: dict[str, str] = NAME_MAPS["vrm"]

_CROWD_PREFIX = re.compile(r"^c\d+_")


def normalize_name(name: str, convention: str = "") -> str:
    """A node name reduced for comparison (namespace, case and separators dropped)."""
    if convention == "crowdstudy":
        return _CROWD_PREFIX.sub("", name)
    base = name.split(":", 1)[1] if ":" in name else name
    base = re.sub(r"^mixamorig\d*_", "", base)
    base = re.sub(r"^(DEF|ORG)[-_]", "", base)  # Rigify's deform / original bone copies
    return re.sub(r"[\s_.\-]", "", base).lower()


_NORMALIZED = {conv: {normalize_name(k, conv): v for k, v in table.items()} for conv, table in NAME_MAPS.items()}


def match_names(names: dict[int, str]) -> tuple[str, dict[int, str]]:
    """The convention that maps the most of ``names`` ({node index: node name}) and its
    map ``{node index: our joint name}`` (each of our joints at most once: the node
    nearest the start of the list wins)."""
    best: tuple[str, dict[int, str]] = ("", {})
    for conv, table in _NORMALIZED.items():
        found: dict[int, str] = {}
        used: set[str] = set()
        for node, name in sorted(names.items()):
            ours = table.get(normalize_name(name, conv))
            if ours is not None and ours not in used:
                found[node] = ours
                used.add(ours)
        if len(found) > len(best[1]):
            best = (conv, found)
    return best

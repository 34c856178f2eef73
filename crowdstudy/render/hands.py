"""A relaxed rest pose of the render mesh's fingers.

The skeleton has no finger joints: the fingers keep the pose of the body's rest mesh,
MakeHuman's spread hand curled by :func:`crowdstudy.body.makehuman` (which the physics'
capsule fit reads, so it stays as it is). Spread and curled, the fingers read as claws in
a close-up. For rendering only, :func:`relax_hands` opens the fingers a little about the
knuckles, draws them together towards the hand's middle (a relaxed hand's fingers nearly
touch) and the thumb towards the index, so the hand hangs half closed, as a hand at rest
does.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX

__all__ = ["FINGER_GATHER", "FINGER_OPEN_DEG", "THUMB_GATHER", "relax_hands"]

#: share of the fingers' sideways spread taken away at the fingertips (0 at the knuckles)
FINGER_GATHER = 0.35
#: degrees the fingers are opened about the knuckles (the body's curl bends them 55 degrees)
FINGER_OPEN_DEG = 25.0
#: share of the thumb's sideways distance from the index taken away
THUMB_GATHER = 0.25
_TIPS = 0.05  # m beyond the hand joint (at the knuckles) the curled fingertips reach, roughly


def _smooth(x: np.ndarray, a: float, b: float) -> np.ndarray:
    t = np.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def relax_hands(verts: np.ndarray, joints: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(V, 3) rest vertices with the fingers drawn together (see the module docstring).

    Args:
        verts: (V, 3) float64 m, the rest mesh (T-pose, palms down).
        joints: (24, 3) float64 m, the rest joints.
        weights: (V, 24) skin weights: the vertices weighted to a hand joint move, by their
            weight, so the wrist is unchanged.
    """
    out = np.array(verts, dtype=np.float64)
    for side in ("left", "right"):
        hand, wrist = JOINT_INDEX[f"{side}_hand"], JOINT_INDEX[f"{side}_wrist"]
        w = np.asarray(weights)[:, hand]
        sel = w > 1e-3
        if not sel.any():
            continue
        along = joints[hand] - joints[wrist]
        along = along / np.linalg.norm(along)
        palm = np.array([0.0, 0.0, -1.0]) - along * -along[2]
        palm /= np.linalg.norm(palm)
        lateral = np.cross(along, palm)
        rel = out[sel] - joints[hand]
        u, lat = rel @ along, rel @ lateral
        fingers = u > 0.0
        middle = float(np.median(lat[fingers])) if fingers.any() else 0.0
        # fingers: the spread about the hand's middle shrinks towards the tips
        gather = FINGER_GATHER * _smooth(u, 0.0, _TIPS)
        # the thumb: the vertices that lie far to one side near the knuckles' line
        spread = np.abs(lat - middle)
        thumb = _smooth(spread, 0.035, 0.05) * (1.0 - _smooth(u, 0.0, _TIPS))
        gather = np.maximum(gather, THUMB_GATHER * thumb)
        shift = -(lat - middle) * gather * w[sel]
        # the fingers opened about the knuckles' line: less of a claw, still flexed
        h = rel @ palm
        a = np.radians(FINGER_OPEN_DEG) * _smooth(u, 0.0, 0.6 * _TIPS) * w[sel]
        du = u * np.cos(a) + h * np.sin(a) - u
        dh = h * np.cos(a) - u * np.sin(a) - h
        out[sel] += shift[:, None] * lateral + du[:, None] * along + dh[:, None] * palm
    return out

"""The default human body: MakeHuman's base mesh shaped by its macro targets, rigged to
the toolkit's 24-joint skeleton.

A record ``{"model": "makehuman", "sex", "height" (m), "age" (years, 18-70), "weight"
(0-1), "muscle" (0-1), "proportions" (0-1), "race" ([african, asian, caucasian] >= 0)}``
becomes a :class:`~crowdstudy.body.model.Body`:

1. **Macro targets** (MakeHuman's own blending rules): gender is 0 (female) or 1 (male);
   age in years maps to MakeHuman's age value (11 y -> 0.1875, 25 y -> 0.5, 90 y -> 1) and
   blends the child/young/old targets; muscle and weight blend their min/average/max
   targets around 0.5; the race weights (normalised to sum 1) blend the race-gender-age
   targets; the height and proportions targets follow the same gender-age-muscle-weight
   combinations. ``height`` also picks MakeHuman's height value (taller people get its
   longer-legged proportions), then an isotropic scale about the soles makes the stature
   exact.
2. **Joints** are the means of MakeHuman's joint cubes (shaped by the same targets):
   :data:`~crowdstudy.body.makehuman_assets.JOINT_CUBES`; skin weights are the ``cmu_mb``
   rig's merged into the joints, the four largest per vertex kept.
3. **T-pose.** MakeHuman's base mesh stands in an A-pose with its feet apart; each arm is
   turned at the shoulder, elbow and wrist until it is horizontal, and each leg at the hip
   until the hip-ankle line is vertical seen from the front (linear blend skinning with
   the transferred weights), so the rest pose is the skeleton's T-pose facing +y.
4. **Fingers** are curled into a relaxed pose (a bend about the knuckle line, 55 degrees at
   the finger tips, none at the knuckles); they follow the hand (``left_hand`` /
   ``right_hand``); the thumb follows the palm (wrist).

The surface is MakeHuman's closed body (13,380 vertices) plus the two eyeballs; ``faces``
(the closed body only) serve volumes and overlap, :attr:`Body.surface` (the UV-split
triangles, eyes included) serves rendering.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.body.makehuman_assets import MUSCLES, RACES, WEIGHTS, makehuman_assets
from crowdstudy.body.model import Body, Surface
from crowdstudy.body.skeleton import JOINT_INDEX, NUM_JOINTS, forward_kinematics
from crowdstudy.errors import InvalidInputError

__all__ = [
    "MH_FIELDS",
    "MH_MODEL_VERSION",
    "macro_weights",
    "age_value",
    "makehuman_body",
    "template_surface",
    "FINGER_CURL_DEG",
]

MH_MODEL_VERSION = 1
MH_FIELDS = ("model", "sex", "height", "age", "weight", "muscle", "proportions", "race")
#: relaxed finger curl at the finger tips, degrees
FINGER_CURL_DEG = 55.0
_FINGER_LENGTH = 0.085  # m, knuckle to tip of a middle finger, for the curl's rate
#: stature (m) that MakeHuman's height value 0 / 1 roughly spans for adults, per sex
_HEIGHT_SPAN = {"female": (1.45, 1.78), "male": (1.55, 1.92)}


def age_value(years: float) -> float:
    """MakeHuman's age value (0..1) of an age in years (1 y -> 0, 11 -> 0.1875, 25 -> 0.5, 90 -> 1)."""
    y = float(years)
    if y < 11.0:
        return max(0.0, (y - 1.0) / 10.0 * 0.1875)
    if y < 25.0:
        return 0.1875 + (y - 11.0) / 14.0 * 0.3125
    return min(1.0, 0.5 + (y - 25.0) / 65.0 * 0.5)


def _three(v: float) -> tuple[float, float, float]:
    """(min, average, max) weights of a 0..1 value with 0.5 = average (MakeHuman's rule)."""
    lo, hi = max(0.0, 1.0 - 2.0 * v), max(0.0, 2.0 * v - 1.0)
    return lo, 1.0 - lo - hi, hi


def macro_weights(
    sex: str, years: float, muscle: float, weight: float, height: float, proportions: float, race
) -> dict[str, float]:
    """{target name: weight} of a shape (the names of ``makehuman_assets.target_names``)."""
    a = age_value(years)
    if a < 0.1875:
        raise InvalidInputError(f"age: the MakeHuman model covers ages 11 and over, got {years}")
    if a < 0.5:
        young = (a - 0.1875) / 0.3125
        ages = {"child": 1.0 - young, "young": young, "old": 0.0}
    else:
        old = 2.0 * a - 1.0
        ages = {"child": 0.0, "young": 1.0 - old, "old": old}
    r = np.asarray(race, dtype=np.float64)
    r = r / r.sum()
    m3, w3 = dict(zip(MUSCLES, _three(muscle), strict=True)), dict(zip(WEIGHTS, _three(weight), strict=True))
    h_lo, h_hi = max(0.0, 1.0 - 2.0 * height), max(0.0, 2.0 * height - 1.0)
    p_lo, p_hi = max(0.0, 1.0 - 2.0 * proportions), max(0.0, 2.0 * proportions - 1.0)
    out: dict[str, float] = {}
    for age, wa in ages.items():
        if wa <= 0.0:
            continue
        for race_name, wr in zip(RACES, r, strict=True):
            out[f"{race_name}-{sex}-{age}"] = wa * wr
        for mname, wm in m3.items():
            for wname, ww in w3.items():
                base = wa * wm * ww
                if base <= 0.0:
                    continue
                stem = f"{sex}-{age}-{mname}-{wname}"
                out[f"universal-{stem}"] = base
                out[f"height/{stem}-minheight"] = base * h_lo
                out[f"height/{stem}-maxheight"] = base * h_hi
                out[f"proportions/{stem}-idealproportions"] = base * p_hi
                out[f"proportions/{stem}-uncommonproportions"] = base * p_lo
    return {k: v for k, v in out.items() if v > 0.0}


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation matrix taking direction ``a`` to direction ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(np.dot(a, b))
    if c < -1.0 + 1e-9:
        raise InvalidInputError("T-pose: a bone points opposite to its target direction")
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def _t_pose(verts: np.ndarray, joints: np.ndarray, weights: np.ndarray):
    """Turn both arms horizontal (A-pose -> T-pose) by linear blend skinning."""
    local = np.tile(np.eye(3), (NUM_JOINTS, 1, 1))
    for side, sign in (("left", -1.0), ("right", 1.0)):
        target = np.array([sign, 0.0, 0.0])
        chain = [JOINT_INDEX[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist", "hand")]
        glob = np.eye(3)
        for k in range(3):
            j, child = chain[k], chain[k + 1]
            bone = glob @ (joints[child] - joints[j])
            new = _align(bone, target) @ glob
            local[j] = glob.T @ new
            glob = new
        # legs: MakeHuman stands with its feet apart; turn each leg about the forward axis
        # until the hip-ankle line is vertical seen from the front (the skeleton's stance)
        hip, ankle = JOINT_INDEX[f"{side}_hip"], JOINT_INDEX[f"{side}_ankle"]
        leg = joints[ankle] - joints[hip]
        local[hip] = _align(np.array([leg[0], 0.0, leg[2]]), np.array([0.0, 0.0, -1.0]))
    glob, pos = forward_kinematics(joints, local, joints[0], rotations_are_matrices=True)
    offset = pos - np.einsum("jab,jb->ja", glob, joints)
    blended = (weights @ glob.reshape(NUM_JOINTS, 9)).reshape(-1, 3, 3)
    posed = np.einsum("vab,vb->va", blended, verts) + weights @ offset
    return posed, pos


def _curl_fingers(verts: np.ndarray, joints: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Bend the fingers (vertices weighted to the hand joints) towards the palm."""
    out = verts.copy()
    kappa = np.radians(FINGER_CURL_DEG) / _FINGER_LENGTH  # rad per metre along the finger
    radius = 1.0 / kappa
    for side in ("left", "right"):
        hand, wrist = JOINT_INDEX[f"{side}_hand"], JOINT_INDEX[f"{side}_wrist"]
        w = weights[:, hand]
        sel = w > 1e-3
        along = joints[hand] - joints[wrist]
        along /= np.linalg.norm(along)
        palm = np.array([0.0, 0.0, -1.0])  # T-pose: palms face the floor
        palm -= along * palm.dot(along)
        palm /= np.linalg.norm(palm)
        rel = verts[sel] - joints[hand]
        u = rel @ along
        h = rel @ palm
        rest = rel - np.outer(u, along) - np.outer(h, palm)
        phi = kappa * np.clip(u, 0.0, None) * w[sel]
        u_new = np.where(u > 0, (radius - h) * np.sin(phi), u)
        h_new = np.where(u > 0, radius - (radius - h) * np.cos(phi), h)
        out[sel] = joints[hand] + np.outer(u_new, along) + np.outer(h_new, palm) + rest
    return out


def _top4(weights: np.ndarray) -> np.ndarray:
    """The four largest weights of each vertex, renormalised (what GPU skinning and the
    metrics' kernels use; every body model keeps at most four)."""
    keep = np.argsort(-weights, axis=1, kind="stable")[:, :4]
    out = np.zeros_like(weights)
    rows = np.arange(len(weights))[:, None]
    out[rows, keep] = weights[rows, keep]
    return out / out.sum(axis=1, keepdims=True)


def _split_surface(quads: np.ndarray, quad_uv: np.ndarray, uv: np.ndarray):
    """Render vertices: one per distinct (vertex, uv) corner pair; triangles on them."""
    corners = np.stack([quads.reshape(-1), quad_uv.reshape(-1)], axis=1)
    pairs, inverse = np.unique(corners, axis=0, return_inverse=True)
    tri_corners = inverse.reshape(-1, 4)
    faces = np.concatenate([tri_corners[:, [0, 1, 2]], tri_corners[:, [0, 2, 3]]])
    return pairs[:, 0].astype(np.int32), uv[pairs[:, 1]].astype(np.float32), faces.astype(np.int32)


_TEMPLATE: dict = {}


def template_surface() -> Surface:
    """The UV-split render surface shared by every MakeHuman body (body then eyes)."""
    if "surface" not in _TEMPLATE:
        a = makehuman_assets()
        quads = np.concatenate([a["quads"], a["eye_quads"]])
        quad_uv = np.concatenate([a["quad_uv"], a["eye_quad_uv"]])
        vertex, uv, faces = _split_surface(quads, quad_uv, a["uv"])
        part = np.where(vertex >= int(a["n_body"]), 1, 0).astype(np.int8)  # 0 body, 1 eye
        _TEMPLATE["surface"] = Surface(vertex=vertex, uv=uv, faces=faces, part=part)
        tri = np.concatenate([a["quads"][:, [0, 1, 2]], a["quads"][:, [0, 2, 3]]]).astype(np.int32)
        tri.flags.writeable = False  # shared by every body
        _TEMPLATE["faces"] = tri
    return _TEMPLATE["surface"]


def makehuman_body(record: dict, fields: dict) -> Body:
    """The Body of a MakeHuman record whose fields were checked by the loader.

    ``fields``: {"sex", "height", "age", "weight", "muscle", "proportions", "race" (3,)}.
    """
    a = makehuman_assets()
    sex, height = fields["sex"], float(fields["height"])
    lo, hi = _HEIGHT_SPAN[sex]
    h_value = float(np.clip((height - lo) / (hi - lo), 0.0, 1.0))
    mw = macro_weights(
        sex, fields["age"], fields["muscle"], fields["weight"], h_value, fields["proportions"], fields["race"]
    )
    names = [str(n) for n in a["target_names"]]
    index = {n: i for i, n in enumerate(names)}
    ids = np.array([index[n] for n in mw])
    w = np.array(list(mw.values()))
    verts = a["base"].astype(np.float64) + np.einsum("t,tvc->vc", w, a["targets"][ids].astype(np.float64))
    cubes = a["cube_base"].astype(np.float64) + np.einsum("t,tvc->vc", w, a["cube_targets"][ids].astype(np.float64))
    joints = np.array([cubes[a["joint_cube_index"][j, : a["joint_counts"][j]]].mean(axis=0) for j in range(NUM_JOINTS)])
    if "weights" not in _TEMPLATE:
        _TEMPLATE["weights"] = _top4(a["weights"].astype(np.float64))
        _TEMPLATE["weights32"] = _TEMPLATE["weights"].astype(np.float32)
        # shared by every body: read-only, so per-array results (digests) can be kept
        _TEMPLATE["weights32"].flags.writeable = False
    weights = _TEMPLATE["weights"]
    verts, joints = _t_pose(verts, joints, weights)
    verts = _curl_fingers(verts, joints, weights)
    n_body = int(a["n_body"])
    floor = verts[:n_body, 2].min()
    stature = verts[:n_body, 2].max() - floor
    scale = height / stature
    origin = np.array([joints[0, 0], joints[0, 1], floor])
    verts = (verts - origin) * scale
    joints = (joints - origin) * scale
    pelvis = joints[0].copy()
    verts -= pelvis
    joints -= pelvis
    surface = template_surface()
    return Body(
        record=dict(record),
        rest_joints=joints,
        rest_vertices=verts,
        faces=_TEMPLATE["faces"],
        weights=_TEMPLATE["weights32"],
        pelvis_height=float(pelvis[2]),
        template_key=f"makehuman-v{MH_MODEL_VERSION}",
        surface=surface,
    )

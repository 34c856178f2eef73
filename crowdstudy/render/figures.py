"""Low-detail people for the audience around the floor: decimated MakeHuman bodies.

The study's characters stand in a hall full of people (:mod:`crowdstudy.render.venue`).
Those are drawn as static, vertex-lit geometry, hundreds of them, so each must be cheap;
but a lathe of a few boxes reads as a block in the wide view V1. A figure here is the same
MakeHuman body as the characters (one woman, one man of average build), simplified to a
few hundred triangles (:data:`FACES`: near and far), posed by rotating the arms about the
shoulders (hanging, or one or both raised: a crowd at a concert), and coloured per vertex
by body part: trousers, shirt, skin, hair and shoes (:data:`PARTS`).

A template is made once per process and scaled to each figure's stature and girth by the
venue; the vertices carry their height in the figure, so the shader's bob on the beat
lifts the head and leaves the feet on the floor.
"""

from __future__ import annotations

import functools
from typing import Literal

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX as J

__all__ = ["FACES", "PARTS", "figure_template"]

#: triangles of a near (detail 1) and a far (detail 0) figure
FACES = {1: 450, 0: 160}
#: part ids of :func:`figure_template`'s vertices, the venue's colour slots
PARTS = ("trousers", "shirt", "skin", "hair", "shoes")
_RECORDS = {
    "female": {"model": "makehuman", "sex": "female", "height": 1.65, "age": 30, "race": [0.34, 0.33, 0.33]},
    "male": {"model": "makehuman", "sex": "male", "height": 1.75, "age": 30, "race": [0.34, 0.33, 0.33]},
}
#: arm angle (radians, about the front axis) below the shoulder of a hanging arm / above it of a raised one
_HANG, _RAISE = np.radians(78.0), np.radians(62.0)


def _arm_weight(weights: np.ndarray, side: str) -> np.ndarray:
    cols = [J[f"{side}_{j}"] for j in ("shoulder", "elbow", "wrist", "hand")]
    return weights[:, cols].sum(axis=1)


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _pose(verts: np.ndarray, joints: np.ndarray, weights: np.ndarray, arms: str) -> np.ndarray:
    """The T-pose ``verts`` with the arms hanging or raised (linear blend about the shoulders)."""
    out = verts.copy()
    for side, sign in (("left", -1.0), ("right", 1.0)):  # the left arm lies along -x
        raised = arms == "both" or (arms == "one" and side == "right")
        # R_y(a) turns the arm (sign, 0, 0) to (sign cos a, 0, -sign sin a)
        angle = sign * (-_RAISE if raised else _HANG)
        rot = _rot_y(angle)
        s = joints[J[f"{side}_shoulder"]]
        w = _arm_weight(weights, side)[:, None]
        out = (1.0 - w) * out + w * ((out - s) @ rot.T + s)
    return out


def _parts(verts: np.ndarray, joints: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(V,) part id (:data:`PARTS`) of each rest-pose vertex."""
    head = weights[:, [J["neck"], J["head"]]].sum(axis=1)
    hands = weights[:, [J[f"{s}_{j}"] for s in ("left", "right") for j in ("wrist", "hand")]].sum(axis=1)
    legs = weights[:, [J[n] for n in ("left_hip", "right_hip", "left_knee", "right_knee")]].sum(axis=1)
    feet = weights[:, [J[n] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]].sum(axis=1)
    h = joints[J["head"]]
    part = np.full(len(verts), 1)  # shirt
    waist = joints[J["pelvis"], 2] + 0.6 * (joints[J["spine1"], 2] - joints[J["pelvis"], 2])
    part[(legs > 0.5) | ((verts[:, 2] < waist) & (hands < 0.5))] = 0
    part[feet > 0.5] = 0
    part[(verts[:, 2] < joints[J["left_ankle"], 2] + 0.03) & (hands < 0.5)] = 4
    part[hands > 0.5] = 2
    part[head > 0.5] = 2
    crown = verts[:, 2] > h[2] + 0.06
    back = (verts[:, 2] > h[2] - 0.03) & (verts[:, 1] < h[1] - 0.02)
    part[(head > 0.5) & (crown | back)] = 3
    return part


@functools.cache
def _base(sex: str, detail: int):
    """(points, faces, weights, joints, parts) of the decimated T-pose body, 1 m tall, feet at z = 0."""
    from crowdstudy.body import load_body
    from crowdstudy.render.bodies import _cluster_mean, _decimate

    body = load_body(_RECORDS[sex])
    faces = np.asarray(body.faces, dtype=np.int64)
    used = np.unique(faces)
    verts = np.asarray(body.rest_vertices, dtype=np.float64)
    weights = np.asarray(body.weights, dtype=np.float64)
    joints = np.asarray(body.rest_joints, dtype=np.float64)
    parts = _parts(verts, joints, weights)
    dec = _decimate(verts, faces, FACES[detail])
    if dec is None:  # fast-simplification missing: the full mesh
        remap = np.full(len(verts), -1)
        remap[used] = np.arange(len(used))
        dec_faces, mapping = remap[faces], remap
    else:
        dec_faces, mapping = dec
    n = int(mapping.max()) + 1
    points = _cluster_mean(verts, mapping, n)
    w = _cluster_mean(weights, mapping, n)
    # one colour per face (no colour smeared across a big triangle): the part of the full
    # mesh's face under its centroid; a vertex is copied once per part of its faces
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    full = parts[faces]
    full_part = np.where(full[:, 1] == full[:, 2], full[:, 1], full[:, 0])
    _, near = cKDTree(verts[faces].mean(axis=1)).query(points[dec_faces].mean(axis=1))
    face_part = full_part[near]
    corner = np.stack([dec_faces.reshape(-1), np.repeat(face_part, 3)], axis=1)
    pairs, inverse = np.unique(corner, axis=0, return_inverse=True)
    floor, top = points[:, 2].min(), points[:, 2].max()
    scale = 1.0 / (top - floor)
    shift = np.array([0.0, 0.0, floor])
    return (
        (points[pairs[:, 0]] - shift) * scale,
        inverse.reshape(-1, 3),
        w[pairs[:, 0]],
        (joints - shift) * scale,
        pairs[:, 1],
    )


def figure_template(
    arms: Literal["none", "one", "both"], detail: int, sex: Literal["female", "male"] = "female"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(V, 3) points, (V, 3) unit normals, (T, 3) faces, (V,) part id (:data:`PARTS`) of a
    figure 1 m tall, feet on z = 0, facing +y with the shoulders along x.

    ``arms``: "none" (hanging), "one" (the right) or "both" raised; ``detail``: 1 (near,
    :data:`FACES`) or 0 (far)."""
    from crowdstudy.render.bodies import vertex_normals

    points, faces, weights, joints, parts = _base(sex, int(detail))
    posed = _pose(points, joints, weights, arms)
    normals = vertex_normals(posed, faces)
    flat = np.linalg.norm(normals, axis=1) < 1e-6  # a vertex of degenerate faces only
    normals[flat] = (0.0, 0.0, 1.0)
    return posed, normals, faces, parts

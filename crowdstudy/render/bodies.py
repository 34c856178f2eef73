"""GPU-ready body data: template groups, per-vertex regions, rest-shape textures.

Characters whose bodies share ``template_key`` (same faces, vertex count and skinning
weights) form one *group*, drawn with one instanced call; their individual rest shapes
(positions and normals) are pulled from a texture by the vertex shader.
"""

from __future__ import annotations

import dataclasses
import hashlib
import warnings

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["BodyGroup", "group_bodies", "region_scores", "vertex_normals", "default_body_loader",
           "REGION_JOINTS"]

#: Joints (SMPL order) whose skin weights define the colour regions of palette.REGIONS.
REGION_JOINTS = {
    0: (15, 12, 20, 21, 22, 23),      # skin: head, neck, wrists, hands
    2: (3, 6, 9, 13, 14, 16, 17),     # shirt: spine, collars, upper arms
    3: (18, 19),                      # sleeve: forearms (skin or shirt per character)
    4: (0, 1, 2, 4, 5),               # trousers: pelvis, thighs, shins
    5: (7, 8, 10, 11),                # shoes: ankles, feet
}
_HEAD = 15


def default_body_loader(record: dict):
    """``crowdstudy.body.load_body`` (imported on first use)."""
    from crowdstudy.body import load_body

    return load_body(record)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals. ``vertices`` (V, 3), ``faces`` (F, 3) -> (V, 3)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length < 1e-12, 1.0, length)


def _full_weights(body, n_vertices: int) -> np.ndarray:
    w = getattr(body, "weights", None)
    if w is not None and np.shape(w) == (n_vertices, 24):
        return np.asarray(w, dtype=np.float64)
    idx, val = body.top_weights()
    full = np.zeros((n_vertices, 24))
    np.add.at(full, (np.repeat(np.arange(n_vertices), idx.shape[1]), np.asarray(idx).reshape(-1)),
              np.asarray(val, dtype=np.float64).reshape(-1))
    return full


def region_scores(body) -> np.ndarray:
    """(V, 6) float32 per-vertex scores of the colour regions (palette.REGIONS order).

    A fragment takes the region with the highest interpolated score, so the borders
    (collar, cuffs, waist, hairline) follow smooth curves over the mesh. Region scores are
    the summed skin weights of the joints in :data:`REGION_JOINTS`; hair takes over the
    head's score above the hairline (more than 12.5 cm above the head joint, or behind it:
    the character faces +y).
    """
    verts = np.asarray(body.rest_vertices, dtype=np.float64)
    weights = _full_weights(body, len(verts))
    scores = np.zeros((len(verts), 6))
    for region, joints in REGION_JOINTS.items():
        scores[:, region] = weights[:, list(joints)].sum(axis=1)
    rel = verts - np.asarray(body.rest_joints, dtype=np.float64)[_HEAD]
    hairness = np.clip(np.maximum.reduce([(rel[:, 2] - 0.115) / 0.02,
                                          np.minimum((0.0 - rel[:, 1]) / 0.02, (rel[:, 2] - 0.03) / 0.02),
                                          np.minimum((0.04 - rel[:, 1]) / 0.02, (rel[:, 2] - 0.095) / 0.02)]), 0, 1)
    head = weights[:, _HEAD] + weights[:, 12] * 0.0
    scores[:, 1] = head * hairness
    scores[:, 0] -= head * hairness
    return scores.astype(np.float32)


_DECIMATIONS: dict[tuple, tuple] = {}


def _decimation(vertices: np.ndarray, faces: np.ndarray, max_faces: int | None):
    """(faces (F', 3), mapping (V,) original -> decimated vertex, -1 for dropped) or None.

    Cached per (mesh, max_faces) in the process: every character of a template shares it.
    """
    if max_faces is None or len(faces) <= max_faces:
        return None
    key = (hashlib.sha1(np.ascontiguousarray(vertices, dtype=np.float64).tobytes()
                        + np.ascontiguousarray(faces, dtype=np.int64).tobytes()).hexdigest(), int(max_faces))
    if key not in _DECIMATIONS:
        if len(_DECIMATIONS) > 64:
            _DECIMATIONS.clear()
        _DECIMATIONS[key] = _decimate(vertices, faces, max_faces)
    return _DECIMATIONS[key]


def _decimate(vertices: np.ndarray, faces: np.ndarray, max_faces: int):
    try:
        import fast_simplification
    except ImportError:
        warnings.warn("fast-simplification is not installed: rendering the full-resolution body meshes "
                      "(slower); `pip install 'crowdstudy[render]'`", RuntimeWarning, stacklevel=3)
        return None
    vertices, faces = np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)  # writable copies
    _, _, collapses = fast_simplification.simplify(vertices, faces, target_count=int(max_faces),
                                                   return_collapses=True)
    _, dec_faces, mapping = fast_simplification.replay_simplification(vertices, faces, collapses)
    return np.asarray(dec_faces, dtype=np.int64), np.asarray(mapping, dtype=np.int64)


def _cluster_mean(values: np.ndarray, mapping: np.ndarray, n_out: int) -> np.ndarray:
    keep = mapping >= 0
    out = np.zeros((n_out,) + values.shape[1:])
    count = np.zeros(n_out)
    np.add.at(out, mapping[keep], values[keep])
    np.add.at(count, mapping[keep], 1.0)
    return out / np.maximum(count, 1.0).reshape((-1,) + (1,) * (values.ndim - 1))


@dataclasses.dataclass
class BodyGroup:
    """Characters sharing one mesh topology and skinning weights.

    Attributes:
        members: (M,) int, character indices.
        faces: (F, 3) uint32.
        joints: (V, 4) int32 bone indices; weights: (V, 4) float32 (rows sum to 1).
        scores: (V, 6) float32 colour-region scores (see :func:`region_scores`).
        rest: (M, V, 2, 4) float32, rest position and rest normal of each member's vertices.
    """
    key: str
    members: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    scores: np.ndarray
    rest: np.ndarray

    @property
    def n_vertices(self) -> int:
        return self.joints.shape[0]


def group_bodies(bodies: list, *, max_faces: int | None = 8000) -> list[BodyGroup]:
    """Group loaded bodies by template (and identical skinning weights).

    Args:
        bodies: objects with the ``crowdstudy.body.Body`` interface.
        max_faces: level of detail: templates with more faces are decimated once (quadric
            edge collapses of the first member, replayed on the topology) to about this
            many faces; every member's decimated vertex is the mean of the original
            vertices it merges, so shapes stay consistent. None keeps the full meshes.
    """
    groups: dict[tuple, dict] = {}
    for i, body in enumerate(bodies):
        for name in ("rest_vertices", "faces", "top_weights", "skinning_matrices", "rest_joints"):
            if not hasattr(body, name):
                raise InvalidInputError(f"bodies[{i}]: body object lacks {name!r} (expected a crowdstudy.body.Body)")
        faces = np.ascontiguousarray(body.faces, dtype=np.int64)
        verts = np.asarray(body.rest_vertices, dtype=np.float64)
        weights = _full_weights(body, len(verts))
        key = (str(getattr(body, "template_key", "")), faces.shape, len(verts),
               hash(faces.tobytes()), hash(np.asarray(body.top_weights()[0]).tobytes()))
        if key not in groups:
            dec = _decimation(verts, faces, max_faces)
            if dec is None:
                mapping, dec_faces, n_out = np.arange(len(verts)), faces, len(verts)
            else:
                dec_faces, mapping = dec
                n_out = int(mapping.max()) + 1
            w = _cluster_mean(weights, mapping, n_out)
            joints = np.argsort(-w, axis=1)[:, :4].astype(np.int32)
            vals = np.take_along_axis(w, joints, axis=1)
            vals = (vals / np.maximum(vals.sum(axis=1, keepdims=True), 1e-12)).astype(np.float32)
            groups[key] = {"members": [], "faces": np.ascontiguousarray(dec_faces, dtype=np.uint32),
                           "joints": joints, "weights": vals, "mapping": mapping, "n_out": n_out,
                           "scores": _cluster_mean(region_scores(body), mapping, n_out).astype(np.float32), "rest": []}
        g = groups[key]
        dec_verts = _cluster_mean(verts, g["mapping"], g["n_out"])
        rest = np.zeros((g["n_out"], 2, 4), dtype=np.float32)
        rest[:, 0, :3] = dec_verts
        rest[:, 0, 3] = 1.0
        rest[:, 1, :3] = vertex_normals(dec_verts, g["faces"])
        g["members"].append(i)
        g["rest"].append(rest)
    return [BodyGroup(key=key[0], members=np.asarray(g["members"]), faces=g["faces"], joints=g["joints"],
                      weights=g["weights"], scores=g["scores"], rest=np.stack(g["rest"])) for key, g in groups.items()]

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

__all__ = ["BodyGroup", "group_bodies", "region_scores", "vertex_normals", "default_body_loader", "REGION_JOINTS"]

#: Joints (SMPL order) whose skin weights define the colour regions of palette.REGIONS.
REGION_JOINTS = {
    0: (15, 12, 20, 21, 22, 23),  # skin: head, neck, wrists, hands
    2: (3, 6, 9, 13, 14, 16, 17),  # shirt: spine, collars, upper arms
    3: (18, 19),  # sleeve: forearms (skin or shirt per character)
    4: (0, 1, 2, 4, 5),  # trousers: pelvis, thighs, shins
    5: (7, 8, 10, 11),  # shoes: ankles, feet
}
_HEAD = 15
#: textured bodies (face, hands and feet in the geometry, not in colour regions) keep this
#: many times the faces ``max_faces`` asks of a region-coloured mannequin (at 1080p: 6,000
#: faces for characters over 600 px tall, 3,000 and 1,500 below; the full mesh has 27,000)
SURFACE_FACE_SCALE = 2


def default_body_loader(record: dict):
    """``crowdstudy.body.load_body`` (imported on first use)."""
    from crowdstudy.body import load_body

    return load_body(record)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, weld: np.ndarray | None = None) -> np.ndarray:
    """Area-weighted unit vertex normals. ``vertices`` (V, 3), ``faces`` (F, 3) -> (V, 3).

    ``weld`` (V,) optional: vertices with the same value (a UV-split surface's copies of one
    point) share one normal, summed over all their faces, so shading is smooth across seams.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    key = np.arange(len(v)) if weld is None else np.asarray(weld, dtype=np.int64)
    at = key[f.T.reshape(-1)]  # corner 0 of every face, then corner 1, then corner 2
    m = int(key.max()) + 1 if len(key) else 0
    n = np.stack([np.bincount(at, weights=np.tile(fn[:, c], 3), minlength=m) for c in range(3)], axis=1)[key]
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length < 1e-12, 1.0, length)


def _full_weights(body, n_vertices: int) -> np.ndarray:
    w = getattr(body, "weights", None)
    if w is not None and np.shape(w) == (n_vertices, 24):
        return np.asarray(w, dtype=np.float64)
    idx, val = body.top_weights()
    full = np.zeros((n_vertices, 24))
    np.add.at(
        full,
        (np.repeat(np.arange(n_vertices), idx.shape[1]), np.asarray(idx).reshape(-1)),
        np.asarray(val, dtype=np.float64).reshape(-1),
    )
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
    hairness = np.clip(
        np.maximum.reduce(
            [
                (rel[:, 2] - 0.115) / 0.02,
                np.minimum((0.0 - rel[:, 1]) / 0.02, (rel[:, 2] - 0.03) / 0.02),
                np.minimum((0.04 - rel[:, 1]) / 0.02, (rel[:, 2] - 0.095) / 0.02),
            ]
        ),
        0,
        1,
    )
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
    key = (
        hashlib.sha1(
            np.ascontiguousarray(vertices, dtype=np.float64).tobytes()
            + np.ascontiguousarray(faces, dtype=np.int64).tobytes()
        ).hexdigest(),
        int(max_faces),
    )
    if key not in _DECIMATIONS:
        if len(_DECIMATIONS) > 64:
            _DECIMATIONS.clear()
        _DECIMATIONS[key] = _decimate(vertices, faces, max_faces)
    return _DECIMATIONS[key]


def _decimate(vertices: np.ndarray, faces: np.ndarray, max_faces: int):
    try:
        import fast_simplification
    except ImportError:
        warnings.warn(
            "fast-simplification is not installed: rendering the full-resolution body meshes "
            "(slower); `pip install 'crowdstudy[render]'`",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    vertices, faces = np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int64)  # writable copies
    _, _, collapses = fast_simplification.simplify(vertices, faces, target_count=int(max_faces), return_collapses=True)
    _, dec_faces, mapping = fast_simplification.replay_simplification(vertices, faces, collapses)
    return np.asarray(dec_faces, dtype=np.int64), np.asarray(mapping, dtype=np.int64)


def _cluster_mean(values: np.ndarray, mapping: np.ndarray, n_out: int) -> np.ndarray:
    keep = mapping >= 0
    idx = mapping[keep]
    vals = np.asarray(values, dtype=np.float64)[keep].reshape(int(keep.sum()), -1)
    out = np.stack([np.bincount(idx, weights=vals[:, c], minlength=n_out) for c in range(vals.shape[1])], axis=1)
    count = np.bincount(idx, minlength=n_out).astype(np.float64)
    out /= np.maximum(count, 1.0)[:, None]
    return out.reshape((n_out,) + np.shape(values)[1:])


@dataclasses.dataclass
class BodyGroup:
    """Characters sharing one mesh topology and skinning weights.

    Attributes:
        members: (M,) int, character indices.
        faces: (F, 3) uint32.
        joints: (V, 4) int32 bone indices; weights: (V, 4) float32 (rows sum to 1).
        scores: (V, 6) float32 colour-region scores (see :func:`region_scores`).
        rest: (M, V, 2, 4) float32, rest position and rest normal of each member's vertices.
        material: (V, 3) float32 texture coordinates and part (1 = eye) of textured groups.
        textured: whether the group is drawn with per-character textures.
    """

    key: str
    members: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    scores: np.ndarray
    rest: np.ndarray
    material: np.ndarray | None = None
    textured: bool = False

    @property
    def n_vertices(self) -> int:
        return self.joints.shape[0]


def group_bodies(
    bodies: list, *, max_faces: int | None = 8000, surface_scale: float = SURFACE_FACE_SCALE
) -> list[BodyGroup]:
    """Group loaded bodies by template (and identical skinning weights).

    Args:
        bodies: objects with the ``crowdstudy.body.Body`` interface.
        max_faces: level of detail: templates with more faces are decimated once (quadric
            edge collapses of the first member, replayed on the topology) to about this
            many faces; every member's decimated vertex is the mean of the original
            vertices it merges, so shapes stay consistent. None keeps the full meshes.
        surface_scale: textured bodies (a :class:`~crowdstudy.body.model.Surface`) keep
            ``max_faces`` times this many faces.
    """
    groups: dict[tuple, dict] = {}
    for i, body in enumerate(bodies):
        for name in ("rest_vertices", "faces", "top_weights", "skinning_matrices", "rest_joints"):
            if not hasattr(body, name):
                raise InvalidInputError(f"bodies[{i}]: body object lacks {name!r} (expected a crowdstudy.body.Body)")
        verts, faces, weights, uv, part, weld = _render_arrays(body)
        key = (
            str(getattr(body, "template_key", "")),
            faces.shape,
            len(verts),
            uv is not None,
            hash(faces.tobytes()),
            hash(np.asarray(body.top_weights()[0]).tobytes()),
        )
        if key not in groups:
            if uv is None:
                dec = _decimation(verts, faces, max_faces)
                if dec is None:
                    mapping, dec_faces = np.arange(len(verts)), faces
                else:
                    dec_faces, mapping = dec
                cluster, gather, new_uv = mapping, np.arange(int(mapping.max()) + 1), None
            else:
                dec = _surface_decimation(
                    verts, faces, weld, uv, None if max_faces is None else int(max_faces * surface_scale), part
                )
                if dec is None:
                    dec_faces, cluster, gather, new_uv = faces, np.arange(len(verts)), np.arange(len(verts)), uv
                else:
                    dec_faces, cluster, gather, new_uv = dec
            n_clusters = int(cluster.max()) + 1
            n_out = len(gather)
            w = _cluster_mean(weights, cluster, n_clusters)[gather]
            joints = np.argsort(-w, axis=1)[:, :4].astype(np.int32)
            vals = np.take_along_axis(w, joints, axis=1)
            vals = (vals / np.maximum(vals.sum(axis=1, keepdims=True), 1e-12)).astype(np.float32)
            scores = (
                np.zeros((n_out, 6), np.float32)
                if uv is not None
                else _cluster_mean(region_scores(body), cluster, n_clusters)[gather].astype(np.float32)
            )
            material = np.zeros((n_out, 3), np.float32)
            if uv is not None:
                material[:, :2] = new_uv
                material[:, 2] = _cluster_mean(part.astype(np.float64), cluster, n_clusters)[gather] > 0.5
            groups[key] = {
                "members": [],
                "faces": np.ascontiguousarray(dec_faces, dtype=np.uint32),
                "joints": joints,
                "weights": vals,
                "cluster": cluster,
                "gather": gather,
                "n_clusters": n_clusters,
                "scores": scores,
                "material": material,
                "textured": uv is not None,
                "weld": None if uv is None else (weld if dec is None else gather),
                "rest": [],
            }
        g = groups[key]
        dec_verts = _cluster_mean(verts, g["cluster"], g["n_clusters"])[g["gather"]]
        rest = np.zeros((len(g["gather"]), 2, 4), dtype=np.float32)
        rest[:, 0, :3] = dec_verts
        rest[:, 0, 3] = 1.0
        rest[:, 1, :3] = vertex_normals(dec_verts, g["faces"], g["weld"])
        g["members"].append(i)
        g["rest"].append(rest)
    return [
        BodyGroup(
            key=key[0],
            members=np.asarray(g["members"]),
            faces=g["faces"],
            joints=g["joints"],
            weights=g["weights"],
            scores=g["scores"],
            rest=np.stack(g["rest"]),
            material=g["material"],
            textured=g["textured"],
        )
        for key, g in groups.items()
    ]


def _render_arrays(body):
    """(vertices, faces, weights (V, 24), uv or None, part or None, weld or None) to draw.

    A body with a :class:`~crowdstudy.body.model.Surface` is drawn on its UV-split render
    vertices (``weld``: the body vertex of each, so normals stay smooth across seams)."""
    verts = np.asarray(body.rest_vertices, dtype=np.float64)
    weights = _full_weights(body, len(verts))
    surface = getattr(body, "surface", None)
    if surface is None:
        return verts, np.ascontiguousarray(body.faces, dtype=np.int64), weights, None, None, None
    weld = np.asarray(surface.vertex, dtype=np.int64)
    return (
        verts[weld],
        np.ascontiguousarray(surface.faces, dtype=np.int64),
        weights[weld],
        np.asarray(surface.uv),
        np.asarray(surface.part),
        weld,
    )


def _surface_decimation(
    verts: np.ndarray,
    faces: np.ndarray,
    weld: np.ndarray,
    uv: np.ndarray,
    max_faces: int | None,
    part: np.ndarray | None = None,
):
    """Decimate a UV-split surface without tearing its seams or mixing its charts.

    The welded mesh (render vertices merged by ``weld``) is simplified, so the copies of a
    cluster on both sides of a seam coincide: no cracks. Each decimated face lies on one
    UV chart (charts: the connected components of the split surface) and each of its
    corners takes the texture coordinate of the closest point of the full surface in that
    chart, on the face's side of any cut through the chart
    (:func:`~crowdstudy.render.uv_transfer.project_face_uvs`); a new render vertex is a
    (welded cluster, texture coordinate) pair.

    Returns ``(faces (F', 3), cluster (R,) render vertex -> welded cluster, gather (R',)
    new vertex -> cluster, uv (R', 2))`` or None when no decimation is needed. Positions,
    weights and normals are per cluster (``values[cluster]`` means, then ``[gather]``).
    Cached per mesh (topology and positions) and face count."""
    if max_faces is None or len(faces) <= max_faces:
        return None
    # keyed on the positions too: the group's first body decides the decimation, so a
    # key on the topology alone made a crowd's meshes depend on the crowds drawn before
    key = (
        "surface-v5",
        hashlib.sha1(
            np.ascontiguousarray(faces, dtype=np.int64).tobytes()
            + np.ascontiguousarray(weld, dtype=np.int64).tobytes()
            + np.ascontiguousarray(verts, dtype=np.float64).tobytes()
        ).hexdigest(),
        int(max_faces),
    )
    if key in _DECIMATIONS:
        return _DECIMATIONS[key]
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from crowdstudy.render.uv_transfer import fit_vertex_uvs, project_face_uvs

    n_r = len(verts)
    rows = np.repeat(np.arange(len(faces)), 3)
    incidence = coo_matrix((np.ones(len(rows)), (faces.reshape(-1), rows)), shape=(n_r, len(faces))).tocsr()
    _, chart = connected_components(incidence @ incidence.T, directed=False)
    n_w = int(weld.max()) + 1
    welded = np.zeros((n_w, 3))
    welded[weld] = verts
    dec = _decimation(welded, weld[faces], max_faces)
    if dec is None:
        return None
    w_faces, w_map = dec
    w_faces = np.asarray(w_faces, dtype=np.int64)
    cluster = w_map[weld].astype(np.int64)
    cluster[cluster < 0] = 0  # render vertices no face uses any more
    centre = _cluster_mean(verts, cluster, int(cluster.max()) + 1)
    part = np.zeros(n_r, np.int64) if part is None else np.asarray(part, dtype=np.int64)
    cluster_part = _cluster_mean(part.astype(np.float64), cluster, int(cluster.max()) + 1) > 0.5
    corner_uv, face_chart = project_face_uvs(
        centre[w_faces],
        faces,
        verts,
        uv,
        chart[faces[:, 0]],
        part=part[faces[:, 0]],
        corner_part=cluster_part[w_faces[:, 0]].astype(np.int64),
    )
    gather, uv_new, out = _merge_corners(w_faces, np.repeat(face_chart, 3), corner_uv.reshape(-1, 2))
    uv_new = fit_vertex_uvs(centre[gather], out, uv_new, verts, faces, uv).astype(np.float32)
    result = (out, cluster, gather, uv_new)
    _DECIMATIONS[key] = result
    return result


#: texture-coordinate distance within which the corners of one cluster on one chart are
#: one vertex (the two sides of a cut through a chart lie much farther apart)
_SAME_SIDE = 0.02


def _merge_corners(faces: np.ndarray, chart: np.ndarray, corner_uv: np.ndarray):
    """One render vertex per (cluster, chart, side of a cut): the corners of ``faces``
    (F', 3) clusters with their ``chart`` (3F',) and texture coordinate (3F', 2) grouped,
    each group at the texture coordinate of its first corner. Returns ``(gather (R',)
    cluster of each new vertex, uv (R', 2) float32, faces (F', 3) on the new vertices)``."""
    flat = faces.reshape(-1)
    order = np.lexsort((chart, flat))
    vertex = np.empty(len(flat), dtype=np.int64)
    gather, uv_new = [], []
    start = 0
    while start < len(order):
        stop = start + 1
        while (
            stop < len(order) and flat[order[stop]] == flat[order[start]] and chart[order[stop]] == chart[order[start]]
        ):
            stop += 1
        reps: list[int] = []
        for corner in order[start:stop]:
            for r in reps:
                if np.abs(uv_new[r] - corner_uv[corner]).max() < _SAME_SIDE:
                    vertex[corner] = r
                    break
            else:
                reps.append(len(gather))
                vertex[corner] = len(gather)
                gather.append(int(flat[corner]))
                uv_new.append(corner_uv[corner])
        start = stop
    return np.asarray(gather, dtype=np.int64), np.asarray(uv_new, dtype=np.float32), vertex.reshape(-1, 3)

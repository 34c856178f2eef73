"""Texture coordinates for a decimated surface, projected from the full one.

A decimated vertex merges many vertices of the full mesh (a *cluster*, placed at their
mean). Averaging their texture coordinates is wrong wherever a UV chart is cut open: the
MakeHuman torso, for one, is a single chart whose two halves meet at the spine, so a
cluster on the spine has members at both ends of the chart and their mean lands on the
chest (the back of every shirt then showed patches of the texture's front). Instead, each
corner of a decimated face takes the texture coordinate of the closest point of the full
surface, in the chart the face lies on, on the side of a cut the face lies on:
:func:`project_face_uvs`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["closest_points_on_triangles", "project_face_uvs"]

#: candidate triangles of the full surface examined per decimated corner
_CANDIDATES = 16
#: m: candidates this much farther than the closest one still compete on their texture
#: coordinate (both sides of a cut lie at the same distance from a corner on the cut)
_TIE = 0.004
#: texture-coordinate distance between a corner's projection and its face's continued
#: map beyond which the corner lies across a cut from its face
_ACROSS = 0.03


def closest_points_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of the point of each triangle (a, b, c) closest to p.

    All inputs (..., 3) float64, metres; Ericson's region tests (Real-Time Collision
    Detection, 5.1.5), vectorised: the weights are non-negative and sum to 1."""
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c
    d1, d2 = np.einsum("...k,...k", ab, ap), np.einsum("...k,...k", ac, ap)
    d3, d4 = np.einsum("...k,...k", ab, bp), np.einsum("...k,...k", ac, bp)
    d5, d6 = np.einsum("...k,...k", ab, cp), np.einsum("...k,...k", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom  # inside the face
        t = d1 / (d1 - d3)  # on edge ab
        v, w = np.where((vc <= 0) & (d1 >= 0) & (d3 <= 0), t, v), np.where((vc <= 0) & (d1 >= 0) & (d3 <= 0), 0.0, w)
        t = d2 / (d2 - d6)  # on edge ac
        on = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        v, w = np.where(on, 0.0, v), np.where(on, t, w)
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))  # on edge bc
        on = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        v, w = np.where(on, 1.0 - t, v), np.where(on, t, w)
    # the vertex regions last: they win their corners
    on = (d1 <= 0) & (d2 <= 0)
    v, w = np.where(on, 0.0, v), np.where(on, 0.0, w)
    on = (d3 >= 0) & (d4 <= d3)
    v, w = np.where(on, 1.0, v), np.where(on, 0.0, w)
    on = (d6 >= 0) & (d5 <= d6)
    v, w = np.where(on, 0.0, v), np.where(on, 1.0, w)
    v, w = np.nan_to_num(v, nan=1.0 / 3.0), np.nan_to_num(w, nan=1.0 / 3.0)
    return np.stack([1.0 - v - w, v, w], axis=-1)


def _project(points: np.ndarray, cand: np.ndarray, tri_pos: np.ndarray, tri_uv: np.ndarray):
    """Closest points of ``points`` (P, 3) on their candidate triangles ``cand`` (P, K):
    (distances (P, K), texture coordinates (P, K, 2))."""
    tri = tri_pos[cand]  # (P, K, 3, 3)
    p = np.broadcast_to(points[:, None, :], tri.shape[:2] + (3,))
    bary = closest_points_on_triangles(p, tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
    closest = np.einsum("pkc,pkcx->pkx", bary, tri)
    return np.linalg.norm(closest - p, axis=-1), np.einsum("pkc,pkcx->pkx", bary, tri_uv[cand])


def project_face_uvs(
    corners: np.ndarray,
    faces: np.ndarray,
    positions: np.ndarray,
    uv: np.ndarray,
    chart: np.ndarray,
    *,
    part: np.ndarray | None = None,
    corner_part: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The texture coordinate and chart of every corner of decimated faces.

    Args:
        corners: (F', 3, 3) float64 m, the corner positions of each decimated face.
        faces: (F, 3) int, the full surface's triangles on its render vertices.
        positions: (R, 3) float64 m and ``uv`` (R, 2) float: the full surface's render vertices.
        chart: (F,) int, the UV chart (connected component of the split surface) of each
            full triangle.
        part, corner_part: optional (F,) and (F',) int material parts of the full and the
            decimated triangles (the eyeballs behind the eyelids): a face only takes its
            texture from triangles of its own part.

    Returns:
        ``(uv (F', 3, 2) float64, chart (F',) int)``: each face lies on the chart of the full
        triangle closest to its centroid; each corner takes the closest point of that chart
        (among near-ties, the one whose texture coordinate is nearest the centroid's: the
        face's side of a cut)."""
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  # missing from scipy stubs

    faces = np.asarray(faces, dtype=np.int64)
    tri_pos = np.asarray(positions, dtype=np.float64)[faces]
    tri_uv = np.asarray(uv, dtype=np.float64)[faces]
    centroids = tri_pos.mean(axis=1)
    corners = np.asarray(corners, dtype=np.float64)
    g = corners.mean(axis=1)
    part = np.zeros(len(faces), np.int64) if part is None else np.asarray(part, dtype=np.int64)
    corner_part = np.zeros(len(g), np.int64) if corner_part is None else np.asarray(corner_part, dtype=np.int64)
    k = min(_CANDIDATES, *(int(np.count_nonzero(part == q)) for q in np.unique(corner_part)))
    cand = np.zeros((len(g), k), dtype=np.int64)
    for q in np.unique(corner_part):
        rows, members = np.flatnonzero(corner_part == q), np.flatnonzero(part == q)
        _, local = cKDTree(centroids[members]).query(g[rows], k=k)
        cand[rows] = members[local.reshape(len(rows), k)]
    dist, cuv = _project(g, cand, tri_pos, tri_uv)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(g))
    face_chart = chart[cand[rows, best]]
    ref_uv = cuv[rows, best]
    out = np.zeros(corners.shape[:2] + (2,))
    for ch in np.unique(face_chart):
        sel = np.flatnonzero(face_chart == ch)
        members = np.flatnonzero(chart == ch)
        kk = min(_CANDIDATES, len(members))
        pts = corners[sel].reshape(-1, 3)
        _, local = cKDTree(centroids[members]).query(pts, k=kk)
        c_cand = members[local.reshape(len(pts), kk)]
        d, u = _project(pts, c_cand, tri_pos, tri_uv)
        ref = np.repeat(ref_uv[sel], 3, axis=0)
        near = d <= d.min(axis=1, keepdims=True) + _TIE
        score = np.where(near, np.linalg.norm(u - ref[:, None, :], axis=-1), np.inf)
        pick = np.argmin(score, axis=1)
        projected = u[np.arange(len(pts)), pick]
        # a corner across a cut from its face (a large decimated face over the spine): the
        # texture coordinate continued from the face's own triangle, past the chart's edge
        ext = _extend(pts, np.repeat(cand[sel, best[sel]], 3), tri_pos, tri_uv)
        across = np.abs(projected - ext).max(axis=1) > _ACROSS
        if across.any():  # kept on the chart: past its edge the texture holds other charts
            ext[across] = _onto_chart(ext[across], tri_uv[members])
        out[sel] = np.where(across[:, None], ext, projected).reshape(len(sel), 3, 2)
    return out, face_chart


def _onto_chart(points: np.ndarray, chart_uv: np.ndarray) -> np.ndarray:
    """(P, 2) texture coordinates moved to the closest point of a chart's triangles
    ``chart_uv`` (T, 3, 2) in texture space (unchanged where already on it)."""
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  # missing from scipy stubs

    flat = np.concatenate([chart_uv, np.zeros(chart_uv.shape[:2] + (1,))], axis=-1)
    k = min(_CANDIDATES, len(flat))
    _, cand = cKDTree(flat.mean(axis=1)[:, :2]).query(points, k=k)
    cand = cand.reshape(len(points), k)
    tri = flat[cand]
    p = np.concatenate([points, np.zeros((len(points), 1))], axis=1)
    p = np.broadcast_to(p[:, None, :], tri.shape[:2] + (3,))
    bary = closest_points_on_triangles(p, tri[..., 0, :], tri[..., 1, :], tri[..., 2, :])
    closest = np.einsum("pkc,pkcx->pkx", bary, tri)
    pick = np.argmin(np.linalg.norm(closest - p, axis=-1), axis=1)
    return closest[np.arange(len(points)), pick, :2]


def _extend(points: np.ndarray, tri: np.ndarray, tri_pos: np.ndarray, tri_uv: np.ndarray) -> np.ndarray:
    """(P, 2) texture coordinates of ``points`` (P, 3) by the affine map of the full
    triangles ``tri`` (P,) continued past their edges (points projected onto their plane)."""
    p0 = tri_pos[tri, 0]
    e1, e2 = tri_pos[tri, 1] - p0, tri_pos[tri, 2] - p0
    d = points - p0
    a11, a12, a22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    b1, b2 = (e1 * d).sum(1), (e2 * d).sum(1)
    det = np.where(np.abs(a11 * a22 - a12 * a12) < 1e-18, 1e-18, a11 * a22 - a12 * a12)
    s, t = (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det
    u0 = tri_uv[tri, 0]
    return u0 + s[:, None] * (tri_uv[tri, 1] - u0) + t[:, None] * (tri_uv[tri, 2] - u0)


def fit_vertex_uvs(
    positions: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    full_positions: np.ndarray,
    full_faces: np.ndarray,
    full_uv: np.ndarray,
    *,
    smooth: float = 0.05,
) -> np.ndarray:
    """Texture coordinates of the decimated vertices fitted to the full surface.

    A decimated face interpolates its corners' texture coordinates linearly; the full
    surface under it maps the texture non-linearly, so a garment's edge drawn on the
    texture wobbles across the large faces (by a centimetre at 3,000 faces). This
    least-squares fit moves each corner's coordinate (starting from ``uv``, its projection)
    so that the points of the full surface (its vertices and face centroids), placed on
    the decimated face under them, show their own texture coordinates; ``smooth`` keeps
    each corner near its start where few points constrain it. Points whose start is far
    off (across a seam) are left out.

    Args:
        positions: (R', 3) m, faces (F', 3), uv (R', 2): the decimated surface.
        full_positions: (R, 3) m, full_faces (F, 3), full_uv (R, 2): the full surface.
    Returns:
        (R', 2) float64 texture coordinates.
    """
    from scipy.sparse import coo_matrix, identity
    from scipy.sparse.linalg import spsolve
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  # missing from scipy stubs

    positions, uv = np.asarray(positions, dtype=np.float64), np.asarray(uv, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    full_tri = np.asarray(full_positions, dtype=np.float64)[np.asarray(full_faces, dtype=np.int64)]
    full_tri_uv = np.asarray(full_uv, dtype=np.float64)[np.asarray(full_faces, dtype=np.int64)]
    pts = np.concatenate([full_tri.reshape(-1, 3), full_tri.mean(axis=1)])
    target = np.concatenate([full_tri_uv.reshape(-1, 2), full_tri_uv.mean(axis=1)])
    tri = positions[faces]
    k = min(6, len(faces))
    _, cand = cKDTree(tri.mean(axis=1)).query(pts, k=k)
    cand = cand.reshape(len(pts), k)
    t = tri[cand]
    p = np.broadcast_to(pts[:, None, :], t.shape[:2] + (3,))
    bary = closest_points_on_triangles(p, t[..., 0, :], t[..., 1, :], t[..., 2, :])
    dist = np.linalg.norm(np.einsum("pkc,pkcx->pkx", bary, t) - p, axis=-1)
    shown = np.einsum("pkc,pkcx->pkx", bary, uv[faces[cand]])
    miss = np.linalg.norm(shown - target[:, None, :], axis=-1)
    # the face under the point: the nearest whose texture already lies near the point's
    score = np.where(miss < _ACROSS, dist, np.inf)
    pick = np.argmin(score, axis=1)
    rows = np.arange(len(pts))
    keep = np.isfinite(score[rows, pick])
    f, b = cand[rows, pick][keep], bary[rows, pick][keep]
    n_eq = int(keep.sum())
    a = coo_matrix((b.reshape(-1), (np.repeat(np.arange(n_eq), 3), faces[f].reshape(-1))), shape=(n_eq, len(uv)))
    a = a.tocsr()
    # the normal equations (A^T A + s^2 I) x = A^T t + s^2 x0, sparse and positive definite
    normal = (a.T @ a + identity(len(uv), format="csr") * smooth**2).tocsc()
    rhs = a.T @ target[keep] + smooth**2 * uv
    cols = [np.asarray(spsolve(normal, rhs[:, axis])) for axis in range(2)]
    return np.column_stack(cols)

"""Texture coordinates of the decimated (level-of-detail) surfaces: every decimated face
shows the part of the texture that lies under it on the full surface, across the cuts of
the UV charts too (the back of the torso and of the head)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdstudy.body import load_body
from crowdstudy.render.bodies import _cluster_mean, _render_arrays, _surface_decimation
from crowdstudy.render.uv_transfer import closest_points_on_triangles

RECORD = {"model": "makehuman", "sex": "female", "height": 1.62, "age": 30, "weight": 0.5, "muscle": 0.5}


def test_closest_points_on_triangles_match_a_dense_sampling():
    rng = np.random.default_rng(3)
    a, b, c = rng.normal(size=(3, 200, 3))
    p = rng.normal(size=(200, 3)) * 2.0
    bary = closest_points_on_triangles(p, a, b, c)
    assert np.all(bary >= -1e-9) and np.allclose(bary.sum(axis=1), 1.0)
    got = np.linalg.norm(bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c - p, axis=1)
    s, t = np.meshgrid(np.linspace(0, 1, 60), np.linspace(0, 1, 60))
    keep = s + t <= 1
    s, t = s[keep], t[keep]
    pts = a[:, None] + s[None, :, None] * (b - a)[:, None] + t[None, :, None] * (c - a)[:, None]
    brute = np.linalg.norm(pts - p[:, None], axis=2).min(axis=1)
    assert np.all(got <= brute + 1e-9) and np.all(got >= brute - 0.05 * np.linalg.norm(b - a, axis=1))


def _uv_to_position(uv_points, uv, positions, faces):
    """The full surface's rest position at texture coordinates ``uv_points`` (P, 2)."""
    tri_uv = np.concatenate([uv[faces], np.zeros(faces.shape + (1,))], axis=2)
    p = np.concatenate([uv_points, np.zeros((len(uv_points), 1))], axis=1)
    from scipy.spatial import cKDTree

    _, cand = cKDTree(tri_uv.mean(axis=1)[:, :2]).query(uv_points, k=12)
    t = tri_uv[cand]
    pp = np.broadcast_to(p[:, None], t.shape[:2] + (3,))
    bary = closest_points_on_triangles(pp, t[..., 0, :], t[..., 1, :], t[..., 2, :])
    d = np.linalg.norm(np.einsum("pkc,pkcx->pkx", bary, t) - pp, axis=-1)
    k = d.argmin(axis=1)
    rows = np.arange(len(p))
    return np.einsum("pc,pcx->px", bary[rows, k], positions[faces[cand[rows, k]]])


@pytest.mark.parametrize("max_faces, tolerance", [(6000, 0.02), (1500, 0.035)])
def test_decimated_faces_show_the_texture_under_them(max_faces, tolerance):
    body = load_body(RECORD)
    verts, faces, _, uv, part, weld = _render_arrays(body)
    dec_faces, cluster, gather, dec_uv = _surface_decimation(verts, faces, weld, uv, max_faces, part)
    pos = _cluster_mean(verts, cluster, int(cluster.max()) + 1)[gather]
    centroid = pos[dec_faces].mean(axis=1)
    shown = _uv_to_position(dec_uv[dec_faces].mean(axis=1), uv, verts, faces)
    error = np.linalg.norm(shown - centroid, axis=1)
    # the texture under a face comes from where the face is: no patch of the chest on the
    # back, of the neck on the crown (a chart's cut lies across the spine and the head)
    assert np.quantile(error, 0.99) < tolerance and error.max() < 0.08
    back = centroid[:, 1] < np.quantile(verts[:, 1], 0.15)
    assert back.sum() > 50 and np.quantile(error[back], 0.99) < tolerance
    # the eyeballs keep the eyes' texture (not the eyelids' in front of them)
    eye = _cluster_mean(part.astype(float), cluster, int(cluster.max()) + 1)[gather][dec_faces].mean(axis=1) > 0.5
    eye_uv = uv[part == 1]
    nearest_eye = np.min(np.linalg.norm(dec_uv[dec_faces[eye]].mean(axis=1)[:, None] - eye_uv[None], axis=2), axis=1)
    assert eye.sum() > 10 and nearest_eye.max() < 0.01
    # one render vertex per cluster and side of a seam: hardly more than the clusters
    assert len(gather) < 1.5 * len(np.unique(gather))

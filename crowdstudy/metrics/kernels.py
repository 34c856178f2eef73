"""Warp kernels of the metrics: mesh column crossings and linear blend skinning (CPU and
CUDA, one code path).

``face_crossings`` is the same computation as
:func:`crowdstudy.metrics.columns.mesh_crossings` (top-left fill rule on edges evaluated
from their lower-index vertex, float64 throughout), restricted to the columns inside each
solid's partner rectangles, in two passes over the faces: count the crossings of each face,
then write them at the face's offset (an exclusive prefix sum of the counts). The
sort-based interval arithmetic that follows stays in numpy (:func:`mesh_crossings_warp`).
``skin_vertices`` poses the bodies of :class:`WarpSkinner`. Units: metres.

This module imports Warp when it is imported; :mod:`crowdstudy.metrics.overlap` imports it
inside the functions that use it.
"""

# pyright: reportInvalidTypeForm=false
# (Warp's parameter types, wp.array(dtype=...), are calls that a type checker rejects as types)

from __future__ import annotations

import numpy as np
import warp as wp

from crowdstudy.warp_runtime import get_warp

__all__ = ["face_crossings", "skin_vertices", "mesh_crossings_warp", "WarpSkinner"]

get_warp()  # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})  # forward only: no adjoints to compile


@wp.func
def edge_value(verts: wp.array(dtype=wp.vec3d), vi: int, vj: int, px: wp.float64, py: wp.float64):
    """Edge function of the directed edge vi -> vj at (px, py), evaluated from the
    lower-index end so both faces sharing the edge get exactly opposite values."""
    lo = vi
    hi = vj
    flip = wp.float64(1.0)
    if vi > vj:
        lo = vj
        hi = vi
        flip = wp.float64(-1.0)
    pl = verts[lo]
    ph = verts[hi]
    ex = ph[0] - pl[0]
    ey = ph[1] - pl[1]
    return flip * (ex * (py - pl[1]) - ey * (px - pl[0]))


@wp.func
def edge_covers(verts: wp.array(dtype=wp.vec3d), vi: int, vj: int, w: wp.float64):
    """Inside test for one edge: w > 0, or w == 0 on a top-left edge."""
    if w > wp.float64(0.0):
        return True
    if w < wp.float64(0.0):
        return False
    dx = verts[vj][0] - verts[vi][0]
    dy = verts[vj][1] - verts[vi][1]
    if dy < wp.float64(0.0):
        return True
    if dy == wp.float64(0.0) and dx < wp.float64(0.0):
        return True
    return False


@wp.kernel
def face_crossings(
    verts: wp.array(dtype=wp.vec3d),
    faces: wp.array2d(dtype=wp.int32),
    face_solid: wp.array(dtype=wp.int32),
    rect_first: wp.array(dtype=wp.int32),
    rects: wp.array2d(dtype=wp.int32),
    h: wp.float64,
    write: int,
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    out_solid: wp.array(dtype=wp.int32),
    out_ix: wp.array(dtype=wp.int32),
    out_iy: wp.array(dtype=wp.int32),
    out_z: wp.array(dtype=wp.float64),
    out_sign: wp.array(dtype=wp.int32),
):
    """The column crossings of face f (thread): columns at ((ix + 1/2) h, (iy + 1/2) h)
    (h m) inside the face's projection and inside one of its solid's partner rectangles
    (``rects`` rows ``rect_first[s]`` to ``rect_first[s + 1]``, column index ranges).

    ``write`` 0 counts them into ``counts[f]``; ``write`` 1 writes them from
    ``offsets[f]``: solid, column (ix, iy), height z of the crossing (m) and its sign (+1
    entering, -1 leaving going up the column, for an outward-oriented surface; see
    :class:`~crowdstudy.metrics.columns.Crossings`)."""
    f = wp.tid()
    s = face_solid[f]
    r0 = rect_first[s]
    r1 = rect_first[s + 1]
    n = int(0)
    if write == 1 and counts[f] == 0:
        r1 = r0  # nothing to write for this face: skip the loops
    if r1 > r0:
        a = faces[f, 0]
        b = faces[f, 1]
        c = faces[f, 2]
        pa = verts[a]
        pb = verts[b]
        pc = verts[c]
        area = (pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0])
        if area != wp.float64(0.0):
            if area < wp.float64(0.0):  # counter-clockwise in (x, y)
                tmp = b
                b = c
                c = tmp
            sign = int(1)
            if area > wp.float64(0.0):
                sign = -1
            half = wp.float64(0.5)
            x0 = int(wp.ceil(wp.min(wp.min(pa[0], pb[0]), pc[0]) / h - half))
            x1 = int(wp.floor(wp.max(wp.max(pa[0], pb[0]), pc[0]) / h - half))
            y0 = int(wp.ceil(wp.min(wp.min(pa[1], pb[1]), pc[1]) / h - half))
            y1 = int(wp.floor(wp.max(wp.max(pa[1], pb[1]), pc[1]) / h - half))
            for ix in range(x0, x1 + 1):
                for iy in range(y0, y1 + 1):
                    in_rect = int(0)
                    for r in range(r0, r1):
                        if ix >= rects[r, 0] and ix <= rects[r, 1] and iy >= rects[r, 2] and iy <= rects[r, 3]:
                            in_rect = 1
                    if in_rect == 1:
                        px = (wp.float64(ix) + half) * h
                        py = (wp.float64(iy) + half) * h
                        wa = edge_value(verts, b, c, px, py)
                        wb = edge_value(verts, c, a, px, py)
                        wc = edge_value(verts, a, b, px, py)
                        denom = wa + wb + wc
                        if (
                            edge_covers(verts, b, c, wa)
                            and edge_covers(verts, c, a, wb)
                            and edge_covers(verts, a, b, wc)
                            and denom > wp.float64(0.0)
                        ):
                            if write == 1:
                                k = offsets[f] + n
                                out_solid[k] = s
                                out_ix[k] = ix
                                out_iy[k] = iy
                                out_z[k] = (wa * verts[a][2] + wb * verts[b][2] + wc * verts[c][2]) / denom
                                out_sign[k] = sign
                            n += 1
    if write == 0:
        counts[f] = n


@wp.kernel
def skin_vertices(
    rest: wp.array(dtype=wp.vec3d),
    joint: wp.array2d(dtype=wp.int32),
    weight: wp.array2d(dtype=wp.float64),
    rot: wp.array(dtype=wp.mat33d),
    trans: wp.array(dtype=wp.vec3d),
    out: wp.array(dtype=wp.vec3d),
):
    """Vertex v (thread) posed by linear blend skinning: sum over its 4 joints of weight
    times (R_joint p_rest + t_joint), R (N J,) mat33d and t (N J,) vec3d (m) each joint's
    world transform relative to the rest pose."""
    v = wp.tid()
    p = rest[v]
    acc = wp.vec3d()
    for k in range(4):
        m = joint[v, k]
        acc = acc + weight[v, k] * (rot[m] * p + trans[m])
    out[v] = acc


def mesh_crossings_warp(
    vertices: np.ndarray, faces: np.ndarray, face_solid: np.ndarray, rects: list[np.ndarray], h: float, device: str
):
    """Column crossings of all faces, on ``device`` (``"cpu"`` or ``"cuda:N"``).

    Args:
        vertices: (V, 3) float64 metres; faces: (F, 3) int rows of ``vertices``;
        face_solid: (F,) the solid of each face; rects: per solid, (K, 4) partner
            rectangles (x_lo, x_hi, y_lo, y_hi) in metres (only columns inside count);
        h: column spacing, metres.

    Returns:
        :class:`crowdstudy.metrics.columns.Crossings`.
    """
    from crowdstudy.metrics.columns import Crossings

    first = np.zeros(len(rects) + 1, np.int32)
    first[1:] = np.cumsum([len(r) for r in rects])
    table = np.concatenate([r for r in rects if len(r)] or [np.zeros((0, 4))])
    cols = np.empty((max(len(table), 1), 4), np.int32)
    if len(table):
        cols[:, 0] = np.ceil(table[:, 0] / h - 0.5)
        cols[:, 1] = np.floor(table[:, 1] / h - 0.5)
        cols[:, 2] = np.ceil(table[:, 2] / h - 0.5)
        cols[:, 3] = np.floor(table[:, 3] / h - 0.5)
    n_faces = len(faces)
    v = wp.array(np.ascontiguousarray(vertices, dtype=np.float64), dtype=wp.vec3d, device=device)
    f = wp.array(np.ascontiguousarray(faces, dtype=np.int32), dtype=wp.int32, device=device)
    fs = wp.array(np.ascontiguousarray(face_solid, dtype=np.int32), dtype=wp.int32, device=device)
    rf = wp.array(first, dtype=wp.int32, device=device)
    rc = wp.array(cols, dtype=wp.int32, device=device)
    counts = wp.zeros(n_faces, dtype=wp.int32, device=device)
    dummy_i = wp.zeros(1, dtype=wp.int32, device=device)
    dummy_f = wp.zeros(1, dtype=wp.float64, device=device)
    wp.launch(
        face_crossings,
        dim=n_faces,
        device=device,
        inputs=[v, f, fs, rf, rc, float(h), 0, dummy_i, counts, dummy_i, dummy_i, dummy_i, dummy_f, dummy_i],
    )
    cnt = counts.numpy().astype(np.int64)
    total = int(cnt.sum())
    if total == 0:
        return Crossings.concatenate([])
    offsets = np.zeros(n_faces, np.int32)
    offsets[1:] = np.cumsum(cnt)[:-1]
    outs = [wp.zeros(total, dtype=dt, device=device) for dt in (wp.int32, wp.int32, wp.int32, wp.float64, wp.int32)]
    wp.launch(
        face_crossings,
        dim=n_faces,
        device=device,
        inputs=[v, f, fs, rf, rc, float(h), 1, wp.array(offsets, dtype=wp.int32, device=device), counts, *outs],
    )
    solid, ix, iy, z, sign = (o.numpy() for o in outs)
    return Crossings(solid.astype(np.int64), ix.astype(np.int64), iy.astype(np.int64), z, sign.astype(np.int64))


class WarpSkinner:
    """Linear blend skinning of N bodies at once with a Warp kernel (float64).

    Exact for bodies whose skinning weights have at most 4 non-zero entries per vertex
    and no pose blendshapes (the open body model); :meth:`supports` says whether a set of
    bodies qualifies. ``__call__(joint_rotations (N, J, 3), root_translation (N, 3))``
    returns the list of posed (V_i, 3) float64 vertex arrays, metres.
    """

    def __init__(self, bodies: list, device: str):
        from crowdstudy.body.skeleton import PARENTS

        self.device = device
        self.rest_joints = np.stack([np.asarray(b.rest_joints, dtype=np.float64) for b in bodies])  # (N, J, 3)
        self.parents = np.asarray(getattr(bodies[0], "parents", PARENTS))
        n_j = self.rest_joints.shape[1]
        rests, joints, weights = [], [], []
        for i, b in enumerate(bodies):
            w = np.asarray(b.weights, dtype=np.float64)
            top = np.argsort(-w, axis=1, kind="stable")[:, :4]
            rests.append(np.asarray(b.rest_vertices, dtype=np.float64))
            joints.append((top + i * n_j).astype(np.int32))
            weights.append(np.take_along_axis(w, top, axis=1))
        self.sizes = [len(r) for r in rests]
        self._rest = wp.array(np.concatenate(rests), dtype=wp.vec3d, device=device)
        self._joint = wp.array(np.concatenate(joints), dtype=wp.int32, device=device)
        self._weight = wp.array(np.concatenate(weights), dtype=wp.float64, device=device)
        self._out = wp.zeros(sum(self.sizes), dtype=wp.vec3d, device=device)

    @staticmethod
    def supports(bodies: list) -> bool:
        for b in bodies:
            if getattr(b, "posedirs", None) is not None or not hasattr(b, "weights"):
                return False
            w = np.asarray(b.weights)
            if w.ndim != 2 or len(w) != len(b.rest_vertices) or np.count_nonzero(w, axis=1).max() > 4:
                return False
        return True

    def __call__(self, joint_rotations: np.ndarray, root_translation: np.ndarray) -> list[np.ndarray]:
        from crowdstudy.body.skeleton import forward_kinematics

        glob, pos = forward_kinematics(self.rest_joints, joint_rotations, root_translation, parents=self.parents)
        trans = pos - np.einsum("njab,njb->nja", glob, self.rest_joints)
        rot = wp.array(np.ascontiguousarray(glob.reshape(-1, 3, 3)), dtype=wp.mat33d, device=self.device)
        tr = wp.array(np.ascontiguousarray(trans.reshape(-1, 3)), dtype=wp.vec3d, device=self.device)
        wp.launch(
            skin_vertices,
            dim=len(self._out),
            device=self.device,
            inputs=[self._rest, self._joint, self._weight, rot, tr, self._out],
        )
        flat = self._out.numpy()
        return np.split(flat, np.cumsum(self.sizes)[:-1])

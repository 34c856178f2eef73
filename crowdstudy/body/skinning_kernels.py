"""Warp kernels of :class:`~crowdstudy.body.skinning.CrowdSkinner`: forward kinematics of N
bodies and linear blend skinning of their vertices, in float32 (CPU and CUDA).

:mod:`crowdstudy.body.skinning` imports this module inside ``CrowdSkinner``, so
``import crowdstudy.body`` does not load Warp; importing it configures Warp
(:func:`~crowdstudy.warp_runtime.get_warp`) before anything here can compile. Positions in
m, rotations as axis-angle vectors (rad). The segment table ``seg`` has the int32 columns
that :mod:`crowdstudy.body.skinning` describes (body, first sorted vertex, first weight
row, vertex count, joints used, output offset, joints j0..j3).
"""

# pyright: reportInvalidTypeForm=false
# (Warp's parameter types, wp.array(dtype=...), are calls that a type checker rejects as types)

from __future__ import annotations

import warp as wp

from crowdstudy.warp_runtime import get_warp

__all__ = ["forward_kinematics", "skin_segments", "skin_vertices"]

get_warp()  # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})  # forward only: no adjoints to compile


@wp.kernel
def forward_kinematics(
    rotvec: wp.array2d(dtype=wp.vec3),
    root: wp.array(dtype=wp.vec3),
    rest: wp.array2d(dtype=wp.vec3),
    parents: wp.array(dtype=wp.int32),
    glob: wp.array2d(dtype=wp.mat33),
    pos: wp.array2d(dtype=wp.vec3),
    skin_trans: wp.array2d(dtype=wp.vec3),
):
    n = wp.tid()
    for j in range(parents.shape[0]):
        rv = rotvec[n, j]
        angle = wp.length(rv)
        local = wp.identity(n=3, dtype=wp.float32)
        if angle > 1.0e-8:
            local = wp.quat_to_matrix(wp.quat_from_axis_angle(rv / angle, angle))
        p = parents[j]
        g = local
        x = root[n]
        if p >= 0:
            g = glob[n, p] * local
            x = pos[n, p] + glob[n, p] * (rest[n, j] - rest[n, p])
        glob[n, j] = g
        pos[n, j] = x
        skin_trans[n, j] = x - g * rest[n, j]


@wp.kernel
def skin_segments(
    seg: wp.array2d(dtype=wp.int32),
    rest: wp.array(dtype=wp.vec3),
    weights: wp.array2d(dtype=wp.float32),
    perm: wp.array(dtype=wp.int32),
    rot: wp.array2d(dtype=wp.mat33),
    trans: wp.array2d(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
):
    # one thread per segment: a run of one body's vertices sharing one set of joints
    s = wp.tid()
    b = seg[s, 0]
    v0 = seg[s, 1]
    w0 = seg[s, 2]
    count = seg[s, 3]
    nk = seg[s, 4]
    base = seg[s, 5]
    r0 = rot[b, seg[s, 6]]
    t0 = trans[b, seg[s, 6]]
    if nk == 1:
        for i in range(count):
            out[base + perm[w0 + i]] = r0 * rest[v0 + i] + t0
    elif nk == 2:
        r1 = rot[b, seg[s, 7]]
        t1 = trans[b, seg[s, 7]]
        for i in range(count):
            p = rest[v0 + i]
            q = w0 + i
            out[base + perm[q]] = weights[q, 0] * (r0 * p + t0) + weights[q, 1] * (r1 * p + t1)
    elif nk == 3:
        r1 = rot[b, seg[s, 7]]
        t1 = trans[b, seg[s, 7]]
        r2 = rot[b, seg[s, 8]]
        t2 = trans[b, seg[s, 8]]
        for i in range(count):
            p = rest[v0 + i]
            q = w0 + i
            out[base + perm[q]] = (
                weights[q, 0] * (r0 * p + t0) + weights[q, 1] * (r1 * p + t1) + weights[q, 2] * (r2 * p + t2)
            )
    else:
        r1 = rot[b, seg[s, 7]]
        t1 = trans[b, seg[s, 7]]
        r2 = rot[b, seg[s, 8]]
        t2 = trans[b, seg[s, 8]]
        r3 = rot[b, seg[s, 9]]
        t3 = trans[b, seg[s, 9]]
        for i in range(count):
            p = rest[v0 + i]
            q = w0 + i
            out[base + perm[q]] = (
                weights[q, 0] * (r0 * p + t0)
                + weights[q, 1] * (r1 * p + t1)
                + weights[q, 2] * (r2 * p + t2)
                + weights[q, 3] * (r3 * p + t3)
            )


@wp.kernel
def skin_vertices(
    seg: wp.array2d(dtype=wp.int32),
    seg_of: wp.array(dtype=wp.int32),
    rest: wp.array(dtype=wp.vec3),
    weights: wp.array2d(dtype=wp.float32),
    perm: wp.array(dtype=wp.int32),
    rot: wp.array2d(dtype=wp.mat33),
    trans: wp.array2d(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
):
    # one thread per (sorted) vertex, for GPUs
    v = wp.tid()
    s = seg_of[v]
    b = seg[s, 0]
    q = seg[s, 2] + (v - seg[s, 1])
    p = rest[v]
    acc = wp.vec3(0.0, 0.0, 0.0)
    for k in range(seg[s, 4]):
        j = seg[s, 6 + k]
        acc += weights[q, k] * (rot[b, j] * p + trans[b, j])
    out[seg[s, 5] + perm[q]] = acc

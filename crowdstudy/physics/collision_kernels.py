"""Warp kernels of collision detection (:mod:`crowdstudy.physics.collision` runs them).

Capsule world poses and character AABBs (``capsules_world_kernel``), the ground plane
(``ground_kernel``), the inter-body broad phase (``broadphase_kernel``, n^2 / 2 tests, and
``sweep_kernel``, a sweep along x on the CPU), the narrow phase (``narrowphase_kernel``, one
thread per character pair), intra-body pairs (``intra_kernel``), point-sampled static
objects in a BVH (``environment_kernel``) and vertical walls (``wall_kernel``). Every
contact goes through ``push_contact``: body a, body b (-1 for static), the unit normal
from b to a, the signed depth (m), the lever arms from each body's centre of mass (m), the
penalty stiffness (N/m) and the kind (0 ground, 1 environment, 2 inter-body, 3 intra-body:
``KIND_*`` in :mod:`crowdstudy.physics.collision`). Units: metres, seconds; quaternions
scalar-last (x, y, z, w).

This module imports Warp when it is imported; :mod:`crowdstudy.physics.collision` imports
it inside the functions that launch its kernels.
"""

# pyright: reportInvalidTypeForm=false
# (Warp's parameter types, wp.array(dtype=...), are calls that a type checker rejects as types)
# pyright: reportOperatorIssue=false, reportArgumentType=false, reportCallIssue=false
# (inside a kernel, Warp's stubs type wp.tid() as int or a tuple, and overload wp.length, wp.dot
# and wp.normalize for quaternions only; Warp's code generator checks these bodies when it compiles)

from __future__ import annotations

import warp as wp

from crowdstudy.warp_runtime import get_warp

__all__ = [
    "capsules_world_kernel",
    "ground_kernel",
    "broadphase_kernel",
    "sweep_kernel",
    "narrowphase_kernel",
    "intra_kernel",
    "environment_kernel",
    "wall_kernel",
]

get_warp()  # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})  # forward only: no adjoints to compile


@wp.func
def segment_params(p0: wp.vec3, p1: wp.vec3, q0: wp.vec3, q1: wp.vec3):
    """Parameters (s, t) in [0, 1] of the closest points of two segments."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = wp.dot(d1, d1)
    e = wp.dot(d2, d2)
    f = wp.dot(d2, r)
    c = wp.dot(d1, r)
    b = wp.dot(d1, d2)
    eps = 1.0e-10
    s = float(0.0)
    t = float(0.0)
    if a <= eps and e <= eps:
        return wp.vec2(0.0, 0.0)
    if a <= eps:
        s = 0.0
        t = wp.clamp(f / e, 0.0, 1.0)
    elif e <= eps:
        t = 0.0
        s = wp.clamp(-c / a, 0.0, 1.0)
    else:
        denom = a * e - b * b
        if denom > eps:
            s = wp.clamp((b * f - c * e) / denom, 0.0, 1.0)
        t = (b * s + f) / e
        if t < 0.0:
            t = 0.0
            s = wp.clamp(-c / a, 0.0, 1.0)
        elif t > 1.0:
            t = 1.0
            s = wp.clamp((b - c) / a, 0.0, 1.0)
    return wp.vec2(s, t)


@wp.func
def push_contact(
    count: wp.array(dtype=wp.int32),
    capacity: int,
    a: int,
    b: int,
    n: wp.vec3,
    depth: float,
    lever_a: wp.vec3,
    lever_b: wp.vec3,
    k: float,
    kind: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    c_n: wp.array(dtype=wp.vec3),
    c_depth: wp.array(dtype=float),
    c_la: wp.array(dtype=wp.vec3),
    c_lb: wp.array(dtype=wp.vec3),
    c_k: wp.array(dtype=float),
    c_kind: wp.array(dtype=wp.int32),
):
    """Append one contact to the contact arrays (C,) at the next slot of ``count``; a
    contact past ``capacity`` is counted but not stored (the caller sees the overflow)."""
    idx = wp.atomic_add(count, 0, 1)
    if idx < capacity:
        c_a[idx] = a
        c_b[idx] = b
        c_n[idx] = n
        c_depth[idx] = depth
        c_la[idx] = lever_a
        c_lb[idx] = lever_b
        c_k[idx] = k
        c_kind[idx] = kind
    return 0


@wp.kernel
def capsules_world_kernel(
    x: wp.array(dtype=wp.vec3),
    q: wp.array(dtype=wp.quat),
    cap_p0: wp.array(dtype=wp.vec3),
    cap_p1: wp.array(dtype=wp.vec3),
    cap_radius: wp.array(dtype=float),
    cap_skin: wp.array(dtype=float),
    n_joints: int,
    grow: float,
    p0w: wp.array(dtype=wp.vec3),
    p1w: wp.array(dtype=wp.vec3),
    char_lo: wp.array(dtype=wp.vec3),
    char_hi: wp.array(dtype=wp.vec3),
    centre: wp.array(dtype=wp.vec3),
    half: wp.array(dtype=float),
):
    """World capsule end points (m), their midpoints and half lengths (m: the bounding
    spheres of the narrow phase) and one AABB per character (thread), grown by ``grow``."""
    i = wp.tid()
    lo = wp.vec3(1.0e9, 1.0e9, 1.0e9)
    hi = wp.vec3(-1.0e9, -1.0e9, -1.0e9)
    for j in range(n_joints):
        b = i * n_joints + j
        a0 = x[b] + wp.quat_rotate(q[b], cap_p0[b])
        a1 = x[b] + wp.quat_rotate(q[b], cap_p1[b])
        p0w[b] = a0
        p1w[b] = a1
        centre[b] = 0.5 * (a0 + a1)
        half[b] = 0.5 * wp.length(a1 - a0)
        r = cap_radius[b] + cap_skin[b] + grow
        rv = wp.vec3(r, r, r)
        lo = wp.min(lo, wp.min(a0, a1) - rv)
        hi = wp.max(hi, wp.max(a0, a1) + rv)
    char_lo[i] = lo
    char_hi[i] = hi


@wp.kernel
def ground_kernel(
    x: wp.array(dtype=wp.vec3),
    p0w: wp.array(dtype=wp.vec3),
    p1w: wp.array(dtype=wp.vec3),
    cap_radius: wp.array(dtype=float),
    relative: int,
    p0t: wp.array(dtype=wp.vec3),
    p1t: wp.array(dtype=wp.vec3),
    band: float,
    spec: float,
    k: float,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    c_n: wp.array(dtype=wp.vec3),
    c_depth: wp.array(dtype=float),
    c_la: wp.array(dtype=wp.vec3),
    c_lb: wp.array(dtype=wp.vec3),
    c_k: wp.array(dtype=float),
    c_kind: wp.array(dtype=wp.int32),
):
    """Both end spheres of each capsule (thread) against the floor z = 0.

    With ``relative`` only the depth beyond the TARGET pose's own counts (p0t, p1t: the
    capsule in the animation's target pose): depth - max(depth_target + band, 0), so an
    animation whose foot dips into the floor is not pushed out of it, and the target pose
    itself lies outside the penalty's activation band (m)."""
    b = wp.tid()
    up = wp.vec3(0.0, 0.0, 1.0)
    zero = wp.vec3(0.0, 0.0, 0.0)
    r = cap_radius[b]
    for e in range(2):
        p = p0w[b]
        pt = p0t[b]
        if e == 1:
            p = p1w[b]
            pt = p1t[b]
        depth = r - p[2]
        if relative != 0:
            depth = depth - wp.max(r - pt[2] + band, 0.0)
        if depth > -spec:
            push_contact(
                count, capacity, b, -1, up, depth, p - x[b], zero, k, 0, c_a, c_b, c_n, c_depth, c_la, c_lb, c_k, c_kind
            )


@wp.kernel
def broadphase_kernel(
    char_lo: wp.array(dtype=wp.vec3),
    char_hi: wp.array(dtype=wp.vec3),
    period: float,
    pair_count: wp.array(dtype=wp.int32),
    pair_capacity: int,
    pair_i: wp.array(dtype=wp.int32),
    pair_j: wp.array(dtype=wp.int32),
    pair_shift: wp.array(dtype=float),
):
    """Character AABB pairs (i < j) that overlap, with the x shift (m) bringing j next to
    i under the minimum-image convention (``period`` > 0 in periodic scenes).

    One thread per character i looping over j > i: on the CPU the threads run in order,
    so the pairs come out sorted by (i, j) (the contacts, and the sums the solver makes
    of them, in a fixed order); an (n, n) launch did the same tests at a per-thread
    cost that dominated at thousands of characters."""
    i = wp.tid()
    n = char_lo.shape[0]
    lo_i = char_lo[i]
    hi_i = char_hi[i]
    ci = 0.5 * (lo_i[0] + hi_i[0])
    for j in range(i + 1, n):
        shift = float(0.0)
        if period > 0.0:
            cj = 0.5 * (char_lo[j][0] + char_hi[j][0])
            shift = period * wp.round((ci - cj) / period)
        sv = wp.vec3(shift, 0.0, 0.0)
        lo_j = char_lo[j] + sv
        hi_j = char_hi[j] + sv
        if lo_i[0] > hi_j[0] or lo_j[0] > hi_i[0] or lo_i[1] > hi_j[1] or lo_j[1] > hi_i[1]:
            continue
        if lo_i[2] > hi_j[2] or lo_j[2] > hi_i[2]:
            continue
        idx = wp.atomic_add(pair_count, 0, 1)
        if idx < pair_capacity:
            pair_i[idx] = i
            pair_j[idx] = j
            pair_shift[idx] = shift


@wp.kernel
def sweep_kernel(
    char_lo: wp.array(dtype=wp.vec3),
    char_hi: wp.array(dtype=wp.vec3),
    order: wp.array(dtype=wp.int32),
    sorted_lo_x: wp.array(dtype=float),
    reach: float,
    pair_count: wp.array(dtype=wp.int32),
    pair_capacity: int,
    pair_i: wp.array(dtype=wp.int32),
    pair_j: wp.array(dtype=wp.int32),
    pair_shift: wp.array(dtype=float),
):
    """``broadphase_kernel``'s pairs without a period, in O(n k): the characters sorted by
    their AABB's lower x (``order``, ``sorted_lo_x``); character i (thread) binary-searches
    the first that starts within ``reach`` m (the widest box along x, plus slack) before
    it, tests those that start before it ends, and sorts its pairs by j. For the CPU,
    where the threads run in order, so that the pairs come out in (i, j) order as from
    ``broadphase_kernel`` (when they overflow ``pair_capacity``, the kept ones may differ)."""
    i = wp.tid()
    n = char_lo.shape[0]
    lo_i = char_lo[i]
    hi_i = char_hi[i]
    key = lo_i[0] - reach
    a = int(0)
    b = n
    while a < b:
        mid = (a + b) / 2
        if sorted_lo_x[mid] < key:
            a = mid + 1
        else:
            b = mid
    start = int(-1)
    k = a
    while k < n:
        if sorted_lo_x[k] > hi_i[0]:
            break
        j = order[k]
        k += 1
        if j <= i:
            continue
        lo_j = char_lo[j]
        hi_j = char_hi[j]
        if lo_i[0] > hi_j[0] or lo_j[0] > hi_i[0] or lo_i[1] > hi_j[1] or lo_j[1] > hi_i[1]:
            continue
        if lo_i[2] > hi_j[2] or lo_j[2] > hi_i[2]:
            continue
        idx = wp.atomic_add(pair_count, 0, 1)
        if start < 0:
            start = idx
        if idx < pair_capacity:
            pair_i[idx] = i
            pair_j[idx] = j
            pair_shift[idx] = 0.0
    if start >= 0:
        end = wp.min(pair_count[0], pair_capacity)
        for s in range(start + 1, end):  # insertion sort of this character's pairs by j
            v = pair_j[s]
            t = s - 1
            while t >= start and pair_j[t] > v:
                pair_j[t + 1] = pair_j[t]
                t -= 1
            pair_j[t + 1] = v


# longer than the house limit of 120 lines (tests/test_code_shape.py): a third of it is the
# 31 buffers a Warp kernel takes as parameters; the pair's tests run in one thread, in one
# order, so that the contacts come out in the same order on every run
@wp.kernel
def narrowphase_kernel(
    x: wp.array(dtype=wp.vec3),
    p0w: wp.array(dtype=wp.vec3),
    p1w: wp.array(dtype=wp.vec3),
    cap_radius: wp.array(dtype=float),
    cap_skin: wp.array(dtype=float),
    centre: wp.array(dtype=wp.vec3),
    half: wp.array(dtype=float),
    char_lo: wp.array(dtype=wp.vec3),
    char_hi: wp.array(dtype=wp.vec3),
    pair_i: wp.array(dtype=wp.int32),
    pair_j: wp.array(dtype=wp.int32),
    pair_shift: wp.array(dtype=float),
    n_joints: int,
    margin: float,
    spec: float,
    k: float,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    c_n: wp.array(dtype=wp.vec3),
    c_depth: wp.array(dtype=float),
    c_la: wp.array(dtype=wp.vec3),
    c_lb: wp.array(dtype=wp.vec3),
    c_k: wp.array(dtype=float),
    c_kind: wp.array(dtype=wp.int32),
    offset: int,
    pass_on: int,
    p0a: wp.array(dtype=wp.vec3),
    p1a: wp.array(dtype=wp.vec3),
    pass_width: float,
):
    """Pair of characters (thread + ``offset``): first the second character's capsules
    that may touch the first (a bit mask); then each capsule of the first character, in
    joint order: its bounding sphere against the second character's AABB, then against
    each masked capsule, in joint order, then the exact segment distance. The contacts
    come out in (pair, first capsule, second capsule) order.

    The mask: the first character's AABB holds every point within r_a + margin +
    speculative distance of its capsules' segments, so a contact's point on the second
    capsule's surface lies inside it; a capsule whose bounding sphere (half length +
    radius + skin) misses that box has no contact and is skipped.

    With ``pass_on`` the capsules (``p0a``, ``p1a``: the animation's pose a little ahead)
    let a crossing pass: where, ahead, the closest points lie c = -(pa' - pb') . n m on
    the far side of each other along this contact's normal n and the capsules are apart
    by g m there, the contact's stiffness is scaled by 1 - clamp(c / w) clamp(g / w)
    (w = ``pass_width``): limbs the animation swings through each other and apart are
    not held up, while a lasting overlap (still touching ahead) is pushed apart."""
    p = wp.tid() + offset
    ia = pair_i[p]
    ib = pair_j[p]
    sv = wp.vec3(pair_shift[p], 0.0, 0.0)
    lo_a = char_lo[ia]
    hi_a = char_hi[ia]
    mask = int(0)
    for jb in range(n_joints):
        bb = ib * n_joints + jb
        cb = centre[bb] + sv
        r = half[bb] + cap_radius[bb] + cap_skin[bb]
        closest = wp.min(wp.max(cb, lo_a), hi_a)
        if wp.length_sq(closest - cb) <= r * r:
            mask = mask | (1 << jb)
    if mask == 0:
        return
    lo = char_lo[ib] + sv
    hi = char_hi[ib] + sv
    for ja in range(n_joints):
        ba = ia * n_joints + ja
        ra = cap_radius[ba] + cap_skin[ba]
        ca = centre[ba]
        bound_a = half[ba] + ra + margin + spec
        # sphere of capsule a against the AABB of character b (already grown)
        closest = wp.min(wp.max(ca, lo), hi)
        if wp.length_sq(closest - ca) > bound_a * bound_a:
            continue
        a0 = p0w[ba]
        a1 = p1w[ba]
        for jb in range(n_joints):
            if (mask >> jb) & 1 == 0:
                continue
            bb = ib * n_joints + jb
            rb = cap_radius[bb] + cap_skin[bb]
            cb = centre[bb] + sv
            reach = bound_a + half[bb] + rb
            if wp.length_sq(cb - ca) > reach * reach:
                continue
            b0 = p0w[bb] + sv
            b1 = p1w[bb] + sv
            st = segment_params(a0, a1, b0, b1)
            pa = a0 + st[0] * (a1 - a0)
            pb = b0 + st[1] * (b1 - b0)
            d = pa - pb
            dist = wp.length(d)
            depth = ra + rb + margin - dist
            if depth > -spec:
                n = wp.vec3(0.0, 1.0, 0.0)
                if dist > 1.0e-6:
                    n = d / dist
                else:
                    dc = x[ba] - (x[bb] + sv)
                    if wp.length(dc) > 1.0e-6:
                        n = wp.normalize(dc)
                k_pair = k
                if pass_on != 0:
                    sa = segment_params(p0a[ba], p1a[ba], p0a[bb] + sv, p1a[bb] + sv)
                    qa = p0a[ba] + sa[0] * (p1a[ba] - p0a[ba])
                    qb = p0a[bb] + sv + sa[1] * (p1a[bb] - p0a[bb])
                    through = -wp.dot(qa - qb, n)
                    apart = wp.length(qa - qb) - (ra + rb + margin)
                    k_pair = k * (
                        1.0 - wp.clamp(through / pass_width, 0.0, 1.0) * wp.clamp(apart / pass_width, 0.0, 1.0)
                    )
                push_contact(
                    count,
                    capacity,
                    ba,
                    bb,
                    n,
                    depth,
                    pa - x[ba],
                    pb - (x[bb] + sv),
                    k_pair,
                    2,
                    c_a,
                    c_b,
                    c_n,
                    c_depth,
                    c_la,
                    c_lb,
                    c_k,
                    c_kind,
                )


@wp.kernel
def intra_kernel(
    x: wp.array(dtype=wp.vec3),
    p0w: wp.array(dtype=wp.vec3),
    p1w: wp.array(dtype=wp.vec3),
    cap_radius: wp.array(dtype=float),
    centre: wp.array(dtype=wp.vec3),
    half: wp.array(dtype=float),
    pairs: wp.array2d(dtype=wp.int32),
    relative: int,
    p0t: wp.array(dtype=wp.vec3),
    p1t: wp.array(dtype=wp.vec3),
    band: float,
    spec: float,
    k: float,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    c_n: wp.array(dtype=wp.vec3),
    c_depth: wp.array(dtype=float),
    c_la: wp.array(dtype=wp.vec3),
    c_lb: wp.array(dtype=wp.vec3),
    c_k: wp.array(dtype=float),
    c_kind: wp.array(dtype=wp.int32),
):
    """One intra-body capsule pair per thread: bounding spheres, then exact distance.

    With ``relative``, pairs that interpenetrate in the animation's TARGET pose (p0t,
    p1t) push only with the depth beyond the target's own: depth - max(depth_target +
    band, 0) (m), so the physics does not fight the animation's own self-overlap."""
    t = wp.tid()
    ba = pairs[t, 0]
    bb = pairs[t, 1]
    ra = cap_radius[ba]
    rb = cap_radius[bb]
    reach = half[ba] + half[bb] + ra + rb + spec
    if wp.length_sq(centre[ba] - centre[bb]) > reach * reach:
        return
    a0 = p0w[ba]
    a1 = p1w[ba]
    b0 = p0w[bb]
    b1 = p1w[bb]
    st = segment_params(a0, a1, b0, b1)
    pa = a0 + st[0] * (a1 - a0)
    pb = b0 + st[1] * (b1 - b0)
    d = pa - pb
    dist = wp.length(d)
    depth = ra + rb - dist
    if relative != 0:
        st_t = segment_params(p0t[ba], p1t[ba], p0t[bb], p1t[bb])
        dt_ = (p0t[ba] + st_t[0] * (p1t[ba] - p0t[ba])) - (p0t[bb] + st_t[1] * (p1t[bb] - p0t[bb]))
        depth = depth - wp.max(ra + rb - wp.length(dt_) + band, 0.0)
    if depth > -spec and dist > 1.0e-6:
        push_contact(
            count,
            capacity,
            ba,
            bb,
            d / dist,
            depth,
            pa - x[ba],
            pb - x[bb],
            k,
            3,
            c_a,
            c_b,
            c_n,
            c_depth,
            c_la,
            c_lb,
            c_k,
            c_kind,
        )


@wp.kernel
def environment_kernel(
    x: wp.array(dtype=wp.vec3),
    p0w: wp.array(dtype=wp.vec3),
    p1w: wp.array(dtype=wp.vec3),
    cap_radius: wp.array(dtype=float),
    cap_skin: wp.array(dtype=float),
    body_char: wp.array(dtype=wp.int32),
    char_lo: wp.array(dtype=wp.vec3),
    char_hi: wp.array(dtype=wp.vec3),
    bvh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    env_lo: wp.vec3,
    env_hi: wp.vec3,
    period: float,
    margin: float,
    spec: float,
    k: float,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    c_n: wp.array(dtype=wp.vec3),
    c_depth: wp.array(dtype=float),
    c_la: wp.array(dtype=wp.vec3),
    c_lb: wp.array(dtype=wp.vec3),
    c_k: wp.array(dtype=float),
    c_kind: wp.array(dtype=wp.int32),
):
    """Capsule (thread) against the static sample points (m) of the scene's BVH; in
    periodic scenes the capsule is wrapped into [0, period) along x first."""
    b = wp.tid()
    i = body_char[b]
    shift = float(0.0)
    if period > 0.0:
        cx = 0.5 * (char_lo[i][0] + char_hi[i][0])
        shift = -period * wp.floor(cx / period)
    sv = wp.vec3(shift, 0.0, 0.0)
    # cull: the character AABB against the bounds of the static samples
    clo = char_lo[i] + sv
    chi = char_hi[i] + sv
    if clo[0] > env_hi[0] or clo[1] > env_hi[1] or clo[2] > env_hi[2]:
        return
    if env_lo[0] > chi[0] or env_lo[1] > chi[1] or env_lo[2] > chi[2]:
        return
    a0 = p0w[b] + sv
    a1 = p1w[b] + sv
    r = cap_radius[b] + cap_skin[b] + margin
    grow = wp.vec3(r + spec, r + spec, r + spec)
    lo = wp.min(a0, a1) - grow
    hi = wp.max(a0, a1) + grow
    query = wp.bvh_query_aabb(bvh, lo, hi)
    idx = int(0)
    while wp.bvh_query_next(query, idx):
        pt = points[idx]
        d1 = a1 - a0
        ll = wp.dot(d1, d1)
        s = float(0.0)
        if ll > 1.0e-10:
            s = wp.clamp(wp.dot(pt - a0, d1) / ll, 0.0, 1.0)
        c = a0 + s * d1
        d = c - pt
        dist = wp.length(d)
        depth = r - dist
        if depth > -spec and dist > 1.0e-6:
            push_contact(
                count,
                capacity,
                b,
                -1,
                d / dist,
                depth,
                c - (x[b] + sv),
                wp.vec3(0.0, 0.0, 0.0),
                k,
                1,
                c_a,
                c_b,
                c_n,
                c_depth,
                c_la,
                c_lb,
                c_k,
                c_kind,
            )


@wp.kernel
def wall_kernel(
    x: wp.array(dtype=wp.vec3),
    p0w: wp.array(dtype=wp.vec3),
    p1w: wp.array(dtype=wp.vec3),
    cap_radius: wp.array(dtype=float),
    cap_skin: wp.array(dtype=float),
    body_char: wp.array(dtype=wp.int32),
    n_joints: int,
    side_x: wp.array(dtype=wp.vec3),
    walls: wp.array(dtype=wp.vec4),
    period: float,
    margin: float,
    spec: float,
    k: float,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    c_n: wp.array(dtype=wp.vec3),
    c_depth: wp.array(dtype=float),
    c_la: wp.array(dtype=wp.vec3),
    c_lb: wp.array(dtype=wp.vec3),
    c_k: wp.array(dtype=float),
    c_kind: wp.array(dtype=wp.int32),
):
    """Both end spheres of each capsule (thread) against each wall (x0, y0, x1, y1), m: a
    vertical plane through the segment, one-sided. Its free side is the side of the
    character's root in ``side_x`` (the animation's target pose when known): a hand that
    reaches through the wall is pushed back to the side its body stands on, never through
    (point samples push a capsule whose axis has crossed them further out). The normal is
    the wall's horizontal normal, so a body sliding along a wall feels no tangential force.
    An end sphere counts where its foot point falls within the segment (in periodic scenes
    at the first image that does, the character wrapped into [0, period) by its root);
    depth r - (signed distance of the sphere centre), r the radius plus skin plus margin."""
    b = wp.tid()
    i = body_char[b]
    rx = side_x[i * n_joints]
    # periodic scenes: the character is taken into [0, period) along x by its root's
    # wrap, then its images at +-period are tried
    wrap = float(0.0)
    if period > 0.0:
        wrap = -period * wp.floor(rx[0] / period)
    rx = wp.vec3(rx[0] + wrap, rx[1], rx[2])
    r = cap_radius[b] + cap_skin[b] + margin
    for m in range(walls.shape[0]):
        s = walls[m]
        dx = s[2] - s[0]
        dy = s[3] - s[1]
        ll = dx * dx + dy * dy
        if ll < 1.0e-12:
            continue
        inv = 1.0 / wp.sqrt(ll)
        nx = -dy * inv
        ny = dx * inv
        side = (rx[0] - s[0]) * nx + (rx[1] - s[1]) * ny
        if side < 0.0:
            nx = -nx
            ny = -ny
        normal = wp.vec3(nx, ny, 0.0)
        for e in range(2):
            p = p0w[b]
            if e == 1:
                p = p1w[b]
            images = int(1)
            if period > 0.0:
                images = 3
            for im in range(images):
                sx = wrap
                if im == 1:
                    sx = wrap + period
                elif im == 2:
                    sx = wrap - period
                ex = p[0] + sx - s[0]
                ey = p[1] - s[1]
                t = (ex * dx + ey * dy) / ll
                if t >= 0.0 and t <= 1.0:
                    depth = r - (ex * nx + ey * ny)
                    if depth > -spec:
                        push_contact(
                            count,
                            capacity,
                            b,
                            -1,
                            normal,
                            depth,
                            p - x[b],
                            wp.vec3(0.0, 0.0, 0.0),
                            k,
                            1,
                            c_a,
                            c_b,
                            c_n,
                            c_depth,
                            c_la,
                            c_lb,
                            c_k,
                            c_kind,
                        )
                    break

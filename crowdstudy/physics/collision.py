"""Collision detection: ground, environment, inter-body and intra-body capsule contacts.

Pipeline (paper Sec. 3.4), every step on the state at the start of the step:

1. one AABB per character (its capsules, grown by the margins);
2. ground: both sphere ends of every capsule against the plane z = 0;
3. environment: walls (vertical planes on floor segments, the scene's obstacles) against
   both end spheres of every capsule, one-sided (``wall_kernel``); other static objects
   point-sampled into a ``wp.Bvh``, each capsule's AABB querying it (culled against the
   character AABB first);
4. inter-body: character AABB pairs (minimum image along x in periodic scenes; one thread
   per character over the later ones, so the pairs come out in (i, j) order on the CPU; on
   the CPU from 200 characters without a period, the characters sorted by x, each against
   those that start before it ends: ``sweep_kernel``, the same pairs in the same order),
   then per pair (one thread) the second character's capsules that can reach the first's
   AABB, a bounding-sphere test per capsule pair (midpoints and half lengths computed once
   per step with the world capsules), then the exact segment-segment distance;
5. intra-body: the model's pair list (pairs touching in the T-pose and parent-child pairs
   are excluded), bounding-sphere test, exact distance.

On the CPU with two host threads (:func:`~crowdstudy.warp_runtime.host_threads`) the
narrow phase runs on two ranges of its character pairs at once, the second range and the
intra-body pairs into a scratch buffer appended after the first: the same contacts in the
same order as one thread; from 200 characters the capsule poses of the state and of the
target and look-ahead poses are computed at once too.

A contact stores body a, body b (-1 for static), the unit normal n from b to a, the signed
depth ``delta = r_a + r_b + margin - distance`` (contacts are kept speculatively down to
``-speculative_distance``; the solver linearises the depth to the predicted state and
only penalises positive depths), the world lever arms from each body's centre of mass to
the segment closest points, and the penalty stiffness (N/m). Inter-body and environment
contacts use the radius plus the capsule's mesh skin (``Model.cap_skin``) plus the margin;
ground and intra-body contacts the bare radius.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from crowdstudy.scene import wall_segments
from crowdstudy.warp_runtime import host_threads, run_parallel

__all__ = ["Contacts", "CollisionPipeline", "collision_kernels", "sample_static_walls", "sweep_pairs",
           "KIND_GROUND", "KIND_ENVIRONMENT", "KIND_INTER", "KIND_INTRA"]

KIND_GROUND, KIND_ENVIRONMENT, KIND_INTER, KIND_INTRA = 0, 1, 2, 3

#: capsule pairs to test (character pairs x J, plus the intra-body pairs) below which
#: detection stays on one host thread
_MIN_SPLIT_THREADS = 20000
#: characters from which the CPU finds the overlapping character AABBs by a sweep along x
#: (``sweep_kernel``, O(n k)) instead of ``broadphase_kernel``'s n^2 / 2 tests
_MIN_CHARACTERS_SWEEP = 200
#: characters from which the three capsule poses are computed on two host threads at once
_MIN_CHARACTERS_PARALLEL = 200


@functools.lru_cache(maxsize=1)
def collision_kernels():
    """Build (once) the Warp collision kernels."""
    from types import SimpleNamespace

    from crowdstudy.warp_runtime import get_warp

    wp = get_warp()
    wp.set_module_options({"enable_backward": False}, module=__name__)   # forward only: no adjoints to compile

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
    def push_contact(count: wp.array(dtype=wp.int32), capacity: int, a: int, b: int, n: wp.vec3, depth: float,
                     lever_a: wp.vec3, lever_b: wp.vec3, k: float, kind: int,
                     c_a: wp.array(dtype=wp.int32), c_b: wp.array(dtype=wp.int32),
                     c_n: wp.array(dtype=wp.vec3), c_depth: wp.array(dtype=float),
                     c_la: wp.array(dtype=wp.vec3), c_lb: wp.array(dtype=wp.vec3),
                     c_k: wp.array(dtype=float), c_kind: wp.array(dtype=wp.int32)):
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
    def capsules_world_kernel(x: wp.array(dtype=wp.vec3), q: wp.array(dtype=wp.quat),
                              cap_p0: wp.array(dtype=wp.vec3), cap_p1: wp.array(dtype=wp.vec3),
                              cap_radius: wp.array(dtype=float), cap_skin: wp.array(dtype=float),
                              n_joints: int, grow: float,
                              p0w: wp.array(dtype=wp.vec3), p1w: wp.array(dtype=wp.vec3),
                              char_lo: wp.array(dtype=wp.vec3), char_hi: wp.array(dtype=wp.vec3),
                              centre: wp.array(dtype=wp.vec3), half: wp.array(dtype=float)):
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
    def ground_kernel(x: wp.array(dtype=wp.vec3), p0w: wp.array(dtype=wp.vec3), p1w: wp.array(dtype=wp.vec3),
                      cap_radius: wp.array(dtype=float), relative: int, p0t: wp.array(dtype=wp.vec3),
                      p1t: wp.array(dtype=wp.vec3), band: float, spec: float, k: float,
                      count: wp.array(dtype=wp.int32), capacity: int,
                      c_a: wp.array(dtype=wp.int32), c_b: wp.array(dtype=wp.int32), c_n: wp.array(dtype=wp.vec3),
                      c_depth: wp.array(dtype=float), c_la: wp.array(dtype=wp.vec3), c_lb: wp.array(dtype=wp.vec3),
                      c_k: wp.array(dtype=float), c_kind: wp.array(dtype=wp.int32)):
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
                push_contact(count, capacity, b, -1, up, depth, p - x[b], zero, k, 0,
                             c_a, c_b, c_n, c_depth, c_la, c_lb, c_k, c_kind)

    @wp.kernel
    def broadphase_kernel(char_lo: wp.array(dtype=wp.vec3), char_hi: wp.array(dtype=wp.vec3), period: float,
                          pair_count: wp.array(dtype=wp.int32), pair_capacity: int,
                          pair_i: wp.array(dtype=wp.int32), pair_j: wp.array(dtype=wp.int32),
                          pair_shift: wp.array(dtype=float)):
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
    def sweep_kernel(char_lo: wp.array(dtype=wp.vec3), char_hi: wp.array(dtype=wp.vec3),
                     order: wp.array(dtype=wp.int32), sorted_lo_x: wp.array(dtype=float), reach: float,
                     pair_count: wp.array(dtype=wp.int32), pair_capacity: int,
                     pair_i: wp.array(dtype=wp.int32), pair_j: wp.array(dtype=wp.int32),
                     pair_shift: wp.array(dtype=float)):
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
            for s in range(start + 1, end):          # insertion sort of this character's pairs by j
                v = pair_j[s]
                t = s - 1
                while t >= start and pair_j[t] > v:
                    pair_j[t + 1] = pair_j[t]
                    t -= 1
                pair_j[t + 1] = v

    @wp.kernel
    def narrowphase_kernel(x: wp.array(dtype=wp.vec3), p0w: wp.array(dtype=wp.vec3), p1w: wp.array(dtype=wp.vec3),
                           cap_radius: wp.array(dtype=float), cap_skin: wp.array(dtype=float),
                           centre: wp.array(dtype=wp.vec3), half: wp.array(dtype=float),
                           char_lo: wp.array(dtype=wp.vec3), char_hi: wp.array(dtype=wp.vec3), pair_i: wp.array(dtype=wp.int32),
                           pair_j: wp.array(dtype=wp.int32), pair_shift: wp.array(dtype=float),
                           n_joints: int, margin: float, spec: float, k: float,
                           count: wp.array(dtype=wp.int32), capacity: int,
                           c_a: wp.array(dtype=wp.int32), c_b: wp.array(dtype=wp.int32),
                           c_n: wp.array(dtype=wp.vec3), c_depth: wp.array(dtype=float),
                           c_la: wp.array(dtype=wp.vec3), c_lb: wp.array(dtype=wp.vec3),
                           c_k: wp.array(dtype=float), c_kind: wp.array(dtype=wp.int32), offset: int,
                           pass_on: int, p0a: wp.array(dtype=wp.vec3), p1a: wp.array(dtype=wp.vec3),
                           pass_width: float):
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
                        k_pair = k * (1.0 - wp.clamp(through / pass_width, 0.0, 1.0)
                                      * wp.clamp(apart / pass_width, 0.0, 1.0))
                    push_contact(count, capacity, ba, bb, n, depth, pa - x[ba], pb - (x[bb] + sv), k_pair, 2,
                                 c_a, c_b, c_n, c_depth, c_la, c_lb, c_k, c_kind)

    @wp.kernel
    def intra_kernel(x: wp.array(dtype=wp.vec3), p0w: wp.array(dtype=wp.vec3), p1w: wp.array(dtype=wp.vec3),
                     cap_radius: wp.array(dtype=float), centre: wp.array(dtype=wp.vec3), half: wp.array(dtype=float),
                     pairs: wp.array2d(dtype=wp.int32), relative: int,
                     p0t: wp.array(dtype=wp.vec3), p1t: wp.array(dtype=wp.vec3), band: float, spec: float, k: float,
                     count: wp.array(dtype=wp.int32), capacity: int,
                     c_a: wp.array(dtype=wp.int32), c_b: wp.array(dtype=wp.int32),
                     c_n: wp.array(dtype=wp.vec3), c_depth: wp.array(dtype=float),
                     c_la: wp.array(dtype=wp.vec3), c_lb: wp.array(dtype=wp.vec3),
                     c_k: wp.array(dtype=float), c_kind: wp.array(dtype=wp.int32)):
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
            push_contact(count, capacity, ba, bb, d / dist, depth, pa - x[ba], pb - x[bb], k, 3,
                         c_a, c_b, c_n, c_depth, c_la, c_lb, c_k, c_kind)

    @wp.kernel
    def environment_kernel(x: wp.array(dtype=wp.vec3), p0w: wp.array(dtype=wp.vec3), p1w: wp.array(dtype=wp.vec3),
                           cap_radius: wp.array(dtype=float), cap_skin: wp.array(dtype=float),
                           body_char: wp.array(dtype=wp.int32),
                           char_lo: wp.array(dtype=wp.vec3), char_hi: wp.array(dtype=wp.vec3),
                           bvh: wp.uint64, points: wp.array(dtype=wp.vec3), env_lo: wp.vec3, env_hi: wp.vec3,
                           period: float, margin: float, spec: float, k: float,
                           count: wp.array(dtype=wp.int32), capacity: int,
                           c_a: wp.array(dtype=wp.int32), c_b: wp.array(dtype=wp.int32),
                           c_n: wp.array(dtype=wp.vec3), c_depth: wp.array(dtype=float),
                           c_la: wp.array(dtype=wp.vec3), c_lb: wp.array(dtype=wp.vec3),
                           c_k: wp.array(dtype=float), c_kind: wp.array(dtype=wp.int32)):
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
                push_contact(count, capacity, b, -1, d / dist, depth, c - (x[b] + sv), wp.vec3(0.0, 0.0, 0.0), k, 1,
                             c_a, c_b, c_n, c_depth, c_la, c_lb, c_k, c_kind)

    @wp.kernel
    def wall_kernel(x: wp.array(dtype=wp.vec3), p0w: wp.array(dtype=wp.vec3), p1w: wp.array(dtype=wp.vec3),
                    cap_radius: wp.array(dtype=float), cap_skin: wp.array(dtype=float),
                    body_char: wp.array(dtype=wp.int32), n_joints: int, side_x: wp.array(dtype=wp.vec3),
                    walls: wp.array(dtype=wp.vec4), period: float, margin: float, spec: float, k: float,
                    count: wp.array(dtype=wp.int32), capacity: int,
                    c_a: wp.array(dtype=wp.int32), c_b: wp.array(dtype=wp.int32),
                    c_n: wp.array(dtype=wp.vec3), c_depth: wp.array(dtype=float),
                    c_la: wp.array(dtype=wp.vec3), c_lb: wp.array(dtype=wp.vec3),
                    c_k: wp.array(dtype=float), c_kind: wp.array(dtype=wp.int32)):
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
                            push_contact(count, capacity, b, -1, normal, depth, p - x[b], wp.vec3(0.0, 0.0, 0.0),
                                         k, 1, c_a, c_b, c_n, c_depth, c_la, c_lb, c_k, c_kind)
                        break

    return SimpleNamespace(wp=wp, segment_params=segment_params, capsules_world_kernel=capsules_world_kernel,
                           ground_kernel=ground_kernel, broadphase_kernel=broadphase_kernel, sweep_kernel=sweep_kernel,
                           narrowphase_kernel=narrowphase_kernel, intra_kernel=intra_kernel,
                           environment_kernel=environment_kernel, wall_kernel=wall_kernel)


def launch_sweep(char_lo, char_hi, order, sorted_lo_x, pair_count, pair_capacity: int,
                 pair_i, pair_j, pair_shift) -> None:
    """Launch ``sweep_kernel`` on the CPU: ``char_lo``, ``char_hi`` the boxes' corners (CPU
    Warp arrays of vec3, m, read here as numpy too); ``order`` and ``sorted_lo_x`` Warp
    scratch arrays of length n."""
    k = collision_kernels()
    wp = k.wp
    lo = char_lo.numpy()
    idx = np.argsort(lo[:, 0], kind="stable")
    order.numpy()[:] = idx
    sorted_lo_x.numpy()[:] = lo[idx, 0]
    hi = char_hi.numpy()
    reach = float(np.max(hi[:, 0] - lo[:, 0])) + 1e-3 if len(lo) else 0.0
    pair_count.zero_()
    wp.launch(k.sweep_kernel, len(lo), [char_lo, char_hi, order, sorted_lo_x, reach, pair_count, pair_capacity,
                                         pair_i, pair_j, pair_shift], device="cpu")


def sweep_pairs(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i < j) of overlapping boxes (``lo``, ``hi``: (n, 3) corners, m) in (i, j)
    order by ``sweep_kernel`` on the CPU: the pairs and the order of ``broadphase_kernel``
    without a period (closed intervals, the kernel's comparisons)."""
    wp = collision_kernels().wp
    lo = np.ascontiguousarray(lo, np.float32)
    hi = np.ascontiguousarray(hi, np.float32)
    n = len(lo)
    cap = max(min(n * (n - 1) // 2, 32 * n), 1)          # grown below if the boxes overlap more
    count = wp.zeros(1, dtype=wp.int32, device="cpu")
    boxes = (wp.array(lo, dtype=wp.vec3, device="cpu"), wp.array(hi, dtype=wp.vec3, device="cpu"),
             wp.zeros(max(n, 1), dtype=wp.int32, device="cpu"), wp.zeros(max(n, 1), dtype=wp.float32, device="cpu"))
    while True:
        pi, pj = wp.zeros(cap, dtype=wp.int32, device="cpu"), wp.zeros(cap, dtype=wp.int32, device="cpu")
        shift = wp.zeros(cap, dtype=wp.float32, device="cpu")
        launch_sweep(*boxes, count, cap, pi, pj, shift)
        m = int(count.numpy()[0])
        if m <= cap:
            return pi.numpy()[:m].copy(), pj.numpy()[:m].copy()
        cap = m


def sample_static_walls(walls: np.ndarray, *, height: float = 2.2, spacing: float = 0.04,
                        period: float | None = None, overhang: float = 0.6) -> np.ndarray:
    """Point samples (P, 3) of vertical walls standing on the floor.

    Args:
        walls: (M, 2, 2) float, metres: wall segments in the floor plane.
        height: wall height, m.
        spacing: sample spacing, m.
        period: for periodic scenes, walls are clipped to x in [-overhang, period + overhang).
        overhang: m, see ``period`` (>= the largest capsule extent a query can have).
    """
    walls = np.asarray(walls, np.float64).reshape(-1, 2, 2)
    pts = []
    zs = np.arange(0.0, height + 1e-9, spacing)
    for (x0, y0), (x1, y1) in walls:
        if period:
            lo, hi = -overhang, period + overhang
            if abs(x1 - x0) > 1e-9:
                t0, t1 = sorted(((lo - x0) / (x1 - x0), (hi - x0) / (x1 - x0)))
                t0, t1 = max(t0, 0.0), min(t1, 1.0)
                if t1 <= t0:
                    continue
                (x0, y0), (x1, y1) = ((x0 + t0 * (x1 - x0), y0 + t0 * (y1 - y0)),
                                      (x0 + t1 * (x1 - x0), y0 + t1 * (y1 - y0)))
        length = float(np.hypot(x1 - x0, y1 - y0))
        n = max(int(np.ceil(length / spacing)), 1) + 1
        t = np.linspace(0.0, 1.0, n)
        xy = np.stack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)], 1)
        grid = np.concatenate([np.repeat(xy, len(zs), 0), np.tile(zs, len(xy))[:, None]], 1)
        pts.append(grid)
    return np.concatenate(pts) if pts else np.zeros((0, 3))


@dataclasses.dataclass(eq=False)
class Contacts:
    """Preallocated contact buffers on the device (capacity C).

    count (1,) int32 (may exceed the capacity: the surplus was dropped); body_a, body_b (C,)
    int32 (b = -1 for static); normal (C,) vec3 from b to a; depth (C,) m (signed);
    lever_a, lever_b (C,) vec3 m (world, from each centre of mass to the contact point);
    stiffness (C,) N/m; kind (C,) int32 (KIND_*).
    """

    capacity: int
    count: object
    body_a: object
    body_b: object
    normal: object
    depth: object
    lever_a: object
    lever_b: object
    stiffness: object
    kind: object

    @classmethod
    def allocate(cls, capacity: int, device: str) -> "Contacts":
        from crowdstudy.warp_runtime import get_warp

        wp = get_warp()
        return cls(capacity=int(capacity), count=wp.zeros(1, dtype=wp.int32, device=device),
                   body_a=wp.zeros(capacity, dtype=wp.int32, device=device),
                   body_b=wp.zeros(capacity, dtype=wp.int32, device=device),
                   normal=wp.zeros(capacity, dtype=wp.vec3, device=device),
                   depth=wp.zeros(capacity, dtype=wp.float32, device=device),
                   lever_a=wp.zeros(capacity, dtype=wp.vec3, device=device),
                   lever_b=wp.zeros(capacity, dtype=wp.vec3, device=device),
                   stiffness=wp.zeros(capacity, dtype=wp.float32, device=device),
                   kind=wp.zeros(capacity, dtype=wp.int32, device=device))

    def buffers(self) -> list:
        return [self.body_a, self.body_b, self.normal, self.depth, self.lever_a, self.lever_b, self.stiffness,
                self.kind]

    def n_active(self) -> int:
        """Contacts stored (host sync on CUDA)."""
        return min(int(self.count.numpy()[0]), self.capacity)

    def to_numpy(self) -> dict:
        n = self.n_active()
        names = ("body_a", "body_b", "normal", "depth", "lever_a", "lever_b", "stiffness", "kind")
        return {name: getattr(self, name).numpy()[:n].copy() for name in names}


class CollisionPipeline:
    """Detects all four contact kinds for a model; ``collide(state, contacts)``.

    Args:
        model: the :class:`~crowdstudy.physics.model.Model`.
        config: :class:`~crowdstudy.physics.config.PhysicsConfig`.
        static_points: (P, 3) metres, point samples of static objects (or None).
        period: length (m) of the periodic x axis, or None.
        static_walls: (M, 2, 2) metres, vertical walls standing on the floor (segments in
            the floor plane, e.g. :func:`crowdstudy.scene.static_walls_from_meta`), or None: one-sided plane
            contacts of every capsule end (``wall_kernel``, stiffness ``config.wall_stiffness``).
    """

    def __init__(self, model, config, *, static_points: np.ndarray | None = None, period: float | None = None,
                 static_walls: np.ndarray | None = None):
        self.model = model
        self.config = config
        self.k = collision_kernels()
        wp = self.k.wp
        dev = model.device
        n, nb = model.n_characters, model.n_bodies
        self.period = float(period or 0.0)
        self.speculative = float(config.speculative_distance)
        self.p0w = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.p1w = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.centre = wp.zeros(nb, dtype=wp.vec3, device=dev)     # capsule midpoints (m)
        self.half = wp.zeros(nb, dtype=wp.float32, device=dev)    # capsule half lengths (m)
        self.centre_t = wp.zeros(nb, dtype=wp.vec3, device=dev)   # the same in the target pose
        self.half_t = wp.zeros(nb, dtype=wp.float32, device=dev)
        self.char_lo = wp.zeros(n, dtype=wp.vec3, device=dev)
        self.char_hi = wp.zeros(n, dtype=wp.vec3, device=dev)
        # the capsules in the target pose (target-relative ground and self contacts)
        self.p0t = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.p1t = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.t_lo = wp.zeros(n, dtype=wp.vec3, device=dev)
        self.t_hi = wp.zeros(n, dtype=wp.vec3, device=dev)
        # ... and in the look-ahead pose (config.contact_pass_ahead)
        self.pass_on = bool(config.contact_pass_ahead > 0 and config.contact_pass_width > 0)
        na = nb if self.pass_on else 1
        self.p0a = wp.zeros(na, dtype=wp.vec3, device=dev)
        self.p1a = wp.zeros(na, dtype=wp.vec3, device=dev)
        self._ahead_scratch = (wp.zeros(n, dtype=wp.vec3, device=dev), wp.zeros(n, dtype=wp.vec3, device=dev),
                               wp.zeros(na, dtype=wp.vec3, device=dev), wp.zeros(na, dtype=wp.float32, device=dev))
        self.pair_capacity = max(16 * n, 64)
        self.pair_count = wp.zeros(1, dtype=wp.int32, device=dev)
        self.pair_i = wp.zeros(self.pair_capacity, dtype=wp.int32, device=dev)
        self.pair_j = wp.zeros(self.pair_capacity, dtype=wp.int32, device=dev)
        self.pair_shift = wp.zeros(self.pair_capacity, dtype=wp.float32, device=dev)
        self.dropped_pairs = 0
        self.bvh = None
        self.static_enabled = True  # switch static objects off (e.g. the damping study's release)
        pts = None if static_points is None else np.asarray(static_points, np.float32).reshape(-1, 3)
        if pts is not None and len(pts):
            self.points = wp.array(pts, dtype=wp.vec3, device=dev)
            self.bvh = wp.Bvh(self.points, self.points)
            self.env_lo = wp.vec3(*(pts.min(0) - 1e-3))
            self.env_hi = wp.vec3(*(pts.max(0) + 1e-3))
        self.n_static_points = 0 if pts is None else len(pts)
        walls = wall_segments([] if static_walls is None else static_walls, "static_walls")
        self.n_static_walls = len(walls)
        self.walls = wp.array(walls.reshape(-1, 4).astype(np.float32), dtype=wp.vec4, device=dev) if len(walls) else None
        self._scratch = None      # the second host thread's contact buffer (CPU)
        self._sweep_scratch = None  # the sweep's sorted order and lower x (CPU)
        self._split = 0.75        # share of the narrow-phase threads run by the first host thread

    def default_capacity(self) -> int:
        return int(self.config.max_contacts_per_character) * self.model.n_characters + 2 * self.model.n_bodies

    def collide(self, state, contacts: Contacts, control=None) -> None:
        """Fill ``contacts`` from ``state`` (positions/orientations at the start of the step).

        ``control`` (:class:`~crowdstudy.physics.state.Control`, advanced to this step): with
        ``config.target_relative_self_contacts``, ground and intra-body contacts count only
        the depth beyond the target pose's own (see ``intra_kernel``)."""
        k, wp, m, cfg = self.k, self.k.wp, self.model, self.config
        dev = m.device
        W = m.wp
        nj, n, nb = m.n_joints, m.n_characters, m.n_bodies
        spec = self.speculative
        margin = float(cfg.contact_margin)
        contacts.count.zero_()
        out = [contacts.count, contacts.capacity, *contacts.buffers()]
        relative = int(bool(cfg.target_relative_self_contacts) and control is not None)
        pass_on = int(self.pass_on and control is not None)

        def capsules_now() -> None:         # the state's capsules and character AABBs
            wp.launch(k.capsules_world_kernel, n, [state.x, state.q, W["cap_p0"], W["cap_p1"], W["cap_radius"],
                                                   W["cap_skin"], nj, margin + spec, self.p0w, self.p1w,
                                                   self.char_lo, self.char_hi, self.centre, self.half], device=dev)

        def capsules_target() -> None:      # ... in the target pose and in the look-ahead pose
            if relative:
                wp.launch(k.capsules_world_kernel, n, [control.t_x, control.t_glob, W["cap_p0"], W["cap_p1"],
                                                       W["cap_radius"], W["cap_skin"], nj, 0.0, self.p0t, self.p1t,
                                                       self.t_lo, self.t_hi, self.centre_t, self.half_t], device=dev)
            if pass_on:
                lo, hi, centre, half = self._ahead_scratch
                wp.launch(k.capsules_world_kernel, n, [control.t_x_ahead, control.t_glob_ahead, W["cap_p0"],
                                                       W["cap_p1"], W["cap_radius"], W["cap_skin"], nj, 0.0, self.p0a,
                                                       self.p1a, lo, hi, centre, half], device=dev)

        if (relative or pass_on) and dev == "cpu" and n >= _MIN_CHARACTERS_PARALLEL and host_threads() >= 2:
            run_parallel(capsules_now, capsules_target)      # disjoint outputs: the same bits either way
        else:
            capsules_now()
            capsules_target()
        band = float(cfg.contact_activation)
        if cfg.ground_stiffness > 0:
            wp.launch(k.ground_kernel, nb, [state.x, self.p0w, self.p1w, W["cap_radius"], relative, self.p0t,
                                            self.p1t, band, spec, float(cfg.ground_stiffness), *out], device=dev)
        if self.bvh is not None and self.static_enabled and cfg.environment_stiffness > 0:
            wp.launch(k.environment_kernel, nb, [state.x, self.p0w, self.p1w, W["cap_radius"], W["cap_skin"],
                                                 W["body_char"],
                                                 self.char_lo, self.char_hi, self.bvh.id, self.points, self.env_lo,
                                                 self.env_hi, self.period, margin, spec,
                                                 float(cfg.environment_stiffness), *out], device=dev)
        if self.walls is not None and self.static_enabled and cfg.wall_stiffness > 0:
            side = control.t_x if control is not None else state.x      # whose root gives each wall's free side
            wp.launch(k.wall_kernel, nb, [state.x, self.p0w, self.p1w, W["cap_radius"], W["cap_skin"], W["body_char"],
                                          nj, side, self.walls, self.period, margin, spec, float(cfg.wall_stiffness),
                                          *out], device=dev)
        n_pairs = 0
        if n > 1 and cfg.contact_stiffness > 0:
            if dev == "cpu" and self.period <= 0.0 and n >= _MIN_CHARACTERS_SWEEP:
                if self._sweep_scratch is None:
                    self._sweep_scratch = (wp.zeros(n, dtype=wp.int32, device=dev),
                                           wp.zeros(n, dtype=wp.float32, device=dev))
                launch_sweep(self.char_lo, self.char_hi, *self._sweep_scratch, self.pair_count, self.pair_capacity,
                             self.pair_i, self.pair_j, self.pair_shift)
            else:
                self.pair_count.zero_()
                wp.launch(k.broadphase_kernel, n, [self.char_lo, self.char_hi, self.period, self.pair_count,
                                                   self.pair_capacity, self.pair_i, self.pair_j, self.pair_shift],
                          device=dev)
            n_pairs = int(self.pair_count.numpy()[0])
            if n_pairs > self.pair_capacity:
                self.dropped_pairs += n_pairs - self.pair_capacity
                n_pairs = self.pair_capacity
        n_intra = W["intra_pairs"].shape[0]
        intra_on = bool(cfg.intra_body and n_intra and cfg.intra_stiffness > 0)

        def narrow(buf, lo: int, hi: int) -> None:     # the pairs [lo, hi) into buf
            if hi > lo:
                wp.launch(k.narrowphase_kernel, hi - lo,
                          [state.x, self.p0w, self.p1w, W["cap_radius"], W["cap_skin"], self.centre, self.half,
                           self.char_lo, self.char_hi, self.pair_i, self.pair_j, self.pair_shift, nj, margin, spec,
                           float(cfg.contact_stiffness), buf.count, buf.capacity, *buf.buffers(), int(lo),
                           pass_on, self.p0a, self.p1a, float(cfg.contact_pass_width)],
                          device=dev)

        def intra(buf) -> None:
            if intra_on:
                wp.launch(k.intra_kernel, n_intra, [state.x, self.p0w, self.p1w, W["cap_radius"], self.centre,
                                                    self.half, W["intra_pairs"], relative, self.p0t, self.p1t,
                                                    band, spec, float(cfg.intra_stiffness), buf.count,
                                                    buf.capacity, *buf.buffers()], device=dev)

        total = n_pairs
        if dev != "cpu" or host_threads() < 2 or total * nj + n_intra < _MIN_SPLIT_THREADS:
            narrow(contacts, 0, total)
            intra(contacts)
            return
        # two host threads: the first runs the first `split` of the character pairs into
        # `contacts`, the second the rest and the intra-body pairs into a scratch buffer,
        # appended after: the same contacts in the same order as one thread (the order the
        # solver sums them in), whatever the split, which only balances the two threads.
        if self._scratch is None or self._scratch.capacity != contacts.capacity:
            self._scratch = Contacts.allocate(contacts.capacity, dev)
        scratch = self._scratch
        scratch.count.zero_()
        cut = min(max(int(round(self._split * n_pairs)), 0), n_pairs)
        t0, t1 = run_parallel(lambda: narrow(contacts, 0, cut), lambda: (narrow(scratch, cut, total), intra(scratch)))
        self._balance(t0, t1, cut, total)
        base = int(contacts.count.numpy()[0])
        extra = int(scratch.count.numpy()[0])
        n_copy = min(extra, scratch.capacity, contacts.capacity - base) if base < contacts.capacity else 0
        if n_copy > 0:
            for dst, src in zip(contacts.buffers(), scratch.buffers()):
                wp.copy(dst, src, dest_offset=base, src_offset=0, count=n_copy)
        contacts.count.fill_(base + extra)

    def _balance(self, t0: float, t1: float, cut: int, total: int) -> None:
        """Move the split of the narrow phase towards equal CPU time on both host threads
        (``t0`` s for the character pairs [0, cut), ``t1`` s for [cut, total) plus the
        intra-body pairs)."""
        if cut <= 0 or total <= 0 or t0 <= 0.0:
            return
        per = t0 / cut                               # s per character pair
        rest = max(t1 - per * (total - cut), 0.0)    # the intra pairs
        target = min(max((per * total + rest) / (2.0 * per * total), 0.05), 0.95)
        self._split = 0.5 * self._split + 0.5 * target

"""Linear algebra of a step: contact assembly, preconditioners, PCG, BSR export (Warp).

* ``contact_assemble_kernel``: adds each contact's penalty gradient and Gauss-Newton
  blocks to the body arrays (atomics).
* ``tree_factor_kernel``: exact block LDL^T of each character's 6J x 6J block (diagonal
  blocks plus joint couplings form a tree; leaves are eliminated into their parents), the
  "character" block-Jacobi preconditioner; ``precond_kernel`` the 6x6 block Jacobi.
* ``pcg_fused_kernel``: the whole PCG in one launch (one thread; for the CPU, where Warp
  runs kernels on a single thread anyway and per-launch costs dominate small vector ops);
  ``pcg_split_*_kernel`` the same PCG over two ranges of whole characters, one host thread
  each.
* ``triplets_*_kernel``: the same system as BSR triplets (6x6 blocks) for
  ``warp.optim.linear.cg`` (CUDA) and scipy (benchmark peer, :func:`bsr_from_triplets`);
  ``tree_precond_kernel`` the tree preconditioner as a ``LinearOperator`` for Warp's CG.

Vectors of the system are split into a translation part ``*_t`` (B,) vec3 and a rotation
part ``*_r`` (B,) vec3 (or packed as (B,) spatial_vector ``(t, r)``); the diagonal blocks
are ``hess_a`` (translation-translation), ``hess_b`` (translation-rotation) and ``hess_c``
(rotation-rotation), (B,) mat33 each. Units: metres, seconds, radians; gradients in N and
N m, stiffnesses in N/m.

This module imports Warp when it is imported; :mod:`crowdstudy.physics.solver` imports it
inside the functions that launch its kernels.
"""

# pyright: reportInvalidTypeForm=false
# (Warp's parameter types, wp.array(dtype=...), are calls that a type checker rejects as types)
# pyright: reportOperatorIssue=false, reportArgumentType=false, reportCallIssue=false
# (inside a kernel, Warp's stubs type wp.tid() as int or a tuple, and overload wp.length, wp.dot
# and wp.normalize for quaternions only; Warp's code generator checks these bodies when it compiles)

from __future__ import annotations

import numpy as np
import warp as wp

from crowdstudy.warp_runtime import get_warp

__all__ = [
    "contact_assemble_kernel",
    "precond_kernel",
    "tree_factor_kernel",
    "tree_precond_kernel",
    "pcg_fused_kernel",
    "pcg_split_init_kernel",
    "pcg_split_matvec_kernel",
    "pcg_split_update_kernel",
    "triplets_bodies_kernel",
    "triplets_contacts_kernel",
    "unpack_kernel",
    "bsr_from_triplets",
]

get_warp()  # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})  # forward only: no adjoints to compile


@wp.func
def release_scale(
    a: int,
    b: int,
    n_joints: int,
    x: wp.array(dtype=wp.vec3),
    t_x: wp.array(dtype=wp.vec3),
    release0: float,
    release_width: float,
):
    """Factor in [0, 1] on the penalty of an inter-body contact between bodies a and b.

    A limb held farther than ``release0`` m from where its animation puts it RELATIVE to
    its character's root (dev = |(x - x^) - (x_root - x^_root)|, centres of mass, m) lets
    go of the contact gradually: clamp(1 - (dev - release0) / release_width, 0, 1) for the
    farther of the two bodies, so a hand caught behind a neighbour while its animation
    swings on slides through instead of staying pinned and whipping back; a character
    pushed as a whole keeps its contacts."""
    ra = (a / n_joints) * n_joints
    rb = (b / n_joints) * n_joints
    dev = wp.max(wp.length((x[a] - t_x[a]) - (x[ra] - t_x[ra])), wp.length((x[b] - t_x[b]) - (x[rb] - t_x[rb])))
    return wp.clamp(1.0 - (dev - release0) / release_width, 0.0, 1.0)


@wp.func
def penalty_force(depth: float, k_c: float, activation: float, stiffen: float, kind: int):
    """Force f = phi'(d) (N) and stiffness k = phi''(d) (N/m) of the penalty phi on the
    depth d (m) of an active contact of stiffness k_c (N/m).

    With ``activation`` e = 0, phi = (k/2) d^2 for d > 0 (only positive predicted depths
    act): its stiffness jumps from 0 to k as a contact starts, so a contact predicted just
    apart is ignored for a step and then pushes at full stiffness, and touching limbs
    chatter. With e > 0 (m) the penalty is C2 in d: phi = k (d + e)^3 / (6 e) for
    -e < d < 0 (the stiffness ramps from 0 to k over the last e of approach), and
    phi = k/2 d^2 + k e/2 d + k e^2/6 for d >= 0 (force k (d + e/2), stiffness k).

    Stiffening (inter-body contacts, ``kind`` 2, ``stiffen`` = d0 > 0, m): for d > 0 phi
    gains k d^3 / (3 d0) (force k d^2 / d0, stiffness 2 k d / d0): deep contacts push
    harder without stiffening the light touches."""
    f = k_c * depth
    k = k_c
    if activation > 0.0:
        if depth < 0.0:
            s = depth + activation
            f = k_c * s * s / (2.0 * activation)
            k = k_c * s / activation
        else:
            f = k_c * (depth + 0.5 * activation)
    if stiffen > 0.0 and depth > 0.0 and kind == 2:
        f += k_c * depth * depth / stiffen
        k += 2.0 * k_c * depth / stiffen
    return f, k


@wp.func
def add_contact_terms(
    body: int,
    f: float,
    k: float,
    u_t: wp.vec3,
    u_r: wp.vec3,
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
):
    """Add a contact's gradient f u (N, N m) and Gauss-Newton blocks k u u^T to ``body``
    (atomics: several contacts touch a body); u = (u_t, u_r) the depth's gradient with
    respect to the body's increments (dx, dw)."""
    wp.atomic_add(grad_t, body, f * u_t)
    wp.atomic_add(grad_r, body, f * u_r)
    wp.atomic_add(hess_a, body, k * wp.outer(u_t, u_t))
    wp.atomic_add(hess_b, body, k * wp.outer(u_t, u_r))
    wp.atomic_add(hess_c, body, k * wp.outer(u_r, u_r))
    return 0


@wp.func
def add_ground_friction(
    a: int,
    n: wp.vec3,
    lever: wp.vec3,
    friction: float,
    h: float,
    v: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=wp.vec3),
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
):
    """Viscous friction of a ground contact of body ``a`` (normal ``n``, lever arm
    ``lever`` m): (c/(2h)) |P_t dp|^2, dp the contact point's displacement over the step
    and P_t the tangent projector, i.e. a force c v_t (c = ``friction``, N s/m) against
    sliding; Hessian (c/h) J^T P_t J."""
    pt = wp.identity(n=3, dtype=float) - wp.outer(n, n)
    vp = v[a] + wp.cross(w[a], lever)
    ft = friction * (pt * vp)
    sl = wp.skew(lever)
    ch = friction / h
    wp.atomic_add(grad_t, a, ft)
    wp.atomic_add(grad_r, a, wp.cross(lever, ft))
    wp.atomic_add(hess_a, a, ch * pt)
    wp.atomic_add(hess_b, a, -ch * (pt * sl))
    wp.atomic_add(hess_c, a, -ch * (sl * pt * sl))
    return 0


@wp.kernel
def contact_assemble_kernel(
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
    friction: float,
    activation: float,
    release0: float,
    release_width: float,
    stiffen: float,
    n_joints: int,
    x: wp.array(dtype=wp.vec3),
    t_x: wp.array(dtype=wp.vec3),
    v: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=wp.vec3),
    h: float,
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    u_at: wp.array(dtype=wp.vec3),
    u_ar: wp.array(dtype=wp.vec3),
    u_bt: wp.array(dtype=wp.vec3),
    u_br: wp.array(dtype=wp.vec3),
    k_eff: wp.array(dtype=float),
    contact_list: wp.array(dtype=wp.int32),
    use_list: int,
    lo: int,
    hi: int,
):
    """Penalty of one contact (thread) on its depth d (m). d(q) is linear in the increments
    with gradient u_a = -(n, l_a x n), u_b = (n, l_b x n); linearised to the prediction
    (q_t + h v). Gradient phi'(d) u, Gauss-Newton Hessian phi''(d) u u^T (``penalty_force``;
    inter-body contacts let go of limbs held far from their animation, ``release_scale``,
    when ``release_width`` > 0). Ground contacts (kind 0) also get viscous friction
    (``add_ground_friction``). Writes the contact's effective stiffness ``k_eff`` (0 when
    inactive) and its ``u`` for the matrix-free contact couplings.

    Only bodies in [``lo``, ``hi``) receive terms, and only a contact whose body a is
    among them writes its ``k_eff`` and ``u``; with ``use_list`` the thread's contact is
    ``contact_list[thread]`` (two host threads: each half of the crowd takes the contacts
    that touch it, in contact order, so every body sums its terms in the same order as
    one launch over all contacts with [0, B))."""
    i = wp.tid()
    if use_list != 0:
        i = contact_list[i]
    n_active = wp.min(count[0], capacity)
    if i >= n_active:
        return
    a = c_a[i]
    b = c_b[i]
    own_a = a >= lo and a < hi
    own_b = b >= lo and b < hi
    n = c_n[i]
    at = -n
    ar = -wp.cross(c_la[i], n)
    bt = n
    br = wp.cross(c_lb[i], n)
    depth = c_depth[i] + h * (wp.dot(at, v[a]) + wp.dot(ar, w[a]))
    if b >= 0:
        depth += h * (wp.dot(bt, v[b]) + wp.dot(br, w[b]))
    k_c = c_k[i]
    if release_width > 0.0 and c_kind[i] == 2 and b >= 0:
        k_c = k_c * release_scale(a, b, n_joints, x, t_x, release0, release_width)
    if k_c <= 0.0 or depth <= -activation or (activation <= 0.0 and depth <= 0.0):
        if own_a:
            k_eff[i] = 0.0
        return
    f, k = penalty_force(depth, k_c, activation, stiffen, c_kind[i])
    if own_a:
        k_eff[i] = k
        u_at[i] = at
        u_ar[i] = ar
        u_bt[i] = bt
        u_br[i] = br
        add_contact_terms(a, f, k, at, ar, grad_t, grad_r, hess_a, hess_b, hess_c)
    if b >= 0:
        if not own_b:
            return
        add_contact_terms(b, f, k, bt, br, grad_t, grad_r, hess_a, hess_b, hess_c)
    elif c_kind[i] == 0 and friction > 0.0 and own_a:
        add_ground_friction(a, n, c_la[i], friction, h, v, w, grad_t, grad_r, hess_a, hess_b, hess_c)


@wp.kernel
def precond_kernel(
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    p_tt: wp.array(dtype=wp.mat33),
    p_tr: wp.array(dtype=wp.mat33),
    p_rr: wp.array(dtype=wp.mat33),
):
    """Inverse of each 6x6 diagonal block [[A, B], [B^T, C]] by its Schur complement."""
    i = wp.tid()
    a = hess_a[i]
    b = hess_b[i]
    ai = wp.inverse(a)
    s = hess_c[i] - wp.transpose(b) * ai * b
    si = wp.inverse(s)
    aib = ai * b
    p_rr[i] = si
    p_tr[i] = -aib * si
    p_tt[i] = ai + aib * si * wp.transpose(aib)


@wp.func
def body_rows(
    lo: int,
    hi: int,
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    parent: wp.array(dtype=wp.int32),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    y_t: wp.array(dtype=wp.vec3),
    y_r: wp.array(dtype=wp.vec3),
):
    """y = (diagonal blocks + joint couplings) x on bodies [lo, hi) (whole characters:
    a joint's parent is in its child's character), sequentially."""
    for i in range(lo, hi):
        bm = hess_b[i]
        y_t[i] = hess_a[i] * x_t[i] + bm * x_r[i]
        y_r[i] = wp.transpose(bm) * x_t[i] + hess_c[i] * x_r[i]
    for c in range(lo, hi):
        p = parent[c]
        if p >= 0:
            rp = lever_p[c]
            rc = lever_c[c]
            cc = ctrl_c[c]
            zc = wp.cross(rc, x_r[c]) - x_t[c]
            zp = x_t[p] - wp.cross(rp, x_r[p])
            y_t[p] = y_t[p] + k_joint * zc
            y_r[p] = y_r[p] + k_joint * wp.cross(rp, zc) - cc * x_r[c]
            y_t[c] = y_t[c] - k_joint * zp
            y_r[c] = y_r[c] - k_joint * wp.cross(rc, zp) - cc * x_r[p]
    return 0


@wp.func
def matvec(
    nb: int,
    n_contacts: int,
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    parent: wp.array(dtype=wp.int32),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    u_at: wp.array(dtype=wp.vec3),
    u_ar: wp.array(dtype=wp.vec3),
    u_bt: wp.array(dtype=wp.vec3),
    u_br: wp.array(dtype=wp.vec3),
    k_eff: wp.array(dtype=float),
    y_t: wp.array(dtype=wp.vec3),
    y_r: wp.array(dtype=wp.vec3),
):
    """y = H x, sequentially: diagonal blocks, joint couplings, contact couplings."""
    body_rows(0, nb, x_t, x_r, hess_a, hess_b, hess_c, parent, lever_p, lever_c, ctrl_c, k_joint, y_t, y_r)
    for i in range(n_contacts):
        b = c_b[i]
        k = k_eff[i]
        if b >= 0 and k > 0.0:
            a = c_a[i]
            sa = wp.dot(u_at[i], x_t[a]) + wp.dot(u_ar[i], x_r[a])
            sb = wp.dot(u_bt[i], x_t[b]) + wp.dot(u_br[i], x_r[b])
            y_t[a] = y_t[a] + (k * sb) * u_at[i]
            y_r[a] = y_r[a] + (k * sb) * u_ar[i]
            y_t[b] = y_t[b] + (k * sa) * u_bt[i]
            y_r[b] = y_r[b] + (k * sa) * u_br[i]
    return 0


@wp.func
def block66(a: wp.mat33, b: wp.mat33, c: wp.mat33, d: wp.mat33):
    """The 6x6 matrix [[a, b], [c, d]] of four 3x3 blocks."""
    m = wp.spatial_matrix()
    for i in range(3):
        for j in range(3):
            m[i, j] = a[i, j]
            m[i, j + 3] = b[i, j]
            m[i + 3, j] = c[i, j]
            m[i + 3, j + 3] = d[i, j]
    return m


@wp.func
def sub33(m: wp.spatial_matrix, r0: int, c0: int):
    """The 3x3 block of ``m`` from row ``r0``, column ``c0``."""
    out = wp.mat33(0.0)
    for i in range(3):
        for j in range(3):
            out[i, j] = m[r0 + i, c0 + j]
    return out


@wp.func
def inv66(m: wp.spatial_matrix):
    """Inverse of a 6x6 matrix whose top-left 3x3 block is invertible (Schur complement)."""
    a = sub33(m, 0, 0)
    b = sub33(m, 0, 3)
    c = sub33(m, 3, 0)
    d = sub33(m, 3, 3)
    ai = wp.inverse(a)
    si = wp.inverse(d - c * ai * b)
    aib = ai * b
    cai = c * ai
    return block66(ai + aib * si * cai, -aib * si, -si * cai, si)


@wp.func
def joint_block(kj: float, rp: wp.vec3, rc: wp.vec3, cc: float):
    """The (parent, child) 6x6 block of a joint: k_j J_p^T J_c - 2 (k + d/h^2) on rotations."""
    eye = wp.identity(n=3, dtype=float)
    sp = wp.skew(rp)
    sc = wp.skew(rc)
    return block66(-kj * eye, kj * sc, -kj * sp, kj * (sp * sc) - cc * eye)


# wp.spatial_vector is an overloaded constructor, a Warp type that pyright does not take as one
@wp.func
def joint_apply_t(kj: float, rp: wp.vec3, rc: wp.vec3, cc: float, y: wp.spatial_vector):  # pyright: ignore[reportGeneralTypeIssues]
    """O^T y for the joint's (parent, child) block O (``joint_block``) without forming
    it: O^T (y_t, y_r) = (k_j z, k_j r_c x z - c y_r) with z = r_p x y_r - y_t (the
    skew blocks are antisymmetric). A few cross products instead of reading and
    multiplying a stored 6x6 matrix in every preconditioner application."""
    yt = wp.vec3(y[0], y[1], y[2])
    yr = wp.vec3(y[3], y[4], y[5])
    z = wp.cross(rp, yr) - yt
    t = kj * z
    r = kj * wp.cross(rc, z) - cc * yr
    return wp.spatial_vector(t[0], t[1], t[2], r[0], r[1], r[2])


@wp.kernel
def tree_factor_kernel(
    n_joints: int,
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    parent: wp.array(dtype=wp.int32),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    work: wp.array(dtype=wp.spatial_matrix),
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    offset: int,
):
    """Exact block LDL^T of one character's (thread + ``offset``) 6J x 6J block (diagonal
    blocks plus joint couplings, a tree): leaves are eliminated into their parents
    (parents[j] < j)."""
    i = wp.tid() + offset
    for j in range(n_joints):
        b = i * n_joints + j
        bm = hess_b[b]
        work[b] = block66(hess_a[b], bm, wp.transpose(bm), hess_c[b])
    for jj in range(n_joints):
        j = n_joints - 1 - jj
        b = i * n_joints + j
        di = inv66(work[b])
        dinv[b] = di
        p = parent[b]
        if p >= 0:
            o = joint_block(k_joint, lever_p[b], lever_c[b], ctrl_c[b])
            lb = o * di
            lmat[b] = lb
            work[p] = work[p] - lb * wp.transpose(o)


@wp.func
def tree_apply(
    lo: int,
    hi: int,
    parent: wp.array(dtype=wp.int32),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    y6: wp.array(dtype=wp.spatial_vector),
    z_t: wp.array(dtype=wp.vec3),
    z_r: wp.array(dtype=wp.vec3),
):
    """z = P r on bodies [lo, hi) (whole characters) with P the inverse of every
    character's tree block (sequential); the joint blocks O^T from the levers
    (``joint_apply_t``)."""
    for b in range(lo, hi):
        rt = r_t[b]
        rr = r_r[b]
        y6[b] = wp.spatial_vector(rt[0], rt[1], rt[2], rr[0], rr[1], rr[2])
    for bb in range(lo, hi):
        b = hi - 1 - (bb - lo)
        p = parent[b]
        if p >= 0:
            y6[p] = y6[p] - lmat[b] * y6[b]
    for b in range(lo, hi):
        p = parent[b]
        y = y6[b]
        if p >= 0:
            y = y - joint_apply_t(k_joint, lever_p[b], lever_c[b], ctrl_c[b], y6[p])
        x = dinv[b] * y
        y6[b] = x
        z_t[b] = wp.vec3(x[0], x[1], x[2])
        z_r[b] = wp.vec3(x[3], x[4], x[5])
    return 0


@wp.kernel
def tree_precond_kernel(
    n_joints: int,
    parent: wp.array(dtype=wp.int32),
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    x: wp.array(dtype=wp.spatial_vector),
    y: wp.array(dtype=wp.spatial_vector),
    z: wp.array(dtype=wp.spatial_vector),
    alpha: float,
    beta: float,
    work: wp.array(dtype=wp.spatial_vector),
):
    """z = alpha P x + beta y, P the tree solve of one character (thread); for
    ``warp.optim.linear`` solvers (a LinearOperator preconditioner, CPU or CUDA)."""
    i = wp.tid()
    b0 = i * n_joints
    for j in range(n_joints):
        work[b0 + j] = x[b0 + j]
    for jj in range(n_joints):
        b = b0 + n_joints - 1 - jj
        p = parent[b]
        if p >= 0:
            work[p] = work[p] - lmat[b] * work[b]
    for j in range(n_joints):
        b = b0 + j
        p = parent[b]
        v = work[b]
        if p >= 0:
            v = v - joint_apply_t(k_joint, lever_p[b], lever_c[b], ctrl_c[b], work[p])
        work[b] = dinv[b] * v
    for j in range(n_joints):
        b = b0 + j
        z[b] = alpha * work[b] + beta * y[b]


@wp.func
def dot6(
    lo: int,
    hi: int,
    a_t: wp.array(dtype=wp.vec3),
    a_r: wp.array(dtype=wp.vec3),
    b_t: wp.array(dtype=wp.vec3),
    b_r: wp.array(dtype=wp.vec3),
):
    """sum over bodies [lo, hi) of a . b (translation and rotation parts), in order."""
    total = float(0.0)
    for i in range(lo, hi):
        total += wp.dot(a_t[i], b_t[i]) + wp.dot(a_r[i], b_r[i])
    return total


@wp.func
def pcg_start(
    lo: int,
    hi: int,
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
):
    """x = 0, r = -g on bodies [lo, hi); returns their |r|^2."""
    bn = float(0.0)
    for i in range(lo, hi):
        x_t[i] = wp.vec3(0.0, 0.0, 0.0)
        x_r[i] = wp.vec3(0.0, 0.0, 0.0)
        rt = -grad_t[i]
        rr = -grad_r[i]
        r_t[i] = rt
        r_r[i] = rr
        bn += wp.dot(rt, rt) + wp.dot(rr, rr)
    return bn


@wp.func
def pcg_advance(
    lo: int,
    hi: int,
    alpha: float,
    p_t: wp.array(dtype=wp.vec3),
    p_r: wp.array(dtype=wp.vec3),
    q_t: wp.array(dtype=wp.vec3),
    q_r: wp.array(dtype=wp.vec3),
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
):
    """x += alpha p, r -= alpha q on bodies [lo, hi); returns their new |r|^2."""
    rr2 = float(0.0)
    for i in range(lo, hi):
        x_t[i] = x_t[i] + alpha * p_t[i]
        x_r[i] = x_r[i] + alpha * p_r[i]
        rt = r_t[i] - alpha * q_t[i]
        rr = r_r[i] - alpha * q_r[i]
        r_t[i] = rt
        r_r[i] = rr
        rr2 += wp.dot(rt, rt) + wp.dot(rr, rr)
    return rr2


@wp.func
def apply_precond(
    mode: int,
    nb: int,
    parent: wp.array(dtype=wp.int32),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
    p_tt: wp.array(dtype=wp.mat33),
    p_tr: wp.array(dtype=wp.mat33),
    p_rr: wp.array(dtype=wp.mat33),
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    y6: wp.array(dtype=wp.spatial_vector),
    z_t: wp.array(dtype=wp.vec3),
    z_r: wp.array(dtype=wp.vec3),
):
    """z = P r: mode 1 the per-character tree solve, mode 0 the 6x6 block Jacobi. Returns r.z."""
    if mode == 1:
        tree_apply(0, nb, parent, r_t, r_r, dinv, lmat, lever_p, lever_c, ctrl_c, k_joint, y6, z_t, z_r)
    else:
        for i in range(nb):
            ptr = p_tr[i]
            z_t[i] = p_tt[i] * r_t[i] + ptr * r_r[i]
            z_r[i] = wp.transpose(ptr) * r_t[i] + p_rr[i] * r_r[i]
    return dot6(0, nb, r_t, r_r, z_t, z_r)


# longer than the house limit of 120 lines (tests/test_code_shape.py): a third of it is the
# 40 buffers a Warp kernel takes as parameters; the whole PCG is one launch on purpose (the
# module docstring: one thread, no per-iteration launches on the CPU)
@wp.kernel
def pcg_fused_kernel(
    nb: int,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    p_tt: wp.array(dtype=wp.mat33),
    p_tr: wp.array(dtype=wp.mat33),
    p_rr: wp.array(dtype=wp.mat33),
    precond_mode: int,
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    y6: wp.array(dtype=wp.spatial_vector),
    parent: wp.array(dtype=wp.int32),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    u_at: wp.array(dtype=wp.vec3),
    u_ar: wp.array(dtype=wp.vec3),
    u_bt: wp.array(dtype=wp.vec3),
    u_br: wp.array(dtype=wp.vec3),
    k_eff: wp.array(dtype=float),
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    tol: float,
    max_iter: int,
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
    z_t: wp.array(dtype=wp.vec3),
    z_r: wp.array(dtype=wp.vec3),
    p_t: wp.array(dtype=wp.vec3),
    p_r: wp.array(dtype=wp.vec3),
    q_t: wp.array(dtype=wp.vec3),
    q_r: wp.array(dtype=wp.vec3),
    stats: wp.array(dtype=float),
):
    """PCG for H x = -g in one launch (one thread; for the CPU). stats = (iterations, |r|/|b|)."""
    nc = wp.min(count[0], capacity)
    bnorm2 = pcg_start(0, nb, grad_t, grad_r, x_t, x_r, r_t, r_r)
    rz = apply_precond(
        precond_mode,
        nb,
        parent,
        r_t,
        r_r,
        p_tt,
        p_tr,
        p_rr,
        dinv,
        lmat,
        lever_p,
        lever_c,
        ctrl_c,
        k_joint,
        y6,
        z_t,
        z_r,
    )
    for i in range(nb):
        p_t[i] = z_t[i]
        p_r[i] = z_r[i]
    it = int(0)
    rel = float(0.0)
    if bnorm2 > 0.0:
        rel = 1.0
    tol2 = tol * tol * bnorm2
    while it < max_iter and rel > tol:
        matvec(
            nb,
            nc,
            p_t,
            p_r,
            hess_a,
            hess_b,
            hess_c,
            parent,
            lever_p,
            lever_c,
            ctrl_c,
            k_joint,
            c_a,
            c_b,
            u_at,
            u_ar,
            u_bt,
            u_br,
            k_eff,
            q_t,
            q_r,
        )
        pq = dot6(0, nb, p_t, p_r, q_t, q_r)
        if pq <= 0.0:
            break
        alpha = rz / pq
        rr2 = pcg_advance(0, nb, alpha, p_t, p_r, q_t, q_r, x_t, x_r, r_t, r_r)
        it += 1
        rel = wp.sqrt(rr2 / bnorm2)
        if rr2 <= tol2:
            break
        rz_new = apply_precond(
            precond_mode,
            nb,
            parent,
            r_t,
            r_r,
            p_tt,
            p_tr,
            p_rr,
            dinv,
            lmat,
            lever_p,
            lever_c,
            ctrl_c,
            k_joint,
            y6,
            z_t,
            z_r,
        )
        beta = rz_new / rz
        rz = rz_new
        for i in range(nb):
            p_t[i] = z_t[i] + beta * p_t[i]
            p_r[i] = z_r[i] + beta * p_r[i]
    stats[0] = float(it)
    stats[1] = rel


@wp.kernel
def pcg_split_init_kernel(
    lo: int,
    hi: int,
    part: int,
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    parent: wp.array(dtype=wp.int32),
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    y6: wp.array(dtype=wp.spatial_vector),
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
    z_t: wp.array(dtype=wp.vec3),
    z_r: wp.array(dtype=wp.vec3),
    p_t: wp.array(dtype=wp.vec3),
    p_r: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=float),
):
    """Split PCG, start, on bodies [lo, hi) (whole characters; one thread): x = 0,
    r = -g, z = P r (the character preconditioner), the direction buffer p zeroed;
    partial sums |r|^2 -> sums[4 part], r.z -> sums[4 part + 1]."""
    for i in range(lo, hi):
        p_t[i] = wp.vec3(0.0, 0.0, 0.0)
        p_r[i] = wp.vec3(0.0, 0.0, 0.0)
    sums[4 * part] = pcg_start(lo, hi, grad_t, grad_r, x_t, x_r, r_t, r_r)
    tree_apply(lo, hi, parent, r_t, r_r, dinv, lmat, lever_p, lever_c, ctrl_c, k_joint, y6, z_t, z_r)
    sums[4 * part + 1] = dot6(lo, hi, r_t, r_r, z_t, z_r)


@wp.kernel
def pcg_split_matvec_kernel(
    lo: int,
    hi: int,
    part: int,
    beta: float,
    n_list: int,
    contact_list: wp.array(dtype=wp.int32),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    parent: wp.array(dtype=wp.int32),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    u_at: wp.array(dtype=wp.vec3),
    u_ar: wp.array(dtype=wp.vec3),
    u_bt: wp.array(dtype=wp.vec3),
    u_br: wp.array(dtype=wp.vec3),
    k_eff: wp.array(dtype=float),
    z_t: wp.array(dtype=wp.vec3),
    z_r: wp.array(dtype=wp.vec3),
    po_t: wp.array(dtype=wp.vec3),
    po_r: wp.array(dtype=wp.vec3),
    p_t: wp.array(dtype=wp.vec3),
    p_r: wp.array(dtype=wp.vec3),
    q_t: wp.array(dtype=wp.vec3),
    q_r: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=float),
):
    """Split PCG, one iteration's direction and product on bodies [lo, hi) (one
    thread): p = z + beta p_old (``po``, the previous direction buffer) into ``p``, then
    q = H p for these rows with the same terms in the same order as ``matvec``; the
    body-body contacts are the first ``n_list`` of ``contact_list`` (those with a body
    in the range, in contact order), and a body of the other range is read as
    z + beta p_old, which that range's thread does not write in this phase. Partial p.q
    -> sums[4 part + 2]."""
    for i in range(lo, hi):
        p_t[i] = z_t[i] + beta * po_t[i]
        p_r[i] = z_r[i] + beta * po_r[i]
    body_rows(lo, hi, p_t, p_r, hess_a, hess_b, hess_c, parent, lever_p, lever_c, ctrl_c, k_joint, q_t, q_r)
    for j in range(n_list):
        i = contact_list[j]
        a = c_a[i]
        b = c_b[i]
        k = k_eff[i]
        if a >= lo and a < hi:
            sb = wp.dot(u_bt[i], z_t[b] + beta * po_t[b]) + wp.dot(u_br[i], z_r[b] + beta * po_r[b])
            q_t[a] = q_t[a] + (k * sb) * u_at[i]
            q_r[a] = q_r[a] + (k * sb) * u_ar[i]
        if b >= lo and b < hi:
            sa = wp.dot(u_at[i], z_t[a] + beta * po_t[a]) + wp.dot(u_ar[i], z_r[a] + beta * po_r[a])
            q_t[b] = q_t[b] + (k * sa) * u_bt[i]
            q_r[b] = q_r[b] + (k * sa) * u_br[i]
    sums[4 * part + 2] = dot6(lo, hi, p_t, p_r, q_t, q_r)


@wp.kernel
def pcg_split_update_kernel(
    lo: int,
    hi: int,
    part: int,
    alpha: float,
    p_t: wp.array(dtype=wp.vec3),
    p_r: wp.array(dtype=wp.vec3),
    q_t: wp.array(dtype=wp.vec3),
    q_r: wp.array(dtype=wp.vec3),
    x_t: wp.array(dtype=wp.vec3),
    x_r: wp.array(dtype=wp.vec3),
    r_t: wp.array(dtype=wp.vec3),
    r_r: wp.array(dtype=wp.vec3),
    parent: wp.array(dtype=wp.int32),
    dinv: wp.array(dtype=wp.spatial_matrix),
    lmat: wp.array(dtype=wp.spatial_matrix),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    y6: wp.array(dtype=wp.spatial_vector),
    z_t: wp.array(dtype=wp.vec3),
    z_r: wp.array(dtype=wp.vec3),
    sums: wp.array(dtype=float),
):
    """Split PCG, one iteration's step on bodies [lo, hi) (one thread): x += alpha p,
    r -= alpha q, z = P r; partial |r|^2 -> sums[4 part + 3], r.z -> sums[4 part + 1]."""
    sums[4 * part + 3] = pcg_advance(lo, hi, alpha, p_t, p_r, q_t, q_r, x_t, x_r, r_t, r_r)
    tree_apply(lo, hi, parent, r_t, r_r, dinv, lmat, lever_p, lever_c, ctrl_c, k_joint, y6, z_t, z_r)
    sums[4 * part + 1] = dot6(lo, hi, r_t, r_r, z_t, z_r)


@wp.kernel
def triplets_bodies_kernel(
    nb: int,
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    parent: wp.array(dtype=wp.int32),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    k_joint: float,
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    rows: wp.array(dtype=wp.int32),
    cols: wp.array(dtype=wp.int32),
    vals: wp.array(dtype=wp.spatial_matrix),
    rhs: wp.array(dtype=wp.spatial_vector),
):
    """BSR triplets: the diagonal block of body i and its joint's two off-diagonal blocks."""
    i = wp.tid()
    b = hess_b[i]
    rows[i] = i
    cols[i] = i
    vals[i] = block66(hess_a[i], b, wp.transpose(b), hess_c[i])
    gt = grad_t[i]
    gr = grad_r[i]
    rhs[i] = wp.spatial_vector(-gt[0], -gt[1], -gt[2], -gr[0], -gr[1], -gr[2])
    p = parent[i]
    j = nb + 2 * i
    if p >= 0:
        eye = wp.identity(n=3, dtype=float)
        sp = wp.skew(lever_p[i])
        sc = wp.skew(lever_c[i])
        o = block66(-k_joint * eye, k_joint * sc, -k_joint * sp, k_joint * (sp * sc) - ctrl_c[i] * eye)
        rows[j] = p
        cols[j] = i
        vals[j] = o
        rows[j + 1] = i
        cols[j + 1] = p
        vals[j + 1] = wp.transpose(o)
    else:
        rows[j] = i
        cols[j] = i
        vals[j] = wp.spatial_matrix()
        rows[j + 1] = i
        cols[j + 1] = i
        vals[j + 1] = wp.spatial_matrix()


@wp.kernel
def triplets_contacts_kernel(
    offset: int,
    count: wp.array(dtype=wp.int32),
    capacity: int,
    c_a: wp.array(dtype=wp.int32),
    c_b: wp.array(dtype=wp.int32),
    u_at: wp.array(dtype=wp.vec3),
    u_ar: wp.array(dtype=wp.vec3),
    u_bt: wp.array(dtype=wp.vec3),
    u_br: wp.array(dtype=wp.vec3),
    k_eff: wp.array(dtype=float),
    rows: wp.array(dtype=wp.int32),
    cols: wp.array(dtype=wp.int32),
    vals: wp.array(dtype=wp.spatial_matrix),
):
    """BSR triplets of the body-body contact couplings k u_a u_b^T (zero blocks otherwise)."""
    i = wp.tid()
    j = offset + 2 * i
    n_active = wp.min(count[0], capacity)
    b = int(-1)
    k = float(0.0)
    if i < n_active:
        b = c_b[i]
        k = k_eff[i]
    if b >= 0 and k > 0.0:
        a = c_a[i]
        o = block66(
            k * wp.outer(u_at[i], u_bt[i]),
            k * wp.outer(u_at[i], u_br[i]),
            k * wp.outer(u_ar[i], u_bt[i]),
            k * wp.outer(u_ar[i], u_br[i]),
        )
        rows[j] = a
        cols[j] = b
        vals[j] = o
        rows[j + 1] = b
        cols[j + 1] = a
        vals[j + 1] = wp.transpose(o)
    else:
        rows[j] = 0
        cols[j] = 0
        vals[j] = wp.spatial_matrix()
        rows[j + 1] = 0
        cols[j + 1] = 0
        vals[j + 1] = wp.spatial_matrix()


@wp.kernel
def unpack_kernel(x6: wp.array(dtype=wp.spatial_vector), x_t: wp.array(dtype=wp.vec3), x_r: wp.array(dtype=wp.vec3)):
    """Split a packed (B,) spatial_vector solution (dx m, dw rad) into its translation and
    rotation parts, (B,) vec3 each."""
    i = wp.tid()
    s = x6[i]
    x_t[i] = wp.vec3(s[0], s[1], s[2])
    x_r[i] = wp.vec3(s[3], s[4], s[5])


def bsr_from_triplets(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, nb: int):
    """scipy BSR matrix (6x6 blocks) summing duplicate triplets."""
    import scipy.sparse as sp

    keep = np.any(vals != 0, axis=(1, 2))
    rows, cols, vals = rows[keep], cols[keep], vals[keep]
    key = rows.astype(np.int64) * nb + cols
    uniq, inverse = np.unique(key, return_inverse=True)
    data = np.zeros((len(uniq), 6, 6))
    np.add.at(data, inverse, vals)
    ur, uc = uniq // nb, uniq % nb
    indptr = np.searchsorted(ur, np.arange(nb + 1))
    return sp.bsr_matrix((data, uc, indptr), shape=(6 * nb, 6 * nb))

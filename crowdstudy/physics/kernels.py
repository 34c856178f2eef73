"""Warp kernels of one implicit-Euler step: targets, prediction, assembly, update, projection.

Kernels take typed ``wp.array`` arguments; one code path runs on CPU and CUDA. Units: metres,
seconds, kilograms, radians; quaternions scalar-last (x, y, z, w). Bodies are indexed
``b = character * J + joint`` (:mod:`crowdstudy.physics.model`); a kernel launched with an
``offset`` handles body ``b = thread + offset`` (one launch per half of the crowd on two
host threads).

The unknowns of a step are, per body, a translation increment ``dx`` (m) and a world-frame
rotation increment ``dw`` (rad), applied as ``x <- x + dx``, ``R <- exp([dw]x) R``. The
Newton system ``H [dx; dw] = -g`` is stored as 6x6 diagonal blocks ``[[A, B], [B^T, C]]``
(three mat33 arrays), plus matrix-free off-diagonal terms per joint and per contact
(see :mod:`crowdstudy.physics.solver`).

This module imports Warp (and configures it through
:func:`~crowdstudy.warp_runtime.get_warp`) when it is imported: the modules that launch
its kernels import it inside the launching function, so ``import crowdstudy.physics``
stays free of Warp. The collision kernels live in
:mod:`crowdstudy.physics.collision_kernels`, the contact assembly and the linear solvers in
:mod:`crowdstudy.physics.linear`.
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
    "targets_kernel",
    "predict_kernel",
    "joint_terms_kernel",
    "assemble_bodies_kernel",
    "update_kernel",
    "project_kernel",
    "set_state_kernel",
    "foot_anchor_kernel",
]

get_warp()  # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})  # forward only: no adjoints to compile


@wp.func
def quat_exp(w: wp.vec3):
    """Unit quaternion of the rotation vector ``w`` (rad)."""
    angle = wp.length(w)
    if angle < 1.0e-7:
        return wp.normalize(wp.quat(0.5 * w[0], 0.5 * w[1], 0.5 * w[2], 1.0))
    return wp.quat_from_axis_angle(w / angle, angle)


@wp.func
def quat_log(q: wp.quat):
    """Rotation vector (rad) of a unit quaternion, angle in [0, pi]."""
    qq = q
    if qq[3] < 0.0:
        qq = wp.quat(-q[0], -q[1], -q[2], -q[3])
    v = wp.vec3(qq[0], qq[1], qq[2])
    s = wp.length(v)
    if s < 1.0e-7:
        return 2.0 * v
    angle = 2.0 * wp.atan2(s, qq[3])
    return v * (angle / s)


@wp.func
def vee_asym(m: wp.mat33):
    """a(M) with tr([e]x M) = e . a(M): (M12 - M21, M20 - M02, M01 - M10)."""
    return wp.vec3(m[1, 2] - m[2, 1], m[2, 0] - m[0, 2], m[0, 1] - m[1, 0])


@wp.func
def quat_nlerp(a: wp.quat, b: wp.quat, t: float):
    """Normalised linear interpolation on the short arc."""
    d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
    s = 1.0
    if d < 0.0:
        s = -1.0
    return wp.normalize(
        wp.quat(
            (1.0 - t) * a[0] + s * t * b[0],
            (1.0 - t) * a[1] + s * t * b[1],
            (1.0 - t) * a[2] + s * t * b[2],
            (1.0 - t) * a[3] + s * t * b[3],
        )
    )


@wp.kernel
def targets_kernel(
    anim_q: wp.array2d(dtype=wp.quat),
    anim_root: wp.array2d(dtype=wp.vec3),
    f0: int,
    f1: int,
    alpha: float,
    n_joints: int,
    body_parent: wp.array(dtype=wp.int32),
    anchor_parent: wp.array(dtype=wp.vec3),
    anchor_child: wp.array(dtype=wp.vec3),
    target_rel: wp.array(dtype=wp.quat),
    target_glob: wp.array(dtype=wp.quat),
    target_x: wp.array(dtype=wp.vec3),
):
    """Target pose of one character (thread) at ``(1 - alpha) frame f0 + alpha frame f1``.

    anim_q: (F, B) joint rotations (root global, others parent-relative), unit quats.
    anim_root: (F, N) pelvis joint positions, m. Writes target_rel (B,) (root: global),
    target_glob (B,) world rotations, target_x (B,) world centres of mass, m.
    """
    i = wp.tid()
    for j in range(n_joints):
        b = i * n_joints + j
        local = quat_nlerp(anim_q[f0, b], anim_q[f1, b], alpha)
        target_rel[b] = local
        p = body_parent[b]
        if p < 0:
            root = (1.0 - alpha) * anim_root[f0, i] + alpha * anim_root[f1, i]
            target_glob[b] = local
            target_x[b] = root - wp.quat_rotate(local, anchor_child[b])
        else:
            g = target_glob[p] * local
            target_glob[b] = g
            joint = target_x[p] + wp.quat_rotate(target_glob[p], anchor_parent[b])
            target_x[b] = joint - wp.quat_rotate(g, anchor_child[b])


@wp.kernel
def predict_kernel(
    x: wp.array(dtype=wp.vec3),
    q: wp.array(dtype=wp.quat),
    v: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=wp.vec3),
    h: float,
    feedforward: int,
    t_x: wp.array(dtype=wp.vec3),
    t_x_old: wp.array(dtype=wp.vec3),
    t_x_older: wp.array(dtype=wp.vec3),
    t_glob: wp.array(dtype=wp.quat),
    t_glob_old: wp.array(dtype=wp.quat),
    t_glob_older: wp.array(dtype=wp.quat),
    x_pred: wp.array(dtype=wp.vec3),
    q_pred: wp.array(dtype=wp.quat),
    offset: int,
):
    """Inertial prediction x~ = x + h v (m), R~ = exp(h [w]x) R (w in rad/s, world frame).

    With ``feedforward`` the prediction also continues the ANIMATION's own acceleration:
    x~ += x^(t+h) - 2 x^(t) + x^(t-h) (m) and R~ = (D^ D^_prev^T) exp(h [w]x) R, with
    D^ = R^(t+h) R^(t)^T and D^_prev = R^(t) R^(t-h)^T the animation's world rotation
    increments over this step and the previous one. A body that follows its target
    exactly is then predicted exactly at the next target, so the step only corrects
    deviations (the animation's accelerations, and its support against gravity, are fed
    forward; the physics answers contacts and the PD terms alone). Body b = thread +
    ``offset`` (a launch may cover a range of the bodies).
    """
    b = wp.tid() + offset
    xp = x[b] + h * v[b]
    qp = quat_exp(h * w[b]) * q[b]
    if feedforward != 0:
        xp = xp + (t_x[b] - t_x_old[b]) - (t_x_old[b] - t_x_older[b])
        d_now = t_glob[b] * wp.quat_inverse(t_glob_old[b])
        d_prev = t_glob_old[b] * wp.quat_inverse(t_glob_older[b])
        qp = d_now * wp.quat_inverse(d_prev) * qp
    x_pred[b] = xp
    q_pred[b] = wp.normalize(qp)


@wp.func
def control_gradient(rp: wp.mat33, rc: wp.mat33, target: wp.mat33, damp_ref: wp.mat33, k: float, dh2: float):
    """Gradient (w.r.t. the child's world rotation increment) of Eq. 4 on R = Rp^T Rc.

    E = k/2 |R - target|^2 + dh2/2 |R - damp_ref|^2, dh2 = d / h^2 (J); the parent's
    gradient is the negative. Gauss-Newton Hessian: 2 (k + dh2) [[I, -I], [-I, I]].
    """
    rel = wp.transpose(rp) * rc
    res = k * (rel - target) + dh2 * (rel - damp_ref)
    return vee_asym(rc * wp.transpose(res) * wp.transpose(rp))


@wp.func
def joint_control_terms(
    b: int,
    parent: int,
    q: wp.array(dtype=wp.quat),
    q_old: wp.array(dtype=wp.quat),
    t_rel: wp.array(dtype=wp.quat),
    t_rel_old: wp.array(dtype=wp.quat),
    k: float,
    dh2: float,
):
    """Child-side rotational gradient of the PD term of the joint between parent and b."""
    rp = wp.quat_to_matrix(q[parent])
    rc = wp.quat_to_matrix(q[b])
    rel_old = wp.quat_to_matrix(wp.quat_inverse(q_old[parent]) * q_old[b])
    tgt = wp.quat_to_matrix(t_rel[b])
    damp_ref = rel_old + tgt - wp.quat_to_matrix(t_rel_old[b])
    return control_gradient(rp, rc, tgt, damp_ref, k, dh2)


@wp.kernel
def joint_terms_kernel(
    q: wp.array(dtype=wp.quat),
    q_old: wp.array(dtype=wp.quat),
    t_rel: wp.array(dtype=wp.quat),
    t_rel_old: wp.array(dtype=wp.quat),
    body_parent: wp.array(dtype=wp.int32),
    anchor_parent: wp.array(dtype=wp.vec3),
    anchor_child: wp.array(dtype=wp.vec3),
    body_k: wp.array(dtype=float),
    body_d: wp.array(dtype=float),
    h: float,
    damp_scale: float,
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    ctrl_g: wp.array(dtype=wp.vec3),
    offset: int,
):
    """The joint of body b = thread + ``offset`` (b the child), at the predicted
    orientations: the world lever arms on the parent (lever_p, m) and on b (lever_c, m),
    the control coupling 2 (k + d/h^2) (ctrl_c) and the child-side gradient of its PD
    term (ctrl_g, N m; the parent's is the negative); zeros for a root. Computed once per
    joint for ``assemble_bodies_kernel`` (the child and the parent read them)."""
    b = wp.tid() + offset
    p = body_parent[b]
    if p < 0:
        lever_p[b] = wp.vec3(0.0, 0.0, 0.0)
        lever_c[b] = wp.vec3(0.0, 0.0, 0.0)
        ctrl_c[b] = 0.0
        ctrl_g[b] = wp.vec3(0.0, 0.0, 0.0)
        return
    inv_h2 = 1.0 / (h * h)
    k = body_k[b]
    dh2 = body_d[b] * damp_scale * inv_h2
    lever_p[b] = wp.quat_rotate(q[p], anchor_parent[b])
    lever_c[b] = wp.quat_rotate(q[b], anchor_child[b])
    ctrl_c[b] = 2.0 * (k + dh2)
    ctrl_g[b] = joint_control_terms(b, p, q, q_old, t_rel, t_rel_old, k, dh2)


@wp.func
def translation_pd_terms(
    e: wp.vec3,
    dv: wp.vec3,
    kt: float,
    dth2: float,
    reach: float,
    kt_far: float,
    eye: wp.mat33,
    gt: wp.vec3,
    a: wp.mat33,
):
    """Absolute translation PD of a body (root; feet and pose springs when enabled) added to
    its gradient ``gt`` (N) and translation block ``a`` (N/m): kt/2 |e|^2 + dt/(2 h^2)
    |dv|^2, e = x - x^ the deviation from the target (m), dv = (x - x_old) - (x^ - x^_old)
    the step's displacement beyond the target's (m), dth2 = dt/h^2 (N/m).

    Where ``reach`` r > 0 (m) the spring softens with the deviation from kt near the target
    to ``kt_far`` kf far from it: energy kf/2 |e|^2 + (kt - kf) r^2 (sqrt(1 + |e|^2 / r^2)
    - 1), force (kf + (kt - kf) / sqrt(1 + |e|^2 / r^2)) e, its Hessian taken as that
    weight times I. Returns the new (gt, a)."""
    k_e = kt
    if reach > 0.0:
        k_e = kt_far + (kt - kt_far) / wp.sqrt(1.0 + wp.dot(e, e) / (reach * reach))
    return gt + (k_e * e + dth2 * dv), a + (k_e + dth2) * eye


@wp.func
def joint_child_terms(
    k_joint: float,
    r_p: wp.vec3,
    r_c: wp.vec3,
    x_p: wp.vec3,
    x_b: wp.vec3,
    ctrl_g: wp.vec3,
    ctrl_c: float,
    eye: wp.mat33,
    gt: wp.vec3,
    gr: wp.vec3,
    a: wp.mat33,
    bb: wp.mat33,
    c: wp.mat33,
):
    """Body b as the CHILD of joint (p, b): the soft ball joint k_j/2 |x_p + r_p - x_b -
    r_c|^2 (Gauss-Newton; r_p, r_c the world lever arms, m; k_j N/m) and the joint's PD
    term (gradient ``ctrl_g`` N m, coupling ``ctrl_c``, from ``joint_terms_kernel``) added
    to b's gradient (gt N, gr N m) and diagonal blocks (a, bb, c). Returns the new
    (gt, gr, a, bb, c)."""
    cvec = x_p + r_p - x_b - r_c
    gt += -k_joint * cvec
    gr += -k_joint * wp.cross(r_c, cvec)
    sk = wp.skew(r_c)
    a += k_joint * eye
    bb += -k_joint * sk
    c += -k_joint * (sk * sk)
    gr += ctrl_g
    c += ctrl_c * eye
    return gt, gr, a, bb, c


@wp.func
def joint_parent_terms(
    k_joint: float,
    r_p: wp.vec3,
    r_c: wp.vec3,
    x_b: wp.vec3,
    x_ch: wp.vec3,
    ctrl_g: wp.vec3,
    ctrl_c: float,
    eye: wp.mat33,
    gt: wp.vec3,
    gr: wp.vec3,
    a: wp.mat33,
    bb: wp.mat33,
    c: wp.mat33,
):
    """Body b as the PARENT of joint (b, ch): the same spring and PD term as
    ``joint_child_terms`` seen from the parent's side (the PD gradient negated). Returns
    the new (gt, gr, a, bb, c)."""
    cvec = x_b + r_p - x_ch - r_c
    gt += k_joint * cvec
    gr += k_joint * wp.cross(r_p, cvec)
    sk = wp.skew(r_p)
    a += k_joint * eye
    bb += -k_joint * sk
    c += -k_joint * (sk * sk)
    gr -= ctrl_g
    c += ctrl_c * eye
    return gt, gr, a, bb, c


@wp.kernel
def assemble_bodies_kernel(
    x: wp.array(dtype=wp.vec3),
    q: wp.array(dtype=wp.quat),
    x_old: wp.array(dtype=wp.vec3),
    q_old: wp.array(dtype=wp.quat),
    t_rel: wp.array(dtype=wp.quat),
    t_rel_old: wp.array(dtype=wp.quat),
    t_x: wp.array(dtype=wp.vec3),
    t_x_old: wp.array(dtype=wp.vec3),
    body_mass: wp.array(dtype=float),
    body_J: wp.array(dtype=wp.mat33),
    body_parent: wp.array(dtype=wp.int32),
    body_children: wp.array2d(dtype=wp.int32),
    body_k: wp.array(dtype=float),
    body_d: wp.array(dtype=float),
    body_kt: wp.array(dtype=float),
    body_dt: wp.array(dtype=float),
    body_reach: wp.array(dtype=float),
    body_kt_far: wp.array(dtype=float),
    h: float,
    gravity: float,
    k_joint: float,
    damp_scale: float,
    grad_t: wp.array(dtype=wp.vec3),
    grad_r: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    hess_b: wp.array(dtype=wp.mat33),
    hess_c: wp.array(dtype=wp.mat33),
    lever_p: wp.array(dtype=wp.vec3),
    lever_c: wp.array(dtype=wp.vec3),
    ctrl_c: wp.array(dtype=float),
    ctrl_g: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Gradient (N, N m) and diagonal Hessian block of every body (b = thread + ``offset``)
    at the predicted state.

    Terms: inertia (zero gradient at the prediction; blocks m/h^2 I and R I_body R^T / h^2),
    gravity m g z (pass 0 with the feed-forward prediction), soft ball joints
    (``joint_child_terms``, ``joint_parent_terms``), PD control of Eq. 4 (root: absolute
    rotation; others: parent-relative) and the translational PD of bodies with
    body_kt/body_dt > 0 (root; feet when enabled; every other body with
    ``pose_translation_stiffness``; ``translation_pd_terms``).
    Reads each joint's lever arms, control coupling and PD gradient from
    ``joint_terms_kernel`` (run first on the same bodies: a body and its children are in
    one character); the lever arms and couplings also serve the matrix-free off-diagonal
    products.

    ``damp_scale`` = h / h0 multiplies every damping coefficient of the d/(2 h^2) form
    (Eq. 4 and the translational dampers), so that the damping force (d / h0) times the
    velocity difference does not change with the step h (d is quoted at h0 = 1/60 s).
    """
    b = wp.tid() + offset
    inv_h2 = 1.0 / (h * h)
    eye = wp.identity(n=3, dtype=float)
    m = body_mass[b]
    rb = wp.quat_to_matrix(q[b])
    gt = wp.vec3(0.0, 0.0, m * gravity)
    gr = wp.vec3(0.0, 0.0, 0.0)
    a = (m * inv_h2) * eye
    bb = wp.mat33(0.0)
    jw = rb * body_J[b] * wp.transpose(rb)
    c = (wp.trace(jw) * inv_h2) * eye - inv_h2 * jw
    k = body_k[b]
    dh2 = body_d[b] * damp_scale * inv_h2
    kt = body_kt[b]
    dth2 = body_dt[b] * damp_scale * inv_h2
    if kt > 0.0 or dth2 > 0.0:
        dv = (x[b] - x_old[b]) - (t_x[b] - t_x_old[b])
        gt, a = translation_pd_terms(x[b] - t_x[b], dv, kt, dth2, body_reach[b], body_kt_far[b], eye, gt, a)
    p = body_parent[b]
    if p < 0:
        # Root: absolute rotation (Eq. 4 with Rp = I) and absolute translation.
        tgt = wp.quat_to_matrix(t_rel[b])
        damp_ref = wp.quat_to_matrix(q_old[b]) + tgt - wp.quat_to_matrix(t_rel_old[b])
        gr += control_gradient(eye, rb, tgt, damp_ref, k, dh2)
        c += (2.0 * (k + dh2)) * eye
    else:
        gt, gr, a, bb, c = joint_child_terms(
            k_joint, lever_p[b], lever_c[b], x[p], x[b], ctrl_g[b], ctrl_c[b], eye, gt, gr, a, bb, c
        )
    for s in range(body_children.shape[1]):
        ch = body_children[b, s]
        if ch >= 0:
            gt, gr, a, bb, c = joint_parent_terms(
                k_joint, lever_p[ch], lever_c[ch], x[b], x[ch], ctrl_g[ch], ctrl_c[ch], eye, gt, gr, a, bb, c
            )
    grad_t[b] = gt
    grad_r[b] = gr
    hess_a[b] = a
    hess_b[b] = bb
    hess_c[b] = c


@wp.kernel
def update_kernel(
    x_pred: wp.array(dtype=wp.vec3),
    q_pred: wp.array(dtype=wp.quat),
    x_old: wp.array(dtype=wp.vec3),
    q_old: wp.array(dtype=wp.quat),
    dx: wp.array(dtype=wp.vec3),
    dw: wp.array(dtype=wp.vec3),
    h: float,
    x_new: wp.array(dtype=wp.vec3),
    q_new: wp.array(dtype=wp.quat),
    v_new: wp.array(dtype=wp.vec3),
    w_new: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Apply the Newton increment; velocities (m/s, rad/s) from the change over h.
    Body b = thread + ``offset``."""
    b = wp.tid() + offset
    xn = x_pred[b] + dx[b]
    qn = wp.normalize(quat_exp(dw[b]) * q_pred[b])
    x_new[b] = xn
    q_new[b] = qn
    v_new[b] = (xn - x_old[b]) / h
    w_new[b] = quat_log(qn * wp.quat_inverse(q_old[b])) / h


@wp.kernel
def project_kernel(
    x: wp.array(dtype=wp.vec3),
    q: wp.array(dtype=wp.quat),
    body_parent: wp.array(dtype=wp.int32),
    anchor_child: wp.array(dtype=wp.vec3),
    n_joints: int,
    frame: int,
    out_rot: wp.array2d(dtype=wp.vec3),
    out_root: wp.array2d(dtype=wp.vec3),
):
    """Joint rotations (axis-angle, rad; root global, others R_parent^T R_child) and the
    pelvis joint position (m) of the rigid state, written to row ``frame`` of the outputs."""
    b = wp.tid()
    p = body_parent[b]
    if p < 0:
        out_rot[frame, b] = quat_log(q[b])
        out_root[frame, b / n_joints] = x[b] + wp.quat_rotate(q[b], anchor_child[b])
    else:
        out_rot[frame, b] = quat_log(wp.quat_inverse(q[p]) * q[b])


@wp.kernel
def set_state_kernel(
    target_x: wp.array(dtype=wp.vec3),
    target_glob: wp.array(dtype=wp.quat),
    x: wp.array(dtype=wp.vec3),
    q: wp.array(dtype=wp.quat),
    v: wp.array(dtype=wp.vec3),
    w: wp.array(dtype=wp.vec3),
):
    """Place every body at its target, at rest."""
    b = wp.tid()
    x[b] = target_x[b]
    q[b] = target_glob[b]
    v[b] = wp.vec3(0.0, 0.0, 0.0)
    w[b] = wp.vec3(0.0, 0.0, 0.0)


@wp.kernel
def foot_anchor_kernel(
    feet: wp.array(dtype=wp.int32),
    x_pred: wp.array(dtype=wp.vec3),
    x_old: wp.array(dtype=wp.vec3),
    t_x: wp.array(dtype=wp.vec3),
    t_x_old: wp.array(dtype=wp.vec3),
    offset: wp.array(dtype=wp.vec3),
    weight: wp.array(dtype=float),
    stepping: wp.array(dtype=wp.int32),
    body_kt: wp.array(dtype=float),
    body_dt: wp.array(dtype=float),
    h: float,
    damp_scale: float,
    planted_speed: float,
    k_anchor: float,
    c_anchor: float,
    max_force: float,
    release_distance: float,
    rejoin_distance: float,
    grad_t: wp.array(dtype=wp.vec3),
    hess_a: wp.array(dtype=wp.mat33),
    offset_feet: int,
):
    """Stance-foot anchor (static friction of planted feet), added to the assembled system.
    Foot i = thread + ``offset_feet`` of ``feet``.

    The animation's foot body is planted when its horizontal speed |v^_xy| is below
    ``planted_speed`` (weight w = 1), free above twice that (w = 0, linear in between).
    While planted, the body's horizontal position is anchored at the animation's target
    plus an offset frozen at touch-down (the simulated foot stays where it landed and
    moves only as the animation's foot moves):
    E = w (k/2 |P (x - x^ - o)|^2 + c/(2h) |P (x - x_old - x^ + x^_old)|^2), P = diag(1, 1, 0),
    minus w times the horizontal part of the body's own translation PD (body_kt, body_dt),
    which the anchor replaces while it holds (the xy Hessian stays
    (1 - w)(kt + dt/h^2) + w (k + c/h) >= 0).
    The offset o slips (is dragged along) when the spring would exceed ``max_force`` N
    (a Coulomb limit): |x_old - x^_old - o| <= max_force / k. While free, o follows the
    body (o = x_old - x^_old, horizontal). A foot farther than ``release_distance`` m
    (horizontally) from the animation's foot takes a corrective step: it is free until it
    is back within ``rejoin_distance`` m (``weight`` (F,) holds w, ``stepping`` (B,) the
    flag).
    """
    i = wp.tid() + offset_feet
    b = feet[i]
    vt = (t_x[b] - t_x_old[b]) / h
    speed = wp.sqrt(vt[0] * vt[0] + vt[1] * vt[1])
    w = wp.clamp(2.0 - speed / planted_speed, 0.0, 1.0)
    rel = x_old[b] - t_x_old[b]
    rel = wp.vec3(rel[0], rel[1], 0.0)
    dist = wp.length(rel)
    if release_distance > 0.0:
        if dist > release_distance:
            stepping[b] = 1
        elif dist < rejoin_distance:
            stepping[b] = 0
        if stepping[b] != 0:
            w = 0.0
    off = offset[b]
    if w <= 0.0:
        off = rel
    else:
        dlt = rel - off
        n = wp.length(dlt)
        slip = max_force / k_anchor
        if n > slip:
            off = off + dlt * (1.0 - slip / n)
    offset[b] = off
    weight[i] = w
    if w > 0.0:
        e = x_pred[b] - t_x[b] - off
        dv = (x_pred[b] - x_old[b]) - (t_x[b] - t_x_old[b])
        ch = c_anchor / h
        g = w * (k_anchor * e + ch * dv)
        # the anchor replaces the foot's horizontal coupling to the animation (body_kt, body_dt)
        dth2 = body_dt[b] * damp_scale / (h * h)
        ea = x_pred[b] - t_x[b]
        g = g - w * (body_kt[b] * ea + dth2 * dv)
        grad_t[b] = grad_t[b] + wp.vec3(g[0], g[1], 0.0)
        s = w * (k_anchor + ch - body_kt[b] - dth2)
        hess_a[b] = hess_a[b] + wp.mat33(s, 0.0, 0.0, 0.0, s, 0.0, 0.0, 0.0, 0.0)

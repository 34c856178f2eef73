"""Energies: analytic gradients/Hessians vs finite differences; Warp assembly vs numpy."""

import types

import numpy as np
import pytest

from crowdstudy.body.rotations import axis_angle_to_matrix
from crowdstudy.body.skeleton import DEFAULT_REST_JOINTS, PARENTS, children
from crowdstudy.physics import energies as E
from crowdstudy.warp_runtime import get_warp

RNG = np.random.default_rng(7)
EPS = 1e-6


def fixture_body(scale=1.0):
    """Test-only capsules along the default skeleton's bones (not the real body fit)."""
    rest = DEFAULT_REST_JOINTS * scale
    kids = children(PARENTS)
    start, end, radius = rest.copy(), rest.copy(), np.full(24, 0.05 * scale)
    radius[[0, 3, 6, 9]] = 0.1 * scale
    radius[15] = 0.09 * scale
    for j in range(24):
        tip = rest[kids[j]].mean(0) if kids[j] else rest[j] + 0.5 * (rest[j] - rest[PARENTS[j]])
        d = tip - rest[j]
        length = np.linalg.norm(d)
        u = d / max(length, 1e-9)
        start[j] = rest[j] + 0.25 * length * u
        end[j] = tip - 0.25 * length * u
    return types.SimpleNamespace(rest_joints=rest, capsules=types.SimpleNamespace(start=start, end=end, radius=radius))


def rand_rot():
    return axis_angle_to_matrix(RNG.normal(size=3))


def perturb(x, R, delta):
    return x + delta[:3], axis_angle_to_matrix(delta[3:]) @ R


def fd_grad(fun, n):
    g = np.zeros(n)
    for i in range(n):
        d = np.zeros(n)
        d[i] = EPS
        g[i] = (fun(d) - fun(-d)) / (2 * EPS)
    return g


def fd_hess(grad, n):
    H = np.zeros((n, n))
    for i in range(n):
        d = np.zeros(n)
        d[i] = EPS
        H[:, i] = (grad(d) - grad(-d)) / (2 * EPS)
    return 0.5 * (H + H.T)


def test_inertia_gradient_and_hessian_match_finite_differences():
    x, R, xp, Rp = RNG.normal(size=3), rand_rot(), RNG.normal(size=3), rand_rot()
    J = np.diag([0.02, 0.03, 0.005])
    f = lambda d: E.inertia_energy(*perturb(x, R, d), xp, Rp, 3.0, J, 1 / 60)  # noqa: E731
    e, g, H = f(np.zeros(6))
    np.testing.assert_allclose(g, fd_grad(lambda d: f(d)[0], 6), rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(H, fd_hess(lambda d: f(d)[1], 6), rtol=1e-5, atol=1e-2)
    # at the prediction the rotational block is the world inertia tensor / h^2
    _, g0, H0 = E.inertia_energy(xp, Rp, xp, Rp, 3.0, J, 1 / 60)
    np.testing.assert_allclose(g0, 0, atol=1e-9)
    np.testing.assert_allclose(H0[3:, 3:] * (1 / 60) ** 2, Rp @ (np.trace(J) * np.eye(3) - J) @ Rp.T, atol=1e-12)


def test_gravity_gradient():
    x = RNG.normal(size=3)
    f = lambda d: E.gravity_energy(x + d[:3], 2.0)  # noqa: E731
    np.testing.assert_allclose(f(np.zeros(6))[1], fd_grad(lambda d: f(d)[0], 6), atol=1e-6)


def test_ball_joint_gradient_and_gauss_newton_hessian():
    xa, Ra, xb, Rb = RNG.normal(size=3), rand_rot(), RNG.normal(size=3), rand_rot()
    pa, pb = RNG.normal(size=3) * 0.2, RNG.normal(size=3) * 0.2

    def f(d, xb=xb):
        ya, Sa = perturb(xa, Ra, d[:6])
        yb, Sb = perturb(xb, Rb, d[6:])
        return E.ball_joint_energy(ya, Sa, pa, yb, Sb, pb, 1e3)

    np.testing.assert_allclose(f(np.zeros(12))[1], fd_grad(lambda d: f(d)[0], 12), rtol=1e-5, atol=1e-4)
    # closed joint: Gauss-Newton == exact Hessian
    xb_closed = xa + Ra @ pa - Rb @ pb
    fc = lambda d: f(d, xb_closed)  # noqa: E731
    assert np.linalg.norm(fc(np.zeros(12))[1]) < 1e-9
    np.testing.assert_allclose(fc(np.zeros(12))[2], fd_hess(lambda d: fc(d)[1], 12), rtol=1e-4, atol=1e-3)
    assert np.linalg.eigvalsh(f(np.zeros(12))[2]).min() > -1e-9


@pytest.mark.parametrize("root", [False, True])
def test_control_gradient_and_hessian(root):
    Rp = np.eye(3) if root else rand_rot()
    Rc, T, C = rand_rot(), rand_rot(), rand_rot()
    k, dh2 = 50.0, 0.006 * 3600

    def f(d, Rc=Rc, T=T, C=C):
        Sp = Rp if root else axis_angle_to_matrix(d[:3]) @ Rp
        return E.control_energy(Sp, axis_angle_to_matrix(d[3:]) @ Rc, T, C, k, dh2)

    e, g, H = f(np.zeros(6))
    num = fd_grad(lambda d: f(d)[0], 6)
    if root:
        np.testing.assert_allclose(g[3:], num[3:], rtol=1e-5, atol=1e-4)
    else:
        np.testing.assert_allclose(g, num, rtol=1e-5, atol=1e-4)
    # at zero residual the Gauss-Newton Hessian is exact
    rel = Rp.T @ Rc
    f0 = lambda d: f(d, Rc, rel, rel)  # noqa: E731
    num_h = fd_hess(lambda d: f0(d)[1], 6)
    sl = slice(3, 6) if root else slice(0, 6)
    np.testing.assert_allclose(f0(np.zeros(6))[2][sl, sl], num_h[sl, sl], rtol=1e-4, atol=1e-2)
    # the spring is 8 sin^2(theta/2) * k/2 of the angle between R and the target
    theta = 0.4
    Rt = axis_angle_to_matrix(np.array([0, 0, theta]))
    e1 = E.control_energy(np.eye(3), Rt, np.eye(3), Rt, k, dh2)[0]
    assert e1 == pytest.approx(0.5 * k * 8 * np.sin(theta / 2) ** 2)


def test_contact_gradient_and_gauss_newton_hessian():
    xa, xb = np.zeros(3), np.array([0.1, 0.05, 0.02])
    Ra, Rb = rand_rot(), rand_rot()
    seg_a = np.array([[0, 0, -0.15], [0, 0, 0.15]])
    seg_b = np.array([[-0.1, 0, 0], [0.1, 0, 0]])

    def f(d):
        ya, Sa = perturb(xa, Ra, d[:6])
        yb, Sb = perturb(xb, Rb, d[6:])
        return E.contact_energy(ya, Sa, seg_a, 0.08, yb, Sb, seg_b, 0.07, 2e4)

    e, g, H, depth = f(np.zeros(12))
    assert depth > 0
    np.testing.assert_allclose(g, fd_grad(lambda d: f(d)[0], 12), rtol=1e-4, atol=1e-3)
    # Gauss-Newton: k u u^T with u the finite-difference gradient of the depth
    u = fd_grad(lambda d: f(d)[3], 12)
    np.testing.assert_allclose(H, 2e4 * np.outer(u, u), rtol=1e-4, atol=1e-2)
    assert np.linalg.eigvalsh(H).min() > -1e-6
    # stiffened with the depth (d0 = 1 cm): k (d^2 / 2 + d^3 / (3 d0)), its gradient and
    # Gauss-Newton Hessian k (1 + 2 d / d0) u u^T
    es, gs, Hs, _ = E.contact_energy(xa, Ra, seg_a, 0.08, xb, Rb, seg_b, 0.07, 2e4, 0.01)
    assert es == pytest.approx(2e4 * (depth**2 / 2 + depth**3 / 0.03))

    def fs(d):
        return E.contact_energy(*perturb(xa, Ra, d[:6]), seg_a, 0.08, *perturb(xb, Rb, d[6:]), seg_b, 0.07, 2e4, 0.01)[
            0
        ]

    np.testing.assert_allclose(gs, fd_grad(fs, 12), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(Hs, 2e4 * (1 + 2 * depth / 0.01) * np.outer(u, u), rtol=1e-4, atol=1e-2)


def test_root_translation_energy():
    x, xo, t, to = (RNG.normal(size=3) for _ in range(4))
    f = lambda d: E.root_translation_energy(x + d[:3], xo, t, to, 100.0, 21.6)  # noqa: E731
    np.testing.assert_allclose(f(np.zeros(3))[1], fd_grad(lambda d: f(d)[0], 3), rtol=1e-6, atol=1e-5)


@pytest.fixture(scope="module")
def small_system():
    from crowdstudy.physics import Control, ModelBuilder, PhysicsConfig, Solver, State

    builder = ModelBuilder()
    for s in (1.0, 0.95):
        builder.add_character(*vars(fixture_body(s)).values())
    model = builder.finalize(device="cpu")
    # linear translation springs: their softening beyond a reach is tested on its own
    # (tests/test_physics_smooth.py)
    cfg = PhysicsConfig().with_values(root_translation_reach=0.0)
    control = Control(model, n_frames=2)
    rng = np.random.default_rng(3)
    rot = rng.normal(scale=0.2, size=(2, 2, 24, 3))
    root = np.array([[[0, 0, 1.0], [0.8, 0, 1.0]], [[0.01, 0.02, 1.0], [0.8, 0.01, 0.99]]])
    control.set_frames(rot, root)
    control.advance(0, 0, 0.0)
    control.advance(0, 1, 1.0)
    state = State(model)
    wp = get_warp()
    nb = model.n_bodies
    f32 = np.float32
    x = (control.t_x.numpy() + rng.normal(scale=0.01, size=(nb, 3))).astype(f32)
    q = control.t_glob.numpy() + rng.normal(scale=0.03, size=(nb, 4))
    q = (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(f32)
    state.x.assign(wp.array(x, dtype=wp.vec3))
    state.q.assign(wp.array(q, dtype=wp.quat))
    state.v.assign(wp.array(rng.normal(scale=0.1, size=(nb, 3)).astype(f32), dtype=wp.vec3))
    state.w.assign(wp.array(rng.normal(scale=0.3, size=(nb, 3)).astype(f32), dtype=wp.vec3))
    solver = Solver(model, cfg)
    return model, cfg, control, state, solver


def _quat_to_mat(q):
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q).as_matrix()


def test_warp_assembly_matches_numpy_reference(small_system):
    from crowdstudy.physics.collision import Contacts

    model, cfg, control, state, solver = small_system
    h = cfg.solver.dt
    contacts = Contacts.allocate(0, "cpu")
    solver.assemble(state, control, contacts, h)
    xp, qp = solver.x_pred.numpy().astype(float), solver.q_pred.numpy().astype(float)
    x_old, q_old = state.x.numpy().astype(float), state.q.numpy().astype(float)
    Rp, Rold = _quat_to_mat(qp), _quat_to_mat(q_old)
    T, Told = _quat_to_mat(control.t_rel.numpy()), _quat_to_mat(control.t_rel_old.numpy())
    tx, tx_old = control.t_x.numpy().astype(float), control.t_x_old.numpy().astype(float)
    nb = model.n_bodies
    g = np.zeros((nb, 6))
    D = np.zeros((nb, 6, 6))
    kb, db = solver.body_k.numpy(), solver.body_d.numpy()
    kt, dtr = solver.body_kt.numpy(), solver.body_dt.numpy()
    # translational PD on the roots and the feet, and the world-space pose springs on the rest
    assert np.all(kt[model.body_parent < 0] == cfg.control.root_translation_stiffness)
    assert cfg.control.pose_translation_stiffness > 0 and np.all(kt > 0)
    others = (model.body_parent >= 0) & ~np.isin(model.body_joint, [7, 8, 10, 11])
    assert np.allclose(kt[others], cfg.control.pose_translation_stiffness)
    for b in range(nb):
        if kt[b] > 0:
            _, gt, Ht = E.root_translation_energy(xp[b], x_old[b], tx[b], tx_old[b], kt[b], dtr[b] / h**2)
            g[b, :3] += gt
            D[b, :3, :3] += Ht
        _, gi, Hi = E.inertia_energy(xp[b], Rp[b], xp[b], Rp[b], model.body_mass[b], model.body_J[b], h)
        # with the feed-forward prediction the animation is taken as supporting itself
        g[b] += gi + E.gravity_energy(xp[b], model.body_mass[b], 0.0 if cfg.solver.feedforward else cfg.body.gravity)[1]
        D[b] += Hi
        p = model.body_parent[b]
        if p < 0:
            _, gc, Hc = E.control_energy(np.eye(3), Rp[b], T[b], Rold[b] + T[b] - Told[b], kb[b], db[b] / h**2)
            g[b, 3:] += gc[3:]
            D[b, 3:, 3:] += Hc[3:, 3:]
        else:
            _, gj, Hj = E.ball_joint_energy(
                xp[p], Rp[p], model.anchor_parent[b], xp[b], Rp[b], model.anchor_child[b], cfg.body.joint_stiffness
            )
            g[p] += gj[:6]
            g[b] += gj[6:]
            D[p] += Hj[:6, :6]
            D[b] += Hj[6:, 6:]
            damp_ref = Rold[p].T @ Rold[b] + T[b] - Told[b]
            _, gc, Hc = E.control_energy(Rp[p], Rp[b], T[b], damp_ref, kb[b], db[b] / h**2)
            g[p, 3:] += gc[:3]
            g[b, 3:] += gc[3:]
            D[p, 3:, 3:] += Hc[:3, :3]
            D[b, 3:, 3:] += Hc[3:, 3:]
    gw = np.concatenate([solver.grad_t.numpy(), solver.grad_r.numpy()], 1)
    scale = np.abs(g).max()
    np.testing.assert_allclose(gw, g, atol=2e-4 * scale)
    A, B, C = solver.hess_a.numpy(), solver.hess_b.numpy(), solver.hess_c.numpy()
    Dw = np.block([[A, B], [np.transpose(B, (0, 2, 1)), C]])
    np.testing.assert_allclose(Dw, D, rtol=2e-4, atol=2e-4 * np.abs(D).max())


def test_fused_pcg_solves_the_assembled_system(small_system):
    import scipy.sparse.linalg as spl

    from crowdstudy.physics import Solver
    from crowdstudy.physics.collision import CollisionPipeline, Contacts
    from crowdstudy.physics.linear import bsr_from_triplets

    model, cfg, control, state, _ = small_system
    cfg = cfg.with_values(cg_tolerance=1e-5, cg_max_iterations=400)  # solved to the exact solution's 5e-3
    solver = Solver(model, cfg)
    pipe = CollisionPipeline(model, cfg)
    contacts = Contacts.allocate(pipe.default_capacity(), "cpu")
    pipe.collide(state, contacts)
    assert contacts.n_active() > 0
    solver.assemble(state, control, contacts, cfg.solver.dt)
    for precond in ("character", "body"):
        solver.preconditioner = precond
        solver.solve(contacts)
        assert solver.last_cg[1] <= cfg.solver.cg_tolerance or solver.last_cg[0] == cfg.solver.cg_max_iterations
        x = np.concatenate([solver.dx.numpy(), solver.dw.numpy()], 1).ravel()
        rows, cols, vals, rhs = solver.triplets(contacts)
        A = bsr_from_triplets(rows.numpy(), cols.numpy(), vals.numpy().astype(float), model.n_bodies)
        exact = spl.spsolve(A.tocsc(), rhs.numpy().astype(float).ravel())
        assert np.linalg.norm(x - exact) <= 5e-3 * np.linalg.norm(exact)
    solver.preconditioner = "character"


def test_tree_preconditioner_is_the_inverse_of_each_characters_block(small_system):
    """The character preconditioner (block LDL^T, joint blocks applied from the levers) equals
    the dense inverse of each character's diagonal blocks plus joint couplings."""
    from crowdstudy.physics.collision import CollisionPipeline, Contacts
    from crowdstudy.physics.linear import bsr_from_triplets, tree_precond_kernel

    model, cfg, control, state, solver = small_system
    pipe = CollisionPipeline(model, cfg)
    contacts = Contacts.allocate(pipe.default_capacity(), "cpu")
    pipe.collide(state, contacts)
    solver.assemble(state, control, contacts, cfg.solver.dt)
    solver._factor_tree()
    nb, nj = model.n_bodies, model.n_joints
    rows, cols, vals, _ = solver.triplets(Contacts.allocate(0, "cpu"))  # bodies and joints only
    tree = bsr_from_triplets(rows.numpy(), cols.numpy(), vals.numpy().astype(float), nb).toarray()
    wp = solver.wp
    rng = np.random.default_rng(7)
    x = rng.normal(size=(nb, 6)).astype(np.float32)
    y = rng.normal(size=(nb, 6)).astype(np.float32)
    xw, yw = wp.array(x, dtype=wp.spatial_vector), wp.array(y, dtype=wp.spatial_vector)
    z = wp.zeros(nb, dtype=wp.spatial_vector)
    work = wp.zeros(nb, dtype=wp.spatial_vector)
    wp.launch(
        tree_precond_kernel,
        model.n_characters,
        [
            nj,
            model.wp["body_parent"],
            solver.tree_dinv,
            solver.tree_l,
            solver.lever_p,
            solver.lever_c,
            solver.ctrl_c,
            float(cfg.body.joint_stiffness),
            xw,
            yw,
            z,
            0.5,
            2.0,
            work,
        ],
    )
    m = 6 * nj
    for c in range(model.n_characters):
        sl = slice(c * m, (c + 1) * m)
        block = tree[sl, sl]
        assert np.abs(tree[sl, : c * m]).max(initial=0) == 0 and np.abs(tree[sl, (c + 1) * m :]).max(initial=0) == 0
        want = 0.5 * np.linalg.solve(block, x.ravel()[sl].astype(float)) + 2.0 * y.ravel()[sl]
        got = z.numpy().ravel()[sl]
        assert np.linalg.norm(got - want) <= 1e-4 * np.linalg.norm(want)


def test_warp_off_diagonal_joint_blocks_match_numpy_reference(small_system):
    from crowdstudy.physics.collision import Contacts

    model, cfg, control, state, solver = small_system
    h = cfg.solver.dt
    contacts = Contacts.allocate(0, "cpu")
    solver.assemble(state, control, contacts, h)
    rows, cols, vals, _ = solver.triplets(contacts)
    rows, cols, vals = rows.numpy(), cols.numpy(), vals.numpy().astype(float)
    xp, Rp = solver.x_pred.numpy().astype(float), _quat_to_mat(solver.q_pred.numpy())
    kb, db = solver.body_k.numpy(), solver.body_d.numpy()
    checked = 0
    for b in range(1, model.n_bodies, 5):
        p = model.body_parent[b]
        if p < 0:
            continue
        _, _, Hj = E.ball_joint_energy(
            xp[p], Rp[p], model.anchor_parent[b], xp[b], Rp[b], model.anchor_child[b], cfg.body.joint_stiffness
        )
        _, _, Hc = E.control_energy(Rp[p], Rp[b], np.eye(3), np.eye(3), kb[b], db[b] / h**2)
        expected = Hj[:6, 6:].copy()
        expected[3:, 3:] += Hc[:3, 3:]
        sel = (rows == p) & (cols == b)
        assert sel.sum() == 1
        np.testing.assert_allclose(vals[sel][0], expected, rtol=2e-4, atol=2e-4 * np.abs(expected).max())
        checked += 1
    assert checked > 5


def test_warp_contact_assembly_matches_numpy_reference(small_system):
    from crowdstudy.physics import Solver
    from crowdstudy.physics.collision import KIND_GROUND, KIND_INTER, CollisionPipeline, Contacts
    from crowdstudy.physics.state import State

    model, cfg, control, state, solver = small_system
    # the plain penalty (k/2) depth^2: the activation band is tested on its own below
    cfg = cfg.with_values({"contacts.activation": 0.0})
    solver = Solver(model, cfg)
    still = State(model)  # same pose, zero velocity: prediction == state
    still.x.assign(state.x)
    still.q.assign(state.q)
    pipe = CollisionPipeline(model, cfg)
    contacts = Contacts.allocate(pipe.default_capacity(), "cpu")
    pipe.collide(still, contacts)
    c = contacts.to_numpy()
    solver.assemble(still, control, Contacts.allocate(0, "cpu"), cfg.solver.dt)
    g0 = np.concatenate([solver.grad_t.numpy(), solver.grad_r.numpy()], 1).astype(float)
    solver.assemble(still, control, contacts, cfg.solver.dt)
    g1 = np.concatenate([solver.grad_t.numpy(), solver.grad_r.numpy()], 1).astype(float)
    x, R = still.x.numpy().astype(float), _quat_to_mat(still.q.numpy())
    expected = np.zeros_like(g0)
    seg = np.stack([model.cap_p0, model.cap_p1], 1)
    kinds = set()
    for i in range(len(c["depth"])):
        a, b, kind = c["body_a"][i], c["body_b"][i], c["kind"][i]
        if kind == KIND_GROUND:
            depth = c["depth"][i]
            if depth > 0:
                lever = c["lever_a"][i]
                expected[a] += (
                    cfg.contacts.ground_stiffness
                    * depth
                    * np.concatenate([-np.array([0, 0, 1.0]), -np.cross(lever, [0, 0, 1.0])])
                )
                kinds.add(kind)
            continue
        margin = cfg.contacts.margin if kind == KIND_INTER else 0.0
        k = cfg.contacts.stiffness if kind == KIND_INTER else cfg.contacts.intra_stiffness
        stiffening = cfg.contacts.stiffening_depth if kind == KIND_INTER else 0.0
        _, g, _, depth = E.contact_energy(
            x[a], R[a], seg[a], model.cap_radius[a] + margin, x[b], R[b], seg[b], model.cap_radius[b], k, stiffening
        )
        expected[a] += g[:6]
        expected[b] += g[6:]
        if depth > 0:
            kinds.add(kind)
    assert {KIND_GROUND, KIND_INTER} <= kinds
    np.testing.assert_allclose(g1 - g0, expected, atol=2e-3 * max(np.abs(expected).max(), 1.0))


def test_ground_contact_friction_gradient():
    from crowdstudy.physics import Control, ModelBuilder, PhysicsConfig, Solver, State
    from crowdstudy.physics.collision import KIND_GROUND, CollisionPipeline, Contacts

    builder = ModelBuilder()
    builder.add_character(*vars(fixture_body()).values())
    model = builder.finalize(device="cpu")
    cfg = PhysicsConfig().with_values({"contacts.ground_friction": 1500.0, "contacts.activation": 0.0})
    control = Control(model)
    control.set_frames(np.zeros((1, 24, 3)), np.array([[0.0, 0.0, 0.95]]))
    control.advance(0, 0, 0.0)
    control.hold()
    state = State(model)
    state.x.assign(control.t_x)
    state.q.assign(control.t_glob)
    wp = get_warp()
    vel = np.array([0.2, -0.1, 0.0])
    state.v.assign(wp.array(np.tile(vel, (model.n_bodies, 1)).astype(np.float32), dtype=wp.vec3))
    pipe = CollisionPipeline(model, cfg)
    contacts = Contacts.allocate(pipe.default_capacity(), "cpu")
    pipe.collide(state, contacts)
    c = contacts.to_numpy()
    solver = Solver(model, cfg)
    solver.assemble(state, control, Contacts.allocate(0, "cpu"), cfg.solver.dt)
    g0 = np.concatenate([solver.grad_t.numpy(), solver.grad_r.numpy()], 1).astype(float)
    solver.assemble(state, control, contacts, cfg.solver.dt)
    g1 = np.concatenate([solver.grad_t.numpy(), solver.grad_r.numpy()], 1).astype(float)
    expected = np.zeros_like(g0)
    up = np.array([0.0, 0.0, 1.0])
    n_active = 0
    for i in np.nonzero(c["kind"] == KIND_GROUND)[0]:
        a, lever = c["body_a"][i], c["lever_a"][i].astype(float)
        u = np.concatenate([-up, -np.cross(lever, up)])
        depth = c["depth"][i] + cfg.solver.dt * u[:3] @ vel
        if depth <= 0:
            continue
        n_active += 1
        vt = vel - (vel @ up) * up
        expected[a] += cfg.contacts.ground_stiffness * depth * u
        friction = cfg.contacts.ground_friction * vt
        expected[a] += np.concatenate([friction, np.cross(lever, friction)])
    assert n_active >= 2
    np.testing.assert_allclose(g1 - g0, expected, atol=1e-3 * np.abs(expected).max())


def test_foot_anchor_energy_gradient_and_hessian_match_finite_differences():
    rng = np.random.default_rng(11)
    x, x_old, t, t_old, off = rng.normal(scale=0.05, size=(5, 3))
    h = 1.0 / 60.0
    params = dict(w=0.7, k=3e5, c=50.0, h=h, kt=5e3, dh2=1.8 / h**2)
    _, g, H = E.foot_anchor_energy(x, x_old, t, t_old, off, **params)
    fd_g, fd_H = np.zeros(3), np.zeros((3, 3))
    for i in range(3):
        dx = np.zeros(3)
        dx[i] = EPS
        ep, gp, _ = E.foot_anchor_energy(x + dx, x_old, t, t_old, off, **params)
        em, gm, _ = E.foot_anchor_energy(x - dx, x_old, t, t_old, off, **params)
        fd_g[i] = (ep - em) / (2 * EPS)
        fd_H[:, i] = (gp - gm) / (2 * EPS)
    np.testing.assert_allclose(g, fd_g, rtol=1e-5, atol=1e-6 * np.abs(g).max())
    np.testing.assert_allclose(H, fd_H, rtol=1e-5, atol=1e-6 * np.abs(H).max())
    assert g[2] == 0 and H[2, 2] == 0  # horizontal only


def test_stance_foot_anchor_assembly_matches_reference():
    """A planted foot is held where it stood (offset dragged only beyond the Coulomb slip
    distance); a far-pushed foot steps (no anchor); a moving animation foot is free."""
    from crowdstudy.physics import Control, ModelBuilder, PhysicsConfig, Solver, State
    from crowdstudy.physics.collision import Contacts

    builder = ModelBuilder()
    builder.add_character(*vars(fixture_body()).values())
    model = builder.finalize(device="cpu")
    cfg = PhysicsConfig().with_values({"feet.anchor_damping": 40.0})
    h = cfg.solver.dt
    slip = cfg.feet.anchor_max_force / cfg.feet.anchor_stiffness
    control = Control(model)
    control.set_frames(np.zeros((1, 24, 3)), np.array([[0.0, 0.0, 0.95]]))
    control.advance(0, 0, 0.0)
    control.hold()
    wp = get_warp()
    state = State(model)
    tx = control.t_x.numpy().astype(float)
    shift = np.zeros_like(tx)
    feet = np.array([7, 8, 10, 11])
    shift[feet] = [[0.5 * slip, 0.0, 0.0], [0.03, -0.02, 0.0], [0.0, 0.0, 0.01], [0.3, 0.0, 0.0]]
    state.x.assign(wp.array((tx + shift).astype(np.float32), dtype=wp.vec3))
    state.q.assign(control.t_glob)
    rng = np.random.default_rng(5)
    state.v.assign(wp.array(rng.normal(scale=0.05, size=tx.shape).astype(np.float32), dtype=wp.vec3))
    none = Contacts.allocate(0, "cpu")

    def assembled(c):
        s = Solver(model, c)
        s.assemble(state, control, none, h)
        return s, s.grad_t.numpy().astype(float), s.hess_a.numpy().astype(float)

    on, g1, A1 = assembled(cfg)
    _, g0, A0 = assembled(cfg.with_values({"feet.anchor_stiffness": 0.0}))
    x_pred, x_old = on.x_pred.numpy().astype(float), state.x.numpy().astype(float)
    kt, dh2 = on.body_kt.numpy().astype(float), on.body_dt.numpy().astype(float) / h**2
    exp_g, exp_A = np.zeros_like(g0), np.zeros_like(A0)
    offsets = on.foot_offset.numpy().astype(float)
    for j, b in enumerate(feet):
        w = E.foot_planted_weight(tx[b], tx[b], h, cfg.feet.planted_speed)
        assert w == 1.0
        off = E.foot_anchor_update(x_old[b], tx[b], np.zeros(3), w, slip)
        if j == 3:  # pushed 30 cm: it steps, no anchor
            assert on.foot_stepping.numpy()[b] == 1
            continue
        np.testing.assert_allclose(offsets[b], off, atol=1e-6)
        _, g, H = E.foot_anchor_energy(
            x_pred[b],
            x_old[b],
            tx[b],
            tx[b],
            off,
            w,
            cfg.feet.anchor_stiffness,
            cfg.feet.anchor_damping,
            h,
            kt[b],
            dh2[b],
        )
        exp_g[b], exp_A[b] = g, H
    assert np.linalg.norm(offsets[8, :2] - shift[8, :2]) == pytest.approx(slip, rel=1e-3)  # dragged
    np.testing.assert_allclose(offsets[7], 0.0, atol=1e-7)  # held
    np.testing.assert_allclose(g1 - g0, exp_g, atol=1e-4 * np.abs(exp_g).max())
    np.testing.assert_allclose(A1 - A0, exp_A, atol=1e-4 * np.abs(exp_A).max())
    # the animation's foot moves at 1 m/s: free, and the anchor follows the body
    moving = control.t_x.numpy().astype(float)
    moving[feet] += [1.0 * h, 0.0, 0.0]
    control.t_x.assign(wp.array(moving.astype(np.float32), dtype=wp.vec3))
    on.assemble(state, control, none, h)
    assert np.all(on.foot_weight.numpy() == 0)
    np.testing.assert_allclose(on.foot_offset.numpy()[feet, :2], shift[feet, :2], atol=1e-6)


def test_arm_trunk_and_hips_scales_set_the_pd_gains_of_exactly_their_joints(small_system):
    """``arm_scale`` multiplies k and d of the collars to hands, ``trunk_scale`` of spine2,
    spine3, neck and head, ``hips_scale`` of the hips and spine1; the pelvis (the root) and
    feet groups keep theirs, the legs the plain k."""
    from crowdstudy.body.skeleton import JOINT_INDEX
    from crowdstudy.physics import Solver

    model, cfg, *_ = small_system
    joint = model.body_joint
    arms = [
        JOINT_INDEX[n]
        for n in (
            "left_collar",
            "right_collar",
            "left_shoulder",
            "right_shoulder",
            "left_elbow",
            "right_elbow",
            "left_wrist",
            "right_wrist",
            "left_hand",
            "right_hand",
        )
    ]
    trunk = [JOINT_INDEX[n] for n in ("spine2", "spine3", "neck", "head")]
    hips = [JOINT_INDEX[n] for n in ("left_hip", "right_hip", "spine1")]
    pelvis = [JOINT_INDEX["pelvis"]]
    feet = [JOINT_INDEX[n] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
    expect = np.ones(len(joint))
    for idx, scale in (
        (arms, 0.5),
        (trunk, 4.0),
        (hips, 3.0),
        (pelvis, cfg.control.pelvis_scale),
        (feet, cfg.control.feet_scale),
    ):
        expect[np.isin(joint, idx)] = scale
    assert np.isin(joint, [JOINT_INDEX["left_knee"], JOINT_INDEX["right_knee"]]).sum() == 4  # two characters
    solver = Solver(model, cfg.with_values(arm_scale=0.5, trunk_scale=4.0, hips_scale=3.0))
    np.testing.assert_allclose(solver.body_k.numpy(), cfg.control.stiffness * expect, rtol=1e-6)
    np.testing.assert_allclose(solver.body_d.numpy(), cfg.control.damping * expect, rtol=1e-6)
    default = Solver(model, cfg)
    expect[np.isin(joint, arms)] = 0.25  # the defaults: soft arms (held by the pose springs)
    expect[np.isin(joint, trunk)] = 1.0  # and the paper's single body k for the trunk
    expect[np.isin(joint, hips)] = cfg.control.pelvis_scale  # the hips as stiff as the pelvis
    np.testing.assert_allclose(default.body_k.numpy(), cfg.control.stiffness * expect, rtol=1e-6)


def test_set_frames_gathers_the_asked_frames_in_blocks(monkeypatch):
    """``frames=`` uploads those frames of the clip, in slot order, the same bits as the
    frames gathered first; the upload blocks (a few frames at a time) do not change them;
    a bad index is named."""
    import crowdstudy.physics.state as state_mod
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.physics import Control, ModelBuilder

    builder = ModelBuilder()
    for s in (1.0, 0.95):
        builder.add_character(*vars(fixture_body(s)).values())
    model = builder.finalize(device="cpu")
    rng = np.random.default_rng(5)
    rot = rng.normal(scale=0.3, size=(7, 2, 24, 3))
    root = rng.normal(size=(7, 2, 3))
    schedule = np.array([5, 6, 0, 1, 2, 3, 4, 5, 6, 0])
    gathered = Control(model, n_frames=len(schedule))
    gathered.set_frames(rot[schedule], root[schedule])
    monkeypatch.setattr(state_mod, "_UPLOAD_ROTATIONS", 3 * model.n_bodies)  # blocks of 3 frames
    indexed = Control(model, n_frames=len(schedule) + 1)
    indexed.set_frames(rot, root, start=1, frames=schedule)
    assert np.array_equal(indexed.anim_q.numpy()[1:], gathered.anim_q.numpy())
    assert np.array_equal(indexed.anim_root.numpy()[1:], gathered.anim_root.numpy())
    for bad in (np.array([0, 7]), np.array([-1]), np.array([0.5]), np.zeros((2, 2), int)):
        with pytest.raises(InvalidInputError, match="frames"):
            indexed.set_frames(rot, root, frames=bad)

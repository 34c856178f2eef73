"""One Newton iteration of implicit Euler per step, solved by block-Jacobi PCG.

``Solver.step(state_in, state_out, control, contacts, dt)``:

1. predict ``x~ = x + h v``, ``R~ = exp(h [w]x) R``;
2. assemble the gradient and the 6x6 diagonal Hessian blocks at the prediction
   (:mod:`crowdstudy.physics.kernels`), then add the contacts (penalty ``k/2 depth^2``, the
   depth linearised to the prediction, Gauss-Newton Hessian ``k u u^T``;
   :mod:`crowdstudy.physics.linear`); the stance-foot anchor (``foot_anchor_kernel``) adds
   its horizontal spring to the planted feet's blocks in between;
3. solve ``H [dx; dw] = -g`` by preconditioned CG; the off-diagonal joint and contact
   couplings are applied matrix-free. Preconditioners (``preconditioner``):
   ``"character"`` (default) block Jacobi with one block per CHARACTER (6J x 6J: bodies and
   joint couplings, a tree), solved exactly by a block LDL^T that eliminates leaves into
   their parents; only contacts are left to CG (about 5-15 iterations instead of 60+);
   ``"body"`` the plain 6x6 block Jacobi (inverted diagonal blocks);
4. update positions/orientations and velocities.

On the CPU with two host threads (:func:`~crowdstudy.warp_runtime.host_threads`), the
per-body and per-character kernels (prediction and body terms, the tree factorisation, the
update) run on the two halves of the crowd at once; they write disjoint bodies, so the
result is the same bits as one thread. From ``_MIN_CHARACTERS_SPLIT_ASSEMBLY`` characters the
contact terms too (each half takes the contacts that touch it, in order, and adds to its own
bodies). From ``_MIN_CHARACTERS_SPLIT_PCG`` characters on, the PCG is split the same way
(``Solver._solve_split``: each half's rows with the contacts that touch them, the partial
dot products added in a fixed order on the host; on two threads each half iterates on its
own thread and the two meet at a barrier after each phase), whatever the threads at hand,
so that a crowd gives the same bits on any machine; below it, the fused one-launch PCG.

Linear solvers (``linear_solver``):

* ``"fused"``: the whole PCG in ONE Warp kernel launch (a single thread loops over the
  blocks). Warp's CPU kernels run on one thread anyway, so this removes every
  per-iteration launch; the fastest on CPU.
* ``"warp"``: a ``warp.sparse`` BSR matrix (6x6 blocks) assembled on the device and
  ``warp.optim.linear.cg`` with the same preconditioner (as a ``LinearOperator``): the
  CUDA default (the CPU tests run the same code path; ``tests/test_gpu.py`` runs it on a
  CUDA device where there is one).
* ``"scipy"``: the same BSR matrix on the host and ``scipy.sparse.linalg.cg`` with the 6x6
  block Jacobi (benchmark peer).

``crowdstudy bench physics`` times them. On a CPU the fused PCG with the character
preconditioner wins: with the 6x6 block Jacobi it needs several times the iterations (it
may stop at the iteration cap); scipy is an order of magnitude slower, and
``warp.optim.linear.cg`` two (its per-iteration launches and the BSR rebuild dominate).

The Warp kernels live in :mod:`crowdstudy.physics.kernels` (bodies) and
:mod:`crowdstudy.physics.linear` (contacts and linear algebra); the methods that launch
them import those modules, so importing this one does not import Warp.
"""

from __future__ import annotations

import functools
import threading
import time
from typing import Any, Literal, NamedTuple, cast, get_args

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.model import GROUP_ARM, GROUP_FEET, GROUP_HIPS, GROUP_PELVIS, GROUP_TRUNK
from crowdstudy.warp_runtime import device_kind, get_warp, host_threads, run_parallel, run_together

__all__ = ["Solver", "LinearSolver", "LINEAR_SOLVERS", "Preconditioner", "PRECONDITIONERS"]

#: The CG implementations (module docstring).
LinearSolver = Literal["fused", "warp", "scipy"]
LINEAR_SOLVERS: tuple[LinearSolver, ...] = get_args(LinearSolver)
#: The CG preconditioners (module docstring).
Preconditioner = Literal["character", "body"]
PRECONDITIONERS: tuple[Preconditioner, ...] = get_args(Preconditioner)
#: joints whose bodies get the optional absolute translation PD (the feet: ankle and toe bodies)
FEET_TRANSLATION_JOINTS = (7, 8, 10, 11)


#: below this many characters per half the two-thread split costs more than it saves
_MIN_CHARACTERS_PER_THREAD = 16
#: from this many characters on, the CPU assembles the two halves of the crowd at once,
#: contacts included (below, listing each half's contacts costs about what it saves)
_MIN_CHARACTERS_SPLIT_ASSEMBLY = 200
#: from this many characters on, the CPU PCG runs split over the two halves of the crowd
#: (``Solver._solve_split``); below, its per-iteration hand-overs cost more than the second
#: core saves (on two host threads the split still loses at a couple of hundred characters
#: and wins at a thousand)
_MIN_CHARACTERS_SPLIT_PCG = 500


class _Step(NamedTuple):
    """What one assembly reads besides the solver's buffers: the state and control at the
    step's start, the contacts, the step ``dt`` (s), whether the PD targets feed forward,
    and the damping's scale ``dt / damping_reference_dt``."""

    state_in: Any
    control: Any
    contacts: Any
    dt: float
    ff: bool
    damp_scale: float


class Solver:
    """Implicit-Euler solver (one Newton iteration per step) for a :class:`Model`.

    Args:
        model: the model.
        config: :class:`~crowdstudy.physics.config.PhysicsConfig`.
        linear_solver: ``"fused"`` (CPU default), ``"warp"`` (CUDA default) or ``"scipy"``.
        profile: when true, :attr:`timings` accumulates seconds per phase (synchronising the
            device between phases).

    After each step :attr:`last_cg` holds ``(iterations, relative residual)``.
    """

    def __init__(
        self,
        model,
        config,
        *,
        linear_solver: LinearSolver | None = None,
        profile: bool = False,
        preconditioner: Preconditioner = "character",
    ):
        self.model = model
        self.config = config
        wp = get_warp()
        self.wp = wp
        dev = model.device
        if linear_solver is None:
            linear_solver = "fused" if device_kind(dev) == "cpu" else "warp"
        if linear_solver not in LINEAR_SOLVERS:
            raise InvalidInputError(f"linear_solver: expected one of {LINEAR_SOLVERS}, got {linear_solver!r}")
        self.linear_solver = linear_solver
        if preconditioner not in PRECONDITIONERS:
            raise InvalidInputError(f"preconditioner: expected one of {PRECONDITIONERS}, got {preconditioner!r}")
        self.preconditioner = preconditioner
        self.profile = profile
        self.timings = {"assembly": 0.0, "solve": 0.0, "update": 0.0}
        nb = model.n_bodies
        z3 = lambda: wp.zeros(nb, dtype=wp.vec3, device=dev)  # noqa: E731
        m3 = lambda: wp.zeros(nb, dtype=wp.mat33, device=dev)  # noqa: E731
        self.x_pred, self.q_pred = z3(), wp.zeros(nb, dtype=wp.quat, device=dev)
        self.grad_t, self.grad_r = z3(), z3()
        self.hess_a, self.hess_b, self.hess_c = m3(), m3(), m3()
        self.p_tt, self.p_tr, self.p_rr = m3(), m3(), m3()
        self.lever_p, self.lever_c = z3(), z3()
        self.ctrl_c = wp.zeros(nb, dtype=wp.float32, device=dev)
        self.ctrl_g = wp.zeros(nb, dtype=wp.vec3, device=dev)  # each joint's PD gradient on its child (N m)
        self.dx, self.dw = z3(), z3()
        self.work = [z3() for _ in range(8)]
        self.work_split = [z3(), z3()]  # the split PCG's second direction buffer (t, r)
        self.split_sums = wp.zeros(8, dtype=wp.float32, device=dev)
        self._split_lists = None  # its per-half contact lists
        self._split_cmds = None  # its recorded launches (and the buffers they were recorded on)
        self.stats = wp.zeros(2, dtype=wp.float32, device=dev)
        s6 = lambda: wp.zeros(nb, dtype=wp.spatial_matrix, device=dev)  # noqa: E731
        self.tree_work, self.tree_dinv, self.tree_l = s6(), s6(), s6()
        # wp.spatial_vector is an overloaded constructor, a Warp type pyright does not take as one
        self.y6 = wp.zeros(nb, dtype=wp.spatial_vector, device=dev)  # pyright: ignore[reportArgumentType]
        groups = model.body_group
        ctl = config.control
        scale = np.select(
            [
                groups == GROUP_PELVIS,
                groups == GROUP_HIPS,
                groups == GROUP_FEET,
                groups == GROUP_ARM,
                groups == GROUP_TRUNK,
            ],
            [ctl.pelvis_scale, ctl.hips_scale, ctl.feet_scale, ctl.arm_scale, ctl.trunk_scale],
            1.0,
        )
        self.body_k = wp.array((ctl.stiffness * scale).astype(np.float32), dtype=wp.float32, device=dev)
        self.body_d = wp.array((ctl.damping * scale).astype(np.float32), dtype=wp.float32, device=dev)
        root = model.body_parent < 0
        feet = np.isin(model.body_joint, FEET_TRANSLATION_JOINTS)
        kt = np.where(
            root,
            ctl.root_translation_stiffness,
            np.where(feet, ctl.feet_translation_stiffness, ctl.pose_translation_stiffness),
        )
        dtr = ctl.damping * np.where(
            root,
            ctl.root_translation_damping_scale,
            np.where(feet, ctl.feet_translation_damping_scale, ctl.pose_translation_damping_scale),
        )
        self.body_kt = wp.array(kt.astype(np.float32), dtype=wp.float32, device=dev)
        self.body_dt = wp.array(dtr.astype(np.float32), dtype=wp.float32, device=dev)
        reach = np.where(root, ctl.root_translation_reach, np.where(feet, 0.0, ctl.pose_translation_reach))
        far = np.where(root, ctl.root_translation_far_stiffness, 0.0)
        self.body_reach = wp.array(reach.astype(np.float32), dtype=wp.float32, device=dev)
        self.body_kt_far = wp.array(far.astype(np.float32), dtype=wp.float32, device=dev)
        self.feet_index = wp.array(np.nonzero(feet)[0].astype(np.int32), dtype=wp.int32, device=dev)
        self.foot_offset = z3()
        self.foot_stepping = wp.zeros(nb, dtype=wp.int32, device=dev)
        self.foot_weight = wp.zeros(max(int(feet.sum()), 1), dtype=wp.float32, device=dev)
        self._feet_host = np.nonzero(feet)[0]  # feet_index on the host (sorted)
        self._no_list = wp.zeros(1, dtype=wp.int32, device=dev)
        self._assembly_lists = None
        self._contact_capacity = -1
        self.last_cg = (0, 0.0)

    def reset_foot_anchors(self) -> None:
        """Forget the stance anchors (call after placing the bodies anew)."""
        self.foot_offset.zero_()
        self.foot_stepping.zero_()

    def _contact_buffers(self, capacity: int) -> None:
        if capacity == self._contact_capacity:
            return
        wp, dev = self.wp, self.model.device
        cap = max(capacity, 1)
        self.u_at, self.u_ar, self.u_bt, self.u_br = (wp.zeros(cap, dtype=wp.vec3, device=dev) for _ in range(4))
        self.k_eff = wp.zeros(cap, dtype=wp.float32, device=dev)
        self._contact_capacity = capacity
        self._bsr = None

    def _tick(self, name: str, t0: float) -> float:
        if not self.profile:
            return t0
        self.wp.synchronize_device(self.model.device)
        t1 = time.perf_counter()
        self.timings[name] += t1 - t0
        return t1

    def assemble(self, state_in, control, contacts, dt: float) -> None:
        """Prediction, gradient and diagonal Hessian blocks (bodies, then contacts)."""
        m, cfg, dev = self.model, self.config, self.model.device
        self._contact_buffers(contacts.capacity)
        step = _Step(
            state_in,
            control,
            contacts,
            float(dt),
            bool(cfg.solver.feedforward),
            float(dt) / float(cfg.solver.damping_reference_dt),
        )
        bodies = functools.partial(self._assemble_bodies, step)
        feet = functools.partial(self._assemble_feet, step)
        contact_terms = functools.partial(self._assemble_contacts, step)
        n_feet = self.feet_index.shape[0] if cfg.feet.anchor_stiffness > 0 else 0

        # on the CPU the host reads the contact count for free: launch only the stored
        # contacts (the kernel skips the rest); on CUDA the whole capacity (no host sync)
        n_launch = contacts.capacity if dev != "cpu" else contacts.n_active()
        if not self._split_assembly():
            # the body terms of a body read its parent's prediction: split at a character boundary
            self._split_characters(lambda c0, c1: bodies(c0 * m.n_joints, c1 * m.n_joints))
            feet(0, n_feet)
            contact_terms(n_launch, self._no_list, 0, 0, m.n_bodies)
            return
        # two host threads, one per half of the crowd: each predicts and assembles its
        # bodies, adds their stance anchors and the terms of the contacts that touch them
        # (a contact across the cut is in both lists; each half adds only to its own
        # bodies): every body sums the same terms in the same order as one thread
        cut = (m.n_characters // 2) * m.n_joints
        a = contacts.body_a.numpy()[:n_launch]
        b = contacts.body_b.numpy()[:n_launch]
        lists, counts = self._half_lists(
            self._assembly_lists, contacts.capacity, ((a < cut) | ((b >= 0) & (b < cut)), (a >= cut) | (b >= cut))
        )
        self._assembly_lists = lists
        feet_cut = int(np.searchsorted(self._feet_host, cut)) if n_feet else 0
        run_parallel(
            lambda: (bodies(0, cut), feet(0, feet_cut), contact_terms(counts[0], lists[0], 1, 0, cut)),
            lambda: (
                bodies(cut, m.n_bodies),
                feet(feet_cut, n_feet),
                contact_terms(counts[1], lists[1], 1, cut, m.n_bodies),
            ),
        )

    def _assemble_bodies(self, step: _Step, lo: int, hi: int) -> None:
        """Prediction and body terms of bodies ``[lo, hi)``."""
        from crowdstudy.physics import kernels as kb

        wp, cfg, W, dev = self.wp, self.config, self.model.wp, self.model.device
        state_in, control, dt, damp_scale = step.state_in, step.control, step.dt, step.damp_scale
        if hi <= lo:
            return
        wp.launch(
            kb.predict_kernel,
            hi - lo,
            [
                state_in.x,
                state_in.q,
                state_in.v,
                state_in.w,
                float(dt),
                int(step.ff),
                control.t_x,
                control.t_x_old,
                control.t_x_older,
                control.t_glob,
                control.t_glob_old,
                control.t_glob_older,
                self.x_pred,
                self.q_pred,
                int(lo),
            ],
            device=dev,
        )
        wp.launch(
            kb.joint_terms_kernel,
            hi - lo,
            [
                self.q_pred,
                state_in.q,
                control.t_rel,
                control.t_rel_old,
                W["body_parent"],
                W["anchor_parent"],
                W["anchor_child"],
                self.body_k,
                self.body_d,
                float(dt),
                damp_scale,
                self.lever_p,
                self.lever_c,
                self.ctrl_c,
                self.ctrl_g,
                int(lo),
            ],
            device=dev,
        )
        wp.launch(
            kb.assemble_bodies_kernel,
            hi - lo,
            [
                self.x_pred,
                self.q_pred,
                state_in.x,
                state_in.q,
                control.t_rel,
                control.t_rel_old,
                control.t_x,
                control.t_x_old,
                W["body_mass"],
                W["body_J"],
                W["body_parent"],
                W["body_children"],
                self.body_k,
                self.body_d,
                self.body_kt,
                self.body_dt,
                self.body_reach,
                self.body_kt_far,
                float(dt),
                0.0 if step.ff else float(cfg.body.gravity),
                float(cfg.body.joint_stiffness),
                damp_scale,
                self.grad_t,
                self.grad_r,
                self.hess_a,
                self.hess_b,
                self.hess_c,
                self.lever_p,
                self.lever_c,
                self.ctrl_c,
                self.ctrl_g,
                int(lo),
            ],
            device=dev,
        )

    def _assemble_feet(self, step: _Step, f0: int, f1: int) -> None:
        """The stance anchors of feet ``[f0, f1)`` (``feet_index`` order)."""
        from crowdstudy.physics import kernels as kb

        wp, cfg, dev = self.wp, self.config, self.model.device
        state_in, control, dt, damp_scale = step.state_in, step.control, step.dt, step.damp_scale
        if f1 > f0:
            wp.launch(
                kb.foot_anchor_kernel,
                f1 - f0,
                [
                    self.feet_index,
                    self.x_pred,
                    state_in.x,
                    control.t_x,
                    control.t_x_old,
                    self.foot_offset,
                    self.foot_weight,
                    self.foot_stepping,
                    self.body_kt,
                    self.body_dt,
                    float(dt),
                    damp_scale,
                    float(cfg.feet.planted_speed),
                    float(cfg.feet.anchor_stiffness),
                    float(cfg.feet.anchor_damping),
                    float(cfg.feet.anchor_max_force),
                    float(cfg.feet.release_distance),
                    float(cfg.feet.rejoin_distance),
                    self.grad_t,
                    self.hess_a,
                    int(f0),
                ],
                device=dev,
            )

    def _assemble_contacts(self, step: _Step, n_threads: int, contact_list, use_list: int, lo: int, hi: int) -> None:
        """The terms of the contacts (all, or the ``n_threads`` of ``contact_list`` when
        ``use_list``) on bodies ``[lo, hi)``."""
        from crowdstudy.physics import linear as ks

        wp, m, cfg, dev = self.wp, self.model, self.config, self.model.device
        state_in, control, contacts, dt = step.state_in, step.control, step.contacts, step.dt
        if n_threads:
            wp.launch(
                ks.contact_assemble_kernel,
                n_threads,
                [
                    contacts.count,
                    contacts.capacity,
                    contacts.body_a,
                    contacts.body_b,
                    contacts.normal,
                    contacts.depth,
                    contacts.lever_a,
                    contacts.lever_b,
                    contacts.stiffness,
                    contacts.kind,
                    float(cfg.contacts.ground_friction),
                    float(cfg.contacts.activation),
                    float(cfg.contacts.release_distance),
                    float(cfg.contacts.release_width),
                    float(cfg.contacts.stiffening_depth),
                    m.n_joints,
                    state_in.x,
                    control.t_x,
                    state_in.v,
                    state_in.w,
                    float(dt),
                    self.grad_t,
                    self.grad_r,
                    self.hess_a,
                    self.hess_b,
                    self.hess_c,
                    self.u_at,
                    self.u_ar,
                    self.u_bt,
                    self.u_br,
                    self.k_eff,
                    contact_list,
                    int(use_list),
                    int(lo),
                    int(hi),
                ],
                device=dev,
            )

    def _half_lists(self, lists, capacity: int, masks) -> tuple[list, list[int]]:
        """The contacts selected by each of the two ``masks`` (the two halves of the crowd),
        in contact order, written into ``lists`` (two int32 arrays of at least ``capacity``,
        allocated anew when None or too short); returns the lists and the two counts."""
        if lists is None or lists[0].shape[0] < max(capacity, 1):
            lists = [self.wp.zeros(max(capacity, 1), dtype=self.wp.int32, device=self.model.device) for _ in range(2)]
        counts = []
        for lst, mine in zip(lists, masks, strict=True):
            idx = np.flatnonzero(mine).astype(np.int32)
            lst.numpy()[: len(idx)] = idx
            counts.append(len(idx))
        return lists, counts

    def _split_assembly(self) -> bool:
        """Whether the assembly runs as two halves of the crowd at once (CPU, two host
        threads, at least ``_MIN_CHARACTERS_SPLIT_ASSEMBLY`` characters; the same bits
        either way)."""
        return (
            self.model.device == "cpu"
            and host_threads() >= 2
            and self.model.n_characters >= _MIN_CHARACTERS_SPLIT_ASSEMBLY
        )

    def solve(self, contacts) -> None:
        """Solve H [dx; dw] = -g into ``self.dx``, ``self.dw``."""
        from crowdstudy.physics import linear as ks

        wp, m, cfg = self.wp, self.model, self.config
        dev, nb = m.device, m.n_bodies
        if self.linear_solver == "fused" and self._split_pcg():
            self._solve_split(contacts)  # factorises each half's characters with its start
        elif self.linear_solver == "fused":
            mode = 1 if self.preconditioner == "character" else 0
            if mode:
                self._factor_tree()
            else:
                wp.launch(
                    ks.precond_kernel,
                    nb,
                    [self.hess_a, self.hess_b, self.hess_c, self.p_tt, self.p_tr, self.p_rr],
                    device=dev,
                )
            wp.launch(
                ks.pcg_fused_kernel,
                1,
                [
                    nb,
                    contacts.count,
                    contacts.capacity,
                    self.hess_a,
                    self.hess_b,
                    self.hess_c,
                    self.p_tt,
                    self.p_tr,
                    self.p_rr,
                    mode,
                    self.tree_dinv,
                    self.tree_l,
                    self.y6,
                    m.wp["body_parent"],
                    self.lever_p,
                    self.lever_c,
                    self.ctrl_c,
                    float(cfg.body.joint_stiffness),
                    contacts.body_a,
                    contacts.body_b,
                    self.u_at,
                    self.u_ar,
                    self.u_bt,
                    self.u_br,
                    self.k_eff,
                    self.grad_t,
                    self.grad_r,
                    float(cfg.solver.cg_tolerance),
                    int(cfg.solver.cg_max_iterations),
                    self.dx,
                    self.dw,
                    *self.work,
                    self.stats,
                ],
                device=dev,
            )
            st = self.stats.numpy()
            self.last_cg = (int(st[0]), float(st[1]))
        else:
            rows, cols, vals, rhs = self.triplets(contacts)
            if self.linear_solver == "warp":
                self._solve_warp(rows, cols, vals, rhs)
            else:
                self._solve_scipy(rows, cols, vals, rhs)

    def triplets(self, contacts):
        """The whole system as BSR triplets (rows, cols, 6x6 values) and the rhs (B,) vec6."""
        from crowdstudy.physics import linear as ks

        wp, m, cfg = self.wp, self.model, self.config
        dev, nb = m.device, m.n_bodies
        cap = contacts.capacity
        n_trip = 3 * nb + 2 * cap
        if getattr(self, "_trip_n", -1) != n_trip:
            self._rows = wp.zeros(n_trip, dtype=wp.int32, device=dev)
            self._cols = wp.zeros(n_trip, dtype=wp.int32, device=dev)
            self._vals = wp.zeros(n_trip, dtype=wp.spatial_matrix, device=dev)
            self._rhs = wp.zeros(nb, dtype=wp.spatial_vector, device=dev)
            self._x6 = wp.zeros(nb, dtype=wp.spatial_vector, device=dev)
            self._trip_n = n_trip
        wp.launch(
            ks.triplets_bodies_kernel,
            nb,
            [
                nb,
                self.hess_a,
                self.hess_b,
                self.hess_c,
                m.wp["body_parent"],
                self.lever_p,
                self.lever_c,
                self.ctrl_c,
                float(cfg.body.joint_stiffness),
                self.grad_t,
                self.grad_r,
                self._rows,
                self._cols,
                self._vals,
                self._rhs,
            ],
            device=dev,
        )
        if cap:
            wp.launch(
                ks.triplets_contacts_kernel,
                cap,
                [
                    3 * nb,
                    contacts.count,
                    cap,
                    contacts.body_a,
                    contacts.body_b,
                    self.u_at,
                    self.u_ar,
                    self.u_bt,
                    self.u_br,
                    self.k_eff,
                    self._rows,
                    self._cols,
                    self._vals,
                ],
                device=dev,
            )
        return self._rows, self._cols, self._vals, self._rhs

    def _split_characters(self, run) -> None:
        """``run(c0, c1)`` on characters [c0, c1): on the CPU with two host threads the two
        halves of the crowd at once (:func:`~crowdstudy.warp_runtime.run_parallel`; the
        kernels split this way write disjoint bodies, so the result does not depend on the
        split), else all of them in one call."""
        n = self.model.n_characters
        if self.model.device != "cpu" or n < 2 * _MIN_CHARACTERS_PER_THREAD or host_threads() < 2:
            run(0, n)
            return
        half = n // 2
        run_parallel(lambda: run(0, half), lambda: run(half, n))

    def _split_pcg(self) -> bool:
        """Whether the CPU PCG runs split over the two halves of the crowd (the character
        preconditioner on the CPU with at least ``_MIN_CHARACTERS_SPLIT_PCG`` characters).
        It depends on the crowd only, never on the threads at hand, so a crowd gives the
        same bits on any machine: with one host thread the halves run one after the other."""
        return (
            self.model.device == "cpu"
            and self.preconditioner == "character"
            and self.model.n_characters >= _MIN_CHARACTERS_SPLIT_PCG
        )

    def _solve_split(self, contacts) -> None:
        """The PCG of ``pcg_fused_kernel`` over the two halves of the crowd (the bodies of
        characters [0, n/2) and [n/2, n)): each phase of an iteration runs on both halves
        at once (:func:`~crowdstudy.warp_runtime.run_parallel`), each half with the
        body-body contacts that touch it, in contact order; the host adds the two partial
        dot products in a fixed order and computes alpha and beta in float32. A row's
        matrix-vector product is the fused kernel's term for term; the dot products differ
        from the fused kernel's in their summation order only."""
        m = self.model
        cut = (m.n_characters // 2) * m.n_joints
        init, matvec, update = self._split_commands(contacts, cut)
        # each half factorises its characters' tree blocks, then starts its PCG rows
        half = m.n_characters // 2
        run_parallel(
            lambda: (self._factor_range(0, half), init[0].launch()),
            lambda: (self._factor_range(half, m.n_characters), init[1].launch()),
        )
        s = self.split_sums.numpy()
        it, rel = self._split_iterations(
            matvec, update, np.float32(s[0]) + np.float32(s[4]), np.float32(s[1]) + np.float32(s[5])
        )
        self.last_cg = (it, float(rel))

    def _split_commands(self, contacts, cut: int) -> tuple[list, list, list]:
        """The split PCG's recorded launches (see :meth:`_record_split`) for the halves
        split at body ``cut``, with this step's body-body contact lists and their counts
        set."""
        m, cfg = self.model, self.config
        halves = ((0, 0, cut), (1, cut, m.n_bodies))
        levers = (self.lever_p, self.lever_c, self.ctrl_c, float(cfg.body.joint_stiffness))  # the joint blocks
        # the body-body contacts of each half (a contact across the cut is in both)
        n_act = contacts.n_active()
        a = contacts.body_a.numpy()[:n_act]
        b = contacts.body_b.numpy()[:n_act]
        coupled = (b >= 0) & (self.k_eff.numpy()[:n_act] > 0)
        lists, counts = self._half_lists(
            self._split_lists,
            contacts.capacity,
            (coupled & ((a < cut) | (b < cut)), coupled & ((a >= cut) | (b >= cut))),
        )
        self._split_lists = lists

        # the ten launches, recorded once per set of buffers (packing their arguments anew
        # each step is host time that grows with the crowd); each step sets the contact counts
        key = (
            id(contacts.body_a),
            id(contacts.body_b),
            id(self.u_at),
            id(self.k_eff),
            *(id(lst) for lst in lists),
        )
        if self._split_cmds is None or self._split_cmds[0] != key:
            self._split_cmds = (key, self._record_split(contacts, halves, lists, levers))
        init, matvec, update = self._split_cmds[1]
        for part, n_list in enumerate(counts):
            for cmd in matvec[part]:
                cmd.set_param_at_index(4, n_list)
        return init, matvec, update

    def _split_iterations(self, matvec, update, bnorm2: np.float32, rz0: np.float32) -> tuple[int, np.float32]:
        """The split PCG's iterations from |r|^2 = ``bnorm2`` and r.z = ``rz0`` (float32, as
        the fused kernel); returns (iterations, |r| / |b|). On two threads each half
        iterates on its own thread and meets the other at a barrier after each phase (one
        wake-up a phase, where handing each phase over costs two); else both halves phase
        by phase from this thread: the same arithmetic either way."""
        cfg, sums = self.config, self.split_sums
        f32 = np.float32
        tol = f32(cfg.solver.cg_tolerance)
        max_it = int(cfg.solver.cg_max_iterations)

        def iterate(phase) -> tuple[int, np.float32]:
            """The PCG iterations; ``phase(cmds, buf, value)`` runs one phase (``matvec`` or
            ``update``, direction buffer ``buf``, beta or alpha) and returns once every half
            has run it. The partial sums are read right after each phase: a half that runs
            ahead into the next phase writes other slots of ``sums``."""
            rz = rz0
            rel = f32(1.0) if bnorm2 > 0 else f32(0.0)
            tol2 = tol * tol * bnorm2
            beta = f32(0.0)
            it, buf = 0, 0
            while it < max_it and rel > tol:
                phase(matvec, buf, float(beta))
                s = sums.numpy()
                pq = f32(s[2]) + f32(s[6])
                if not pq > 0:
                    break
                phase(update, buf, float(rz / pq))
                s = sums.numpy()
                rr2, rz_new = f32(s[3]) + f32(s[7]), f32(s[1]) + f32(s[5])
                it += 1
                rel = np.sqrt(rr2 / bnorm2, dtype=f32)
                if rr2 <= tol2:
                    break
                beta = rz_new / rz
                rz = rz_new
                buf = 1 - buf
            return it, rel

        barrier = threading.Barrier(2)
        result = []

        def half_loop(part: int):
            def phase(cmds, buf, value):
                cmd = cmds[part][buf]
                cmd.set_param_at_index(3, value)
                try:
                    cmd.launch()
                finally:
                    barrier.wait()

            try:
                out = iterate(phase)
            except BaseException:
                barrier.abort()
                raise
            if part == 0:
                result.append(out)

        def both(cmds, buf, value) -> None:  # one phase of both halves, from this thread
            pair = [cmds[0][buf], cmds[1][buf]]
            for cmd in pair:
                cmd.set_param_at_index(3, value)
            run_parallel(pair[0].launch, pair[1].launch)

        if not run_together(lambda: half_loop(0), lambda: half_loop(1)):
            result.append(iterate(both))
        return result[0]

    def _record_split(self, contacts, halves, lists, levers):
        """The split PCG's launches (init, matvec and update of each half, over its contact
        list of ``lists``; the two direction buffers alternate), recorded for ``_solve_split``."""
        from crowdstudy.physics import linear as ks

        wp, m, cfg = self.wp, self.model, self.config
        dev = m.device
        r_t, r_r, z_t, z_r, p_t, p_r, q_t, q_r = self.work
        po_t, po_r = self.work_split
        sums = self.split_sums
        parent = m.wp["body_parent"]

        def record(kernel, inputs):
            return wp.launch(kernel, 1, inputs, device=dev, record_cmd=True)

        init, matvec, update = [], [], []
        for (part, lo, hi), lst in zip(halves, lists, strict=True):
            init.append(
                record(
                    ks.pcg_split_init_kernel,
                    [
                        lo,
                        hi,
                        part,
                        self.grad_t,
                        self.grad_r,
                        parent,
                        self.tree_dinv,
                        self.tree_l,
                        *levers,
                        self.y6,
                        self.dx,
                        self.dw,
                        r_t,
                        r_r,
                        z_t,
                        z_r,
                        po_t,
                        po_r,
                        sums,
                    ],
                )
            )
            mv, up = [], []
            for (pot, por), (pnt, pnr) in (((po_t, po_r), (p_t, p_r)), ((p_t, p_r), (po_t, po_r))):
                mv.append(
                    record(
                        ks.pcg_split_matvec_kernel,
                        [
                            lo,
                            hi,
                            part,
                            0.0,
                            0,
                            lst,
                            self.hess_a,
                            self.hess_b,
                            self.hess_c,
                            parent,
                            self.lever_p,
                            self.lever_c,
                            self.ctrl_c,
                            float(cfg.body.joint_stiffness),
                            contacts.body_a,
                            contacts.body_b,
                            self.u_at,
                            self.u_ar,
                            self.u_bt,
                            self.u_br,
                            self.k_eff,
                            z_t,
                            z_r,
                            pot,
                            por,
                            pnt,
                            pnr,
                            q_t,
                            q_r,
                            sums,
                        ],
                    )
                )
                up.append(
                    record(
                        ks.pcg_split_update_kernel,
                        [
                            lo,
                            hi,
                            part,
                            0.0,
                            pnt,
                            pnr,
                            q_t,
                            q_r,
                            self.dx,
                            self.dw,
                            r_t,
                            r_r,
                            parent,
                            self.tree_dinv,
                            self.tree_l,
                            *levers,
                            self.y6,
                            z_t,
                            z_r,
                            sums,
                        ],
                    )
                )
            matvec.append(mv)
            update.append(up)

        return init, matvec, update

    def _factor_range(self, c0: int, c1: int) -> None:
        """The tree preconditioner's factors of characters [c0, c1)."""
        from crowdstudy.physics import linear as ks

        m, cfg = self.model, self.config
        if c1 > c0:
            self.wp.launch(
                ks.tree_factor_kernel,
                c1 - c0,
                [
                    m.n_joints,
                    self.hess_a,
                    self.hess_b,
                    self.hess_c,
                    m.wp["body_parent"],
                    self.lever_p,
                    self.lever_c,
                    self.ctrl_c,
                    float(cfg.body.joint_stiffness),
                    self.tree_work,
                    self.tree_dinv,
                    self.tree_l,
                    int(c0),
                ],
                device=m.device,
            )

    def _factor_tree(self) -> None:
        self._split_characters(self._factor_range)

    def _solve_warp(self, rows, cols, vals, rhs) -> None:
        import warp.optim.linear as wl
        import warp.sparse as wsp

        from crowdstudy.physics import linear as ks

        wp, cfg, m = self.wp, self.config, self.model
        nb = m.n_bodies
        if self._bsr is None:
            self._bsr = wsp.bsr_zeros(nb, nb, block_type=wp.spatial_matrix, device=m.device)
        wsp.bsr_set_from_triplets(self._bsr, rows, cols, vals)
        if self.preconditioner == "character":
            self._factor_tree()
            work = self.y6

            def matvec(x, y, z, alpha, beta):
                wp.launch(
                    ks.tree_precond_kernel,
                    m.n_characters,
                    [
                        m.n_joints,
                        m.wp["body_parent"],
                        self.tree_dinv,
                        self.tree_l,
                        self.lever_p,
                        self.lever_c,
                        self.ctrl_c,
                        float(cfg.body.joint_stiffness),
                        x,
                        y,
                        z,
                        float(alpha),
                        float(beta),
                        work,
                    ],
                    device=m.device,
                )

            precond = wl.LinearOperator(self._bsr.shape, self._bsr.dtype, self._bsr.device, matvec)
        else:
            precond = wl.preconditioner(self._bsr, ptype="block_jacobi_sequential")
        self._x6.zero_()
        # Warp's stub returns the solver or its result; without a callback it is the result
        it, res, atol = cast(
            "tuple[int, float, float]",
            wl.cg(
                self._bsr,
                rhs,
                self._x6,
                tol=float(cfg.solver.cg_tolerance),
                maxiter=int(cfg.solver.cg_max_iterations),
                M=precond,
                check_every=5,
                use_cuda_graph=False,
            ),
        )
        wp.launch(ks.unpack_kernel, nb, [self._x6, self.dx, self.dw], device=m.device)
        # cg returns the absolute residual and atol = tol * |b|: report |r| / |b| like the others
        rel = float(res) * float(cfg.solver.cg_tolerance) / float(atol) if float(atol) > 0 else float(res)
        self.last_cg = (int(it), rel)

    def _solve_scipy(self, rows, cols, vals, rhs) -> None:
        import scipy.sparse.linalg as spl

        from crowdstudy.physics.linear import bsr_from_triplets

        wp, cfg, nb = self.wp, self.config, self.model.n_bodies
        r, c, v, b = rows.numpy(), cols.numpy(), vals.numpy().astype(np.float64), rhs.numpy().astype(np.float64)
        A = bsr_from_triplets(r, c, v, nb)
        inv = np.linalg.inv(v[:nb])  # the first nb triplets are the full diagonal blocks
        # scipy's stub knows only LinearOperator's abstract form (dtype, shape), not this one
        M = spl.LinearOperator(
            A.shape,
            matvec=lambda x: np.einsum("bij,bj->bi", inv, x.reshape(nb, 6)).ravel(),  # pyright: ignore[reportCallIssue]
            dtype=np.float64,  # pyright: ignore[reportCallIssue]
        )
        counter = [0]
        x, _ = spl.cg(
            A,
            b.ravel(),
            rtol=float(cfg.solver.cg_tolerance),
            maxiter=int(cfg.solver.cg_max_iterations),
            M=M,
            callback=lambda _x: counter.__setitem__(0, counter[0] + 1),
        )
        x = x.reshape(nb, 6).astype(np.float32)
        self.dx.assign(wp.array(np.ascontiguousarray(x[:, :3]), dtype=wp.vec3, device=self.model.device))
        self.dw.assign(wp.array(np.ascontiguousarray(x[:, 3:]), dtype=wp.vec3, device=self.model.device))
        res = np.linalg.norm(A @ x.ravel().astype(np.float64) - b.ravel()) / max(np.linalg.norm(b), 1e-30)
        self.last_cg = (counter[0], float(res))

    def update(self, state_in, state_out, dt: float) -> None:
        from crowdstudy.physics import kernels as kb

        wp, m = self.wp, self.model

        def update(c0: int, c1: int) -> None:
            lo, hi = c0 * m.n_joints, c1 * m.n_joints
            if hi > lo:
                wp.launch(
                    kb.update_kernel,
                    hi - lo,
                    [
                        self.x_pred,
                        self.q_pred,
                        state_in.x,
                        state_in.q,
                        self.dx,
                        self.dw,
                        float(dt),
                        state_out.x,
                        state_out.q,
                        state_out.v,
                        state_out.w,
                        int(lo),
                    ],
                    device=m.device,
                )

        self._split_characters(update)

    def step(self, state_in, state_out, control, contacts, dt: float | None = None) -> None:
        """Advance ``state_in`` by ``dt`` (s, default config.solver.dt) into ``state_out``.

        ``control`` holds the target of this step and of the previous one (advance it
        first); ``contacts`` were detected on ``state_in``.
        """
        dt = float(self.config.solver.dt if dt is None else dt)
        if not dt > 0:
            raise InvalidInputError(f"dt: expected a positive time step, got {dt!r}")
        t0 = time.perf_counter()
        self.assemble(state_in, control, contacts, dt)
        t0 = self._tick("assembly", t0)
        self.solve(contacts)
        t0 = self._tick("solve", t0)
        self.update(state_in, state_out, dt)
        self._tick("update", t0)

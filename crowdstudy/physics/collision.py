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
ground and intra-body contacts the bare radius. The Warp kernels are in
:mod:`crowdstudy.physics.collision_kernels`.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.scene_meta import wall_segments
from crowdstudy.warp_runtime import get_warp, host_threads, run_parallel

if TYPE_CHECKING:  # for annotations only: Warp loads with the first pipeline
    import warp as wp

__all__ = [
    "Contacts",
    "CollisionPipeline",
    "sample_static_walls",
    "sweep_pairs",
    "KIND_GROUND",
    "KIND_ENVIRONMENT",
    "KIND_INTER",
    "KIND_INTRA",
]

#: contact kinds (``Contacts.kind``; the kernels write them as these literals)
KIND_GROUND, KIND_ENVIRONMENT, KIND_INTER, KIND_INTRA = 0, 1, 2, 3

#: capsule pairs to test (character pairs x J, plus the intra-body pairs) below which
#: detection stays on one host thread
_MIN_SPLIT_THREADS = 20000
#: characters from which the CPU finds the overlapping character AABBs by a sweep along x
#: (``sweep_kernel``, O(n k)) instead of ``broadphase_kernel``'s n^2 / 2 tests
_MIN_CHARACTERS_SWEEP = 200
#: characters from which the three capsule poses are computed on two host threads at once
_MIN_CHARACTERS_PARALLEL = 200


def launch_sweep(
    char_lo, char_hi, order, sorted_lo_x, pair_count, pair_capacity: int, pair_i, pair_j, pair_shift
) -> None:
    """Launch ``sweep_kernel`` on the CPU: ``char_lo``, ``char_hi`` the boxes' corners (CPU
    Warp arrays of vec3, m, read here as numpy too); ``order`` and ``sorted_lo_x`` Warp
    scratch arrays of length n."""
    from crowdstudy.physics.collision_kernels import sweep_kernel

    lo = char_lo.numpy()
    idx = np.argsort(lo[:, 0], kind="stable")
    order.numpy()[:] = idx
    sorted_lo_x.numpy()[:] = lo[idx, 0]
    hi = char_hi.numpy()
    reach = float(np.max(hi[:, 0] - lo[:, 0])) + 1e-3 if len(lo) else 0.0
    pair_count.zero_()
    get_warp().launch(
        sweep_kernel,
        len(lo),
        [char_lo, char_hi, order, sorted_lo_x, reach, pair_count, pair_capacity, pair_i, pair_j, pair_shift],
        device="cpu",
    )


def sweep_pairs(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (i < j) of overlapping boxes (``lo``, ``hi``: (n, 3) corners, m) in (i, j)
    order by ``sweep_kernel`` on the CPU: the pairs and the order of ``broadphase_kernel``
    without a period (closed intervals, the kernel's comparisons)."""
    wp = get_warp()
    lo = np.ascontiguousarray(lo, np.float32)
    hi = np.ascontiguousarray(hi, np.float32)
    n = len(lo)
    cap = max(min(n * (n - 1) // 2, 32 * n), 1)  # grown below if the boxes overlap more
    count = wp.zeros(1, dtype=wp.int32, device="cpu")
    boxes = (
        wp.array(lo, dtype=wp.vec3, device="cpu"),
        wp.array(hi, dtype=wp.vec3, device="cpu"),
        wp.zeros(max(n, 1), dtype=wp.int32, device="cpu"),
        wp.zeros(max(n, 1), dtype=wp.float32, device="cpu"),
    )
    while True:
        pi, pj = wp.zeros(cap, dtype=wp.int32, device="cpu"), wp.zeros(cap, dtype=wp.int32, device="cpu")
        shift = wp.zeros(cap, dtype=wp.float32, device="cpu")
        launch_sweep(*boxes, count, cap, pi, pj, shift)
        m = int(count.numpy()[0])
        if m <= cap:
            return pi.numpy()[:m].copy(), pj.numpy()[:m].copy()
        cap = m


def sample_static_walls(
    walls: np.ndarray, *, height: float = 2.2, spacing: float = 0.04, period: float | None = None, overhang: float = 0.6
) -> np.ndarray:
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
                (x0, y0), (x1, y1) = (
                    (x0 + t0 * (x1 - x0), y0 + t0 * (y1 - y0)),
                    (x0 + t1 * (x1 - x0), y0 + t1 * (y1 - y0)),
                )
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
    count: wp.array
    body_a: wp.array
    body_b: wp.array
    normal: wp.array
    depth: wp.array
    lever_a: wp.array
    lever_b: wp.array
    stiffness: wp.array
    kind: wp.array

    @classmethod
    def allocate(cls, capacity: int, device: str) -> Contacts:
        wp = get_warp()
        return cls(
            capacity=int(capacity),
            count=wp.zeros(1, dtype=wp.int32, device=device),
            body_a=wp.zeros(capacity, dtype=wp.int32, device=device),
            body_b=wp.zeros(capacity, dtype=wp.int32, device=device),
            normal=wp.zeros(capacity, dtype=wp.vec3, device=device),
            depth=wp.zeros(capacity, dtype=wp.float32, device=device),
            lever_a=wp.zeros(capacity, dtype=wp.vec3, device=device),
            lever_b=wp.zeros(capacity, dtype=wp.vec3, device=device),
            stiffness=wp.zeros(capacity, dtype=wp.float32, device=device),
            kind=wp.zeros(capacity, dtype=wp.int32, device=device),
        )

    def buffers(self) -> list:
        return [
            self.body_a,
            self.body_b,
            self.normal,
            self.depth,
            self.lever_a,
            self.lever_b,
            self.stiffness,
            self.kind,
        ]

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
            the floor plane, e.g. :func:`crowdstudy.scene_meta.static_walls_from_meta`), or None: one-sided plane
            contacts of every capsule end (``wall_kernel``, stiffness ``config.contacts.wall_stiffness``).
    """

    def __init__(
        self,
        model,
        config,
        *,
        static_points: np.ndarray | None = None,
        period: float | None = None,
        static_walls: np.ndarray | None = None,
    ):
        self.model = model
        self.config = config
        wp = get_warp()
        dev = model.device
        n, nb = model.n_characters, model.n_bodies
        self.period = float(period or 0.0)
        self.speculative = float(config.contacts.speculative_distance)
        self.p0w = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.p1w = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.centre = wp.zeros(nb, dtype=wp.vec3, device=dev)  # capsule midpoints (m)
        self.half = wp.zeros(nb, dtype=wp.float32, device=dev)  # capsule half lengths (m)
        self.centre_t = wp.zeros(nb, dtype=wp.vec3, device=dev)  # the same in the target pose
        self.half_t = wp.zeros(nb, dtype=wp.float32, device=dev)
        self.char_lo = wp.zeros(n, dtype=wp.vec3, device=dev)
        self.char_hi = wp.zeros(n, dtype=wp.vec3, device=dev)
        # the capsules in the target pose (target-relative ground and self contacts)
        self.p0t = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.p1t = wp.zeros(nb, dtype=wp.vec3, device=dev)
        self.t_lo = wp.zeros(n, dtype=wp.vec3, device=dev)
        self.t_hi = wp.zeros(n, dtype=wp.vec3, device=dev)
        # ... and in the look-ahead pose (config.contacts.pass_ahead)
        self.pass_on = bool(config.contacts.pass_ahead > 0 and config.contacts.pass_width > 0)
        na = nb if self.pass_on else 1
        self.p0a = wp.zeros(na, dtype=wp.vec3, device=dev)
        self.p1a = wp.zeros(na, dtype=wp.vec3, device=dev)
        self._ahead_scratch = (
            wp.zeros(n, dtype=wp.vec3, device=dev),
            wp.zeros(n, dtype=wp.vec3, device=dev),
            wp.zeros(na, dtype=wp.vec3, device=dev),
            wp.zeros(na, dtype=wp.float32, device=dev),
        )
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
        self.walls = (
            wp.array(walls.reshape(-1, 4).astype(np.float32), dtype=wp.vec4, device=dev) if len(walls) else None
        )
        self._scratch = None  # the second host thread's contact buffer (CPU)
        self._sweep_scratch = None  # the sweep's sorted order and lower x (CPU)
        self._split = 0.75  # share of the narrow-phase threads run by the first host thread

    def default_capacity(self) -> int:
        return int(self.config.contacts.max_per_character) * self.model.n_characters + 2 * self.model.n_bodies

    def collide(self, state, contacts: Contacts, control=None) -> None:
        """Fill ``contacts`` from ``state`` (positions/orientations at the start of the step).

        ``control`` (:class:`~crowdstudy.physics.state.Control`, advanced to this step): with
        ``config.contacts.target_relative_self``, ground and intra-body contacts count only
        the depth beyond the target pose's own (see ``intra_kernel``)."""
        cfg = self.config
        margin = float(cfg.contacts.margin)
        contacts.count.zero_()
        relative = int(bool(cfg.contacts.target_relative_self) and control is not None)
        pass_on = int(self.pass_on and control is not None)
        self._capsule_poses(state, control, relative, pass_on, margin)
        self._static_contacts(state, contacts, control, relative, margin)
        n_pairs = self._character_pairs()
        self._pair_contacts(state, contacts, relative, pass_on, margin, n_pairs)

    def _capsule_poses(self, state, control, relative: int, pass_on: int, margin: float) -> None:
        """World capsules, their midpoints and half lengths, and the character AABBs (grown
        by ``margin`` plus the speculative distance, m) of ``state``; with ``relative`` the
        same in the target pose, with ``pass_on`` in the look-ahead pose (``control``)."""
        from crowdstudy.physics import collision_kernels as k

        wp, m = get_warp(), self.model
        dev = m.device
        W = m.wp
        nj, n = m.n_joints, m.n_characters
        spec = self.speculative

        def capsules_now() -> None:  # the state's capsules and character AABBs
            wp.launch(
                k.capsules_world_kernel,
                n,
                [
                    state.x,
                    state.q,
                    W["cap_p0"],
                    W["cap_p1"],
                    W["cap_radius"],
                    W["cap_skin"],
                    nj,
                    margin + spec,
                    self.p0w,
                    self.p1w,
                    self.char_lo,
                    self.char_hi,
                    self.centre,
                    self.half,
                ],
                device=dev,
            )

        def capsules_target() -> None:  # ... in the target pose and in the look-ahead pose
            if relative:
                wp.launch(
                    k.capsules_world_kernel,
                    n,
                    [
                        control.t_x,
                        control.t_glob,
                        W["cap_p0"],
                        W["cap_p1"],
                        W["cap_radius"],
                        W["cap_skin"],
                        nj,
                        0.0,
                        self.p0t,
                        self.p1t,
                        self.t_lo,
                        self.t_hi,
                        self.centre_t,
                        self.half_t,
                    ],
                    device=dev,
                )
            if pass_on:
                lo, hi, centre, half = self._ahead_scratch
                wp.launch(
                    k.capsules_world_kernel,
                    n,
                    [
                        control.t_x_ahead,
                        control.t_glob_ahead,
                        W["cap_p0"],
                        W["cap_p1"],
                        W["cap_radius"],
                        W["cap_skin"],
                        nj,
                        0.0,
                        self.p0a,
                        self.p1a,
                        lo,
                        hi,
                        centre,
                        half,
                    ],
                    device=dev,
                )

        if (relative or pass_on) and dev == "cpu" and n >= _MIN_CHARACTERS_PARALLEL and host_threads() >= 2:
            run_parallel(capsules_now, capsules_target)  # disjoint outputs: the same bits either way
        else:
            capsules_now()
            capsules_target()

    def _static_contacts(self, state, contacts: Contacts, control, relative: int, margin: float) -> None:
        """The contacts with the ground, the point-sampled static objects and the walls
        (needs :meth:`_capsule_poses` first)."""
        from crowdstudy.physics import collision_kernels as k

        wp, m, cfg = get_warp(), self.model, self.config
        dev = m.device
        W = m.wp
        nj, nb = m.n_joints, m.n_bodies
        spec = self.speculative
        out = [contacts.count, contacts.capacity, *contacts.buffers()]
        band = float(cfg.contacts.activation)
        if cfg.contacts.ground_stiffness > 0:
            wp.launch(
                k.ground_kernel,
                nb,
                [
                    state.x,
                    self.p0w,
                    self.p1w,
                    W["cap_radius"],
                    relative,
                    self.p0t,
                    self.p1t,
                    band,
                    spec,
                    float(cfg.contacts.ground_stiffness),
                    *out,
                ],
                device=dev,
            )
        if self.bvh is not None and self.static_enabled and cfg.contacts.environment_stiffness > 0:
            wp.launch(
                k.environment_kernel,
                nb,
                [
                    state.x,
                    self.p0w,
                    self.p1w,
                    W["cap_radius"],
                    W["cap_skin"],
                    W["body_char"],
                    self.char_lo,
                    self.char_hi,
                    self.bvh.id,
                    self.points,
                    self.env_lo,
                    self.env_hi,
                    self.period,
                    margin,
                    spec,
                    float(cfg.contacts.environment_stiffness),
                    *out,
                ],
                device=dev,
            )
        if self.walls is not None and self.static_enabled and cfg.contacts.wall_stiffness > 0:
            side = control.t_x if control is not None else state.x  # whose root gives each wall's free side
            wp.launch(
                k.wall_kernel,
                nb,
                [
                    state.x,
                    self.p0w,
                    self.p1w,
                    W["cap_radius"],
                    W["cap_skin"],
                    W["body_char"],
                    nj,
                    side,
                    self.walls,
                    self.period,
                    margin,
                    spec,
                    float(cfg.contacts.wall_stiffness),
                    *out,
                ],
                device=dev,
            )

    def _character_pairs(self) -> int:
        """The broad phase: the overlapping character AABBs into ``pair_i``, ``pair_j``,
        ``pair_shift`` (needs :meth:`_capsule_poses` first); returns how many were kept (the
        surplus over ``pair_capacity`` is counted in ``dropped_pairs``)."""
        from crowdstudy.physics import collision_kernels as k

        wp, m, cfg = get_warp(), self.model, self.config
        dev, n = m.device, m.n_characters
        n_pairs = 0
        if n > 1 and cfg.contacts.stiffness > 0:
            if dev == "cpu" and self.period <= 0.0 and n >= _MIN_CHARACTERS_SWEEP:
                if self._sweep_scratch is None:
                    self._sweep_scratch = (
                        wp.zeros(n, dtype=wp.int32, device=dev),
                        wp.zeros(n, dtype=wp.float32, device=dev),
                    )
                launch_sweep(
                    self.char_lo,
                    self.char_hi,
                    *self._sweep_scratch,
                    self.pair_count,
                    self.pair_capacity,
                    self.pair_i,
                    self.pair_j,
                    self.pair_shift,
                )
            else:
                self.pair_count.zero_()
                wp.launch(
                    k.broadphase_kernel,
                    n,
                    [
                        self.char_lo,
                        self.char_hi,
                        self.period,
                        self.pair_count,
                        self.pair_capacity,
                        self.pair_i,
                        self.pair_j,
                        self.pair_shift,
                    ],
                    device=dev,
                )
            n_pairs = int(self.pair_count.numpy()[0])
            if n_pairs > self.pair_capacity:
                self.dropped_pairs += n_pairs - self.pair_capacity
                n_pairs = self.pair_capacity
        return n_pairs

    def _pair_contacts(
        self, state, contacts: Contacts, relative: int, pass_on: int, margin: float, n_pairs: int
    ) -> None:
        """The inter-body contacts of the first ``n_pairs`` character pairs (the narrow
        phase) and the intra-body contacts, appended to ``contacts``: on the CPU with two
        host threads, split over both (see below)."""
        from crowdstudy.physics import collision_kernels as k

        wp, m, cfg = get_warp(), self.model, self.config
        dev = m.device
        W = m.wp
        nj = m.n_joints
        spec = self.speculative
        band = float(cfg.contacts.activation)
        n_intra = W["intra_pairs"].shape[0]
        intra_on = bool(cfg.contacts.intra_body and n_intra and cfg.contacts.intra_stiffness > 0)

        def narrow(buf, lo: int, hi: int) -> None:  # the pairs [lo, hi) into buf
            if hi > lo:
                wp.launch(
                    k.narrowphase_kernel,
                    hi - lo,
                    [
                        state.x,
                        self.p0w,
                        self.p1w,
                        W["cap_radius"],
                        W["cap_skin"],
                        self.centre,
                        self.half,
                        self.char_lo,
                        self.char_hi,
                        self.pair_i,
                        self.pair_j,
                        self.pair_shift,
                        nj,
                        margin,
                        spec,
                        float(cfg.contacts.stiffness),
                        buf.count,
                        buf.capacity,
                        *buf.buffers(),
                        int(lo),
                        pass_on,
                        self.p0a,
                        self.p1a,
                        float(cfg.contacts.pass_width),
                    ],
                    device=dev,
                )

        def intra(buf) -> None:
            if intra_on:
                wp.launch(
                    k.intra_kernel,
                    n_intra,
                    [
                        state.x,
                        self.p0w,
                        self.p1w,
                        W["cap_radius"],
                        self.centre,
                        self.half,
                        W["intra_pairs"],
                        relative,
                        self.p0t,
                        self.p1t,
                        band,
                        spec,
                        float(cfg.contacts.intra_stiffness),
                        buf.count,
                        buf.capacity,
                        *buf.buffers(),
                    ],
                    device=dev,
                )

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
            for dst, src in zip(contacts.buffers(), scratch.buffers(), strict=True):
                wp.copy(dst, src, dest_offset=base, src_offset=0, count=n_copy)
        contacts.count.fill_(base + extra)

    def _balance(self, t0: float, t1: float, cut: int, total: int) -> None:
        """Move the split of the narrow phase towards equal CPU time on both host threads
        (``t0`` s for the character pairs [0, cut), ``t1`` s for [cut, total) plus the
        intra-body pairs)."""
        if cut <= 0 or total <= 0 or t0 <= 0.0:
            return
        per = t0 / cut  # s per character pair
        rest = max(t1 - per * (total - cut), 0.0)  # the intra pairs
        target = min(max((per * total + rest) / (2.0 * per * total), 0.05), 0.95)
        self._split = 0.5 * self._split + 0.5 * target

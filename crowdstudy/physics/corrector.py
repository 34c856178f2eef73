"""Online (frame by frame) and offline collision correction of crowd animations.

The animation runs at ``fps`` (30 in the study); the physics takes
``round(1 / (fps * dt))`` steps per frame (2 steps of 1/60 s), the target pose between two
frames interpolated (nlerp of joint rotations, lerp of the root). After every frame the
rigid state is projected back to joint rotations (``R_parent^T R_child``; root global) and
the pelvis position.
"""

from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.collision import CollisionPipeline, Contacts
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.physics.crowding import crowd_config
from crowdstudy.physics.model import ModelBuilder
from crowdstudy.physics.output_stage import finish_crowd
from crowdstudy.physics.solver import LinearSolver, Solver
from crowdstudy.physics.state import Control, State
from crowdstudy.scene_meta import loop_mode, static_walls_from_meta

if TYPE_CHECKING:  # for annotations only: Warp loads when a correction starts
    import warp as wp

    from crowdstudy.scene import CrowdAnimation

__all__ = ["CrowdCorrector", "correct", "load_bodies"]


def load_bodies(records) -> list:
    """Body models (rest joints + capsules) for character records (``crowdstudy.body``)."""
    from crowdstudy.body import load_body

    return [load_body(rec) for rec in records]


class CrowdCorrector:
    """Frame-by-frame collision correction (usable inside a game loop).

    Example::

        corr = CrowdCorrector(bodies, fps=30)
        corr.reset(rot0, root0)                       # (N, J, 3) rad, (N, 3) m
        for rot, root in frames:
            rot_c, root_c = corr.step(rot, root)      # corrected pose of this frame

    Args:
        bodies: N objects with ``rest_joints`` (J, 3) m and ``capsules`` (start, end, radius).
        config: :class:`PhysicsConfig` (defaults: the paper's). Fed frame by frame there is
            no crowd to measure yet, so the fields that follow the density profile
            (``skin.max``, ``skin.hand_scale``, ``output.hold`` left None) take its dense
            end (:meth:`PhysicsConfig.for_dense_crowd`; :attr:`config` is that resolved
            copy) unless the caller passes ``config.for_density(density)`` (the median of
            :func:`~crowdstudy.physics.crowding.local_density` over the expected crowd's
            positions).
        device: Warp device: "cpu", "cuda" or "cuda:N" (None or "auto": CUDA when
            present; :func:`~crowdstudy.warp_runtime.resolve_device`).
        fps: frame rate of the fed animation (Hz).
        periodic_length: period (m) along x for periodic scenes, else None.
        static_points: (P, 3) m, point samples of static objects (see
            :func:`~crowdstudy.physics.collision.sample_static_walls`).
        static_walls: (M, 2, 2) m, vertical walls on floor segments (one-sided plane
            contacts; :func:`~crowdstudy.scene_meta.static_walls_from_meta`).
        linear_solver: see :class:`~crowdstudy.physics.solver.Solver`.
        n_frames: frame slots kept on the device (offline use uploads a whole clip).
    """

    def __init__(
        self,
        bodies,
        *,
        config: PhysicsConfig | None = None,
        device: str | None = None,
        fps: float = 30.0,
        periodic_length: float | None = None,
        static_points=None,
        static_walls=None,
        linear_solver: LinearSolver | None = None,
        n_frames: int = 2,
        profile: bool = False,
    ):
        config = PhysicsConfig() if config is None else config
        if not isinstance(config, PhysicsConfig):
            raise InvalidInputError(f"config: expected a PhysicsConfig, got {type(config).__name__}")
        self.config = config.for_dense_crowd()
        if not fps or fps <= 0:
            raise InvalidInputError(f"fps: expected a positive frame rate, got {fps!r}")
        builder = ModelBuilder()
        for body in bodies:
            builder.add_character(body.rest_joints, body.capsules, self.config.mesh_skin(body))
        self.model = builder.finalize(density=self.config.body.density, device=device)
        self.fps = float(fps)
        self.substeps = max(1, int(round(1.0 / (self.fps * self.config.solver.dt))))
        self.dt = 1.0 / (self.fps * self.substeps)
        self.states = [State(self.model), State(self.model)]
        self.control = Control(self.model, n_frames=max(2, n_frames))
        self.control.ahead_frames = float(self.config.contacts.pass_ahead) * self.fps
        self.pipeline = CollisionPipeline(
            self.model, self.config, static_points=static_points, period=periodic_length, static_walls=static_walls
        )
        self.contacts = Contacts.allocate(self.pipeline.default_capacity(), self.model.device)
        self.solver = Solver(self.model, self.config, linear_solver=linear_solver, profile=profile)
        wp = self.solver.wp
        nb, n = self.model.n_bodies, self.model.n_characters
        self._out_rot = wp.zeros((1, nb), dtype=wp.vec3, device=self.model.device)
        self._out_root = wp.zeros((1, n), dtype=wp.vec3, device=self.model.device)
        self.steps = 0
        self.contact_counts: list[int] = []
        self.cg_iterations: list[int] = []
        self.timings = {"detection": 0.0, "assembly": 0.0, "solve": 0.0, "update": 0.0}
        self.profile = profile
        self._ready = False

    @property
    def state(self) -> State:
        return self.states[0]

    def _place(self) -> None:
        from crowdstudy.physics.kernels import set_state_kernel

        self.solver.wp.launch(
            set_state_kernel,
            self.model.n_bodies,
            [self.control.t_x, self.control.t_glob, self.state.x, self.state.q, self.state.v, self.state.w],
            device=self.model.device,
        )
        self.solver.reset_foot_anchors()

    def reset(self, joint_rotations: np.ndarray, root_translation: np.ndarray, *, settle: bool = False) -> None:
        """Place every body at the given pose, at rest: (N, J, 3) rad and (N, 3) m; with
        ``settle`` then simulate ``config.solver.settle_time`` on that pose (see :meth:`settle`)."""
        self.control.set_frames(joint_rotations, root_translation, start=0)
        self.control.set_frames(joint_rotations, root_translation, start=1)
        self.control.advance(0, 0, 0.0)
        self.control.hold()
        self._place()
        self._ready = True
        if settle:
            self.settle(frame=1)

    def reset_to_frame(self, frame: int) -> None:
        """Offline use: place the bodies at uploaded frame ``frame``."""
        self.control.advance(frame, frame, 0.0)
        self.control.hold()
        self._place()
        self._ready = True

    def settle(self, seconds: float | None = None, frame: int = 0) -> None:
        """Simulate ``seconds`` (default ``config.solver.settle_time``) with the target frozen at
        uploaded frame ``frame``: resolves the overlaps of the starting pose."""
        seconds = self.config.solver.settle_time if seconds is None else float(seconds)
        for _ in range(int(round(seconds / self.dt))):
            self.control.advance(frame, frame, 0.0)
            self.pipeline.collide(self.states[0], self.contacts, self.control)
            self.solver.step(self.states[0], self.states[1], self.control, self.contacts, self.dt)
            self.states.reverse()

    def _advance_between(self, f0: int, f1: int) -> None:
        wp = self.solver.wp
        for s in range(1, self.substeps + 1):
            self.control.advance(f0, f1, s / self.substeps)
            t0 = time.perf_counter()
            self.pipeline.collide(self.states[0], self.contacts, self.control)
            if self.profile:
                wp.synchronize_device(self.model.device)
                self.timings["detection"] += time.perf_counter() - t0
            self.solver.step(self.states[0], self.states[1], self.control, self.contacts, self.dt)
            self.states.reverse()
            self.steps += 1
            self.contact_counts.append(int(self.contacts.count.numpy()[0]))
            self.cg_iterations.append(self.solver.last_cg[0])
        if self.profile:
            for key in ("assembly", "solve", "update"):
                self.timings[key] = self.solver.timings[key]

    def project(self, out_rot, out_root, frame: int) -> None:
        """Write the current pose into row ``frame`` of (F, B) vec3 / (F, N) vec3 device arrays."""
        from crowdstudy.physics.kernels import project_kernel

        m = self.model
        self.solver.wp.launch(
            project_kernel,
            m.n_bodies,
            [
                self.state.x,
                self.state.q,
                m.wp["body_parent"],
                m.wp["anchor_child"],
                m.n_joints,
                int(frame),
                out_rot,
                out_root,
            ],
            device=m.device,
        )

    def step(self, joint_rotations: np.ndarray, root_translation: np.ndarray):
        """Feed the next target frame; returns the corrected pose of that frame:
        ``(joint_rotations (N, J, 3) rad, root_translation (N, 3) m)``."""
        if not self._ready:
            raise InvalidInputError("CrowdCorrector.step: call reset(joint_rotations, root_translation) first")
        self.control.anim_q[0:1].assign(self.control.anim_q[1:2])
        self.control.anim_root[0:1].assign(self.control.anim_root[1:2])
        self.control.set_frames(joint_rotations, root_translation, start=1)
        self._advance_between(0, 1)
        self.project(self._out_rot, self._out_root, 0)
        m = self.model
        rot = self._out_rot.numpy().reshape(m.n_characters, m.n_joints, 3).astype(np.float64)
        root = self._out_root.numpy().reshape(m.n_characters, 3).astype(np.float64)
        return rot, root


@dataclasses.dataclass
class _Run:
    """One offline correction being set up and run (:func:`correct`)."""

    anim: CrowdAnimation  # the input
    config: PhysicsConfig  # resolved for the crowd
    density: float  # the crowd's measured density, characters per m^2
    weight: float | None  # its profile weight
    bodies: list
    corr: CrowdCorrector
    looped: bool  # corrected as a loop
    warmup: int  # frames simulated before the clip (a loop's end)
    blend: int  # frames simulated past it, cross-faded into its start


def _loop_schedule(anim, config: PhysicsConfig) -> tuple[np.ndarray, bool, int, int]:
    """The input frames to simulate in order, and ``(looped, warmup, blend)``: a periodic
    clip is simulated from ``warmup`` frames before its start (the end of the loop), through
    the period, and ``blend`` frames on, to close the loop (:func:`~crowdstudy.physics.finish.close_loop`)."""
    n_out = anim.n_frames
    looped = loop_mode(anim.meta) == "periodic" and n_out > 2
    warmup = blend = 0
    if looped:
        warmup = min(int(round(config.output.loop_warmup * anim.fps)), n_out)
        blend = min(int(round(config.output.loop_blend * anim.fps)), n_out - 1)
    schedule = np.concatenate([np.arange(n_out - warmup, n_out), np.arange(n_out), np.arange(blend)])
    return schedule, looped, warmup, blend


def _set_up(anim, config: PhysicsConfig | None, bodies, device: str | None, linear_solver: LinearSolver | None) -> _Run:
    """Check the input, resolve the configuration for its crowd, build the corrector and
    upload the frames to simulate."""
    from crowdstudy.body.skeleton import PARENTS
    from crowdstudy.scene import CrowdAnimation

    if not isinstance(anim, CrowdAnimation):
        raise InvalidInputError(f"anim: expected a CrowdAnimation, got {type(anim).__name__}")
    if anim.n_joints != len(PARENTS) or not np.array_equal(anim.parents, PARENTS):
        raise InvalidInputError(f"anim.parents: the physics expects the {len(PARENTS)}-joint skeleton")
    config, density, weight = crowd_config(anim, config)
    bodies = load_bodies(anim.bodies) if bodies is None else list(bodies)
    if len(bodies) != anim.n_characters:
        raise InvalidInputError(f"bodies: expected {anim.n_characters} body models, got {len(bodies)}")
    schedule, looped, warmup, blend = _loop_schedule(anim, config)
    corr = CrowdCorrector(
        bodies,
        config=config,
        device=device,
        fps=anim.fps,
        periodic_length=anim.periodic_length,
        static_walls=static_walls_from_meta(anim.meta),
        linear_solver=linear_solver,
        n_frames=len(schedule),
        profile=False,
    )
    corr.control.set_frames(anim.joint_rotations, anim.root_translation, start=0, frames=schedule)
    return _Run(anim, config, density, weight, bodies, corr, looped, warmup, blend)


@dataclasses.dataclass
class _Clock:
    """The clock readings of a correction: ``start`` and ``settled`` (perf_counter s) and
    ``frame_seconds`` (s, one per frame step)."""

    start: float
    settled: float = 0.0
    frame_seconds: list[float] = dataclasses.field(default_factory=list)


def _simulate(run: _Run, progress: bool) -> tuple[wp.array, wp.array, _Clock]:
    """Settle on the first frame, then step through the schedule, projecting every frame:
    ``(rotations (F, B) vec3, roots (F, N) vec3 device arrays, clock)``."""
    corr = run.corr
    wp, m = corr.solver.wp, corr.model
    t_frames = run.warmup + run.anim.n_frames + run.blend
    out_rot = wp.zeros((t_frames, m.n_bodies), dtype=wp.vec3, device=m.device)
    out_root = wp.zeros((t_frames, m.n_characters), dtype=wp.vec3, device=m.device)
    clock = _Clock(start=time.perf_counter())
    corr.reset_to_frame(0)
    corr.settle(frame=0)
    wp.synchronize_device(m.device)
    clock.settled = time.perf_counter()
    frame_seconds = clock.frame_seconds
    corr.project(out_rot, out_root, 0)
    bar = None
    if progress:
        from crowdstudy.progress import progress_bar

        bar = progress_bar(total=t_frames - 1, desc="correct", unit="frame", leave=False)
    for f in range(1, t_frames):
        t0 = time.perf_counter()
        corr._advance_between(f - 1, f)
        wp.synchronize_device(m.device)
        frame_seconds.append(time.perf_counter() - t0)
        corr.project(out_rot, out_root, f)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return out_rot, out_root, clock


def _fill_timings(timings: dict, run: _Run, clock: _Clock, t_setup: float, t_output: float, t_end: float) -> None:
    """``timings`` (see :func:`correct`) from the clock readings."""
    corr = run.corr
    frame_seconds = clock.frame_seconds
    timed = frame_seconds if round(run.config.solver.settle_time / corr.dt) > 0 else frame_seconds[1:]
    timed_steps = len(timed) * corr.substeps
    timings.update(
        {
            "setup_seconds": clock.start - t_setup,
            "settle_seconds": clock.settled - clock.start,
            "simulate_seconds": float(sum(frame_seconds)),
            "output_seconds": t_end - t_output,
            "wall_seconds": t_end - clock.start,
            "steps": corr.steps,
            "timed_steps": timed_steps,
            "ms_per_step": 1000.0 * sum(timed) / timed_steps if timed_steps else None,
            "ms_per_step_median": 1000.0 * float(np.median(timed)) / corr.substeps if timed else None,
        }
    )


def _physics_meta(run: _Run, speed_report) -> dict:
    """``meta["physics"]`` (:class:`~crowdstudy.scene_meta.PhysicsMeta`): deterministic
    values only."""
    corr = run.corr
    iters = np.asarray(corr.cg_iterations) if corr.cg_iterations else np.zeros(1)
    counts = corr.contact_counts
    return {
        "config": run.config.as_dict(),
        "crowd_density": run.density,
        "profile_weight": run.weight,
        "device": corr.model.device,
        "linear_solver": corr.solver.linear_solver,
        "steps": corr.steps,
        "substeps_per_frame": corr.substeps,
        "dt": corr.dt,
        "cg_iterations_mean": float(iters.mean()),
        "cg_iterations_max": int(iters.max()),
        "static_walls": corr.pipeline.n_static_walls,
        "contacts_mean": float(np.mean(counts)) if counts else 0.0,
        "contacts_max": int(max(counts, default=0)),
        "contacts_dropped_steps": int(sum(c > corr.contacts.capacity for c in counts)),
        "pairs_dropped": int(corr.pipeline.dropped_pairs),
        "loop": {"periodic": bool(run.looped), "warmup_frames": run.warmup, "blend_frames": run.blend},
        "speed_limit": speed_report.as_dict() if speed_report is not None else None,
    }


def correct(
    anim,
    config: PhysicsConfig | None = None,
    *,
    device: str | None = None,
    progress: bool = True,
    bodies=None,
    linear_solver: LinearSolver | None = None,
    timings: dict | None = None,
):
    """Resolve the collisions of a whole animation (Baseline -> Ours).

    Args:
        anim: :class:`~crowdstudy.scene.CrowdAnimation` (T frames, N characters).
        config: :class:`PhysicsConfig` (None: the defaults).
        device: Warp device, "cpu", "cuda" or "cuda:N" (None: CUDA when present, else CPU).
        progress: tqdm bar on stderr.
        bodies: N body models (default: ``crowdstudy.body.load_body`` of ``anim.bodies``).
        linear_solver: see :class:`~crowdstudy.physics.solver.Solver`.
        timings: a dict to fill with this run's timings (they are never written into the
            animation, so the same input gives the same bytes): ``setup_seconds`` (model
            build and upload), ``settle_seconds`` (placement and the settle steps),
            ``simulate_seconds`` (the clip's simulation steps), ``output_seconds`` (the
            output stage, :func:`~crowdstudy.physics.output_stage.finish_crowd`),
            ``wall_seconds`` (settle, clip, projection, readback and output stage), ``steps``,
            ``timed_steps`` and ``ms_per_step``
            (``simulate_seconds`` over the timed steps: the clip's steps only, not the settle
            steps, the projection or the readback; when there is no settle step, the first
            frame, which launches (and may compile) the kernels, is left out; None when no
            step was timed) and ``ms_per_step_median`` (the median over the timed frames of
            a frame's seconds per step: less swayed by other work on a busy machine).

    The crowd's density is measured first
    (:func:`~crowdstudy.physics.crowding.crowd_density`) and the crowd corrected with
    ``config.for_density(density)``: the fields that follow the density profile (by default
    the skins and the output's hold) take their values at that density
    (:func:`~crowdstudy.physics.crowding.crowd_config`).

    The simulated poses go through the output stage (:mod:`crowdstudy.physics.output_stage`,
    a few characters at a time on both host threads; :mod:`crowdstudy.physics.finish`): a
    periodic input (``meta["loop"]["mode"] == "periodic"``) is simulated from
    ``config.output.loop_warmup`` before its start to ``config.output.loop_blend`` past its
    end and the loop closed; the deviation from the input is low-passed (held at its peaks
    first); planted feet are held; where a joint is left faster than the input crowd's
    fastest (plus ``config.output.speed_limit_margin``) the correction there is re-timed
    (:mod:`crowdstudy.physics.speed_limit`; its report in ``meta["physics"]["speed_limit"]``).

    Returns:
        A new CrowdAnimation with the same bodies/clips, the corrected ``root_translation``
        (T, N, 3) m and ``joint_rotations`` (T, N, J, 3) rad, and meta ``method = "Ours"``,
        ``physics`` (:class:`~crowdstudy.scene_meta.PhysicsMeta`: the configuration used,
        the crowd's measured density and its profile weight, device, linear solver, steps,
        substeps, dt, CG iterations, contact counts, dropped pairs, static walls;
        deterministic values only), ``baseline_method`` and ``baseline_provenance``.
    """
    if timings is not None and not isinstance(timings, dict):
        raise InvalidInputError(f"timings: expected a dict to fill (or None), got {type(timings).__name__}")
    t_setup = time.perf_counter()
    from crowdstudy.provenance import provenance

    run = _set_up(anim, config, bodies, device, linear_solver)
    out_rot, out_root, clock = _simulate(run, progress)
    t_output = time.perf_counter()
    m = run.corr.model
    rest = np.stack([np.asarray(b.rest_joints, np.float64) for b in run.bodies])
    rot, root, speed_report = finish_crowd(
        out_rot.numpy().reshape(-1, m.n_characters, m.n_joints, 3),
        out_root.numpy(),
        anim.joint_rotations,
        anim.root_translation,
        rest,
        anim.fps,
        run.config,
        warmup=run.warmup,
        blend=run.blend,
        looped=run.looped,
        periodic_length=anim.periodic_length,
        progress=progress,
    )
    if timings is not None:
        _fill_timings(timings, run, clock, t_setup, t_output, time.perf_counter())
    meta = {
        "method": "Ours",
        "physics": _physics_meta(run, speed_report),
        "baseline_method": anim.meta.get("method"),
        "baseline_provenance": anim.meta.get("provenance"),
        "provenance": provenance(anim.meta.get("seed"), stage="physics"),
    }
    return anim.replace(root_translation=root, joint_rotations=rot, meta=meta)

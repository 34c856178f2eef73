"""The paper's live case (Fig. 6): the crowd corrected one frame at a time, as a game loop
would, and timed against the frame budget.

:func:`run_live` feeds an animation (e.g. :func:`crowdstudy.motion.walker.live_scene`: a
motion-captured walker pushed through the dancing D5 concert) to a
:class:`~crowdstudy.physics.corrector.CrowdCorrector` one frame at a time: at frame f only
frame f's target pose is known (no look-ahead), and the corrected pose of frame f comes
back before frame f + 1 is fed. It times every frame (wall clock and this process' CPU
time) against the frame budget ``1 / fps``.

What a live loop gives up against the offline :func:`~crowdstudy.physics.corrector.correct`:
the output stage (:mod:`crowdstudy.physics.output_stage`: low-pass of the deviation, held
feet, speed limit, loop closing) needs the whole clip, so the live poses are the raw
projected rigid state; the crowd's density is not measured, so the fields that follow the
density profile take its dense end (:meth:`~crowdstudy.physics.config.PhysicsConfig.for_dense_crowd`).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.config import PhysicsConfig

__all__ = ["LiveRun", "run_live", "frame_stats"]


@dataclasses.dataclass(frozen=True)
class LiveRun:
    """A frame-by-frame correction (:func:`run_live`).

    Attributes:
        ours: the corrected :class:`~crowdstudy.scene.CrowdAnimation` (meta ``method``
            "Ours", ``live`` with the configuration and substeps used).
        wall_seconds: (T - 1,) wall-clock seconds of each ``CrowdCorrector.step`` (feed the
            frame, simulate its substeps, project, read back).
        cpu_seconds: (T - 1,) this process' CPU seconds of the same calls (less sensitive to
            other work on a shared machine; Warp's CPU kernels run on the calling thread).
        setup_seconds: model build and settle on the first frame (before the loop).
        substeps: physics steps per frame.
        profile: with ``run_live(profile=True)``: mean ms per frame of each phase
            (``detection``, ``assembly``, ``solve``, ``update``: each synchronised, which
            adds a little; ``readback``: projection and the copy to the host), else empty.
    """

    ours: object
    wall_seconds: np.ndarray
    cpu_seconds: np.ndarray
    setup_seconds: float
    substeps: int
    profile: dict = dataclasses.field(default_factory=dict)


def run_live(
    anim,
    config: PhysicsConfig | None = None,
    *,
    device: str | None = "cpu",
    settle: bool = True,
    profile: bool = False,
) -> LiveRun:
    """Correct ``anim`` as a game loop would: ``reset`` on its first frame (settled when
    ``settle``), then one ``step`` per frame, timed. ``config`` is used as given, the
    density-profile fields at the dense end (:class:`~crowdstudy.physics.corrector.CrowdCorrector`);
    ``profile`` times the phases of every step (:attr:`LiveRun.profile`)."""
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies
    from crowdstudy.provenance import provenance
    from crowdstudy.scene import CrowdAnimation
    from crowdstudy.scene_meta import static_walls_from_meta

    if not isinstance(anim, CrowdAnimation):
        raise InvalidInputError(f"anim: expected a CrowdAnimation, got {type(anim).__name__}")
    t0 = time.perf_counter()
    corr = CrowdCorrector(
        load_bodies(anim.bodies),
        config=config,
        device=device,
        fps=anim.fps,
        periodic_length=anim.periodic_length,
        static_walls=static_walls_from_meta(anim.meta),
        profile=profile,
    )
    corr.reset(anim.joint_rotations[0], anim.root_translation[0], settle=settle)
    rot = np.empty(anim.joint_rotations.shape)
    root = np.empty(anim.root_translation.shape)
    # frame 0 fed again (one more frame held on the first pose): its poses are the output's
    # first frame, and the kernels are loaded before the timed loop
    rot[0], root[0] = corr.step(anim.joint_rotations[0], anim.root_translation[0])
    setup = time.perf_counter() - t0
    before = dict(corr.timings)
    wall = np.empty(anim.n_frames - 1)
    cpu = np.empty(anim.n_frames - 1)
    for f in range(1, anim.n_frames):
        w0, c0 = time.perf_counter(), time.process_time()
        rot[f], root[f] = corr.step(anim.joint_rotations[f], anim.root_translation[f])
        wall[f - 1], cpu[f - 1] = time.perf_counter() - w0, time.process_time() - c0
    phases = {}
    if profile:
        frames = anim.n_frames - 1
        phases = {k: 1000.0 * (corr.timings[k] - before[k]) / frames for k in before}
        phases["readback"] = 1000.0 * float(wall.sum()) / frames - sum(phases.values())
    live = {
        "config": corr.config.as_dict(),
        "substeps_per_frame": corr.substeps,
        "dt": corr.dt,
        "settle": bool(settle),
        "device": corr.model.device,
    }
    ours = anim.replace(
        root_translation=root,
        joint_rotations=rot,
        meta={
            "method": "Ours",
            "live": live,
            "baseline_method": anim.meta.get("method"),
            "baseline_provenance": anim.meta.get("provenance"),
            "provenance": provenance(anim.meta.get("seed"), stage="physics"),
        },
    )
    return LiveRun(ours, wall, cpu, setup, corr.substeps, phases)


def frame_stats(seconds: np.ndarray, fps: float) -> dict[str, float]:
    """Median, p95 and max of per-frame seconds, in ms, and the share of frames over the
    budget ``1000 / fps`` ms."""
    ms = 1000.0 * np.asarray(seconds, dtype=np.float64)
    budget = 1000.0 / fps
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "max_ms": float(ms.max()),
        "budget_ms": budget,
        "over_budget": float(np.mean(ms > budget)),
    }

"""The live walker measured: what the frame-by-frame correction costs per frame against the
frame budget, and what it does to the walker and the crowd.

``crowdstudy bench live`` runs :func:`time_live` several times per variant and
:func:`live_quality` on one run of each; ``paper_figs/fig6_live.py`` draws the scene
(:func:`crowdstudy.motion.walker.live_scene`, :func:`crowdstudy.physics.live.run_live`).
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["LIVE_VARIANTS", "live_config", "time_live", "live_quality", "offline_peer"]

#: The configurations a live loop may run: ``paper`` the paper's step (two 1/60 s steps per
#: 30 fps frame, everything else the defaults); ``one-step`` one 1/30 s step per frame (half
#: the work; the PD and contact terms then act over the longer step).
LIVE_VARIANTS: Mapping[str, dict[str, float]] = {"paper": {}, "one-step": {"solver.dt": 1.0 / 30.0}}


def live_config(variant: str):
    """The :class:`~crowdstudy.physics.config.PhysicsConfig` of a :data:`LIVE_VARIANTS` name."""
    from crowdstudy.physics.config import PhysicsConfig

    if variant not in LIVE_VARIANTS:
        raise InvalidInputError(f"variant: expected one of {', '.join(LIVE_VARIANTS)}, got {variant!r}")
    return PhysicsConfig().with_values(dict(LIVE_VARIANTS[variant]))


def time_live(base, variant: str, repeat: int, *, profile: bool = True) -> dict:
    """``repeat`` live runs of ``base`` (plus one profiled run when ``profile``): per run
    the median, p95 and max ms per frame (wall and CPU, :func:`~crowdstudy.physics.live.frame_stats`),
    and their medians over the runs; ``last`` is the last run's :class:`~crowdstudy.physics.live.LiveRun`."""
    from crowdstudy.physics.live import frame_stats, run_live

    if repeat < 1:
        raise InvalidInputError(f"repeat: expected at least one run, got {repeat!r}")
    config = live_config(variant)
    last = run_live(base, config)
    runs = []
    for i in range(repeat):
        if i:
            last = run_live(base, config)
        runs.append(
            {
                "wall": frame_stats(last.wall_seconds, base.fps),
                "cpu": frame_stats(last.cpu_seconds, base.fps),
                "setup_s": last.setup_seconds,
            }
        )
    out = {"variant": variant, "substeps": last.substeps, "runs": runs, "last": last}
    for clock in ("wall", "cpu"):
        for key in ("median_ms", "p95_ms", "max_ms"):
            out[f"{clock}_{key}"] = float(np.median([r[clock][key] for r in runs]))
    if profile:
        out["phases_ms"] = run_live(base, config, profile=True).profile
    return out


def _walker_overlap(anim, walker: int, frames: np.ndarray, resolution: float) -> dict[str, float]:
    """Mesh overlap (litres) of the walker and of the crowd's other characters."""
    from crowdstudy.metrics.overlap import overlap_volume

    res = overlap_volume(anim, resolution=resolution, geometry="mesh", frames=frames)
    per = res.per_character
    crowd = np.delete(per, walker, axis=1)
    return {
        "walker_overlap_l": 1000.0 * float(per[:, walker].mean()),
        "walker_overlap_max_l": 1000.0 * float(per[:, walker].max()),
        "crowd_overlap_l": 1000.0 * float(crowd.mean()),
    }


def live_quality(base, ours, *, frame_step: int = 4, resolution: float = 0.02) -> dict:
    """The walker and the crowd in ``base`` (Baseline) and ``ours`` (the live output):
    mesh overlap (litres per character, every ``frame_step``-th frame, columns of
    ``resolution`` m) before and after, and the tracking error (cm) of the walker and of
    the dancers (:func:`~crowdstudy.metrics.tracking.tracking_parts`)."""
    from crowdstudy.metrics.tracking import tracking_parts
    from crowdstudy.motion.walker import walker_index

    walker = walker_index(base)
    frames = np.arange(0, base.n_frames, max(1, int(frame_step)))
    before = _walker_overlap(base, walker, frames, resolution)
    after = _walker_overlap(ours, walker, frames, resolution)
    parts = tracking_parts(ours, base)
    per = parts.per_character_cm
    return {
        **{f"baseline_{k}": v for k, v in before.items()},
        **{f"ours_{k}": v for k, v in after.items()},
        "walker_tracking_cm": float(per[walker]),
        "crowd_tracking_cm": float(np.delete(per, walker).mean()),
        "frames_measured": int(len(frames)),
    }


def offline_peer(base) -> dict:
    """``correct()`` on the same scene in the same process: its ms per frame (simulation
    steps only, the peer of the live loop's frames) and the output stage's ms per frame."""
    from crowdstudy.physics.corrector import correct

    timings: dict = {}
    t0 = time.perf_counter()
    ours = correct(base, device="cpu", progress=False, timings=timings)
    wall = time.perf_counter() - t0
    substeps = int(ours.meta["physics"]["substeps_per_frame"])
    return {
        "ours": ours,
        "sim_ms_per_frame": timings["ms_per_step"] * substeps,
        "output_ms_per_frame": 1000.0 * timings["output_seconds"] / base.n_frames,
        "wall_s": wall,
    }

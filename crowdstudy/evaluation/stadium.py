"""Stadium crowds: the correction at thousands of characters.

A stadium crowd is the concert scene at one density level's characters per square metre on
a floor large enough for ``n`` characters (:func:`stadium_crowd`). :func:`stadium_run`
corrects one and measures what it cost (time, peak memory) and whether it held (finite,
stable, the bars of :class:`~crowdstudy.metrics.BarTolerances`); ``crowdstudy bench physics
--stadium 1000,5000`` prints its rows.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from crowdstudy.evaluation.acceptance import profile_columns
from crowdstudy.metrics.bars import BarTolerances, check_bars, failed_bars, loop_mode, smoothness_columns
from crowdstudy.physics.step_timing import rss_mib

__all__ = ["stadium_crowd", "BodyProxy", "central_subset", "select_characters", "stadium_run"]


def stadium_crowd(n: int, level: str, duration: float, seed: int = 1):
    """The Baseline of a stadium concert: ``n`` characters at ``level``'s density
    (:func:`~crowdstudy.layout.concert_layout` with ``n_characters``), ``duration`` s,
    animated as ``crowdstudy animate layout.npz`` does."""
    from crowdstudy.design import load_design
    from crowdstudy.layout import concert_layout
    from crowdstudy.motion.baseline import animate_stationary

    design = load_design()
    crowd = concert_layout(design, level, seed, n_characters=n)
    meta = {k: crowd.meta[k] for k in ("density_level", "density", "n_characters")}
    return animate_stationary(
        crowd, duration=duration, fps=design.fps, seed=seed, meta={**meta, "seed": seed, "stage": "stationary"}
    )


class BodyProxy:
    """What the physics and the joint metrics read of a body: rest joints, capsules, and (for
    the capsules' mesh skin, ``capsule_skin``) the rest vertices with a one-hot of each
    vertex's dominant bone instead of the float skinning weights and the faces. The same
    skin as the full body; about 0.7 MB instead of several MB per MakeHuman character."""

    def __init__(self, body):
        self.rest_joints = np.asarray(body.rest_joints, np.float64)
        self.capsules = body.capsules
        self.rest_vertices = np.asarray(body.rest_vertices, np.float64)
        weights = np.asarray(body.weights)
        dominant = weights.argmax(1)
        self.weights = np.zeros(weights.shape, np.uint8)
        self.weights[np.arange(len(dominant)), dominant] = 1


def central_subset(anim, k: int) -> np.ndarray:
    """The indices of the ``k`` characters nearest the floor's centre (frame 0), in index order."""
    d = np.linalg.norm(anim.root_translation[0, :, :2], axis=1)
    return np.sort(np.argsort(d, kind="stable")[:k])


def select_characters(anim, idx):
    """The animation of the characters ``idx`` only (their bodies and clips with them)."""
    return anim.replace(
        root_translation=anim.root_translation[:, idx],
        joint_rotations=anim.joint_rotations[:, idx],
        bodies=tuple(anim.bodies[i] for i in idx),
        clips=tuple(anim.clips[i] for i in idx),
    )


def stadium_run(
    n: int,
    level: str = "D3",
    duration: float = 20.0,
    frame_stride: int = 10,
    overlap_characters: int = 300,
    light_bodies: bool = False,
    config=None,
    tolerances: BarTolerances | None = None,
    report: Callable[[dict], None] | None = None,
) -> dict:
    """``correct()`` on a stadium crowd (:func:`stadium_crowd`): wall time, ms per step, peak
    memory, NaN/stability, and the bars (:func:`~crowdstudy.metrics.check_bars`; ``tolerances``,
    None: the defaults) of Ours against its Baseline; ``report`` is called with the row.

    The mesh overlap is measured on every ``frame_stride``-th frame and on the
    ``overlap_characters`` characters nearest the floor's centre (the overlap among them;
    the full crowd's mesh overlap costs minutes per frame at 5,000); the smoothness and
    tracking on every character and frame. The overlap is also given neighbourhood by
    neighbourhood (:func:`~crowdstudy.metrics.tile_ratios` on study-cell-sized tiles:
    ``tiles``, ``mesh_ratio_tile_min/median/max``, ``tiles_over_overlap_bar``), the spread a
    study cell of the same density shows from crowd to crowd. ``light_bodies`` hands
    ``correct()`` and the joint metrics :class:`BodyProxy` objects (at 5,000 MakeHuman
    characters the full body models alone would not fit in 24 GiB: ``correct()`` keeps every
    body for the run)."""
    from crowdstudy.body import load_body
    from crowdstudy.design import load_design
    from crowdstudy.metrics import overlap_volume, tile_ratios, tracking_error
    from crowdstudy.physics.corrector import correct

    tolerances = BarTolerances() if tolerances is None else tolerances
    design = load_design()
    levels = list(design.densities)
    rss0 = rss_mib()
    t0 = time.perf_counter()
    base = stadium_crowd(n, level, duration)
    t_anim = time.perf_counter() - t0
    rss_base = rss_mib()
    timings: dict = {}
    c0 = time.process_time()
    t0 = time.perf_counter()
    bodies = [BodyProxy(load_body(rec)) for rec in base.bodies] if light_bodies else None
    ours = correct(base, config, progress=False, device="cpu", timings=timings, bodies=bodies)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    peak = rss_mib("VmHWM")
    finite = bool(np.all(np.isfinite(ours.root_translation)) and np.all(np.isfinite(ours.joint_rotations)))
    # stable: no body ran away from its animation (the largest root deviation, m)
    max_dev = float(np.max(np.linalg.norm(ours.root_translation - base.root_translation, axis=-1)))
    row = {
        "stage": "stationary",
        "level": level,
        "characters": n,
        "frames": base.n_frames,
        "seconds": duration,
        "animate_s": t_anim,
        "correct_wall_s": wall,
        "correct_cpu_s": cpu,
        "setup_s": timings.get("setup_seconds"),
        "simulate_s": timings.get("simulate_seconds"),
        "output_s": timings.get("output_seconds"),
        "ms_per_step_wall": timings.get("ms_per_step"),
        "steps": timings.get("steps"),
        "finite": finite,
        "max_root_deviation_m": max_dev,
        "baseline_rss_mib": rss_base - rss0,
        "peak_rss_mib": peak,
        "peak_kib_per_character": 1024.0 * (peak - rss0) / n,
        "bodies": "proxies (rest joints, capsules, vertices)" if light_bodies else "full body models",
        "loop": loop_mode(base),
        **profile_columns(ours),
    }
    sub = central_subset(base, min(overlap_characters, n))
    frames = np.arange(0, base.n_frames, frame_stride)
    per_character: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # (Baseline, Ours) per character
    for geom in ("mesh", "capsule"):
        rb = overlap_volume(select_characters(base, sub), geometry=geom, frames=frames)
        ro = overlap_volume(select_characters(ours, sub), geometry=geom, frames=frames)
        ob, oo = rb.mean, ro.mean
        row[f"{geom}_baseline_m3"], row[f"{geom}_ours_m3"], row[f"{geom}_ratio"] = ob, oo, oo / max(ob, 1e-12)
        per_character[geom] = (rb.per_character.mean(axis=0), ro.per_character.mean(axis=0))
    row["overlap_subset"] = f"{len(sub)} central characters, every {frame_stride}th frame"
    # the same overlap neighbourhood by neighbourhood: study-cell-sized tiles of the floor
    tile = (float(design.floor_width), float(design.floor_depth))
    ratios = tile_ratios(
        base.root_translation[0, sub, :2],
        *per_character["mesh"],
        tile,
        min_characters=max(1, design.n_characters(level) // 2),
    )
    row["tile_m"] = f"{tile[0]:g} x {tile[1]:g}"
    row["tiles"] = len(ratios)
    if len(ratios):
        row["mesh_ratio_tile_min"], row["mesh_ratio_tile_median"], row["mesh_ratio_tile_max"] = (
            float(ratios.min()),
            float(np.median(ratios)),
            float(ratios.max()),
        )
        row["tiles_over_overlap_bar"] = f"{int(np.sum(ratios > tolerances.overlap_ratio))}/{len(ratios)}"
    row["tracking_cm"] = tracking_error(ours, base, bodies=bodies)
    row.update(smoothness_columns(base, ours, bodies))
    row["bars_failed"] = failed_bars(check_bars(row, tolerances, levels.index(level), len(levels)))
    if report is not None:
        report(row)
    return row

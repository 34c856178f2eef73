"""The acceptance bars measured on the study's cells: each cell's Baseline corrected, and
Ours measured against it (overlap, tracking, smoothness, skin through the walls) with the
bars of :class:`~crowdstudy.metrics.BarTolerances` checked.

``crowdstudy bench physics --bars`` runs :func:`measure_bars` on every cell (or some, on
other seeds of them) and prints the rows; the stadium crowds are
:mod:`crowdstudy.evaluation.stadium`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from crowdstudy.body.shapes import BodyShapes
from crowdstudy.metrics.bars import BarTolerances, check_bars, failed_bars, loop_mode, smoothness_columns

__all__ = ["measure_bars", "measure_cell", "profile_columns"]


def profile_columns(ours) -> dict:
    """How crowded ``correct()`` found the crowd and the skins and hold it used
    (``PhysicsConfig.for_density``): ``crowd_density`` (characters/m^2), ``profile_weight``,
    ``mesh_skin_max`` (m), ``output_hold``."""
    phys = ours.meta["physics"]
    return {
        "crowd_density": phys["crowd_density"],
        "profile_weight": phys["profile_weight"],
        "mesh_skin_max": phys["config"]["skin"]["max"],
        "output_hold": phys["config"]["output"]["hold"],
    }


def measure_bars(
    duration: float,
    frame_stride: int = 10,
    config=None,
    cells: Sequence[tuple[str, str]] | None = None,
    seeds: Sequence[int | None] = (None,),
    tolerances: BarTolerances | None = None,
    report: Callable[[dict], None] | None = None,
    body_shapes: BodyShapes = "study",
) -> list[dict]:
    """Every (stage, density) cell of the study, ``duration`` seconds each: one row per cell
    and seed (:func:`measure_cell`), cells in the design's order (stationary, then walking;
    levels sparsest first), each cell's seeds in the given order.

    ``config``: the :class:`~crowdstudy.physics.config.PhysicsConfig` of Ours (None: the
    defaults); ``cells``: (stage, level) pairs to measure (None: all ten); ``seeds``: the
    cells' seeds, each one a crowd of its own (layout, bodies, clips; None: the design's
    seed of the cell, the study's stimulus); ``tolerances``: the bars (None: the defaults);
    ``report`` is called with each row as it is measured; ``body_shapes`` the bodies' draw
    (:data:`~crowdstudy.body.shapes.BodyShapes`; the paper's design: ``"study"``)."""
    import dataclasses

    from crowdstudy.design import load_design

    design = dataclasses.replace(load_design(), body_shapes=body_shapes)
    levels = list(design.densities)
    rows = []
    for stage in ("stationary", "walking"):
        for li, level in enumerate(levels):
            if cells is not None and (stage, level) not in cells:
                continue
            for seed in seeds:
                rows.append(measure_cell(design, stage, li, level, seed, duration, frame_stride, config, tolerances))
                if report is not None:
                    report(rows[-1])
    return rows


def measure_cell(
    design,
    stage: str,
    li: int,
    level: str,
    seed: int | None,
    duration: float,
    frame_stride: int,
    config,
    tolerances: BarTolerances | None = None,
) -> dict:
    """One crowd of one cell (``level``, the ``li``-th of the design's levels), corrected and
    measured: overlap (mesh and capsule, m^3 per character, every ``frame_stride``-th frame,
    and Ours / Baseline as ``mesh_ratio``/``capsule_ratio``), tracking error (cm; with its
    placement and motion parts, :func:`crowdstudy.metrics.tracking_parts`), the smoothness
    of Ours against its Baseline (:func:`~crowdstudy.metrics.smoothness_columns`), the bars
    checked (``bars_failed`` lists the failed ones, :func:`~crowdstudy.metrics.check_bars`),
    and how far the skin reaches through the scene's walls (``wall_p99_cm_*``,
    ``wall_max_cm_*``: :func:`crowdstudy.metrics.wall_penetration`, the same frames as the
    overlap; not a bar). The row records its ``seed`` and whether it is the study's
    (``study_seed``)."""
    from crowdstudy.metrics import overlap_volume, tracking_parts, wall_penetration
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.corrector import correct

    tolerances = BarTolerances() if tolerances is None else tolerances
    levels = list(design.densities)
    base = build_baseline(design, stage, level, duration=duration, seed=seed)
    t0 = time.perf_counter()
    run_timings: dict = {}
    ours = correct(base, config, progress=False, timings=run_timings)
    wall = time.perf_counter() - t0
    frames = np.arange(0, base.n_frames, frame_stride)
    study_seed = design.cell_seed(design.stage(stage), level)
    row = {
        "stage": stage,
        "level": level,
        "seed": int(base.meta["seed"]),
        "study_seed": int(base.meta["seed"]) == study_seed,
        "characters": base.n_characters,
        "frames": base.n_frames,
        "loop": loop_mode(base),
        "tracking_bar_cm": tolerances.tracking_cm(li, len(levels)),
        **profile_columns(ours),
    }
    for geom in ("mesh", "capsule"):
        ob = overlap_volume(base, geometry=geom, frames=frames).mean
        oo = overlap_volume(ours, geometry=geom, frames=frames).mean
        row[f"{geom}_baseline_m3"] = ob
        row[f"{geom}_ours_m3"] = oo
        row[f"{geom}_ratio"] = oo / max(ob, 1e-12)
    for name, a in (("baseline", base), ("ours", ours)):  # skin through the walls (not a bar)
        walls = wall_penetration(a, frames=frames)
        row[f"wall_p99_cm_{name}"], row[f"wall_max_cm_{name}"] = walls.p99_cm, walls.max_cm
    parts = tracking_parts(ours, base)
    row["tracking_cm"] = parts.total_cm
    # placement, motion and each body part's mean (where the tracking goes; not bars)
    row.update({key: value for key, value in parts.as_dict().items() if key != "tracking_error_cm"})
    row.update(smoothness_columns(base, ours))
    row["bars_failed"] = failed_bars(check_bars(row, tolerances, li, len(levels)))
    limited = (ours.meta.get("physics") or {}).get("speed_limit") or {}
    row["speed_limited_characters"] = len(limited.get("characters", ()))  # re-timed by the speed limit
    row["correct_wall_s"] = wall
    row["ms_per_step_wall"] = run_timings["ms_per_step"]  # the clip's steps only
    return row

"""Ours and the MuJoCo peer (:mod:`crowdstudy.physics.mujoco_peer`) side by side on the
densest study cells: cost per step and per simulated 1/60 s, mesh and capsule overlap as a
fraction of the Baseline's, tracking error and jerk, for each MuJoCo tuning.

``crowdstudy bench physics --mujoco`` prints and saves these rows (:data:`MUJOCO_COLUMNS`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.mujoco_peer import MUJOCO_SETTINGS, mujoco_peer
from crowdstudy.physics.step_timing import time_steps

__all__ = ["MujocoScenario", "MUJOCO_COLUMNS", "compare_mujoco", "mark_best"]

#: the D5 cells compared: the concert (stationary) and the corridor (walking)
MujocoScenario = Literal["concert", "corridor"]

#: the columns of the comparison's table, in order
MUJOCO_COLUMNS = [
    "scene",
    "method",
    "setting",
    "dt_ms",
    "cpu_ms_per_step",
    "wall_ms_per_step",
    "cpu_ms_per_60th",
    "wall_ms_per_60th",
    "x_ours_cpu_per_60th",
    "mesh_overlap_vs_baseline",
    "capsule_overlap_vs_baseline",
    "tracking_cm",
    "jerk_vs_baseline",
    "best",
]


def _d5_scene(kind: MujocoScenario, duration: float):
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary" if kind == "concert" else "walking", "D5", duration=duration)


def compare_mujoco(
    duration: float = 4.0,
    scenes: Sequence[MujocoScenario] = ("concert", "corridor"),
    settings: Sequence[str] | None = None,
    frame_stride: int = 10,
    steps: int = 200,
    report: Callable[[dict], None] | None = None,
) -> list[dict]:
    """Ours and MuJoCo (each of ``settings``, names of
    :data:`~crowdstudy.physics.mujoco_peer.MUJOCO_SETTINGS`; default all) side by side on the
    D5 ``scenes``, ``duration`` s each: cost per step and per simulated 1/60 s (Ours timed
    over ``steps`` steps), mesh/capsule overlap as a fraction of the Baseline's (every
    ``frame_stride``-th frame), tracking error (cm), jerk ratio. ``report`` is called with
    each row as it is measured. Per scene the rows are Ours, each MuJoCo tuning
    (:func:`mark_best`) and the Baseline."""
    from crowdstudy.metrics import mean_jerk, overlap_volume, tracking_error
    from crowdstudy.physics.corrector import correct

    settings = list(settings or MUJOCO_SETTINGS)
    unknown = sorted(set(settings) - set(MUJOCO_SETTINGS))
    if unknown:
        raise InvalidInputError(f"settings: unknown {unknown}; expected some of {list(MUJOCO_SETTINGS)}")
    rows = []
    for kind in scenes:
        base = _d5_scene(kind, duration)
        frames = np.arange(0, base.n_frames, frame_stride)
        ov_base = {g: overlap_volume(base, geometry=g, frames=frames).mean for g in ("mesh", "capsule")}
        jerk_base = mean_jerk(base)
        ours = correct(base, progress=False, device="cpu")
        t = time_steps(base, min(steps, 2 * (base.n_frames - 1)))
        runs = [
            (
                "Ours",
                "crowdstudy (Warp CPU)",
                ours,
                {
                    "cpu_ms_per_step": t["total_cpu_ms"],
                    "wall_ms_per_step": t["total_wall_ms"],
                    "dt": 1.0 / 60.0,
                    "steps_per_60th": 1.0,
                },
            )
        ]
        for name in settings:
            mj, mj_t = mujoco_peer(base, setting=name)
            runs.append(("MuJoCo", name, mj, mj_t))
        for method, setting, a, tm in runs:
            row = {
                "scene": f"{kind} D5",
                "method": method,
                "setting": setting,
                "characters": base.n_characters,
                "frames": base.n_frames,
                "dt_ms": 1000 * tm["dt"],
                "cpu_ms_per_step": tm["cpu_ms_per_step"],
                "wall_ms_per_step": tm["wall_ms_per_step"],
                "cpu_ms_per_60th": tm["cpu_ms_per_step"] * tm["steps_per_60th"],
                "wall_ms_per_60th": tm["wall_ms_per_step"] * tm["steps_per_60th"],
            }
            for g in ("mesh", "capsule"):
                overlap = overlap_volume(a, geometry=g, frames=frames).mean
                row[f"{g}_overlap_vs_baseline"] = overlap / max(ov_base[g], 1e-12)
            row["tracking_cm"] = tracking_error(a, base)
            row["jerk_vs_baseline"] = mean_jerk(a) / max(jerk_base, 1e-12)
            if tm.get("unstable"):
                row["setting"] += " (UNSTABLE)"
            rows.append(row)
            if report is not None:
                report(row)
        mark_best(rows[-len(runs) :])
        rows.append(
            {
                "scene": f"{kind} D5",
                "method": "Baseline",
                "setting": "input",
                "characters": base.n_characters,
                "frames": base.n_frames,
                "mesh_overlap_vs_baseline": 1.0,
                "capsule_overlap_vs_baseline": 1.0,
                "tracking_cm": 0.0,
                "jerk_vs_baseline": 1.0,
                "mesh_baseline_m3": ov_base["mesh"],
                "capsule_baseline_m3": ov_base["capsule"],
            }
        )
    return rows


def mark_best(rows: list[dict], tracking_slack: float = 1.25) -> None:
    """Cost ratios to Ours (rows[0]) and ``best`` = "*" on the MuJoCo setting with the least
    mesh overlap among those tracking comparably (within ``tracking_slack`` x Ours' error)."""
    ref = rows[0]
    for r in rows:
        r["x_ours_cpu_per_60th"] = r["cpu_ms_per_60th"] / max(ref["cpu_ms_per_60th"], 1e-12)
        r["best"] = ""
    ok = [
        r
        for r in rows[1:]
        if r["tracking_cm"] <= tracking_slack * ref["tracking_cm"] and "UNSTABLE" not in r["setting"]
    ]
    if ok:
        min(ok, key=lambda r: r["mesh_overlap_vs_baseline"])["best"] = "*"

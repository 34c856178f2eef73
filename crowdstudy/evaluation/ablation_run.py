"""``crowdstudy bench physics --ablation``: the study's cells corrected with the paper's method,
the defaults, and the defaults without each addition (:mod:`crowdstudy.physics.ablation`),
each measured against the bars (:class:`~crowdstudy.metrics.bars.BarTolerances`).

A cell's Baseline is built and its mesh overlap measured once; then the defaults are
corrected first, in the same process as the variants that follow, so that each variant's
median milliseconds per step stand beside the defaults' measured under the same load
(``ms_ratio``). Every finished (cell, variant) row is kept in a cache folder (one JSON file
each, keyed by the configuration, the clip length and the measurement's frames); a rerun
skips it, and a cell with every variant cached is not even built, so a run of hours on a
shared machine can stop and go on. The two ``noise_*`` variants (:data:`NOISE_VARIANTS`)
change nothing of the method: the defaults solved to a tighter CG tolerance, and with the
contact stiffness 0.1 % higher. A crowd of contacts is chaotic, so the smallest change moves
every bar a little; how far is the yardstick of "buys nothing measurable".
"""

from __future__ import annotations

import dataclasses
import json
import os
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics.bars import (
    BAR_NAMES,
    BarName,
    BarTolerances,
    check_bars,
    failed_bars,
    loop_mode,
    smoothness_columns,
)
from crowdstudy.physics.ablation import ADDITIONS, without
from crowdstudy.physics.config import PhysicsConfig

__all__ = [
    "NOISE_VARIANTS",
    "AblationCell",
    "AblationOptions",
    "variant_configs",
    "study_cells",
    "cell_rows",
    "run_ablation",
    "ROW_COLUMNS",
]

#: the noise variants: {name: the changes to the defaults}, each nothing of the method: CG
#: stopped at 1e-3 rather than 3e-3 (which :class:`~crowdstudy.physics.config_sections.SolverConfig`
#: calls equivalent), the contact stiffness 0.1 % higher
NOISE_VARIANTS: dict[str, dict[str, object]] = {
    "noise_cg": {"solver.cg_tolerance": 1e-3},
    "noise_k": {"contacts.stiffness": 6.006e4},
}

#: each bar's measured value in a row, {bar: column}; every one positive, larger is worse
BAR_VALUES: dict[BarName, str] = {
    "overlap": "overlap_pct",
    "tracking": "tracking_cm",
    "jerk": "jerk_ratio",
    "hf": "hf_ratio",
    "speed": "max_joint_speed_m_s",
    "pelvis": "pelvis_p99_m_s2",
    "slide": "slide_p99_cm_s",
    "seam": "seam_ratio",
}

#: the columns of a row, in order
ROW_COLUMNS: tuple[str, ...] = (
    "cell",
    "variant",
    "characters",
    "crowd_density",
    "profile_weight",
    *BAR_VALUES.values(),
    "tracking_placement_cm",
    "tracking_motion_cm",
    *(f"ok_{bar}" for bar in BAR_NAMES),
    "bars_failed",
    "ms_per_step",
    "default_ms_per_step",
    "ms_ratio",
    "output_s",
    "cg_iterations",
    "contacts",
    "load",
    "git_sha",
)


@dataclasses.dataclass(frozen=True)
class AblationCell:
    """One cell of the study: ``stage`` ("stationary"/"walking"), ``level`` ("D1" ...), the
    level's index among the design's ``n_levels`` (which tracking bar applies)."""

    stage: str
    level: str
    level_index: int
    n_levels: int

    @property
    def name(self) -> str:
        """``concert:D1`` / ``corridor:D5``, as ``--cells`` names it."""
        return f"{'concert' if self.stage == 'stationary' else 'corridor'}:{self.level}"


@dataclasses.dataclass(frozen=True)
class AblationOptions:
    """How the cells are corrected and measured.

    Attributes:
        seconds: s of each cell's clip (the study's: 20).
        frame_stride: the mesh overlap is measured on every this-th frame.
        cache_dir: the folder of the finished rows (one JSON file per cell and variant).
        design_path: the study design (None: the paper's, ``stimuli/study.toml``).
        tolerances: the bars.
    """

    seconds: float = 20.0
    frame_stride: int = 10
    cache_dir: Path = Path("build/bench/physics_ablation_cache")
    design_path: str | None = None
    tolerances: BarTolerances = BarTolerances()

    def __post_init__(self) -> None:
        if not self.seconds > 0:
            raise InvalidInputError(f"--seconds: expected a positive clip length, got {self.seconds!r}")
        if self.frame_stride < 1:
            raise InvalidInputError(f"frame_stride: expected a positive integer, got {self.frame_stride!r}")


def variant_configs(groups: Sequence[str]) -> dict[str, PhysicsConfig]:
    """{variant: configuration}: ``default`` first (the timing reference), ``paper``
    (:meth:`PhysicsConfig.paper`), the noise variants (:data:`NOISE_VARIANTS`), then each
    addition of ``groups`` switched off alone (:func:`~crowdstudy.physics.ablation.without`)."""
    out = {"default": PhysicsConfig(), "paper": PhysicsConfig.paper()}
    out.update({name: PhysicsConfig().with_values(changes) for name, changes in NOISE_VARIANTS.items()})
    out.update({name: without([name]) for name in groups})
    return out


def study_cells(design, cells: Sequence[tuple[str, str]] | None = None) -> list[AblationCell]:
    """The design's (stage, level) cells in its order (stationary, then walking; sparsest
    first), or those of ``cells`` only."""
    levels = list(design.densities)
    return [
        AblationCell(stage, level, i, len(levels))
        for stage in ("stationary", "walking")
        for i, level in enumerate(levels)
        if cells is None or (stage, level) in cells
    ]


def _cache_file(options: AblationOptions, cell: AblationCell, variant: str) -> Path:
    return Path(options.cache_dir) / f"{cell.stage}_{cell.level}" / f"{variant}.json"


def _cache_key(options: AblationOptions, cell: AblationCell, config: PhysicsConfig) -> dict:
    """What a cached row was measured with: a row is reused only when all of it is equal."""
    return {
        "stage": cell.stage,
        "level": cell.level,
        "design": options.design_path,
        "seconds": float(options.seconds),
        "frame_stride": int(options.frame_stride),
        "tolerances": dataclasses.asdict(options.tolerances),
        "config": config.as_dict(),
    }


def _cached(options: AblationOptions, cell: AblationCell, variant: str, config: PhysicsConfig) -> dict | None:
    path = _cache_file(options, cell, variant)
    try:
        entry = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return entry["row"] if entry.get("key") == _cache_key(options, cell, config) else None


def _store(options: AblationOptions, cell: AblationCell, variant: str, config: PhysicsConfig, row: dict) -> None:
    """Write the row's cache file whole or not at all (a temporary file renamed)."""
    path = _cache_file(options, cell, variant)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps({"key": _cache_key(options, cell, config), "row": row}, indent=1, default=float))
    tmp.replace(path)


def _bar_row(cell: AblationCell, base, ours, base_mesh_m3: float, frames, tolerances: BarTolerances) -> dict:
    """The bars of ``ours`` against its Baseline ``base`` (as ``measure_cell`` measures them:
    mesh overlap on ``frames``, tracking, smoothness): each bar's value and whether it is met
    (None where the bar does not apply)."""
    from crowdstudy.metrics import overlap_volume, tracking_parts

    ours_mesh = overlap_volume(ours, geometry="mesh", frames=frames).mean
    parts = tracking_parts(ours, base)
    measured = {
        "mesh_ratio": ours_mesh / max(base_mesh_m3, 1e-12),
        "tracking_cm": parts.total_cm,
        "loop": loop_mode(base),
        **smoothness_columns(base, ours),
    }
    checks = check_bars(measured, tolerances, cell.level_index, cell.n_levels)
    periodic = measured["loop"] == "periodic"
    row = {
        "overlap_pct": 100.0 * measured["mesh_ratio"],
        "tracking_cm": measured["tracking_cm"],
        "jerk_ratio": measured["jerk_ratio"],
        "hf_ratio": measured["hf_share_ours"] / max(measured["hf_share_baseline"], 1e-12),
        "max_joint_speed_m_s": measured["max_joint_speed_ours"],
        "pelvis_p99_m_s2": measured["pelvis_p99_ours"],
        "slide_p99_cm_s": 100.0 * measured["foot_slide_p99_ours"],
        "seam_ratio": measured["seam_ratio_ours"] if periodic else None,
        "tracking_placement_cm": parts.placement_cm,
        "tracking_motion_cm": parts.motion_cm,
    }
    row.update({f"ok_{bar}": checks.get(bar) for bar in BAR_NAMES})
    row["bars_failed"] = failed_bars(checks)
    return row


def _correct_and_measure(cell: AblationCell, variant: str, config: PhysicsConfig, base, base_mesh_m3, frames, options):
    """One variant of one cell: corrected, timed and measured (a row without the ratio)."""
    from crowdstudy.physics.corrector import correct
    from crowdstudy.provenance import git_sha

    timings: dict = {}
    ours = correct(base, config, progress=False, timings=timings)
    phys = ours.meta["physics"]
    row = {
        "cell": cell.name,
        "variant": variant,
        "characters": base.n_characters,
        "crowd_density": phys["crowd_density"],
        "profile_weight": phys["profile_weight"],
        **_bar_row(cell, base, ours, base_mesh_m3, frames, options.tolerances),
        "ms_per_step": timings["ms_per_step_median"],
        "output_s": timings["output_seconds"],
        "cg_iterations": phys["cg_iterations_mean"],
        "contacts": phys["contacts_mean"],
        "load": os.getloadavg()[0],
        "git_sha": git_sha(),
    }
    return row


def cell_rows(
    cell: AblationCell,
    configs: dict[str, PhysicsConfig],
    options: AblationOptions,
    report: Callable[[dict], None] | None = None,
) -> list[dict]:
    """Every variant of ``configs`` on one cell, in their order: cached rows as they are; the
    others corrected and measured, the defaults first (corrected again when cached, so that
    the variants' ``ms_ratio`` compares steps timed in this process), each stored as it is
    done. ``report`` is called with each new row."""
    from crowdstudy.design import load_design
    from crowdstudy.metrics import overlap_volume
    from crowdstudy.motion.baseline import build_baseline

    if "default" not in configs:
        raise InvalidInputError("configs: the defaults ('default') are the timing reference of the others")
    rows = {v: _cached(options, cell, v, c) for v, c in configs.items()}
    if all(row is not None for row in rows.values()):
        return [row for row in rows.values() if row is not None]
    design = load_design(options.design_path)
    base = build_baseline(design, cell.stage, cell.level, duration=options.seconds)
    frames = list(range(0, base.n_frames, options.frame_stride))
    base_mesh = overlap_volume(base, geometry="mesh", frames=frames).mean
    reference = None
    for variant in ["default", *(v for v in configs if v != "default" and rows[v] is None)]:
        try:
            row = _correct_and_measure(cell, variant, configs[variant], base, base_mesh, frames, options)
        except Exception as exc:  # noqa: BLE001 - one variant's failure must not stop a run of hours
            if variant == "default":
                raise
            traceback.print_exc()
            rows[variant] = {"cell": cell.name, "variant": variant, "bars_failed": f"error: {exc!r}"[:200]}
            continue  # not cached: a rerun tries it again
        reference = row["ms_per_step"] if reference is None else reference
        row["default_ms_per_step"] = reference
        row["ms_ratio"] = row["ms_per_step"] / reference if reference else None
        row = {key: row.get(key) for key in ROW_COLUMNS}
        _store(options, cell, variant, configs[variant], row)
        rows[variant] = row
        if report is not None:
            report(row)
    return [row for row in rows.values() if row is not None]  # every variant has its row now


def _cell_job(args) -> list[dict]:
    """A worker process's job: :func:`cell_rows` of one cell (rows reported by printing)."""
    cell, configs, options = args
    return cell_rows(cell, configs, options, report=_print_row)


def _print_row(row: dict) -> None:
    values = " ".join(f"{BAR_VALUES[b]}={row[BAR_VALUES[b]]:.4g}" for b in BAR_VALUES if row[BAR_VALUES[b]] is not None)
    print(
        f"[ablation] {row['cell']} {row['variant']}: {values} failed={row['bars_failed']} "
        f"ms/step={row['ms_per_step']:.3g} (x{row['ms_ratio']:.3f} of the defaults')",
        flush=True,
    )


def run_ablation(
    cells: Sequence[AblationCell],
    groups: Sequence[str],
    options: AblationOptions,
    *,
    workers: int = 1,
    report: Callable[[dict], None] | None = _print_row,
) -> list[dict]:
    """Every cell with every variant (:func:`variant_configs` of ``groups``): rows in cell
    order, each cell's variants in :func:`variant_configs`' order. ``workers`` > 1 runs
    that many cells at once in worker processes (each prints its rows as they finish)."""
    unknown = [g for g in groups if g not in ADDITIONS]
    if unknown:
        raise InvalidInputError(f"groups: unknown addition(s) {unknown}")
    if workers < 1:
        raise InvalidInputError(f"--workers: expected a positive number of processes, got {workers!r}")
    configs = variant_configs(groups)
    if workers == 1 or len(cells) < 2:
        return [row for cell in cells for row in cell_rows(cell, configs, options, report=report)]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(workers, len(cells)), mp_context=ctx) as pool:
        done = list(pool.map(_cell_job, [(cell, configs, options) for cell in cells]))
    return [row for rows in done for row in rows]

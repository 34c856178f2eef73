"""``crowdstudy bench physics``: cost per step of the collision-correction physics, its bars,
and its MuJoCo peer.

* the device rows (cpu; cuda:N when present, else "cuda: not present");
* median ms per step (split detection / assembly / solve) over ``--steps`` steps for 20
  characters (D1), 60 (D5) and 200 (the D5 scene tiled on a larger floor;
  :mod:`crowdstudy.physics.step_timing`);
* ``--curve-only --sizes 20,60,200,1000,5000``: the cost curve (ms per simulated 1/60 s,
  CPU and wall, memory per character) and its log-log figure
  ``build/bench/physics_runtime.png``;
* ``--stadium 1000,5000``: ``correct()`` on stadium crowds (``--stadium-level``,
  ``--stadium-seconds``; :mod:`crowdstudy.evaluation.stadium`): time, peak memory per
  character, NaN/stability and the bars;
* ``--bars-only --bars 20 [--cells ...] [--seeds study,1,2]``: the bars
  (:class:`crowdstudy.metrics.BarTolerances`) of every study cell (or of some), on the
  study's own crowds or on other seeds of the same cells (:mod:`crowdstudy.evaluation.acceptance`);
  with more than one seed, the spread per cell (:func:`seed_spread`) and its figure
  ``build/bench/physics_bars_seeds.png``;
* ``--ablation [--groups NAME,...] [--cells ...] [--seconds 20] [--workers N]``: what each
  addition to the paper's method buys: every study cell corrected with the paper's method
  alone (``PhysicsConfig.paper()``), the defaults, two noise variants and the defaults
  without each addition (:mod:`crowdstudy.physics.ablation`), the bars and ms per step of
  each; resumable (:mod:`crowdstudy.evaluation.ablation_run`), with a summary per variant and
  the heat map ``build/bench/physics_ablation.png`` (:mod:`crowdstudy.evaluation.ablation_report`);
* the CG implementations on the same assembled 60-character system (fused single-launch
  PCG with the per-character tree preconditioner or 6x6 block Jacobi, scipy CG on a BSR
  matrix, warp.optim.linear.cg on a warp.sparse BSR matrix);
* side by side (``--mujoco`` alone), the same characters as a MuJoCo model
  (:mod:`crowdstudy.physics.mujoco_peer`) on concert D5 and corridor D5: ms per step and per
  simulated 1/60 s (CPU and wall), mesh and capsule overlap as a fraction of the Baseline's,
  tracking error and jerk, for each MuJoCo tuning in ``MUJOCO_SETTINGS``
  (:mod:`crowdstudy.evaluation.mujoco_compare`).

This script keeps the command line and the tables; what it measures lives in the package.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from crowdstudy.bench import report_path, write_report
from crowdstudy.evaluation.acceptance import measure_bars
from crowdstudy.evaluation.mujoco_compare import MUJOCO_COLUMNS, compare_mujoco
from crowdstudy.evaluation.stadium import stadium_run
from crowdstudy.metrics.bars import BarTolerances
from crowdstudy.physics.config_file import add_config_option, config_from_cli
from crowdstudy.physics.mujoco_peer import MUJOCO_SETTINGS
from crowdstudy.physics.step_timing import rss_mib, tile_crowd, time_steps, timed_corrector
from crowdstudy.tables import format_table

#: the bars every table of this benchmark checks
TOLERANCES = BarTolerances()
#: the bars in words, as the reports record them
BAR_TEXT = TOLERANCES.text()


def _scene(level: str, duration: float, seed: int | None = None):
    """The study's concert (stationary) cell at ``level``, ``duration`` s."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary", level, duration=duration, seed=seed)


def _print_row(row: dict) -> None:
    print(format_table([row]), flush=True)


def device_rows(cpu_only: bool = False) -> list[dict]:
    """One row per Warp device the benchmark can run on: ``cpu`` always, ``cuda:0`` with
    its name when a CUDA device is present, else the row ``cuda: not present``."""
    from crowdstudy.warp_runtime import get_warp, host_threads

    wp = get_warp()
    cpu = wp.get_device("cpu")
    rows = [{"device": "cpu", "present": True, "name": getattr(cpu, "name", "cpu"), "host_threads": host_threads()}]
    if cpu_only:
        rows.append({"device": "cuda", "present": False, "name": "skipped (--cpu-only)"})
    elif wp.is_cuda_available():
        for dev in wp.get_cuda_devices():
            rows.append({"device": str(dev), "present": True, "name": dev.name, "host_threads": None})
    else:
        rows.append({"device": "cuda", "present": False, "name": "cuda: not present"})
    for r in rows:
        print(f"device {r['device']}: {r['name'] if r['present'] else r['name']}", flush=True)
    return rows


def cost_curve(sizes, steps: int, device: str = "cpu", base=None, config=None) -> list[dict]:
    """ms per step (= per simulated 1/60 s at the study's 1/60 s step) against characters:
    the D5 concert tiled on a grid of floors
    (:func:`~crowdstudy.physics.step_timing.tile_crowd`) for each size; CPU (main thread)
    and wall medians over ``steps`` steps, the phases, and memory: the Warp arrays
    of the corrector (MiB, and KiB per character) and the resident growth of the process
    (MiB; the allocator reuses what earlier sizes freed, so it undercounts after the first)."""
    import gc

    base = base if base is not None else _scene("D5", max(steps, 8) / 60.0 + 0.5)
    rows = []
    for n in sizes:
        anim = base if n == base.n_characters else tile_crowd(base, n)
        gc.collect()
        rss0 = rss_mib()
        r = time_steps(anim, steps, device=device, config=config)
        grown = rss_mib() - rss0
        row = {
            "characters": n,
            "device": device,
            "steps": steps,
            "load": os.getloadavg()[0],
            "cpu_ms_per_60th": r["total_cpu_ms"],
            "wall_ms_per_60th": r["total_wall_ms"],
            "wall_min_ms": r["total_wall_min_ms"],
            **{k: r[k] for k in r if k.endswith("_cpu_ms") and k != "total_cpu_ms"},
            "cg_iterations": r["cg_iterations"],
            "contacts": r["contacts"],
            "warp_mib": r["warp_mib"],
            "warp_kib_per_character": 1024.0 * r["warp_mib"] / n,
            "rss_growth_mib": grown,
            "peak_rss_mib": rss_mib("VmHWM"),
        }
        rows.append(row)
        print(format_table([row]), flush=True)
        del anim
    return rows


def runtime_figure(rows: list[dict], path=None):
    """ms per simulated 1/60 s against characters, log-log (PNG): CPU and wall time per
    device, with the 40 ms bar at 1,000 characters and a linear-cost guide."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = report_path("physics_runtime").with_suffix(".png") if path is None else path
    fig, ax = plt.subplots(figsize=(6.0, 4.2), dpi=120)
    for dev in sorted({r["device"] for r in rows}):
        sel = sorted((r for r in rows if r["device"] == dev), key=lambda r: r["characters"])
        n = [r["characters"] for r in sel]
        ax.loglog(n, [r["cpu_ms_per_60th"] for r in sel], "o-", label=f"{dev}: CPU time (main thread)")
        ax.loglog(n, [r["wall_ms_per_60th"] for r in sel], "s--", label=f"{dev}: wall time")
    ns = np.array(sorted({r["characters"] for r in rows}), float)
    if len(ns):
        ref = min(rows, key=lambda r: r["characters"])
        ax.loglog(ns, ref["cpu_ms_per_60th"] * ns / ref["characters"], ":", color="grey", label="linear in N")
    ax.plot([1000], [40.0], "r*", ms=12, label="bar: 40 ms at 1,000")
    ax.set_xlabel("characters")
    ax.set_ylabel("ms per simulated 1/60 s")
    ax.set_title("crowdstudy physics step (Warp CPU)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def compare_cg(anim, repeat: int = 10) -> list[dict]:
    """The CG implementations on the same assembled CPU system (after 10 steps)."""
    corr = timed_corrector(anim, device="cpu")
    for s in range(10):  # get into a contact-rich state
        f = 1 + s // 2
        corr.control.advance(f - 1, f, (s % 2 + 1) / 2)
        corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
        corr.solver.step(corr.states[0], corr.states[1], corr.control, corr.contacts, corr.dt)
        corr.states.reverse()
    corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
    corr.solver.assemble(corr.states[0], corr.control, corr.contacts, corr.dt)
    rows = []
    for name, solver, precond in (
        ("fused PCG, tree precond", "fused", "character"),
        ("fused PCG, 6x6 block Jacobi", "fused", "body"),
        ("scipy CG on BSR, 6x6 block Jacobi", "scipy", "body"),
        ("warp.optim.linear.cg on BSR, tree precond", "warp", "character"),
        ("warp.optim.linear.cg on BSR, 6x6 block Jacobi", "warp", "body"),
    ):
        corr.solver.linear_solver, corr.solver.preconditioner = solver, precond
        corr.solver.solve(corr.contacts)  # warm-up (compiles)
        times, cpu = [], []
        for _ in range(repeat):
            t0, c0 = time.perf_counter(), time.thread_time()
            corr.solver.solve(corr.contacts)
            times.append(1000 * (time.perf_counter() - t0))
            cpu.append(1000 * (time.thread_time() - c0))
        rows.append(
            {
                "cg": name,
                "cpu_ms": statistics.median(cpu),
                "wall_ms": statistics.median(times),
                "iterations": corr.solver.last_cg[0],
                "rel_residual": corr.solver.last_cg[1],
            }
        )
    best = rows[0]["cpu_ms"]
    for r in rows:
        r["x_fused_tree"] = r["cpu_ms"] / best
    return rows


def parse_cells(text: str, levels) -> list[tuple[str, str]] | None:
    """``"concert:D1,corridor:D5"`` -> [("stationary", "D1"), ("walking", "D5")]; "" -> None
    (every cell). Scenes are ``concert``/``stationary`` and ``corridor``/``walking``."""
    if not text.strip():
        return None
    stages = {"concert": "stationary", "stationary": "stationary", "corridor": "walking", "walking": "walking"}
    cells = []
    for item in text.split(","):
        scene, _, level = item.strip().partition(":")
        if scene not in stages or level not in levels:
            raise SystemExit(
                f"--cells: expected SCENE:LEVEL with SCENE in concert, corridor and LEVEL in "
                f"{', '.join(levels)}, got {item.strip()!r}"
            )
        cells.append((stages[scene], level))
    return cells


def parse_seeds(text: str) -> list[int | None]:
    """``"study,1,2"`` -> [None, 1, 2] (``study``: the design's seed of each cell)."""
    seeds: list[int | None] = []
    for item in text.split(","):
        item = item.strip()
        if item == "study":
            seeds.append(None)
            continue
        try:
            value = int(item)
        except ValueError:
            value = -1
        if value < 0:
            raise SystemExit(f"--seeds: expected 'study' or non-negative integers, comma-separated, got {item!r}")
        seeds.append(value)
    if len(set(seeds)) != len(seeds):
        raise SystemExit(f"--seeds: a seed is given twice in {text!r}")
    return seeds


SPREAD_COLUMNS = [
    "stage",
    "level",
    "seeds",
    "mesh_ratio_study",
    "mesh_ratio_mean",
    "mesh_ratio_sd",
    "mesh_ratio_min",
    "mesh_ratio_max",
    "baseline_cm3_mean",
    "ours_cm3_mean",
    "ours_cm3_max",
    "overlap_met",
    "tracking_cm_mean",
    "tracking_cm_max",
    "tracking_met",
    "all_bars_met",
]


def seed_spread(rows: list[dict]) -> list[dict]:
    """Per cell, how the bars vary from crowd to crowd (rows of :func:`measure_bars` with
    several seeds): the mesh overlap ratio's mean, sample standard deviation, range and the
    study seed's value (NaN where the study's own crowd was not measured), the overlap itself
    in cm^3 per character (the Baseline's mean, Ours' mean and largest: a sparse cell's ratio
    is a ratio of small volumes), the tracking
    error's mean and largest value, and how many crowds meet the overlap bar, the tracking
    bar (D1 and D5 only; "" elsewhere) and every bar, as "k/n"."""
    cells: dict = {}
    for r in rows:
        cells.setdefault((r["stage"], r["level"]), []).append(r)
    out = []
    for (stage, level), rs in cells.items():
        ratio = np.array([r["mesh_ratio"] for r in rs], float)
        track = np.array([r["tracking_cm"] for r in rs], float)
        failed = [set(filter(None, r["bars_failed"].replace("-", "").split(","))) for r in rs]
        study = [r["mesh_ratio"] for r in rs if r.get("study_seed")]
        n = len(rs)
        out.append(
            {
                "stage": stage,
                "level": level,
                "seeds": n,
                "mesh_ratio_study": float(study[0]) if study else float("nan"),
                "mesh_ratio_mean": float(ratio.mean()),
                "mesh_ratio_sd": float(ratio.std(ddof=1)) if n > 1 else 0.0,
                "mesh_ratio_min": float(ratio.min()),
                "mesh_ratio_max": float(ratio.max()),
                "baseline_cm3_mean": 1e6 * float(np.mean([r["mesh_baseline_m3"] for r in rs])),
                "ours_cm3_mean": 1e6 * float(np.mean([r["mesh_ours_m3"] for r in rs])),
                "ours_cm3_max": 1e6 * float(np.max([r["mesh_ours_m3"] for r in rs])),
                "overlap_met": f"{sum('overlap' not in f for f in failed)}/{n}",
                "tracking_cm_mean": float(track.mean()),
                "tracking_cm_max": float(track.max()),
                "tracking_met": (
                    f"{sum('tracking' not in f for f in failed)}/{n}"
                    if rs[0].get("tracking_bar_cm") is not None
                    else ""
                ),
                "all_bars_met": f"{sum(not f for f in failed)}/{n}",
            }
        )
    return out


def seed_figure(rows: list[dict], path=None, tolerances: BarTolerances | None = None):
    """The bars crowd by crowd (PNG): mesh overlap (% of the Baseline's) and tracking error
    (cm) per cell, one dot per seed, the study's own crowd ringed, the bars (``tolerances``,
    None: the defaults) as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = report_path("physics_bars_seeds").with_suffix(".png") if path is None else path
    cells = list(dict.fromkeys((r["stage"], r["level"]) for r in rows))
    names = [f"{'concert' if st == 'stationary' else 'corridor'}\n{lv}" for st, lv in cells]
    fig, axes = plt.subplots(2, 1, figsize=(max(6.0, 0.8 * len(cells) + 2), 6.4), dpi=120, sharex=True)
    for ax, key, scale, label in (
        (axes[0], "mesh_ratio", 100.0, "mesh overlap, % of the Baseline's"),
        (axes[1], "tracking_cm", 1.0, "tracking error, cm"),
    ):
        for i, cell in enumerate(cells):
            sel = [r for r in rows if (r["stage"], r["level"]) == cell]
            ys = np.array([r[key] * scale for r in sel])
            xs = i + np.linspace(-0.15, 0.15, len(ys)) if len(ys) > 1 else np.full(1, float(i))
            ax.plot(xs, ys, "o", color="tab:blue", ms=5, alpha=0.8)
            for x, r, y in zip(xs, sel, ys, strict=True):
                if r.get("study_seed"):
                    ax.plot([x], [y], "o", mfc="none", mec="k", ms=10, mew=1.5)
            ax.plot([i - 0.25, i + 0.25], [ys.mean()] * 2, "-", color="tab:blue", lw=2)
        ax.set_ylabel(label)
        ax.grid(True, axis="y", alpha=0.3)
    overlap_bar = 100.0 * (BarTolerances() if tolerances is None else tolerances).overlap_ratio
    axes[0].axhline(overlap_bar, color="r", ls="--", lw=1, label=f"bar: {overlap_bar:g} %")
    for i, cell in enumerate(cells):
        bar = next(r.get("tracking_bar_cm") for r in rows if (r["stage"], r["level"]) == cell)
        if bar is not None:
            axes[1].plot([i - 0.3, i + 0.3], [bar, bar], "r--", lw=1)
    axes[0].plot([], [], "o", mfc="none", mec="k", ms=10, label="the study's own crowd")
    axes[0].plot([], [], "-", color="tab:blue", lw=2, label="mean over seeds")
    axes[0].legend(fontsize=7, loc="upper right", framealpha=0.9)
    axes[1].set_xticks(range(len(cells)), names, fontsize=8)
    axes[0].set_title("The bars crowd by crowd: one dot per seed of each study cell")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def _run_mujoco(args) -> list[dict]:
    unknown = set(args.mujoco_settings.split(",")) - set(MUJOCO_SETTINGS)
    if unknown:
        raise SystemExit(f"--mujoco-settings: unknown {sorted(unknown)}; expected some of {list(MUJOCO_SETTINGS)}")
    rows = compare_mujoco(
        args.mujoco_duration,
        scenes=tuple(args.mujoco_scenes.split(",")),
        settings=args.mujoco_settings.split(","),
        steps=args.steps,
        report=_print_row,
    )
    print(format_table(rows, MUJOCO_COLUMNS), flush=True)
    return rows


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="crowdstudy bench physics")
    parser.add_argument("--steps", type=int, default=200, help="steps timed per scene")
    parser.add_argument("--sizes", default="20,60,200")
    parser.add_argument("--no-peer", action="store_true")
    parser.add_argument("--cpu-only", action="store_true", help="skip the CUDA rows even when a GPU is present")
    parser.add_argument(
        "--mujoco",
        action="store_true",
        help="only the side-by-side comparison with MuJoCo (concert D5 and corridor D5)",
    )
    parser.add_argument(
        "--mujoco-duration",
        type=float,
        default=4.0,
        metavar="SECONDS",
        help="seconds of each scene simulated for the MuJoCo comparison (20 = the full clips)",
    )
    parser.add_argument(
        "--mujoco-settings",
        default=",".join(MUJOCO_SETTINGS),
        help=f"MuJoCo tunings to run, comma-separated among {', '.join(MUJOCO_SETTINGS)}",
    )
    parser.add_argument("--mujoco-scenes", default="concert,corridor", help="D5 scenes: concert, corridor")
    parser.add_argument(
        "--bars",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="also measure overlap/tracking on every study cell for SECONDS (20 = the full clips)",
    )
    parser.add_argument("--bars-only", action="store_true", help="only the --bars measurement")
    parser.add_argument(
        "--shapes",
        choices=("study", "population"),
        default="study",
        help="--bars: the bodies' shape draw (default 'study', the paper's; 'population': "
        "weights spread as adults' BMI, [bodies] shapes of a design)",
    )
    parser.add_argument(
        "--cells",
        default="",
        metavar="SCENE:LEVEL,...",
        help="--bars on these cells only (e.g. concert:D1,corridor:D5; default all ten)",
    )
    parser.add_argument(
        "--seeds",
        default="study",
        metavar="SEED,...",
        help="--bars-only on these seeds of each cell ('study': the stimulus's own crowd; "
        "e.g. study,1,2,3): with more than one, the spread per cell and its figure",
    )
    add_config_option(
        parser,
        "the physics of the timed steps, --bars and --stadium (e.g. cg_tolerance=1e-4); "
        "the report (physics_*_trial) records them",
    )
    parser.add_argument(
        "--curve-only",
        action="store_true",
        help="only the cost curve over --sizes (and its figure), no CG comparison or peers",
    )
    parser.add_argument(
        "--stadium",
        default="",
        metavar="N,N",
        help="only correct() on stadium crowds of these sizes (e.g. 1000,5000): time, memory, bars",
    )
    parser.add_argument("--stadium-level", default="D3", help="density level of the stadium crowds (default D3)")
    parser.add_argument(
        "--stadium-seconds",
        default="20",
        metavar="S[,S]",
        help="seconds simulated per stadium size (one value, or one per size)",
    )
    parser.add_argument(
        "--ablation",
        action="store_true",
        help="only the ablation: every study cell (or --cells) corrected with the paper's method "
        "(PhysicsConfig.paper()), the defaults, and the defaults without each addition (--groups), "
        "with the bars and ms per step of each; resumable (finished rows are cached under "
        "build/bench/physics_ablation_cache/)",
    )
    parser.add_argument(
        "--groups",
        default="all",
        metavar="NAME,...",
        help="--ablation: the additions to switch off one at a time (default all; "
        "crowdstudy.physics.ablation.ADDITIONS)",
    )
    parser.add_argument(
        "--seconds", type=float, default=20.0, help="--ablation: seconds of each cell's clip (default 20, the study's)"
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="--ablation: cells corrected at once, in worker processes (default 1)"
    )
    parser.add_argument(
        "--design",
        default=None,
        metavar="FILE.toml",
        help="--ablation: the study design whose cells are corrected (default the paper's, stimuli/study.toml)",
    )
    parser.add_argument(
        "--light-bodies",
        action="store_true",
        help="stadium runs hand correct() body proxies without the meshes (needed at 5,000 "
        "MakeHuman characters in 24 GiB)",
    )
    return parser


def _main_stadium(args, config, trial: str) -> int:
    try:
        counts = [int(v) for v in args.stadium.split(",")]
        secs = [float(v) for v in args.stadium_seconds.split(",")]
    except ValueError:
        raise SystemExit("--stadium/--stadium-seconds: expected comma-separated numbers") from None
    if len(secs) == 1:
        secs = secs * len(counts)
    if len(secs) != len(counts) or min(counts) < 1 or min(secs) <= 0:
        raise SystemExit("--stadium-seconds: one positive value, or one per --stadium size")
    devices = device_rows()  # the stadium runs are CPU runs; the rows say what else is there
    rows = [
        stadium_run(
            n,
            args.stadium_level,
            s,
            light_bodies=args.light_bodies,
            config=config,
            tolerances=TOLERANCES,
            report=_print_row,
        )
        for n, s in zip(counts, secs, strict=True)
    ]
    print("bars: " + "; ".join(BAR_TEXT.values()), flush=True)
    path = write_report(
        "physics_stadium" + trial, rows, seed=None, devices=devices, bar_text=BAR_TEXT, config_changes=list(args.config)
    )
    print(f"wrote {path}", file=sys.stderr)
    return 0


def _main_bars(args, config, trial: str) -> int:
    from crowdstudy.design import load_design

    cells = parse_cells(args.cells, list(load_design().densities))
    seeds = parse_seeds(args.seeds)
    bars = measure_bars(
        args.bars or 20.0,
        config=config,
        cells=cells,
        seeds=seeds,
        tolerances=TOLERANCES,
        report=_print_row,
        body_shapes=args.shapes,
    )
    print("bars: " + "; ".join(BAR_TEXT.values()), flush=True)
    extra: dict = {}
    if len(seeds) > 1:
        extra["spread"] = seed_spread(bars)
        print(format_table(extra["spread"], SPREAD_COLUMNS), flush=True)
        extra["figure"] = str(
            seed_figure(bars, path=report_path(f"physics_bars_seeds{trial}").with_suffix(".png"), tolerances=TOLERANCES)
        )
        print(f"figure: {extra['figure']}", flush=True)
        name = f"physics_bars_seeds{trial}"
    else:
        trial_run = trial or cells is not None or seeds != [None] or args.shapes != "study"
        name = "physics_bars_trial" if trial_run else "physics_bars"
    path = write_report(
        name,
        bars,
        seed=None,
        bar_text=BAR_TEXT,
        config_changes=list(args.config),
        seeds=["study" if v is None else v for v in seeds],
        body_shapes=args.shapes,
        **extra,
    )
    print(f"wrote {path}", file=sys.stderr)
    return 0


def _main_ablation(args) -> int:
    """``--ablation``: the rows of :func:`crowdstudy.evaluation.ablation_run.run_ablation`, the
    summary per variant and the figure (:mod:`crowdstudy.evaluation.ablation_report`)."""
    from crowdstudy.design import load_design
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.evaluation.ablation_report import ablation_figure, noise_bands, summarize
    from crowdstudy.evaluation.ablation_run import NOISE_VARIANTS, AblationOptions, run_ablation, study_cells
    from crowdstudy.physics.ablation import ADDITIONS, parse_additions

    if args.config:
        raise InvalidInputError(
            "--config: --ablation compares the defaults with the paper's method and takes no --config"
        )
    groups = parse_additions(args.groups)
    design = load_design(args.design)
    try:
        cells = study_cells(design, parse_cells(args.cells, list(design.densities)))
    except SystemExit as exc:
        raise InvalidInputError(str(exc)) from None
    options = AblationOptions(
        seconds=args.seconds,
        cache_dir=report_path("physics_ablation_cache").with_suffix(""),
        design_path=None if args.design is None else str(Path(args.design).resolve()),
    )
    figure_path = report_path("physics_ablation").with_suffix(".png")
    rows = run_ablation(cells, groups, options, workers=args.workers)
    summary = summarize(rows)
    print(format_table(summary), flush=True)
    figure = ablation_figure(rows, path=figure_path, tolerances=TOLERANCES)
    print(f"figure: {figure}", flush=True)
    path = write_report(
        "physics_ablation",
        rows,
        seed=None,
        summary=summary,
        noise=noise_bands(rows),
        groups={
            name: {"description": ADDITIONS[name].description, "changes": ADDITIONS[name].changes} for name in groups
        },
        noise_variants=NOISE_VARIANTS,
        seconds=args.seconds,
        bar_text=BAR_TEXT,
        figure=str(figure),
    )
    print(f"wrote {path}", file=sys.stderr)
    return 0


def _main_curve(args, config, trial: str, sizes: list[int], devices: list[dict], cuda: bool) -> int:
    d5 = _scene("D5", args.steps / 60.0 + 0.5)
    rows = cost_curve(sizes, args.steps, base=d5, config=config)
    if cuda:
        rows += cost_curve(sizes, args.steps, device="cuda:0", base=d5, config=config)
    figure = runtime_figure(rows, path=report_path(f"physics_runtime{trial}").with_suffix(".png"))
    print(f"figure: {figure}", flush=True)
    path = write_report(
        f"physics_curve{trial}", rows, seed=None, devices=devices, figure=str(figure), config_changes=list(args.config)
    )
    print(f"wrote {path}", file=sys.stderr)
    return 0


def _main_steps(args, config, trial: str, sizes: list[int], devices: list[dict], cuda: bool) -> int:
    duration = args.steps / 60.0 + 0.5
    d1, d5 = _scene("D1", duration), _scene("D5", duration)
    rows = []
    for n in sizes:
        anim = d1 if n == d1.n_characters else d5 if n == d5.n_characters else tile_crowd(d5, n)
        for device in ("cpu", "cuda:0") if cuda else ("cpu",):
            r = time_steps(anim, args.steps, device=device, config=config)
            rows.append({"characters": n, **r, "cpu_ms_per_character": r["total_cpu_ms"] / n})
            print(format_table([rows[-1]]), flush=True)
    cg_rows = compare_cg(d5)
    print(format_table(cg_rows), flush=True)
    peer_rows = [] if args.no_peer else _run_mujoco(args)
    bars = (
        measure_bars(args.bars, config=config, tolerances=TOLERANCES, report=_print_row, body_shapes=args.shapes)
        if args.bars > 0
        else []
    )
    path = write_report(
        f"physics{trial}",
        rows,
        seed=None,
        cg=cg_rows,
        peer=peer_rows,
        bars=bars,
        bar_text=BAR_TEXT,
        config_changes=list(args.config),
        devices=devices,
    )
    print(f"wrote {path}", file=sys.stderr)
    return 0


def main(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    config = config_from_cli(args.config)  # the defaults without --config
    trial = "_trial" if args.config else ""  # reports of changed settings keep their own names
    try:
        sizes = [int(v) for v in args.sizes.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"--sizes: expected comma-separated character counts, got {args.sizes!r}") from None
    if not sizes or min(sizes) < 1:
        raise SystemExit(f"--sizes: expected positive character counts, got {args.sizes!r}")
    if args.ablation:
        return _main_ablation(args)
    if args.stadium:
        return _main_stadium(args, config, trial)
    if args.bars_only:
        return _main_bars(args, config, trial)
    if args.mujoco:
        peer_rows = _run_mujoco(args)
        path = write_report("physics_mujoco", peer_rows, seed=None)
        print(f"wrote {path}", file=sys.stderr)
        return 0
    devices = device_rows(cpu_only=args.cpu_only)
    cuda = any(r["present"] and r["device"].startswith("cuda") for r in devices)
    if args.curve_only:
        return _main_curve(args, config, trial, sizes, devices, cuda)
    return _main_steps(args, config, trial, sizes, devices, cuda)

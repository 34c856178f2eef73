"""Paper Fig. 3: mean per-character overlap volume against crowd density, Baseline vs Ours.

For each stage (stationary concert, walking corridor) and density level D1..D5 of the study
design, the script builds the Baseline animation (``crowdstudy.motion.build_baseline``),
corrects it (``crowdstudy.physics.correct``) and measures the mean per-character volume
of each body inside other bodies (``crowdstudy.metrics.overlap_volume``) on the body meshes
(and on the capsule proxies, dashed). Measurements are cached per cell in
``paper_figs/cache/fig3_overlap[_quick].csv`` (with a JSON sidecar holding provenance);
the figure goes to ``paper_figs/out/fig3_overlap[_quick].png``.

    .venv/bin/python paper_figs/fig3_overlap.py            # 20 s clips, every 10th frame, 2 cm
    .venv/bin/python paper_figs/fig3_overlap.py --quick    # D1, D3, D5; 0.5 s clips, 4 cm, every 5th frame
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from figstyle import METHOD_COLOURS, apply_style, cache_path, figure_args, out_path, save_figure  # noqa: E402

STAGES = ("stationary", "walking")
COLUMNS = [
    "stage",
    "scenario",
    "density_level",
    "density",
    "characters",
    "method",
    "duration",
    "frames_measured",
    "resolution",
    "overlap_mesh_litres",
    "overlap_mesh_sd_litres",
    "overlap_capsule_litres",
    "overlap_capsule_sd_litres",
    "tracking_error_cm",
    "seconds_correct",
    "seconds_metrics",
    "seed",
]


def configuration(quick: bool) -> dict:
    if quick:
        return {"duration": 0.5, "frames": "every:5", "resolution": 0.04, "levels": ["D1", "D3", "D5"]}
    return {"duration": None, "frames": "every:10", "resolution": 0.02, "levels": None}


def measure_cell(design, stage: str, level: str, config: dict) -> list[dict]:
    """Build, correct and measure one (stage, density) cell: two rows (Baseline, Ours)."""
    from crowdstudy.metrics import overlap_volume, tracking_error
    from crowdstudy.motion import build_baseline
    from crowdstudy.physics import correct

    baseline = build_baseline(design, stage, level, duration=config["duration"])
    t0 = time.perf_counter()
    ours = correct(baseline, progress=True)
    t_correct = time.perf_counter() - t0
    rows = []
    for method, anim in (("Baseline", baseline), ("Ours", ours)):
        t0 = time.perf_counter()
        mesh = overlap_volume(
            anim, resolution=config["resolution"], geometry="mesh", frames=config["frames"], progress=True
        )
        caps = overlap_volume(anim, resolution=config["resolution"], geometry="capsule", frames=config["frames"])
        t_metrics = time.perf_counter() - t0
        rows.append(
            {
                "stage": stage,
                "scenario": anim.meta.get("scenario", ""),
                "density_level": level,
                "density": float(design.densities[level]),
                "characters": anim.n_characters,
                "method": method,
                "duration": anim.duration,
                "frames_measured": len(mesh.frames),
                "resolution": config["resolution"],
                "overlap_mesh_litres": mesh.mean_litres,
                "overlap_mesh_sd_litres": 1000 * float(mesh.per_frame.std()),
                "overlap_capsule_litres": caps.mean_litres,
                "overlap_capsule_sd_litres": 1000 * float(caps.per_frame.std()),
                "tracking_error_cm": tracking_error(anim, baseline) if method == "Ours" else 0.0,
                "seconds_correct": t_correct if method == "Ours" else 0.0,
                "seconds_metrics": t_metrics,
                "seed": baseline.meta.get("seed", ""),
            }
        )
    return rows


def load_rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def save_rows(path: Path, rows: list[dict], config: dict) -> None:
    from crowdstudy.provenance import provenance

    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: row.get(k, "") for k in COLUMNS})
    path.with_suffix(".json").write_text(
        json.dumps({"csv": path.name, "configuration": config, "provenance": provenance(None)}, indent=2, default=str)
    )


def collect(design, config: dict, csv_path: Path, refresh: bool) -> list[dict]:
    sidecar = csv_path.with_suffix(".json")
    stale = sidecar.is_file() and json.loads(sidecar.read_text()).get("configuration") != config
    rows = [] if refresh or stale else load_rows(csv_path)
    done = {(r["stage"], r["density_level"]) for r in rows}
    for stage in STAGES:
        for level in config["levels"] or list(design.densities):
            if (stage, level) in done:
                continue
            print(f"[fig3] {stage} {level}: building, correcting, measuring", flush=True)
            rows.extend(measure_cell(design, stage, level, config))
            save_rows(csv_path, rows, config)  # resumable: one cell at a time
    return rows


def plot(rows: list[dict], path: Path, config: dict) -> None:
    import matplotlib.pyplot as plt

    apply_style()
    fig, axes = plt.subplots(1, 2, figsize=(7.2, 2.9), sharey=False)
    titles = {"stationary": "Stationary (concert)", "walking": "Walking (corridor)"}
    series = []  # the plotted numbers, for the JSON sidecar
    for ax, stage in zip(axes, STAGES, strict=True):
        for method in ("Baseline", "Ours"):
            sel = sorted(
                (r for r in rows if r["stage"] == stage and r["method"] == method), key=lambda r: float(r["density"])
            )
            if not sel:
                continue
            x = [float(r["density"]) for r in sel]
            y = [float(r["overlap_mesh_litres"]) for r in sel]
            sd = [float(r["overlap_mesh_sd_litres"]) for r in sel]
            colour = METHOD_COLOURS[method]
            ax.errorbar(x, y, yerr=sd, color=colour, marker="o", ms=4, capsize=2, label=f"{method} (mesh)")
            yc = [float(r["overlap_capsule_litres"]) for r in sel]
            ax.plot(x, yc, color=colour, ls="--", lw=1.0, alpha=0.7, label=f"{method} (capsules)")
            series.append(
                {
                    "stage": stage,
                    "method": method,
                    "density_level": [r["density_level"] for r in sel],
                    "density": x,
                    "characters": [int(r["characters"]) for r in sel],
                    "overlap_mesh_litres": y,
                    "overlap_mesh_sd_litres": sd,
                    "overlap_capsule_litres": yc,
                    "tracking_error_cm": [float(r["tracking_error_cm"]) for r in sel],
                }
            )
        ax.set_title(titles[stage])
        ax.set_xlabel("density (characters / m$^2$)")
        ax.set_ylim(bottom=0)
    axes[0].set_ylabel("mean overlap per character (L)")
    axes[0].legend(loc="upper left", fontsize=7)
    res_cm = 100 * config["resolution"]
    fig.suptitle(
        f"Per-character body volume inside other characters (mesh grid {res_cm:g} cm, "
        f"frames {config['frames']}; bars: SD over frames)",
        fontsize=9,
        y=1.04,
    )
    save_figure(fig, path, configuration=config, rows=len(rows), series=series)
    plt.close(fig)


def main(argv=None) -> int:
    args = figure_args(__doc__.splitlines()[0], argv)
    from crowdstudy.design import load_design

    config = configuration(args.quick)
    design = load_design()
    csv_path = cache_path("fig3_overlap_quick.csv" if args.quick else "fig3_overlap.csv")
    rows = collect(design, config, csv_path, args.refresh)
    print(f"[fig3] measurements in {csv_path}")
    plot(rows, out_path("fig3_overlap", args), config)
    return 0


if __name__ == "__main__":
    sys.exit(main())

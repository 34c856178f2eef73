"""``crowdstudy demo`` (what ``make demo`` runs): the whole pipeline on a small configuration.

1. Poisson-disk layouts of the five study densities and an ORCA corridor crowd (plot).
2. A dense stationary (concert) and a dense walking (corridor) crowd: Baseline animations.
3. The physics correction (Baseline -> Ours).
4. Metrics: overlap volume before/after, tracking error, smoothness (table).
5. Short videos of both crowds and an overlap image (red = interpenetrating surfaces).
6. The study: the quick stimulus set (all 60 videos, small and 2 s long, or ``--duration``
   when that is shorter), simulated participants answering through the real server and
   database, the export, and the repeated-measures analysis with its report and figures.

Every output goes under ``--out`` (default ``demo_out/``); the last lines list them and say
how to run the full study.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from crowdstudy.design import Stage, StudyDesign, load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.scene import CrowdAnimation

__all__ = ["run_demo"]


class _Steps:
    def __init__(self, total: int):
        self.total, self.index, self.t0 = total, 0, time.perf_counter()

    def __call__(self, title: str) -> None:
        self.index += 1
        print(f"\n[{self.index}/{self.total}] {title}  (t = {time.perf_counter() - self.t0:.0f} s)", flush=True)


def _table(rows: list[dict], columns: list[str]) -> str:
    from crowdstudy.tables import format_table

    return format_table(rows, columns)


def run_demo(
    *,
    out: Path = Path("demo_out"),
    design: str | Path | None = None,
    density: str = "D5",
    duration: float = 4.0,
    participants: int = 12,
    seed: int = 1,
    study: bool = True,
) -> dict[str, Path]:
    """Run the demo; returns ``{name: path}`` of everything written.

    The steps of the module docstring, one function each; ``study=False`` stops after step 5."""
    study_design = load_design(design)
    _check_arguments(study_design, density, duration, participants)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    outputs: dict[str, Path] = {}
    step = _Steps(6 if study else 5)
    stationary, walking = study_design.stage("stationary"), study_design.stage("walking")
    showcase = (stationary, walking)

    step("Crowd layouts (Poisson disk) and corridor trajectories (ORCA)")
    outputs.update(_layouts(study_design, density, duration, out, stationary, walking))
    step(f"Baseline animations at {density} ({duration:g} s)")
    anims: dict[tuple[str, str], CrowdAnimation] = {}
    outputs.update(_baselines(study_design, density, duration, out, showcase, anims))
    step("Physics correction (Baseline -> Ours)")
    outputs.update(_correction(density, out, showcase, anims))
    step("Metrics: overlap before / after correction (mesh grid 2 cm, every 10th frame)")
    outputs.update(_metrics(out, showcase, anims))
    step("Rendering: short videos and the overlap image")
    outputs.update(_renders(study_design, density, out, showcase, anims, outputs))
    if study:
        step(f"The study: quick stimulus set, {participants} simulated participants, analysis")
        outputs.update(_study(study_design, out, participants, seed, duration))
    _print_outputs(outputs)
    return outputs


def _check_arguments(design: StudyDesign, density: str, duration: float, participants: int) -> None:
    """The demo's arguments, checked before any work (errors name the CLI option)."""
    if density not in design.densities:
        raise InvalidInputError(f"--density: unknown level {density!r}; expected one of {', '.join(design.densities)}")
    if not duration > 0:
        raise InvalidInputError(f"--duration: must be > 0 seconds, got {duration}")
    if participants < 2:
        raise InvalidInputError(f"--participants: need at least 2 for the analysis, got {participants}")


def _layouts(
    design: StudyDesign, density: str, duration: float, out: Path, stationary: Stage, walking: Stage
) -> dict[str, Path]:
    """Step 1: the concert layouts of every density (a table of their spacing) and the
    corridor crowd's ORCA trajectories at ``density`` (a summary line), in one plot."""
    from crowdstudy.layout import concert_layout
    from crowdstudy.navigation import corridor_crowd, trajectory_summary
    from crowdstudy.navigation.plot import plot_layouts_and_trajectories

    layouts, rows = [], []
    for level in design.densities:
        crowd = concert_layout(design, level, design.cell_seed(stationary, level))
        layouts.append(crowd)
        rows.append(
            {
                "level": level,
                "density": design.densities[level],
                "characters": crowd.n_agents,
                "min_distance_m": float(crowd.meta.get("min_distance", float("nan"))),
                "required_m": float(crowd.meta.get("target_distance", float("nan"))),
            }
        )
    print(_table(rows, list(rows[0])))
    corridor = corridor_crowd(design, density, design.cell_seed(walking, density), duration=duration)
    summary = trajectory_summary(corridor)
    print(
        f"corridor {density}: {corridor.n_agents} walkers over {corridor.n_frames / corridor.fps:g} s, "
        f"mean speed {summary['mean_speed']:.2f} m/s, largest disc overlap {100 * summary['max_overlap']:.1f} % "
        f"of the radius (negative = gap), wall clearance {summary['wall_clearance']:.3f} m, "
        f"fastest turn {summary['max_turn_rate'] * 180 / 3.141592653589793:.0f} deg/s"
    )
    return {
        "layouts and trajectories": plot_layouts_and_trajectories(
            layouts, corridor, out / "layouts_and_trajectories.png"
        )
    }


def _baselines(
    design: StudyDesign,
    density: str,
    duration: float,
    out: Path,
    stages: tuple[Stage, ...],
    anims: dict[tuple[str, str], CrowdAnimation],
) -> dict[str, Path]:
    """Step 2: the Baseline animation of each showcase crowd, into ``anims`` and saved."""
    from crowdstudy.motion import build_baseline

    outputs = {}
    for stage in stages:
        t0 = time.perf_counter()
        base = build_baseline(design, stage.key, density, duration=duration)
        anims[(stage.key, "Baseline")] = base
        outputs[f"{stage.key} Baseline animation"] = base.save(
            out / "animations" / f"{stage.key}_{density}_Baseline.npz"
        )
        print(
            f"{stage.key}: {base.n_characters} characters x {base.n_frames} frames in {time.perf_counter() - t0:.2f} s"
        )
    return outputs


def _correction(
    density: str, out: Path, stages: tuple[Stage, ...], anims: dict[tuple[str, str], CrowdAnimation]
) -> dict[str, Path]:
    """Step 3: the physics correction of each Baseline (Ours), into ``anims`` and saved."""
    from crowdstudy.physics import correct

    outputs = {}
    for stage in stages:
        t0 = time.perf_counter()
        timings: dict = {}
        ours = correct(anims[(stage.key, "Baseline")], progress=True, timings=timings)
        anims[(stage.key, "Ours")] = ours
        outputs[f"{stage.key} Ours animation"] = ours.save(out / "animations" / f"{stage.key}_{density}_Ours.npz")
        ms = timings.get("ms_per_step")
        print(
            f"{stage.key}: corrected in {time.perf_counter() - t0:.1f} s"
            + (f" ({ms:.2f} ms per simulation step, {ours.meta['physics']['device']})" if ms is not None else "")
        )
    return outputs


def _metrics(out: Path, stages: tuple[Stage, ...], anims: dict[tuple[str, str], CrowdAnimation]) -> dict[str, Path]:
    """Step 4: overlap, tracking error and jerk of both methods (a table; metrics.json)."""
    # every 10th frame, as the stimulus set's and the bars' overlap (halves this step; on the 1 s
    # D5 clips the Baseline / Ours ratios move 18.0 -> 18.5x and 91 -> 78x against every 5th)
    from crowdstudy.metrics import summarize

    rows = []
    for stage in stages:
        base = anims[(stage.key, "Baseline")]
        for method in ("Baseline", "Ours"):
            anim = anims[(stage.key, method)]
            m = summarize(anim, None if method == "Baseline" else base, frames="every:10")
            rows.append(
                {
                    "scene": stage.key,
                    "method": method,
                    "overlap_mesh_L": m.get("overlap_mesh_litres", float("nan")),
                    "overlap_capsule_L": m.get("overlap_capsule_litres", float("nan")),
                    "tracking_cm": m.get("tracking_error_cm", 0.0),
                    "jerk_m_s3": m.get("jerk_m_s3", float("nan")),
                }
            )
    print(_table(rows, list(rows[0])))
    metrics_path = out / "metrics.json"
    from crowdstudy.provenance import provenance

    metrics_path.write_text(json.dumps({"rows": rows, "provenance": provenance(None)}, indent=2))
    return {"metrics": metrics_path}


def _renders(
    design: StudyDesign,
    density: str,
    out: Path,
    stages: tuple[Stage, ...],
    anims: dict[tuple[str, str], CrowdAnimation],
    outputs: dict[str, Path],
) -> dict[str, Path]:
    """Step 5: a short video of each crowd and method, the overlap image and the capsule
    image; colours follow the saved Baseline animations (``outputs``)."""
    from crowdstudy.render import render_frame, render_video
    from crowdstudy.render.renderer import baseline_color_positions

    written = {}
    colours = {}
    for stage in stages:
        view = stage.viewpoints[0] if stage.key == "walking" else "V3"
        # "Ours" is dressed like its Baseline: colours follow the Baseline's frame-0 positions.
        colours[stage.key] = baseline_color_positions(outputs[f"{stage.key} Baseline animation"])
        for method in ("Baseline", "Ours"):
            path = out / "videos" / f"{stage.key}_{density}_{view}_{method}.mp4"
            render_video(
                anims[(stage.key, method)],
                view,
                path,
                width=640,
                height=360,
                design=design,
                progress=False,
                color_positions=colours[stage.key],
            )
            written[f"{stage.key} {method} video"] = path
    written["overlap image"] = _overlap_image(
        anims[("stationary", "Baseline")],
        anims[("stationary", "Ours")],
        design,
        out / "overlap_frame.png",
        render_frame,
        colours["stationary"],
    )
    written["bodies and capsules"] = _capsule_image(
        anims[("stationary", "Baseline")], design, out / "bodies_capsules.png", render_frame, colours["stationary"]
    )
    return written


def _print_outputs(outputs: dict[str, Path]) -> None:
    """The last lines: every output, and how to run the full study."""
    print("\nDone. Outputs:")
    for name, path in outputs.items():
        print(f"  {name:<32} {path}")
    print(
        "\nThe full study (1920x1080, 20 s videos, real participants):\n"
        "  crowdstudy stimuli --out stimuli/videos                                    "
        "# 60 videos (+ --design FILE, --scheduler)\n"
        "  crowdstudy serve --stimuli stimuli/videos --db sqlite:///study.db          "
        "# participants open the printed URL\n"
        "  crowdstudy export --db sqlite:///study.db --out responses.csv --demographics demographics.csv\n"
        "  crowdstudy analyze responses.csv --out analysis_out"
    )


def _overlap_image(base, ours, design, path: Path, render_frame, color_positions) -> Path:
    """Baseline and Ours side by side in the overlap view (red = inside another body)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frame = base.n_frames // 2
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.6))
    for ax, anim, label in zip(axes, (base, ours), ("Baseline", "Ours"), strict=True):
        img = render_frame(
            anim, "V1", frame, width=960, height=540, overlap_view=True, design=design, color_positions=color_positions
        )
        red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
        ax.imshow(img)
        ax.set_title(f"{label}: red pixels {100 * red.mean():.2f} %")
        ax.axis("off")
    fig.suptitle("Overlap view (paper Fig. 5): surfaces inside another character in red")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _capsule_image(anim, design, path: Path, render_frame, color_positions) -> Path:
    """A frame of the dense crowd from the front: the rendered bodies beside their capsule
    proxies (orthographic front view, capsules drawn far to near)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.collections import PolyCollection
    from scipy.spatial import ConvexHull

    from crowdstudy.body import load_body
    from crowdstudy.body.capsules import posed_capsules

    frame = anim.n_frames // 2
    circle = np.stack(
        [np.cos(np.linspace(0, 2 * np.pi, 24, endpoint=False)), np.sin(np.linspace(0, 2 * np.pi, 24, endpoint=False))],
        axis=1,
    )
    polys, colours, depth = [], [], []
    for i in range(anim.n_characters):
        body = load_body(anim.bodies[i])
        start, end = posed_capsules(body, anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        base = np.array(plt.cm.tab20(i % 20)[:3])
        for a, b, r in zip(start, end, body.capsules.radius, strict=True):
            # the outline of a capsule seen along y: the hull of its two end discs in (x, z)
            pts = np.concatenate([a[[0, 2]] + r * circle, b[[0, 2]] + r * circle])
            polys.append(pts[ConvexHull(pts).vertices])  # 2-D hull vertices come in counter-clockwise order
            depth.append(0.5 * (a[1] + b[1]))
            colours.append(base)
    depth = np.asarray(depth)
    shade = 0.55 + 0.45 * (depth - depth.min()) / max(np.ptp(depth), 1e-9)  # nearer (larger y) = brighter
    order = np.argsort(depth)
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.2), gridspec_kw={"width_ratios": [1.45, 1]})
    img = render_frame(anim, "V1", frame, width=960, height=540, design=design, color_positions=color_positions)
    axes[0].imshow(img)
    axes[0].set_title(f"rendered bodies (V1), frame {frame}")
    axes[0].axis("off")
    axes[1].add_collection(
        PolyCollection(
            [polys[k] for k in order],
            facecolors=[np.clip(colours[k] * shade[k], 0, 1) for k in order],
            edgecolors=(0, 0, 0, 0.25),
            linewidths=0.3,
        )
    )
    axes[1].set_xlim(-2.0, 2.0)
    axes[1].set_ylim(0.0, 2.3)
    axes[1].set_aspect("equal")
    axes[1].set_title(f"capsule proxies, front view ({anim.n_characters} x 24 capsules)")
    axes[1].set_xlabel("x (m)")
    axes[1].set_ylabel("z (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _study(design, out: Path, participants: int, seed: int, duration: float) -> dict:
    """The quick stimulus set (its 2 s clips, or the demo's shorter ``duration``), simulated
    participants on a local server, the export and the analysis."""
    from crowdstudy.render import build_stimuli
    from crowdstudy.render.stimuli import PRESETS
    from crowdstudy.stats.options import AnalysisOptions
    from crowdstudy.stats.pipeline import analyze
    from crowdstudy.study.bots import run_simulation
    from crowdstudy.study.export import export_study
    from crowdstudy.study.local_server import LocalServer

    stimuli_dir = out / "stimuli"
    t0 = time.perf_counter()
    build_stimuli(
        design, stimuli_dir, preset="quick", duration=min(float(duration), PRESETS["quick"]["duration"]), progress=True
    )
    print(f"stimulus set (quick preset) ready in {time.perf_counter() - t0:.0f} s: {stimuli_dir / 'manifest.csv'}")
    db_path = (out / "study.db").resolve()
    db_url = f"sqlite:///{db_path}"
    server_args = ["--stimuli", str(stimuli_dir.resolve()), "--db", db_url]
    if design.source and design.source != "<memory>":
        server_args += ["--design", str(design.source)]
    with LocalServer(server_args) as server:
        print(f"server running at {server.url}")
        result = run_simulation(server.url, participants, seed=seed, admin_token=server.admin_token)
        print(result.summary())
    responses, demographics = out / "responses.csv", out / "demographics.csv"
    export_study(db_url, responses, demographics)
    analysis_dir = out / "analysis"
    res = analyze(responses, design, analysis_dir, AnalysisOptions(figure_note=" - SIMULATED participants"))
    print("\n".join(res.summary.splitlines()[:25]))
    return {
        "stimulus manifest": stimuli_dir / "manifest.csv",
        "study database": db_path,
        "responses": responses,
        "demographics": demographics,
        "analysis report": analysis_dir / "summary.md",
        "analysis figures": analysis_dir,
    }

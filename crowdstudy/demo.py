"""``crowdstudy demo`` (what ``make demo`` runs): the whole pipeline on a small configuration.

1. Poisson-disk layouts of the design's densities (its concert scenario) and an ORCA
   corridor crowd (its corridor scenario, when it has one) (plot).
2. A dense crowd of each scenario kind of the design (the first stage of each: the paper's
   stationary concert and walking corridor): Baseline animations.
3. The design's methods (Baseline -> Ours for the paper; any number of recipes,
   :func:`crowdstudy.recipes.make_method_animation`).
4. Metrics: overlap volume of every method, tracking error, smoothness (table).
5. Short videos of each crowd and method and an overlap image (red = interpenetrating surfaces).
6. The study: the quick stimulus set (the paper's 60 videos, small and 2 s long, or
   ``--duration`` when that is shorter), simulated participants answering through the real
   server and database, the export, and the repeated-measures analysis with its report and
   figures.

Every output goes under ``--out`` (default ``demo_out/``); the last lines list them and say
how to run the full study.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from crowdstudy.design import Stage, StudyDesign, default_design_path, load_design
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
    design: StudyDesign | str | Path | None = None,
    density: str | None = None,
    duration: float = 4.0,
    participants: int = 12,
    seed: int = 1,
    study: bool = True,
) -> dict[str, Path]:
    """Run the demo; returns ``{name: path}`` of everything written.

    The steps of the module docstring, one function each; ``study=False`` stops after step 5.
    ``density`` is the showcase crowds' level (None: the design's densest)."""
    design = design if isinstance(design, StudyDesign) else load_design(design)
    density = density or _densest(design)
    _check_arguments(design, density, duration, participants)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    outputs: dict[str, Path] = {}
    step = _Steps(6 if study else 5)
    showcase = _showcase_stages(design)

    step("Crowd layouts (Poisson disk) and corridor trajectories (ORCA)")
    outputs.update(_layouts(design, density, duration, out, showcase))
    step(f"Baseline animations at {density} ({duration:g} s)")
    anims: dict[tuple[str, str], CrowdAnimation] = {}
    outputs.update(_baselines(design, density, duration, out, showcase, anims))
    step(f"The methods: {', '.join(design.methods)} (reference {design.reference_method})")
    outputs.update(_methods(design, density, out, showcase, anims))
    step("Metrics: overlap of every method (mesh grid 2 cm, every 10th frame)")
    outputs.update(_metrics(design, out, showcase, anims))
    step("Rendering: short videos and the overlap image")
    outputs.update(_renders(design, density, out, showcase, anims, outputs))
    if study:
        step(f"The study: quick stimulus set, {participants} simulated participants, analysis")
        outputs.update(_study(design, out, participants, seed, duration))
    _print_outputs(outputs, design)
    return outputs


def _densest(design: StudyDesign) -> str:
    """The design's densest level: the demo's showcase crowds by default."""
    return max(design.densities, key=lambda level: design.densities[level])


def _showcase_stages(design: StudyDesign) -> tuple[Stage, ...]:
    """The first stage of each scenario kind of the design, in stage order (the paper's
    stationary concert and walking corridor)."""
    seen: dict[str, Stage] = {}
    for st in design.stages:
        seen.setdefault(design.scenarios[st.scenario].kind, st)
    return tuple(seen.values())


def _check_arguments(design: StudyDesign, density: str, duration: float, participants: int) -> None:
    """The demo's arguments, checked before any work (errors name the CLI option)."""
    if density not in design.densities:
        raise InvalidInputError(f"--density: unknown level {density!r}; expected one of {', '.join(design.densities)}")
    if not duration > 0:
        raise InvalidInputError(f"--duration: must be > 0 seconds, got {duration}")
    if participants < 2:
        raise InvalidInputError(f"--participants: need at least 2 for the analysis, got {participants}")


def _layouts(
    design: StudyDesign, density: str, duration: float, out: Path, stages: tuple[Stage, ...]
) -> dict[str, Path]:
    """Step 1: the concert layouts of every density (a table of their spacing) and the
    corridor crowd's ORCA trajectories at ``density`` (a summary line), in one plot; each
    where the design has a stage of that scenario kind."""
    from crowdstudy.layout import concert_layout
    from crowdstudy.navigation import corridor_crowd, trajectory_summary
    from crowdstudy.navigation.plot import plot_layouts_and_trajectories

    kinds = {design.scenarios[st.scenario].kind: st for st in stages}
    layouts, rows = [], []
    concert = kinds.get("concert")
    if concert is not None:
        for level in design.densities:
            crowd = concert_layout(design, level, design.cell_seed(concert, level), scenario=concert.scenario)
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
    if rows:
        print(_table(rows, list(rows[0])))
    walking = kinds.get("corridor")
    corridor = None
    if walking is not None:
        corridor = corridor_crowd(
            design, density, design.cell_seed(walking, density), duration=duration, scenario=walking.scenario
        )
        summary = trajectory_summary(corridor)
        print(
            f"corridor {density}: {corridor.n_agents} walkers over {corridor.n_frames / corridor.fps:g} s, "
            f"mean speed {summary['mean_speed']:.2f} m/s, largest disc overlap {100 * summary['max_overlap']:.1f} % "
            f"of the radius (negative = gap), wall clearance {summary['wall_clearance']:.3f} m, "
            f"fastest turn {summary['max_turn_rate'] * 180 / 3.141592653589793:.0f} deg/s"
        )
    if not layouts and corridor is None:
        return {}
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


def _methods(
    design: StudyDesign,
    density: str,
    out: Path,
    stages: tuple[Stage, ...],
    anims: dict[tuple[str, str], CrowdAnimation],
) -> dict[str, Path]:
    """Step 3: every method of the design made from each Baseline (its recipe,
    :func:`crowdstudy.recipes.make_method_animation`), into ``anims`` and saved."""
    from crowdstudy.recipes import check_method_inputs, make_method_animation

    check_method_inputs(design, design.methods, [f"S{st.number}-{density}" for st in stages])
    design_dir = None if design.source in ("", "<memory>") else Path(design.source).parent
    outputs = {}
    for stage in stages:
        base = anims[(stage.key, "Baseline")]
        for name in design.methods:
            method = design.method(name)
            t0 = time.perf_counter()
            timings: dict = {}
            anim = make_method_animation(
                method,
                base,
                cell=f"S{stage.number}-{density}",
                design_dir=design_dir,
                progress=method.correction in ("physics", "paper"),
                timings=timings,
            )
            anims[(stage.key, name)] = anim
            outputs[f"{stage.key} {name} animation"] = anim.save(
                out / "animations" / f"{stage.key}_{density}_{name}.npz"
            )
            if method.correction == "none":
                continue
            ms = timings.get("ms_per_step")
            device = anim.meta.get("physics", {}).get("device")
            print(
                f"{stage.key}: {name} ({method.correction}) in {time.perf_counter() - t0:.1f} s"
                + (f" ({ms:.2f} ms per simulation step, {device})" if ms is not None else "")
            )
    return outputs


def _metrics(
    design: StudyDesign, out: Path, stages: tuple[Stage, ...], anims: dict[tuple[str, str], CrowdAnimation]
) -> dict[str, Path]:
    """Step 4: overlap, tracking error and jerk of every method (a table; metrics.json);
    tracking against the Baseline each method starts from."""
    # every 10th frame, as the stimulus set's and the bars' overlap (halves this step; on the 1 s
    # D5 clips the Baseline / Ours ratios move 18.0 -> 18.5x and 91 -> 78x against every 5th)
    from crowdstudy.metrics import summarize

    rows = []
    for stage in stages:
        base = anims[(stage.key, "Baseline")]
        for method in design.methods:
            anim = anims[(stage.key, method)]
            uncorrected = design.method(method).correction == "none"
            m = summarize(anim, None if uncorrected else base, frames="every:10")
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
    image; colours follow the saved reference animations (``outputs``)."""
    from crowdstudy.render import render_frame, render_video
    from crowdstudy.render.renderer import baseline_color_positions

    written = {}
    colours = {}
    ref = design.reference_method
    for stage in stages:
        # the paper's front-side camera where the design has it (the walking stage's first), else the stage's first
        view = "V3" if "V3" in design.viewpoints else stage.viewpoints[0]
        # every method is dressed like the reference: colours follow its frame-0 positions
        colours[stage.key] = baseline_color_positions(outputs[f"{stage.key} {ref} animation"])
        for method in design.methods:
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
    first = stages[0]
    written["overlap image"] = _overlap_image(
        [(m, anims[(first.key, m)]) for m in design.methods],
        design,
        first.viewpoints[0],
        out / "overlap_frame.png",
        render_frame,
        colours[first.key],
    )
    written["bodies and capsules"] = _capsule_image(
        anims[(first.key, ref)],
        design,
        first.viewpoints[0],
        out / "bodies_capsules.png",
        render_frame,
        colours[first.key],
    )
    return written


def _print_outputs(outputs: dict[str, Path], design: StudyDesign) -> None:
    """The last lines: every output, and how to run the full study of the design."""
    print("\nDone. Outputs:")
    for name, path in outputs.items():
        print(f"  {name:<32} {path}")
    own = design.source not in ("", "<memory>", str(default_design_path()))
    flag = f" --design {design.source}" if own else ""
    print(
        f"\nThe full study ({design.video_width}x{design.video_height}, {design.duration:g} s videos, "
        "real participants):\n"
        f"  crowdstudy stimuli{flag} --out stimuli/videos      # {len(design.stimuli())} videos (+ --scheduler)\n"
        "  crowdstudy serve --stimuli stimuli/videos --db sqlite:///study.db     # participants open the printed URL\n"
        "  crowdstudy export --db sqlite:///study.db --out responses.csv --demographics demographics.csv\n"
        f"  crowdstudy analyze responses.csv{flag} --out analysis_out"
    )


def _overlap_image(methods, design, view: str, path: Path, render_frame, color_positions) -> Path:
    """Every method's animation (``[(name, anim)]``) side by side in the overlap view (red =
    inside another body), from viewpoint ``view``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frame = methods[0][1].n_frames // 2
    fig, axes = plt.subplots(1, len(methods), figsize=(6 * len(methods), 3.6), squeeze=False)
    for ax, (label, anim) in zip(axes[0], methods, strict=True):
        img = render_frame(
            anim, view, frame, width=960, height=540, overlap_view=True, design=design, color_positions=color_positions
        )
        red = (img[..., 0] > 180) & (img[..., 1] < 80) & (img[..., 2] < 80)
        ax.imshow(img)
        ax.set_title(f"{label}: red pixels {100 * red.mean():.2f} %")
        ax.axis("off")
    fig.suptitle("Overlap view (paper Fig. 5): surfaces inside another character in red")
    fig.tight_layout(rect=(0, 0, 1, 0.93))  # room for the title above the panels' own
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _capsule_image(anim, design, view: str, path: Path, render_frame, color_positions) -> Path:
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
    img = render_frame(anim, view, frame, width=960, height=540, design=design, color_positions=color_positions)
    axes[0].imshow(img)
    axes[0].set_title(f"rendered bodies ({view}), frame {frame}")
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

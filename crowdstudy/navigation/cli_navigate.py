"""``crowdstudy navigate``: ORCA trajectories of the corridor crowd for one density."""

from __future__ import annotations

import argparse
import math

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--design", default=None, help="study design TOML (default: stimuli/study.toml)")
    parser.add_argument("--density", default="D5", help="density level, e.g. D5 (default D5)")
    parser.add_argument(
        "--seed", type=int, default=None, help="random seed (default: the design's seed of the walking stage's cell)"
    )
    parser.add_argument("--out", default="build/navigation/walk.npz", help="output trajectories .npz")
    parser.add_argument("--duration", type=float, default=None, help="seconds (default: the design's video duration)")
    parser.add_argument("--fps", type=float, default=None, help="output frame rate (default: the design's)")
    parser.add_argument("--bidirectional", action="store_true", help="half of the crowd walks towards -x")
    parser.add_argument("--device", default="cpu", help="Warp device: cpu (default, reproducible bytes) or cuda:0")
    parser.add_argument("--plot", default=None, metavar="PNG", help="also draw the trajectories to this image")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.navigation.corridor import corridor_crowd, trajectory_summary
    from crowdstudy.paths import check_output_path

    design = load_design(args.design)
    if args.density not in design.densities:
        raise InvalidInputError(
            f"--density: unknown level {args.density!r}; expected one of {', '.join(design.densities)}"
        )
    if args.seed is not None and args.seed < 0:
        raise InvalidInputError(f"--seed: expected a non-negative integer, got {args.seed}")
    stage = design.stage_of_kind("corridor")
    check_output_path(args.out, "--out")
    if args.plot:
        check_output_path(args.plot, "--plot")
    seed = design.cell_seed(stage, args.density) if args.seed is None else args.seed
    crowd = corridor_crowd(
        design,
        args.density,
        seed,
        scenario=stage.scenario,
        duration=args.duration,
        fps=args.fps,
        direction="bidirectional" if args.bidirectional else None,
        device=args.device,
        progress=True,
    )
    path = crowd.save(args.out)
    s = trajectory_summary(crowd)
    m = crowd.meta
    print(
        f"corridor {args.density} ({m['direction']}): {s['n_agents']} agents, {s['n_frames']} frames at "
        f"{crowd.fps:g} fps, disc radius {crowd.radius[0]:.3f} m, section {m['length']:g} x {m['width']:g} m"
    )
    print(
        f"  mean speed {s['mean_speed']:.3f} m/s (preferred {m['preferred_speed']:.3f}), "
        f"max overlap {100 * s['max_overlap']:.2f} % of radius, overlapping pair-frames {s['overlapping_pairs']}, "
        f"wall clearance {s['wall_clearance']:.4f} m, max turn rate {math.degrees(s['max_turn_rate']):.1f} deg/s"
    )
    print(f"  wrote {path}")
    if args.plot:
        from crowdstudy.navigation.plot import plot_layouts_and_trajectories

        print(f"  plot: {plot_layouts_and_trajectories([], crowd, args.plot)}")
    return 0

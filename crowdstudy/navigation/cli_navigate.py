"""``crowdstudy navigate``: ORCA trajectories of a walking crowd (the design's corridor, or
a crossing's two flows on a plaza) for one density."""

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
    parser.add_argument(
        "--scenario",
        default=None,
        help="the design's walking scenario, a corridor or a crossing (default: its corridor, else its first crossing)",
    )
    parser.add_argument("--bidirectional", action="store_true", help="corridor: half of the crowd walks towards -x")
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
    sc = _walking_scenario(design, args.scenario)
    stage = next((st for st in design.stages if st.scenario == sc.name), None)
    if args.seed is not None:
        seed = args.seed
    elif stage is not None:
        seed = design.cell_seed(stage, args.density)
    else:
        raise InvalidInputError(f"--seed: no stage of the design walks {sc.name!r}; give a seed")
    check_output_path(args.out, "--out")
    if args.plot:
        check_output_path(args.plot, "--plot")
    if sc.kind == "crossing":
        if args.bidirectional:
            raise InvalidInputError("--bidirectional: applies to a corridor, not to the crossing " + repr(sc.name))
        return _crossing(design, sc.name, seed, args)
    crowd = corridor_crowd(
        design,
        args.density,
        seed,
        duration=args.duration,
        fps=args.fps,
        direction="bidirectional" if args.bidirectional else None,
        device=args.device,
        progress=True,
        scenario=sc.name,
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


def _walking_scenario(design, name: str | None):
    """The scenario ``--scenario`` names (a corridor or a crossing), else the design's
    corridor, else its first crossing."""
    from crowdstudy.errors import InvalidInputError

    if name is not None:
        sc = design.scenario_of(name)
        if sc.kind not in ("corridor", "crossing"):
            raise InvalidInputError(f"--scenario: {name!r} is a {sc.kind}, not a walking scenario (corridor, crossing)")
        return sc
    for kind in ("corridor", "crossing"):
        for sc in design.scenarios.values():
            if sc.kind == kind:
                return sc
    raise InvalidInputError(
        f"{design.source}: no stage of the design is a corridor or a crossing (navigate walks one of them)"
    )


def _crossing(design, name: str, seed: int, args: argparse.Namespace) -> int:
    """Walk the crossing ``name``, write it and print its summary."""
    import numpy as np

    from crowdstudy.navigation.corridor import trajectory_summary
    from crowdstudy.navigation.crossing import crossing_crowd, obstacle_clearance, obstacle_polygons

    crowd = crossing_crowd(
        design,
        args.density,
        seed,
        duration=args.duration,
        fps=args.fps,
        device=args.device,
        progress=True,
        scenario=name,
    )
    path = crowd.save(args.out)
    s = trajectory_summary(crowd)
    m = crowd.meta
    w, d = m["floor"]["width"], m["floor"]["depth"]
    inside = np.all(np.abs(crowd.positions) <= np.array([w / 2, d / 2]), axis=-1).sum(axis=1)
    clearance = obstacle_clearance(crowd, obstacle_polygons(m["plaza"]["obstacles"]))
    print(
        f"crossing {name} {args.density}: {s['n_agents']} agents, {s['n_frames']} frames at {crowd.fps:g} fps, "
        f"disc radius {crowd.radius[0]:.3f} m; in the {w:g} x {d:g} m crossing area {inside.mean():.1f} "
        f"(min {inside.min()}, target {design.n_characters(args.density)})"
    )
    print(
        f"  mean speed {s['mean_speed']:.3f} m/s, max overlap {100 * s['max_overlap']:.2f} % of radius, "
        f"obstacle clearance {clearance:.4f} m, max turn rate {math.degrees(s['max_turn_rate']):.1f} deg/s"
    )
    print(f"  wrote {path}")
    if args.plot:
        from crowdstudy.navigation.plot import plot_layouts_and_trajectories

        print(f"  plot: {plot_layouts_and_trajectories([], crowd, args.plot)}")
    return 0

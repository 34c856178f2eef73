"""``crowdstudy layout``: Poisson-disk layouts of the concert crowd for one or all densities.

``--characters N`` lays out a stadium crowd: N characters at the level's density on a
proportionally larger floor (``crowdstudy layout --density D3 --characters 1000``), which
``crowdstudy animate layout.npz`` then animates.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--design", default=None, help="study design TOML (default: stimuli/study.toml)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--density", default="D3", help="density level, e.g. D3 (default D3)")
    group.add_argument("--all", action="store_true", help="lay out every density level of the design")
    parser.add_argument(
        "--characters",
        type=int,
        default=None,
        metavar="N",
        help="a stadium crowd: N characters on a floor scaled (aspect kept) to the level's "
        "density (default: the design's floor and its count for the level)",
    )
    parser.add_argument(
        "--seed", type=int, default=None, help="random seed (default: the design's seed of the stationary stage's cell)"
    )
    parser.add_argument(
        "--out", default="build/layout/layout.npz", help="output .npz (with --all, one file per level: NAME-D1.npz ...)"
    )
    parser.add_argument("--plot", default=None, metavar="PNG", help="also draw the layout(s) to this image")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.layout.concert import concert_layout
    from crowdstudy.paths import check_output_path

    design = load_design(args.design)
    levels = list(design.densities) if args.all else [args.density]
    for level in levels:
        if level not in design.densities:
            raise InvalidInputError(
                f"--density: unknown level {level!r}; expected one of {', '.join(design.densities)}"
            )
    if args.characters is not None and args.characters < 1:
        raise InvalidInputError(f"--characters: expected a positive number of characters, got {args.characters}")
    if args.seed is not None and args.seed < 0:
        raise InvalidInputError(f"--seed: expected a non-negative integer, got {args.seed}")
    stage = design.stage_of_kind("concert")
    out = Path(args.out)
    paths = {level: out.with_name(f"{out.stem}-{level}{out.suffix or '.npz'}") if args.all else out for level in levels}
    for path in paths.values():
        check_output_path(path, "--out")
    if args.plot:
        check_output_path(args.plot, "--plot")
    crowds = []
    print(f"{'level':>5} {'chars':>5} {'floor (m)':>13} {'min dist (m)':>12} {'bound (m)':>9}  file")
    for level in levels:
        seed = design.cell_seed(stage, level) if args.seed is None else args.seed
        crowd = concert_layout(design, level, seed, n_characters=args.characters, scenario=stage.scenario)
        path = paths[level]
        crowd.save(path)
        crowds.append(crowd)
        m = crowd.meta
        floor = f"{m['floor']['width']:.2f}x{m['floor']['depth']:.2f}"
        print(
            f"{level:>5} {crowd.n_agents:>5} {floor:>13} "
            f"{m['min_distance']:>12.3f} {m['target_distance']:>9.3f}  {path}"
        )
    if args.plot:
        from crowdstudy.layout.plot import plot_layouts

        print(f"plot: {plot_layouts(crowds, args.plot)}")
    return 0

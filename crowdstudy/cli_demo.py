"""``crowdstudy demo`` (what ``make demo`` runs): the whole pipeline on a small configuration
(:func:`crowdstudy.demo.run_demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("demo_out"), help="output folder (default demo_out/)")
    parser.add_argument("--design", type=Path, default=None, help="study design TOML (default stimuli/study.toml)")
    parser.add_argument(
        "--density", default=None, help="density level of the showcase crowds (default: the design's densest, D5)"
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=4.0,
        help="seconds of the showcase animations (default 4); the quick stimulus set's videos are "
        "2 s, or this long when it is shorter",
    )
    parser.add_argument("--participants", type=int, default=12, help="simulated participants (default 12)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the simulated participants (default 1)")
    parser.add_argument(
        "--skip-study", action="store_true", help="stop after step 5 (no stimulus set, no participants)"
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.demo import run_demo
    from crowdstudy.design import load_design
    from crowdstudy.paths import check_output_dir

    design = load_design(args.design)  # a bad design fails before anything is written
    check_output_dir(args.out, "--out")
    run_demo(
        out=args.out,
        design=design,
        density=args.density,
        duration=args.duration,
        participants=args.participants,
        seed=args.seed,
        study=not args.skip_study,
    )
    return 0

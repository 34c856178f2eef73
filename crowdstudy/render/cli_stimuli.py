"""``crowdstudy stimuli``: build the whole stimulus video set and its manifest.

crowdstudy stimuli --design stimuli/study.toml --out stimuli/videos
crowdstudy stimuli --out build/quick --preset quick --workers 2
crowdstudy stimuli --out /shared/stimuli --scheduler tcp://10.0.0.5:8786
crowdstudy stimuli --design my_study.toml --out build/mine --method Stiff   # one method only
"""

from __future__ import annotations

import argparse

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    from crowdstudy.physics.config_file import add_config_option

    parser.add_argument("--design", help="study design TOML (default stimuli/study.toml)")
    parser.add_argument("--out", required=True, help="output folder (videos/, animations/, manifest.json/.csv)")
    parser.add_argument(
        "--preset",
        choices=("quick", "full"),
        default="full",
        help="full: the design's 1920x1080, 20 s; quick: 320x180, 2 s (same character counts)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="SECONDS",
        help="seconds per video instead of the preset's (a short pilot set; at most the design's)",
    )
    parser.add_argument("--scheduler", help="Dask distributed scheduler address, tcp://HOST:PORT")
    parser.add_argument(
        "--workers",
        type=int,
        help="local worker processes (default one per 2 CPUs, at least 2 with 2 CPUs; 0 = in process)",
    )
    add_config_option(
        parser,
        "the physics every `physics` method of the design starts from (then its own config "
        "overrides), as for `crowdstudy correct --config`; a change re-makes those methods' "
        "animations and videos on resume",
    )
    parser.add_argument(
        "--method",
        action="append",
        metavar="NAME",
        dest="methods",
        help="build only this method's animations and videos (repeatable; default every method of the design)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.paths import check_output_dir
    from crowdstudy.physics.config_file import config_from_cli
    from crowdstudy.render.stimuli import build_stimuli, check_stimuli_inputs

    design = load_design(args.design)
    physics = config_from_cli(args.config)
    check_stimuli_inputs(design, args.methods)  # a files method's files, mujoco: before any output
    check_output_dir(args.out, "--out")
    manifest = build_stimuli(
        design,
        args.out,
        preset=args.preset,
        duration=args.duration,
        scheduler=args.scheduler,
        workers=args.workers,
        progress=not args.quiet,
        physics=physics,
        methods=args.methods,
    )
    print(f"stimuli: {len(manifest['stimuli'])} videos listed in {args.out}/manifest.json and manifest.csv")
    return 0

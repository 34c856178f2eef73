"""``crowdstudy animate``: Baseline full-body animations from a study design or a crowd file.

Examples::

    crowdstudy animate --stage stationary --density D3 --out build/anim/S1-D3-Baseline.npz
    crowdstudy animate --stage all --density all --out build/anim/          # the 10 study cells
    crowdstudy animate crowd.npz --out anim.npz                              # layout or trajectories
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.paths import check_output_dir, check_output_path

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "crowd",
        nargs="?",
        default=None,
        help="a Crowd .npz (layout -> dancing crowd, trajectories -> walking crowd); "
        "without it the cells of --design are animated",
    )
    parser.add_argument(
        "--design", default=None, help="study design TOML (default: the paper's, shipped in the package)"
    )
    parser.add_argument(
        "--stage", default=None, help="stationary | walking | all (or 1 | 2); required without a crowd file"
    )
    parser.add_argument("--density", default="all", help="density level D1..D5 or 'all' (default all)")
    parser.add_argument(
        "--out", required=True, help="output .npz (one animation) or directory (files S<stage>-<level>-Baseline.npz)"
    )
    parser.add_argument("--duration", type=float, default=None, help="seconds (default the design's video duration)")
    parser.add_argument("--fps", type=float, default=None, help="frames per second (default the design's / crowd's)")
    parser.add_argument("--seed", type=int, default=None, help="seed (default the design's seed of each cell)")


def _summary(anim, path: Path) -> str:
    return (
        f"wrote {path} ({anim.n_characters} characters, {anim.n_frames} frames at {anim.fps:g} fps, "
        f"{anim.meta.get('scenario', '?')})"
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design

    design = load_design(args.design)  # a bad design fails before anything is written
    out = Path(args.out)
    if out.suffix == ".npz":
        check_output_path(out, "--out")
    else:
        check_output_dir(out, "--out")
    if args.crowd is not None:
        from crowdstudy.body import sample_bodies
        from crowdstudy.motion.baseline import animate_stationary, animate_walking, bodies_meta
        from crowdstudy.scene import Crowd

        crowd = Crowd.load(args.crowd)
        seed = int(args.seed if args.seed is not None else crowd.meta.get("seed", design.seed))
        meta = {k: crowd.meta[k] for k in ("density_level", "density", "n_characters") if k in crowd.meta}
        meta["seed"] = seed
        meta["source"] = str(args.crowd)
        meta.update(bodies_meta(design.body_shapes))
        bodies = sample_bodies(crowd.n_agents, seed, shapes=design.body_shapes)
        if crowd.n_frames == 1:
            anim = animate_stationary(
                crowd,
                duration=args.duration or design.duration,
                fps=args.fps or design.fps,
                seed=seed,
                meta={**meta, "stage": "stationary"},
                bodies=bodies,
            )
        else:
            if args.duration is not None:
                raise InvalidInputError("--duration: a trajectory file sets the duration; leave it out")
            anim = animate_walking(crowd, fps=args.fps, seed=seed, meta={**meta, "stage": "walking"}, bodies=bodies)
        path = out / "animation.npz" if out.suffix != ".npz" else out
        anim.save(path)
        print(_summary(anim, path))
        return 0

    if args.stage is None:
        raise InvalidInputError(
            f"--stage: required without a crowd file ({', '.join(st.key for st in design.stages)} or all)"
        )
    stages = list(design.stages) if args.stage == "all" else [design.stage(args.stage)]
    levels = list(design.densities) if args.density == "all" else [args.density]
    for level in levels:
        if level not in design.densities:
            raise InvalidInputError(
                f"--density: unknown level {level!r}; expected one of {', '.join(design.densities)} or 'all'"
            )
    cells = [(st, level) for st in stages for level in levels]
    if len(cells) > 1 and out.suffix == ".npz":
        raise InvalidInputError(f"--out: {len(cells)} animations need a directory, got the file {str(out)!r}")
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.progress import progress_bar

    bar = progress_bar(cells, desc="animate", unit="cell", file=sys.stderr, enabled=len(cells) > 1)
    for st, level in bar:
        anim = build_baseline(design, st.key, level, duration=args.duration, fps=args.fps, seed=args.seed)
        path = out if out.suffix == ".npz" else out / f"S{st.number}-{level}-Baseline.npz"
        anim.save(path)
        bar.write(_summary(anim, path), file=sys.stdout)
    return 0

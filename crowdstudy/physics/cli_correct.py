"""``crowdstudy correct IN.npz OUT.npz``: Baseline -> Ours with the physics layer.

The output path and the arguments are checked before the simulation starts; the run's
timings are printed and written to the sidecar ``OUT.timings.json``, never into OUT.
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    from crowdstudy.physics.config_file import add_config_option
    from crowdstudy.physics.solver import LINEAR_SOLVERS

    parser.add_argument("input", help="CrowdAnimation .npz (the Baseline)")
    parser.add_argument(
        "output",
        help="corrected CrowdAnimation .npz to write (Ours); the run's timings go to "
        "the sidecar OUTPUT_STEM.timings.json beside it",
    )
    parser.add_argument("--device", default=None, help="Warp device: cpu, cuda or cuda:N (default: CUDA when present)")
    add_config_option(parser, "e.g. --config physics.toml control.damping=0.006 contacts.stiffness=3e4")
    parser.add_argument(
        "--frames", type=int, default=None, help="correct only the first FRAMES frames (2 .. the clip's frame count)"
    )
    parser.add_argument(
        "--linear-solver",
        choices=LINEAR_SOLVERS,
        default=None,
        help="CG implementation (default: fused on CPU, warp on CUDA)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.paths import check_output_path, timings_path
    from crowdstudy.physics.config_file import config_from_cli
    from crowdstudy.physics.corrector import correct
    from crowdstudy.scene import CrowdAnimation

    # every check before the long run: the output paths, the config, the input, --frames
    output = check_output_path(args.output, "output")
    sidecar = check_output_path(timings_path(output), "output (timings sidecar)")
    config = config_from_cli(args.config)
    anim = CrowdAnimation.load(args.input)
    if args.frames is not None:
        if args.frames < 2:
            raise InvalidInputError(f"--frames: expected at least 2, got {args.frames}")
        if args.frames > anim.n_frames:
            raise InvalidInputError(
                f"--frames: {args.frames} is more than the {anim.n_frames} frames of the clip "
                f"{args.input!r}; give at most {anim.n_frames} (or leave --frames out)"
            )
        anim = anim.frames(0, args.frames)
    timings: dict = {}
    out = correct(
        anim,
        config,
        device=args.device,
        progress=not args.no_progress,
        linear_solver=args.linear_solver,
        timings=timings,
    )
    out.save(output)
    phys = out.meta["physics"]
    record = {
        "output": str(output),
        "frames": out.n_frames,
        "characters": out.n_characters,
        "device": phys["device"],
        "linear_solver": phys["linear_solver"],
        "substeps_per_frame": phys["substeps_per_frame"],
        # how crowded the input is and the skins and hold it was corrected with
        "crowd_density": round(phys["crowd_density"], 3),
        "profile_weight": phys["profile_weight"],
        "mesh_skin_max": phys["config"]["skin"]["max"],
        "output_hold": phys["config"]["output"]["hold"],
        **timings,
    }
    sidecar.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    ms = timings.get("ms_per_step")
    print(
        json.dumps({**record, "ms_per_step": None if ms is None else round(ms, 3), "timings": str(sidecar)}),
        file=sys.stdout,
    )
    return 0

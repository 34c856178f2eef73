"""``crowdstudy correct IN.npz OUT.npz``: Baseline -> Ours with the physics layer;
``crowdstudy correct IN.glb OUT.glb`` (or ``.gltf``, ``.usd``, ``.usda``, ``.usdc``) corrects a
glTF or USD (UsdSkel) crowd file to a file
of the same format (:mod:`crowdstudy.physics.correct_file`).

The output path and the arguments are checked before the simulation starts; the run's
timings are printed and written to the sidecar ``OUT.timings.json``, never into OUT. A
glTF run also prints and writes the mesh overlap before and after (``OUT.overlap.json``);
nothing is written when any step fails.
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    from crowdstudy.physics.config_file import add_config_option
    from crowdstudy.physics.solver import LINEAR_SOLVERS

    parser.add_argument(
        "input", help="CrowdAnimation .npz (the Baseline), or a glTF (.glb, .gltf) or USD (.usd, .usda, .usdc) crowd"
    )
    parser.add_argument(
        "output",
        help="corrected file to write, in the input's format (Ours); the run's timings go to "
        "the sidecar OUTPUT_STEM.timings.json beside it (glTF: the overlap to OUTPUT_STEM.overlap.json)",
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
    gltf = parser.add_argument_group("glTF or USD input (see crowdstudy import-crowd)")
    gltf.add_argument("--fps", type=float, default=None, help="resample to FPS (default: the file's key rate)")
    gltf.add_argument(
        "--animation", action="append", default=None, metavar="NAME", help="animation to correct (repeatable)"
    )
    gltf.add_argument("--map", default=None, metavar="FILE.json", help="{physics joint: source joint} overrides")
    gltf.add_argument(
        "--overlap-every", type=float, default=1.0, metavar="S", help="measure the overlap every S seconds (1)"
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.paths import check_output_path, timings_path
    from crowdstudy.physics.config_file import config_from_cli
    from crowdstudy.physics.correct_file import SCENE_SUFFIXES, check_gltf_paths
    from crowdstudy.physics.corrector import correct
    from crowdstudy.scene import CrowdAnimation

    # every check before the long run: the output paths, the config, the input, --frames
    check_gltf_paths(args.input, args.output)
    output = check_output_path(args.output, "output")
    sidecar = check_output_path(timings_path(output), "output (timings sidecar)")
    config = config_from_cli(args.config)
    if output.suffix.lower() in SCENE_SUFFIXES:
        return _run_gltf(args, output, sidecar, config)
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


def _run_gltf(args: argparse.Namespace, output, sidecar, config) -> int:
    from crowdstudy.body.rig_map import read_overrides
    from crowdstudy.paths import check_output_path
    from crowdstudy.physics.correct_file import (
        correct_gltf,
        format_overlap,
        overlap_report_path,
        report_bytes,
        write_outputs,
    )

    report_path = check_output_path(overlap_report_path(output), "output (overlap report)")
    overrides = read_overrides(args.map) if args.map else None
    res = correct_gltf(
        args.input,
        output,
        config,
        fps=args.fps,
        animations=args.animation,
        overrides=overrides,
        frames=args.frames,
        device=args.device,
        linear_solver=args.linear_solver,
        progress=not args.no_progress,
        overlap_every=args.overlap_every,
    )
    print(res.crowd.report())
    phys = res.corrected.meta["physics"]
    record = {
        "output": str(output),
        "frames": res.corrected.n_frames,
        "characters": res.corrected.n_characters,
        "device": phys["device"],
        "linear_solver": phys["linear_solver"],
        **res.timings,
    }
    write_outputs(
        {
            output: res.data,
            report_path: report_bytes(res.overlap),
            sidecar: (json.dumps(record, indent=2, sort_keys=True) + "\n").encode("utf-8"),
        }
    )
    print("mesh overlap, mean over the measured frames (litres per character):")
    print(format_overlap(res.overlap))
    print(f"wrote {output}, {report_path}, {sidecar}")
    return 0

"""``crowdstudy correct IN.npz OUT.npz``: Baseline -> Ours with the physics layer."""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="CrowdAnimation .npz (the Baseline)")
    parser.add_argument("output", help="corrected CrowdAnimation .npz to write (Ours)")
    parser.add_argument("--device", default=None, help="Warp device: cpu or cuda:0 (default: CUDA when present)")
    parser.add_argument("--config", nargs="*", default=[], metavar="KEY=VALUE",
                        help="PhysicsConfig overrides, e.g. damping=0.006 contact_stiffness=3e4")
    parser.add_argument("--frames", type=int, default=None, help="correct only the first FRAMES frames")
    parser.add_argument("--linear-solver", choices=("fused", "warp", "scipy"), default=None,
                        help="CG implementation (default: fused on CPU, warp on CUDA)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.errors import InvalidInputError
    from crowdstudy.physics.config import PhysicsConfig
    from crowdstudy.physics.corrector import correct
    from crowdstudy.scene import CrowdAnimation

    config = PhysicsConfig.from_strings(args.config)
    anim = CrowdAnimation.load(args.input)
    if args.frames is not None:
        if args.frames < 2:
            raise InvalidInputError(f"--frames: expected at least 2, got {args.frames}")
        anim = anim.frames(0, args.frames)
    out = correct(anim, config, device=args.device, progress=not args.no_progress,
                  linear_solver=args.linear_solver)
    out.save(args.output)
    phys = out.meta["physics"]
    print(json.dumps({"output": args.output, "frames": out.n_frames, "characters": out.n_characters,
                      "ms_per_step": round(phys["ms_per_step"], 3), "device": phys["device"]}), file=sys.stdout)
    return 0

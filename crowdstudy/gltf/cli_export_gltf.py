"""``crowdstudy export-gltf ANIM.npz OUT.glb``: a CrowdAnimation and its bodies as one binary glTF."""

from __future__ import annotations

import argparse
from pathlib import Path

from crowdstudy.errors import InvalidInputError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="CrowdAnimation .npz (from `crowdstudy animate` or `crowdstudy correct`)")
    parser.add_argument("output", help="output .glb")
    parser.add_argument("--start", type=int, default=0, help="first frame to export (default 0)")
    parser.add_argument("--stop", type=int, help="frame after the last one to export (default: all)")
    parser.add_argument(
        "--no-colors", action="store_true", help="no COLOR_0 clothing colours for bodies without a texture (plain grey)"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.gltf.export import export_gltf
    from crowdstudy.paths import check_output_path
    from crowdstudy.scene import CrowdAnimation

    out = Path(args.output)
    if out.suffix.lower() != ".glb":
        raise InvalidInputError(f"output: expected a .glb file name, got {args.output!r}")
    check_output_path(out, "output")
    anim = CrowdAnimation.load(args.input)
    if args.start or args.stop is not None:
        anim = anim.frames(args.start, args.stop)
    export_gltf(anim, out, colors=not args.no_colors, progress=not args.quiet)
    size = out.stat().st_size / 1e6
    print(f"wrote {out}: {anim.n_characters} characters, {anim.n_frames} frames at {anim.fps:g} fps, {size:.1f} MB")
    return 0

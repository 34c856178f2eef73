"""``crowdstudy export-usd ANIM.npz OUT.usda|usdc``: a CrowdAnimation and its bodies as a
UsdSkel crowd (:mod:`crowdstudy.gltf.export_usd`), which ``import-crowd`` reads back."""

from __future__ import annotations

import argparse
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="CrowdAnimation .npz (from `crowdstudy animate` or `crowdstudy correct`)")
    parser.add_argument("output", help="output .usda (text), .usdc or .usd (binary crate)")
    parser.add_argument("--start", type=int, default=0, help="first frame to export (default 0)")
    parser.add_argument("--stop", type=int, help="frame after the last one to export (default: all)")
    parser.add_argument("--up-axis", choices=("Y", "Z"), default="Z", help="the stage's upAxis (default Z)")
    parser.add_argument(
        "--meters-per-unit", type=float, default=1.0, help="the stage's metersPerUnit (default 1; 0.01: centimetres)"
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.gltf.export_usd import export_usd
    from crowdstudy.paths import check_output_path
    from crowdstudy.scene import CrowdAnimation

    out = Path(args.output)
    if out.suffix.lower() not in (".usd", ".usda", ".usdc"):
        raise InvalidInputError(f"output: expected a .usda, .usdc or .usd file name, got {args.output!r}")
    check_output_path(out, "output")
    anim = CrowdAnimation.load(args.input)
    if args.start or args.stop is not None:
        anim = anim.frames(args.start, args.stop)
    export_usd(anim, out, up_axis=args.up_axis, meters_per_unit=args.meters_per_unit)
    size = out.stat().st_size / 1e6
    print(f"wrote {out}: {anim.n_characters} characters, {anim.n_frames} frames at {anim.fps:g} fps, {size:.1f} MB")
    return 0

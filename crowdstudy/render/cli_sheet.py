"""``crowdstudy sheet``: contact sheets (8 frames over 2 s, a row per character or clip).

Examples::

    crowdstudy sheet --clips twist,macarena,cheer --out build/sheets/dances.png
    crowdstudy sheet --clips gait_short_steps,gait_fast --side --out build/sheets/walks.png
    crowdstudy sheet S1-D5-Baseline.npz --characters 0,7,12 --start 4 --out build/sheets/baseline.png
    crowdstudy sheet S1-D5-Ours.npz --reference S1-D5-Baseline.npz --characters 7 --out build/sheets/b_vs_o.png
"""

from __future__ import annotations

import argparse

from crowdstudy.errors import InvalidInputError
from crowdstudy.paths import check_output_path

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("animation", nargs="?", default=None, help="a CrowdAnimation .npz (or use --clips)")
    parser.add_argument("--clips", default=None, help="comma-separated shipped clip names (crowdstudy motion list)")
    parser.add_argument("--characters", default="0", help="comma-separated character indices (default 0)")
    parser.add_argument("--start", type=float, default=0.0, help="first frame's time, s (default 0)")
    parser.add_argument("--span", type=float, default=2.0, help="seconds covered by the 8 frames (default 2)")
    parser.add_argument("--frames", type=int, default=8, help="frames per row (default 8)")
    parser.add_argument("--side", action="store_true", help="view from the side (+x) instead of the front (+y)")
    parser.add_argument(
        "--reference",
        default=None,
        help="the Baseline of a corrected animation: each character gets a Baseline row above its own",
    )
    parser.add_argument("--out", required=True, help="output PNG")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.render.sheets import animation_sheet, clip_sheet

    out = check_output_path(args.out, "--out")
    if (args.animation is None) == (args.clips is None):
        raise InvalidInputError("give an animation file or --clips, not both and not neither")
    if args.reference is not None and args.animation is None:
        raise InvalidInputError("--reference: needs an animation file (the corrected one) to compare with")
    if args.frames < 1:
        raise InvalidInputError(f"--frames: expected a positive number, got {args.frames}")
    if args.clips is not None:
        from crowdstudy.motion.library import load_clip

        clips = [load_clip(name.strip()) for name in args.clips.split(",") if name.strip()]
        path = clip_sheet(clips, out, start=args.start, span=args.span, side=args.side, frames=args.frames)
    else:
        from crowdstudy.scene import CrowdAnimation

        try:
            chars = [int(c) for c in args.characters.split(",")]
        except ValueError:
            raise InvalidInputError(
                f"--characters: expected comma-separated integers, got {args.characters!r}"
            ) from None
        anim = CrowdAnimation.load(args.animation)
        ref = CrowdAnimation.load(args.reference) if args.reference else None
        path = animation_sheet(
            anim, out, chars, start=args.start, span=args.span, side=args.side, frames=args.frames, reference=ref
        )
    print(f"wrote {path}")
    return 0

"""``crowdstudy render``: one animation to an MP4, or one frame to a PNG.

crowdstudy render IN.npz --view V3 --out clip.mp4
crowdstudy render IN.npz --view V1 --frame 120 --png --out frame.png --overlap
crowdstudy render IN.npz --eye 6,4,3 --target 0,0,1 --out preview.mp4 --width 640 --height 360
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run", "parse_vector", "save_png"]


def parse_vector(text: str, name: str):
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise InvalidInputError(f"{name}: expected three comma-separated numbers like 6,4,3, got {text!r}")
    return values


def save_png(image, path: Path) -> Path:
    """Write an (H, W, 3) uint8 image as PNG."""
    from PIL import Image

    from crowdstudy.paths import check_output_path

    check_output_path(path, "--out")
    Image.fromarray(image).save(path)
    return path


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", help="CrowdAnimation .npz (from `crowdstudy animate` or `crowdstudy correct`)")
    parser.add_argument(
        "--view",
        default="V3",
        help="design viewpoint (V1 front, V2 upper-front, V3 front-side, "
        "V4 overhead); ignored when --eye/--target give a free camera",
    )
    parser.add_argument("--eye", help="free camera position x,y,z (m)")
    parser.add_argument("--target", help="free camera target x,y,z (m)")
    parser.add_argument("--fov", type=float, default=45.0, help="free camera vertical field of view (deg)")
    parser.add_argument("--out", required=True, help="output .mp4 (or .png with --png)")
    parser.add_argument("--frame", type=int, help="render only this frame (with --png)")
    parser.add_argument("--png", action="store_true", help="write one frame as PNG (frame 0 unless --frame)")
    parser.add_argument("--overlap", action="store_true", help="overlap view: interpenetrating surfaces in red")
    parser.add_argument("--design", help="study design TOML (default stimuli/study.toml)")
    parser.add_argument("--width", type=int, help="pixels (default the design's, 1920)")
    parser.add_argument("--height", type=int, help="pixels (default the design's, 1080)")
    parser.add_argument("--fps", type=float, help="frames per second (default the design's, 30)")
    parser.add_argument(
        "--duration",
        type=float,
        help="seconds (default the whole animation; a corridor's video "
        "length, its extra frames dissolved into the loop seam)",
    )
    parser.add_argument("--msaa", type=int, default=4, help="anti-aliasing samples per pixel (0 = off)")
    parser.add_argument(
        "--post-aa",
        choices=("none", "fxaa"),
        default="none",
        help="post-process anti-aliasing (the stimulus videos use --msaa 0 --post-aa fxaa)",
    )
    parser.add_argument("--no-shadows", action="store_true", help="skip the shadow map")
    parser.add_argument(
        "--colors-from",
        help="Baseline .npz whose frame-0 positions decide the clothing colours "
        "(render a corrected animation with its Baseline's colours)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.paths import check_output_path
    from crowdstudy.render.camera import free_camera
    from crowdstudy.scene import CrowdAnimation

    check_output_path(args.out, "--out")
    anim = CrowdAnimation.load(args.input)
    design = load_design(args.design)
    if (args.eye is None) != (args.target is None):
        raise InvalidInputError("--eye and --target: give both for a free camera, or neither")
    view = args.view
    if args.eye is not None:
        view = free_camera(parse_vector(args.eye, "--eye"), parse_vector(args.target, "--target"), args.fov)
    elif view not in design.viewpoints:
        raise InvalidInputError(
            f"--view: unknown viewpoint {view!r}; the design defines {', '.join(design.viewpoints)} "
            "(or use --eye/--target for a free camera)"
        )
    colors = None
    if args.colors_from:
        from crowdstudy.render.renderer import baseline_color_positions

        colors = baseline_color_positions(args.colors_from)
        if colors.shape[0] != anim.n_characters:
            raise InvalidInputError(
                f"--colors-from: {args.colors_from!r} has {colors.shape[0]} characters, "
                f"the animation {anim.n_characters}"
            )
    out = Path(args.out)
    png = args.png or args.frame is not None or out.suffix.lower() == ".png"
    if png:
        from crowdstudy.render.renderer import CrowdRenderer

        frame = 0 if args.frame is None else args.frame
        if not 0 <= frame < anim.n_frames:
            raise InvalidInputError(f"--frame: expected 0 <= frame < {anim.n_frames}, got {frame}")
        with CrowdRenderer(
            anim,
            design=design,
            width=args.width or design.video_width,
            height=args.height or design.video_height,
            msaa=args.msaa,
            post_aa=args.post_aa,
            shadows=not args.no_shadows,
            color_positions=colors,
        ) as renderer:
            renderer.set_view(view)
            if args.overlap:
                result = renderer.overlap(frame)
                image, extra = (
                    result.image,
                    {"red_fraction": result.red_fraction, "crowd_fraction": result.crowd_fraction},
                )
            else:
                image, extra = renderer.render(frame), {}
        save_png(image, out)
        print(json.dumps({"png": str(out), "frame": frame, **extra}))
        return 0
    from crowdstudy.render.video import render_video

    res = render_video(
        anim,
        view,
        out,
        width=args.width,
        height=args.height,
        duration=args.duration,
        fps=args.fps,
        msaa=args.msaa,
        post_aa=args.post_aa,
        overlap_view=args.overlap,
        design=design,
        progress=not args.quiet,
        shadows=not args.no_shadows,
        color_positions=colors,
    )
    summary = {
        k: res[k]
        for k in (
            "path",
            "frames",
            "width",
            "height",
            "fps",
            "duration",
            "sha256",
            "seconds_per_frame",
            "mean_red_fraction",
        )
    }
    print(json.dumps(summary))
    return 0

"""``crowdstudy metrics FILE.npz [--reference BASELINE.npz]``: overlap, jerk, tracking.

Prints a small table; ``--json out.json`` also writes the numbers with provenance. Overlap
is measured on sampled frames (``--frames auto``: every 10th frame of clips longer than
100 frames, e.g. 60 of the 600 frames of a 20 s clip at 30 fps), which the output states.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="CrowdAnimation .npz to measure")
    parser.add_argument("--reference", type=Path, default=None,
                        help="the input animation it should follow (e.g. the Baseline): adds tracking "
                             "error and overlap ratios")
    parser.add_argument("--resolution", type=float, default=0.02, help="overlap grid spacing in metres (0.02)")
    parser.add_argument("--frames", default="auto",
                        help="frames for overlap: 'auto' (every 10th when > 100 frames), 'all', 'every:K' "
                             "or a comma-separated list of indices")
    parser.add_argument("--geometry", choices=("mesh", "capsule", "both"), default="both",
                        help="overlap geometry (both)")
    parser.add_argument("--device", default=None,
                        help="mesh crossings on 'cpu' / 'cuda:0' (Warp) or 'numpy' (default: CUDA when present)")
    parser.add_argument("--json", type=Path, default=None, help="also write the results as JSON here")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _parse_frames(text: str):
    text = str(text).strip()
    if text in ("auto", "all") or text.startswith("every:"):
        return text
    try:
        return [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise InvalidInputError(f"--frames: expected 'auto', 'all', 'every:K' or indices like 0,10,20; got {text!r}") from None


def _table(summary: dict) -> str:
    rows = [("characters", f"{summary['characters']}"),
            ("frames", f"{summary['frames']} at {summary['fps']:g} fps"),
            ("overlap frames", f"{summary.get('frames_measured', '-')}"
                               + (f" (every {summary['frame_step']})" if summary.get("frame_step") else " (selected)")),
            ("resolution", f"{100 * summary['resolution_m']:g} cm")]
    for geometry in ("mesh", "capsule"):
        key = f"overlap_{geometry}_litres"
        if key in summary:
            text = f"{summary[key]:.3f} L/character"
            ref = summary.get(f"reference_overlap_{geometry}_litres")
            if ref is not None:
                ratio = summary.get(f"overlap_{geometry}_ratio")
                text += f"  (reference {ref:.3f} L, ratio {ratio:.3f})" if ratio is not None else f"  (reference {ref:.3f} L)"
            rows.append((f"overlap {geometry}", text))
    if "jerk_m_s3" in summary:
        text = f"{summary['jerk_m_s3']:.1f} m/s^3"
        if "reference_jerk_m_s3" in summary:
            text += f"  (reference {summary['reference_jerk_m_s3']:.1f})"
        rows.append(("mean jerk", text))
    rows.append(("intra-body penetration", f"{summary['intra_penetration_cm']:.2f} cm mean deepest "
                                           f"({100 * summary['intra_penetration_fraction']:.1f} % of samples)"))
    if "tracking_error_cm" in summary:
        rows.append(("tracking error", f"{summary['tracking_error_cm']:.2f} cm"))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k.ljust(width)}  {v}" for k, v in rows)


def run(args: argparse.Namespace) -> int:
    from crowdstudy.metrics.summary import summarize
    from crowdstudy.provenance import provenance
    from crowdstudy.scene import CrowdAnimation

    anim = CrowdAnimation.load(args.file)
    reference = CrowdAnimation.load(args.reference) if args.reference is not None else None
    geometries = ("mesh", "capsule") if args.geometry == "both" else (args.geometry,)
    frames = _parse_frames(args.frames)
    summary = summarize(anim, reference, resolution=args.resolution, frames=frames, geometries=geometries,
                        device=args.device, progress=not args.no_progress)
    step = summary.get("frame_step")
    if summary.get("frames_measured", summary["frames"]) < summary["frames"]:
        how = f"one frame in {step}" if step else "selected frames"
        print(f"note: overlap measured on {how} ({summary['frames_measured']} of {summary['frames']}); "
              "--frames all for every frame", file=sys.stderr)
    print(f"{args.file}  [{summary.get('method') or 'unknown method'}]")
    print(_table(summary))
    if args.json is not None:
        seed = anim.meta.get("seed")
        record = {"file": str(args.file), "reference": None if args.reference is None else str(args.reference),
                  "metrics": summary, "provenance": provenance(seed if isinstance(seed, int) else None)}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(record, indent=2, default=float))
        print(f"wrote {args.json}")
    return 0

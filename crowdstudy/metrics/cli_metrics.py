"""``crowdstudy metrics FILE.npz [--reference BASELINE.npz]``: overlap, smoothness, tracking.

``--floor`` adds an estimate of how little any correction could move the characters
(:func:`crowdstudy.metrics.separation_floor`), to read beside the tracking error.

Prints a small table; ``--json out.json`` also writes the numbers (per-character smoothness
included) with provenance; ``--per-character`` also prints a per-character smoothness
table and, with ``--reference``, where the tracking error goes: each character's tracking,
placement and body parts (legs, trunk, arms), with ``--floor`` beside its own floor and
whom it touches in the reference (how often, how deep). With ``--reference`` each
smoothness row shows the reference's value and the ratio (jerk, high-frequency share,
pelvis acceleration: Ours / reference) or the difference (largest joint speed, foot slide
p99: Ours - reference, m/s). Overlap
is measured on sampled frames (``--frames auto``: every 10th frame of clips longer than
100 frames, e.g. 60 of the 600 frames of a 20 s clip at 30 fps), which the output states.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from crowdstudy.body.skeleton import BODY_PARTS
from crowdstudy.errors import InvalidInputError

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="CrowdAnimation .npz to measure")
    parser.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="the input animation it should follow (e.g. the Baseline): adds tracking error and overlap ratios",
    )
    parser.add_argument("--resolution", type=float, default=0.02, help="overlap grid spacing in metres (0.02)")
    parser.add_argument(
        "--frames",
        default="auto",
        help="frames for overlap: 'auto' (every 10th when > 100 frames), 'all', 'every:K' "
        "or a comma-separated list of indices",
    )
    parser.add_argument(
        "--geometry", choices=("mesh", "capsule", "both"), default="both", help="overlap geometry (both)"
    )
    parser.add_argument(
        "--device",
        default=None,
        help="mesh crossings on 'cpu' / 'cuda:0' (Warp) or 'numpy' (default: CUDA when present)",
    )
    parser.add_argument("--json", type=Path, default=None, help="also write the results as JSON here")
    parser.add_argument(
        "--per-character",
        action="store_true",
        help="also print a table of the smoothness of each character and, with --reference, of "
        "where each character's tracking error is (placement, legs, trunk, arms; with --floor "
        "also its floor and whom it touches in the reference)",
    )
    parser.add_argument(
        "--floor",
        action="store_true",
        help="also estimate the tracking floor: the least joint displacement that would take the "
        "capsules of the reference (or of FILE) apart, every 30th frame "
        "(crowdstudy.metrics.separation_floor; seconds a frame, much slower than the overlap)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _parse_frames(text: str):
    text = str(text).strip()
    if text in ("auto", "all") or text.startswith("every:"):
        return text
    try:
        return [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise InvalidInputError(
            f"--frames: expected 'auto', 'all', 'every:K' or indices like 0,10,20; got {text!r}"
        ) from None


def _table(summary: dict) -> str:
    rows = [
        ("characters", f"{summary['characters']}"),
        ("frames", f"{summary['frames']} at {summary['fps']:g} fps"),
        (
            "overlap frames",
            f"{summary.get('frames_measured', '-')}"
            + (f" (every {summary['frame_step']})" if summary.get("frame_step") else " (selected)"),
        ),
        ("resolution", f"{100 * summary['resolution_m']:g} cm"),
    ]
    for geometry in ("mesh", "capsule"):
        key = f"overlap_{geometry}_litres"
        if key in summary:
            text = f"{summary[key]:.3f} L/character"
            ref = summary.get(f"reference_overlap_{geometry}_litres")
            if ref is not None:
                ratio = summary.get(f"overlap_{geometry}_ratio")
                text += (
                    f"  (reference {ref:.3f} L, ratio {ratio:.3f})"
                    if ratio is not None
                    else f"  (reference {ref:.3f} L)"
                )
            rows.append((f"overlap {geometry}", text))
    rows.extend(_smoothness_rows(summary))
    rows.append(
        (
            "intra-body penetration",
            f"{summary['intra_penetration_cm']:.2f} cm mean deepest "
            f"({100 * summary['intra_penetration_fraction']:.1f} % of samples)",
        )
    )
    rows.append(
        (
            "skin through walls",
            f"p99 {summary['wall_penetration_p99_cm']:.2f} cm, max "
            f"{summary['wall_penetration_max_cm']:.2f} cm"
            + _compare(summary, "wall_penetration_p99_cm", ".2f", ref_unit=" cm"),
        )
    )
    if "tracking_error_cm" in summary:
        parts = "".join(
            f", {part} {summary[f'tracking_{part}_cm']:.2f}"
            for part, _ in BODY_PARTS
            if summary.get(f"tracking_{part}_cm") is not None
        )
        rows.append(
            (
                "tracking error",
                f"{summary['tracking_error_cm']:.2f} cm (placement "
                f"{summary['tracking_placement_cm']:.2f} cm, motion "
                f"{summary['tracking_motion_cm']:.2f} cm{parts})",
            )
        )
    if "separation_floor_cm" in summary:
        rows.append(
            (
                "tracking floor (estimate)",
                f"{summary['separation_floor_cm']:.2f} cm (arms "
                f"{summary['separation_floor_arms_cm']:.2f} cm; "
                f"{summary['separation_floor_frames']} frames)",
            )
        )
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k.ljust(width)}  {v}" for k, v in rows)


def _fmt(value, spec: str, scale: float = 1.0) -> str:
    return "-" if value is None else format(scale * value, spec)


def _compare(
    summary: dict,
    key: str,
    spec: str,
    *,
    scale: float = 1.0,
    ratio: str | None = None,
    diff: str | None = None,
    unit: str = "",
    ref_unit: str = "",
) -> str:
    """``  (reference R, ratio Q)`` / ``(reference R, +D unit)`` when the summary has a reference."""
    ref_key = f"reference_{key}"
    if ref_key not in summary:
        return ""
    text = f"  (reference {_fmt(summary[ref_key], spec, scale)}{ref_unit}"
    if ratio is not None:
        text += f", ratio {_fmt(summary.get(ratio), '.3f')}"
    if diff is not None:
        text += f", {_fmt(summary.get(diff), '+.3f')}{unit}"
    return text + ")"


def _smoothness_rows(summary: dict) -> list[tuple[str, str]]:
    if "jerk_m_s3" not in summary:
        return []
    from crowdstudy.body.skeleton import JOINT_NAMES

    s = summary
    joint = s.get("max_joint_speed_joint")
    joint_name = JOINT_NAMES[joint] if joint is not None and 0 <= joint < len(JOINT_NAMES) else f"joint {joint}"
    rows = [
        ("mean jerk", f"{_fmt(s['jerk_m_s3'], '.1f')} m/s^3" + _compare(s, "jerk_m_s3", ".1f", ratio="jerk_ratio")),
        (
            f"HF share > {s.get('hf_cutoff_hz', 6.0):g} Hz",
            f"{_fmt(s['hf_share'], '.2f', 100)} %"
            + _compare(s, "hf_share", ".2f", scale=100, ratio="hf_share_ratio", ref_unit=" %"),
        ),
        (
            "max joint speed",
            f"{_fmt(s['max_joint_speed_m_s'], '.2f')} m/s (frame {s['max_joint_speed_frame']}, "
            f"character {s['max_joint_speed_character']}, {joint_name})"
            + _compare(s, "max_joint_speed_m_s", ".2f", diff="max_joint_speed_diff_m_s", unit=" m/s"),
        ),
        (
            "pelvis accel p99",
            f"{_fmt(s['pelvis_accel_p99_m_s2'], '.2f')} m/s^2"
            + _compare(s, "pelvis_accel_p99_m_s2", ".2f", ratio="pelvis_accel_p99_ratio"),
        ),
        (
            "foot slide p99",
            f"{_fmt(s['foot_slide_p99_m_s'], '.3f')} m/s, "
            f"{_fmt(s['foot_slide_fraction_over_5cm_s'], '.1f', 100)} % > 5 cm/s "
            f"of {s['foot_planted_samples']} planted"
            + _compare(s, "foot_slide_p99_m_s", ".3f", diff="foot_slide_p99_diff_m_s", unit=" m/s"),
        ),
        (
            "loop seam jump",
            f"ratio {_fmt(s['seam_ratio'], '.2f')} (seam {_fmt(s['seam_jump_m'], '.2f', 100)} cm, "
            f"step {_fmt(s['seam_frame_step_m'], '.2f', 100)} cm, worst character "
            f"{_fmt(s['seam_ratio_max_character'], '.2f')})" + _compare(s, "seam_ratio", ".2f"),
        ),
    ]
    return rows


def _per_character_table(summary: dict) -> str:
    """One row per character: the smoothness lists of the summary (and jerk / HF ratios
    against the reference when it has one)."""
    per = summary.get("smoothness_per_character")
    if not per:
        return "no per-character smoothness (fewer than 4 frames)"
    ref = summary.get("reference_smoothness_per_character")
    cols = [
        ("jerk m/s^3", "jerk_m_s3", ".1f", 1.0),
        ("HF %", "hf_share", ".2f", 100.0),
        ("max speed m/s", "max_joint_speed_m_s", ".2f", 1.0),
        ("pelvis p99 m/s^2", "pelvis_accel_p99_m_s2", ".2f", 1.0),
        ("slide p99 m/s", "foot_slide_p99_m_s", ".3f", 1.0),
        ("planted", "foot_planted_samples", "d", 1),
        ("seam ratio", "seam_ratio", ".2f", 1.0),
    ]
    header = ["character"] + [c[0] for c in cols]
    if ref:
        header += ["jerk ratio", "HF ratio"]
    lines = []
    for i in range(len(per["jerk_m_s3"])):
        row = [str(i)] + [_fmt(per[key][i], spec, scale) for _, key, spec, scale in cols]
        if ref:
            for key in ("jerk_m_s3", "hf_share"):
                a, b = per[key][i], ref[key][i]
                row.append(_fmt(a / b, ".3f") if a is not None and b else "-")
        lines.append(row)
    return _aligned(header, lines)


def _aligned(header: list[str], lines: list[list[str]]) -> str:
    """The header and rows as right-aligned text columns."""
    widths = [max(len(r[k]) for r in [header] + lines) for k in range(len(header))]
    return "\n".join("  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)) for r in [header] + lines)


def _tracking_table(summary: dict) -> str:
    """One row per character: where its tracking error is (cm), and with ``--floor`` its
    floor and whom it touches in the reference; then the worst characters."""
    per = summary["tracking_per_character"]
    floor = summary.get("separation_floor_per_character")
    cols = [("tracking cm", per["tracking_cm"], ".2f", 1.0), ("placement cm", per["placement_cm"], ".2f", 1.0)]
    cols += [(f"{part} cm", per.get(f"{part}_cm"), ".2f", 1.0) for part, _ in BODY_PARTS]
    if floor:
        cols += [
            ("floor cm", floor["floor_cm"], ".2f", 1.0),
            ("touching %", floor["contact_fraction"], ".0f", 100.0),
            ("partner", floor["partner"], "d", 1),
            ("with it %", floor["partner_fraction"], ".0f", 100.0),
            ("deepest cm", floor["deepest_cm"], ".1f", 1.0),
        ]
    cols = [c for c in cols if c[1] is not None]
    header = ["character"] + [c[0] for c in cols]
    lines = []
    for i in range(len(per["tracking_cm"])):
        row = [str(i)]
        for name, values, spec, scale in cols:
            value = values[i]
            row.append("-" if value is None or (name == "partner" and value < 0) else format(scale * value, spec))
        lines.append(row)
    text = _aligned(header, lines)
    worst = sorted(range(len(per["tracking_cm"])), key=lambda i: -per["tracking_cm"][i])[:3]
    text += "\nlargest tracking: " + ", ".join(f"character {i} ({per['tracking_cm'][i]:.2f} cm)" for i in worst)
    if floor:
        text += (
            "\n(touching: share of the floor's frames in which the reference's capsules, with the mesh skin "
            "and margin, reach into another character's; partner: the one reached deepest most often)"
        )
    return text


def run(args: argparse.Namespace) -> int:
    from crowdstudy.metrics.summary import summarize
    from crowdstudy.paths import check_output_path
    from crowdstudy.provenance import provenance
    from crowdstudy.scene import CrowdAnimation

    if args.json is not None:
        check_output_path(args.json, "--json")
    anim = CrowdAnimation.load(args.file)
    reference = CrowdAnimation.load(args.reference) if args.reference is not None else None
    geometries = ("mesh", "capsule") if args.geometry == "both" else (args.geometry,)
    frames = _parse_frames(args.frames)
    summary = summarize(
        anim,
        reference,
        resolution=args.resolution,
        frames=frames,
        geometries=geometries,
        device=args.device,
        progress=not args.no_progress,
        per_character=True,
    )
    if args.floor:
        from crowdstudy.metrics.floor import separation_floor

        summary.update(separation_floor(reference if reference is not None else anim).as_dict(per_character=True))
    step = summary.get("frame_step")
    if summary.get("frames_measured", summary["frames"]) < summary["frames"]:
        how = f"one frame in {step}" if step else "selected frames"
        print(
            f"note: overlap measured on {how} ({summary['frames_measured']} of {summary['frames']}); "
            "--frames all for every frame",
            file=sys.stderr,
        )
    print(f"{args.file}  [{summary.get('method') or 'unknown method'}]")
    print(_table(summary))
    if args.per_character:
        print()
        print(_per_character_table(summary))
        if "tracking_per_character" in summary:
            print()
            print(_tracking_table(summary))
    if args.json is not None:
        seed = anim.meta.get("seed")
        record = {
            "file": str(args.file),
            "reference": None if args.reference is None else str(args.reference),
            "metrics": summary,
            "provenance": provenance(seed if isinstance(seed, int) else None),
        }
        args.json.write_text(json.dumps(record, indent=2, default=float))
        print(f"wrote {args.json}")
    return 0

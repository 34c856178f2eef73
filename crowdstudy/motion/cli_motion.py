"""``crowdstudy motion``: the motion-capture library: list it, rebuild it, measure it.

Examples::

    crowdstudy motion list                                   # the shipped clips
    crowdstudy motion build-library --source ../shared/data/mocap
    crowdstudy motion report --level D5 --json build/motion_report.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.paths import check_output_dir, check_output_path
from crowdstudy.tables import format_table

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    sub.add_parser("list", help="the shipped clips: name, kind, source, length")
    b = sub.add_parser("build-library", help="convert the CMU BVH takes into the package's clip library")
    b.add_argument("--source", required=True, help="folder of the BVH takes (shared/data/mocap)")
    b.add_argument(
        "--out",
        default=None,
        help="output folder (default: crowdstudy/motion/mocap in a source checkout; required otherwise)",
    )
    b.add_argument("--take", action="append", default=None, help="only this take (repeatable)")
    r = sub.add_parser("report", help="loops, beat, hands, feet and walks of the library, measured")
    r.add_argument("--design", default=None, help="study design TOML (default: the paper's)")
    r.add_argument("--level", default="D5", help="density level of the concert and corridor cells (default D5)")
    r.add_argument("--no-hands", action="store_true", help="skip the hand self-contact table (the slowest)")
    r.add_argument("--json", default=None, help="also write the tables to this JSON file")


def _list() -> int:
    from crowdstudy.motion.library import list_clips, load_clip

    rows = []
    for source in ("mocap", "procedural"):
        for kind in ("dance", "idle", "walk"):
            for name in list_clips(kind, source):
                c = load_clip(name)
                rows.append(
                    {
                        "clip": name,
                        "kind": kind,
                        "source": c.meta.get("trial", source),
                        "default": "yes"
                        if source == "mocap" and name in list_clips(kind, source, default_only=True)
                        else "",
                        "seconds": round(c.duration, 2),
                        "loop": "yes" if c.loop else "take",
                        "speed": "" if c.speed is None else round(c.speed, 2),
                    }
                )
    print(format_table(rows))
    return 0


def _build(args) -> int:
    from crowdstudy.motion.mocap_build import build_library, default_output

    if args.out is None:
        out = default_output()
        if not (out.parent.parent.parent / "pyproject.toml").is_file():
            raise InvalidInputError("--out: required outside a source checkout (the installed package is read-only)")
    else:
        out = check_output_dir(args.out, "--out")
    source = Path(args.source)
    if not source.is_dir():
        raise InvalidInputError(f"--source: {str(source)!r} is not a folder")
    build_library(source, out, names=args.take, progress=True)
    print(f"wrote {out / 'takes.npz'} and {out / 'library.json'}")
    return 0


def _report(args) -> int:
    from crowdstudy.design import load_design
    from crowdstudy.motion.report import motion_report

    if args.json:
        check_output_path(args.json, "--json")
    design = load_design(args.design)
    if args.level not in design.densities:
        raise InvalidInputError(
            f"--level: unknown density level {args.level!r}; expected one of {', '.join(design.densities)}"
        )
    rep = motion_report(design, level=args.level, with_hands=not args.no_hands)
    titles = {
        "dances": "Dances: loops on the beat",
        "beat": f"Concert {args.level}: bounce against the beat",
        "hands": "Hands inside the own body beyond 2 cm (6 bodies)",
        "feet": "Foot skate per contact",
        "walks": "Walking loops",
    }
    for key, title in titles.items():
        if key in rep:
            print(f"\n{title}\n{format_table(rep[key])}")
    if args.json:
        Path(args.json).write_text(json.dumps(rep, indent=1) + "\n")
        print(f"\nwrote {args.json}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.action == "list":
        return _list()
    if args.action == "build-library":
        return _build(args)
    return _report(args)

"""``crowdstudy export``: responses.csv, participants.csv (and demographics.csv) from the study database."""

from __future__ import annotations

import argparse

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--db", required=True, metavar="URL", help="SQLAlchemy URL of the study database")
    parser.add_argument("--out", required=True, metavar="CSV", help="responses CSV to write")
    parser.add_argument("--demographics", metavar="CSV", help="also write the demographics CSV here")
    parser.add_argument(
        "--participants",
        metavar="CSV",
        help="participants CSV with the exclusion flags (default: participants.csv beside --out)",
    )
    parser.add_argument(
        "--online",
        metavar="TOML",
        help="the exclusion rules' file (default: the [online] table of the toolkit's study.toml)",
    )


def run(args: argparse.Namespace) -> int:
    from crowdstudy.paths import check_output_path
    from crowdstudy.study.export import export_study

    check_output_path(args.out, "--out")
    if args.demographics:
        check_output_path(args.demographics, "--demographics")
    if args.participants:
        check_output_path(args.participants, "--participants")
    summary = export_study(args.db, args.out, args.demographics, participants=args.participants, online=args.online)
    print(
        f"crowdstudy export: {summary['responses']} answers"
        + (f" and {summary['comparisons']} comparisons" if summary["comparisons"] else "")
        + f" of {summary['participants']} participants "
        f"({summary['excluded']} flagged for exclusion) -> {', '.join(summary['files'])}"
    )
    return 0

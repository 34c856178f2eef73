"""``crowdstudy export``: responses.csv (and demographics.csv) from the study database."""

from __future__ import annotations

import argparse

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--db", required=True, metavar="URL", help="SQLAlchemy URL of the study database")
    parser.add_argument("--out", required=True, metavar="CSV", help="responses CSV to write")
    parser.add_argument("--demographics", metavar="CSV", help="also write the demographics CSV here")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.paths import check_output_path
    from crowdstudy.study.export import export_study

    check_output_path(args.out, "--out")
    if args.demographics:
        check_output_path(args.demographics, "--demographics")
    summary = export_study(args.db, args.out, args.demographics)
    print(f"crowdstudy export: {summary['responses']} answers of {summary['participants']} participants -> "
          f"{', '.join(summary['files'])}")
    return 0

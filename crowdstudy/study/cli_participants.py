"""``crowdstudy participants``: list the study's participants, or withdraw one.

    crowdstudy participants list --db URL [--status withdrawn] [--json FILE]
    crowdstudy participants withdraw --db URL PARTICIPANT_ID [--reason TEXT]
    crowdstudy participants audit --db URL

``withdraw`` deletes the participant's answers and demographics and keeps one audit line
(:mod:`crowdstudy.study.roster`), as the consent text promises; it works on a running
study (every server process refuses that participant from then on).
"""

from __future__ import annotations

import argparse
import json

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    ls = sub.add_parser("list", help="one line per participant: status, answers, platform ids")
    ls.add_argument("--db", required=True, metavar="URL", help="SQLAlchemy URL of the study database")
    ls.add_argument("--status", choices=("active", "completed", "screened_out", "withdrawn"), help="only these")
    ls.add_argument("--json", metavar="FILE", help="also write the list as JSON")
    wd = sub.add_parser("withdraw", help="delete a participant's answers and demographics (audit line kept)")
    wd.add_argument("--db", required=True, metavar="URL", help="SQLAlchemy URL of the study database")
    wd.add_argument("participant", metavar="PARTICIPANT_ID")
    wd.add_argument("--reason", default="", help="recorded in the audit line (<= 200 characters)")
    au = sub.add_parser("audit", help="print the audit log")
    au.add_argument("--db", required=True, metavar="URL", help="SQLAlchemy URL of the study database")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.paths import check_output_path
    from crowdstudy.study.roster import audit_rows, list_participants, withdraw_participant
    from crowdstudy.study.schedule import check_participant_id
    from crowdstudy.study.storage import StudyStore
    from crowdstudy.tables import format_table

    if args.action == "list" and args.json:
        check_output_path(args.json, "--json")
    if args.action == "withdraw":
        check_participant_id(args.participant, "PARTICIPANT_ID")
    if args.db.startswith("sqlite:///"):
        from pathlib import Path

        from crowdstudy.errors import InvalidInputError

        path = args.db[len("sqlite:///") :]
        if path not in ("", ":memory:") and not Path(path).is_file():
            raise InvalidInputError(f"--db: database file {path!r} does not exist")
    store = StudyStore(args.db, create=False)
    try:
        if args.action == "list":
            rows = [r for r in list_participants(store) if args.status is None or r["status"] == args.status]
            cols = ["participant", "status", "answered", "trials", "started_at", "completed_at", "prolific_pid"]
            print(
                format_table([{c: ("" if r[c] is None else r[c]) for c in cols} for r in rows], cols)
                if rows
                else "no participants"
            )
            if args.json:
                with open(args.json, "w", encoding="utf-8") as fh:
                    json.dump(rows, fh, indent=2)
                    fh.write("\n")
        elif args.action == "withdraw":
            line = withdraw_participant(store, args.participant, by="cli", reason=args.reason)
            print(f"crowdstudy participants: withdrew {args.participant} at {line['at']}: {line['detail']}")
        else:
            for line in audit_rows(store):
                print(f"{line['at']}  {line['action']}  {line['participant_id']}  {line['detail']}")
    finally:
        store.close()
    return 0

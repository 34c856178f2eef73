"""Export the study database to the CSV files the analysis reads (formats: :mod:`crowdstudy.schema`).

``responses.csv``: one row per answered study trial (practice excluded), columns
:data:`RESPONSE_EXPORT_COLUMNS` (:data:`RESPONSE_COLUMNS` then the per-trial data-quality
columns), sorted by participant then trial_index; Q1..Q6 are the raw answers (negative items
NOT reversed). ``participants.csv`` (beside it unless told otherwise): one row per
participant with status, platform ids and the exclusion flags of the online config's rules
(:mod:`crowdstudy.study.quality`, columns :data:`crowdstudy.study.quality.PARTICIPANT_COLUMNS`).
``demographics.csv``: one row per participant, columns :data:`DEMOGRAPHIC_COLUMNS`
(withdrawn participants' cells are empty). A JSON sidecar ``<out>.provenance.json`` records
the software provenance and the row counts.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.provenance import provenance
from crowdstudy.schema import DEMOGRAPHIC_COLUMNS, RESPONSE_COLUMNS, RESPONSE_QUALITY_COLUMNS

__all__ = [
    "RESPONSE_COLUMNS",
    "DEMOGRAPHIC_COLUMNS",
    "RESPONSE_EXPORT_COLUMNS",
    "rows_to_csv",
    "export_study",
    "participants_rows",
]

#: responses.csv as written by the export: the analysis columns, then the data-quality ones.
RESPONSE_EXPORT_COLUMNS = (*RESPONSE_COLUMNS, *RESPONSE_QUALITY_COLUMNS)


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


def rows_to_csv(rows: Iterable[Mapping], columns: Sequence[str]) -> str:
    """CSV text (header + rows, ``\\n`` line ends) of ``rows`` restricted to ``columns``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row[c]) for c in columns])
    return buf.getvalue()


def participants_rows(store, online, item_ids) -> list[dict]:
    """participants.csv rows of ``store`` flagged with the rules of ``online`` (an OnlineConfig)."""
    from crowdstudy.study.quality import flag_participants
    from crowdstudy.study.roster import list_participants

    return flag_participants(list_participants(store), store.response_rows(), online, item_ids)


def export_study(
    db_url: str,
    out: str | Path,
    demographics: str | Path | None = None,
    *,
    participants: str | Path | None = None,
    online: str | Path | None = None,
) -> dict:
    """Write responses.csv, participants.csv (default: beside ``out``) and, if asked,
    demographics.csv from the database at ``db_url``; online: the TOML file of the exclusion
    rules (default: the [online] table of the toolkit's study.toml).

    Returns {"responses": rows written, "participants": ..., "excluded": ..., "files": [paths]}.
    """
    from crowdstudy.schema import ITEM_COLUMNS
    from crowdstudy.study.quality import PARTICIPANT_COLUMNS, load_online_config
    from crowdstudy.study.storage import StudyStore

    if db_url.startswith("sqlite:///"):
        path = Path(db_url[len("sqlite:///") :])
        if str(path) not in ("", ":memory:") and not path.is_file():
            raise InvalidInputError(f"--db: database file {str(path)!r} does not exist")
    rules = load_online_config(online)
    store = StudyStore(db_url, create=False)
    try:
        responses = store.response_rows()
        people = store.demographics_rows() if demographics is not None else []
        flagged = participants_rows(store, rules, ITEM_COLUMNS)
    finally:
        store.close()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(rows_to_csv(responses, RESPONSE_EXPORT_COLUMNS), encoding="utf-8")
    part_path = Path(participants) if participants is not None else out.with_name("participants.csv")
    part_path.parent.mkdir(parents=True, exist_ok=True)
    part_path.write_text(rows_to_csv(flagged, PARTICIPANT_COLUMNS), encoding="utf-8")
    files = [str(out), str(part_path)]
    if demographics is not None:
        demographics = Path(demographics)
        demographics.parent.mkdir(parents=True, exist_ok=True)
        demographics.write_text(rows_to_csv(people, DEMOGRAPHIC_COLUMNS), encoding="utf-8")
        files.append(str(demographics))
    summary = {
        "responses": len(responses),
        "participants": len({r["participant_id"] for r in responses}),
        "excluded": sum(r["excluded"] for r in flagged),
        "files": files,
    }
    sidecar = out.with_name(out.name + ".provenance.json")
    sidecar.write_text(
        json.dumps(
            provenance(
                None,
                command="crowdstudy export",
                responses=summary["responses"],
                participants=summary["participants"],
                excluded=summary["excluded"],
                exclusion_rules=rules.source,
                demographics_rows=len(people) if demographics is not None else None,
            ),
            indent=2,
        )
        + "\n",
        encoding="utf-8",
    )
    return summary

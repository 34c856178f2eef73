"""Export the study database to the CSV files the analysis reads (formats: :mod:`crowdstudy.schema`).

``responses.csv``: one row per answered study trial (practice excluded), columns
:data:`RESPONSE_COLUMNS`, sorted by participant then trial_index; Q1..Q6 are the raw
answers (negative items NOT reversed). ``demographics.csv``: one row per participant,
columns :data:`DEMOGRAPHIC_COLUMNS`. A JSON sidecar ``<out>.provenance.json`` records the
software provenance and the row counts.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Iterable, Mapping, Sequence

from crowdstudy.errors import InvalidInputError
from crowdstudy.provenance import provenance
from crowdstudy.schema import DEMOGRAPHIC_COLUMNS, RESPONSE_COLUMNS

__all__ = ["RESPONSE_COLUMNS", "DEMOGRAPHIC_COLUMNS", "rows_to_csv", "export_study"]



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


def export_study(db_url: str, out: str | Path, demographics: str | Path | None = None) -> dict:
    """Write responses.csv (and demographics.csv) from the database at ``db_url``.

    Returns {"responses": rows written, "participants": ..., "files": [paths]}.
    """
    from crowdstudy.study.storage import StudyStore

    if db_url.startswith("sqlite:///"):
        path = Path(db_url[len("sqlite:///"):])
        if str(path) not in ("", ":memory:") and not path.is_file():
            raise InvalidInputError(f"--db: database file {str(path)!r} does not exist")
    store = StudyStore(db_url, create=False)
    try:
        responses = store.response_rows()
        people = store.demographics_rows() if demographics is not None else []
    finally:
        store.close()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(rows_to_csv(responses, RESPONSE_COLUMNS), encoding="utf-8")
    files = [str(out)]
    if demographics is not None:
        demographics = Path(demographics)
        demographics.parent.mkdir(parents=True, exist_ok=True)
        demographics.write_text(rows_to_csv(people, DEMOGRAPHIC_COLUMNS), encoding="utf-8")
        files.append(str(demographics))
    summary = {"responses": len(responses), "participants": len({r["participant_id"] for r in responses}),
               "files": files}
    sidecar = out.with_name(out.name + ".provenance.json")
    sidecar.write_text(json.dumps(provenance(None, command="crowdstudy export", responses=summary["responses"],
                                             participants=summary["participants"],
                                             demographics_rows=len(people) if demographics is not None else None),
                                  indent=2) + "\n", encoding="utf-8")
    return summary

"""Export the study database to the CSV files the analysis reads (formats: :mod:`crowdstudy.schema`).

``responses.csv``: one row per answered Likert or slider trial (practice excluded), columns
:func:`response_export_columns` of the study's item ids (:data:`RESPONSE_EXPORT_COLUMNS` for
the paper's Q1..Q6: :data:`RESPONSE_COLUMNS` then the per-trial data-quality columns), sorted
by participant then trial_index; the item columns hold the raw answers (negative items NOT
reversed). ``comparisons.csv`` (beside it, when the study has 2afc answers or a 2afc stage):
one row per answered 2afc trial, columns :data:`COMPARISON_EXPORT_COLUMNS`; its attention
check columns say ``left`` / ``right``. ``participants.csv`` (beside it unless told otherwise): one row per
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
from crowdstudy.schema import (
    CHOICES,
    COMPARISON_COLUMNS,
    DEMOGRAPHIC_COLUMNS,
    RESPONSE_COLUMNS,
    RESPONSE_QUALITY_COLUMNS,
    response_columns,
)

__all__ = [
    "RESPONSE_COLUMNS",
    "DEMOGRAPHIC_COLUMNS",
    "RESPONSE_EXPORT_COLUMNS",
    "COMPARISON_EXPORT_COLUMNS",
    "response_export_columns",
    "split_rows",
    "rows_to_csv",
    "export_study",
    "participants_rows",
]

#: responses.csv as written by the export: the analysis columns, then the data-quality ones.
RESPONSE_EXPORT_COLUMNS = (*RESPONSE_COLUMNS, *RESPONSE_QUALITY_COLUMNS)
#: comparisons.csv as written by the export.
COMPARISON_EXPORT_COLUMNS = (*COMPARISON_COLUMNS, *RESPONSE_QUALITY_COLUMNS)


def response_export_columns(item_ids: Sequence[str]) -> tuple[str, ...]:
    """responses.csv's columns for a study whose items are ``item_ids``."""
    return (*response_columns(item_ids), *RESPONSE_QUALITY_COLUMNS)


def split_rows(rows: Iterable[Mapping]) -> tuple[list[dict], list[dict]]:
    """StudyStore.response_rows split into (responses.csv rows, comparisons.csv rows): the
    2afc rows get their left/right columns, ``chosen_method`` and the check as a side."""
    ratings, comparisons = [], []
    for row in rows:
        if row["task"] != "2afc":
            ratings.append(dict(row))
            continue
        side = {k: (None if row[k] is None else CHOICES[int(row[k]) - 1]) for k in ("check_answer", "check_value")}
        comparisons.append(
            {
                **row,
                **side,
                "stimulus_left": row["stimulus_id"],
                "method_left": row["method"],
                "chosen_method": row["method"] if row["choice"] == "left" else row["method_right"],
            }
        )
    return ratings, comparisons


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


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


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

    comparisons.csv (beside ``out``) is written when the database holds 2afc answers or a
    2afc schedule. Returns {"responses": rows written, "comparisons": ..., "participants":
    ..., "excluded": ..., "files": [paths]}.
    """
    from crowdstudy.study.quality import PARTICIPANT_COLUMNS, load_online_config
    from crowdstudy.study.storage import StudyStore

    if db_url.startswith("sqlite:///"):
        path = Path(db_url[len("sqlite:///") :])
        if str(path) not in ("", ":memory:") and not path.is_file():
            raise InvalidInputError(f"--db: database file {str(path)!r} does not exist")
    rules = load_online_config(online)
    store = StudyStore(db_url, create=False)
    try:
        item_ids = store.item_ids()
        responses, comparisons = split_rows(store.response_rows())
        has_2afc = bool(comparisons) or store.has_task("2afc")
        people = store.demographics_rows() if demographics is not None else []
        flagged = participants_rows(store, rules, item_ids)
    finally:
        store.close()
    out = Path(out)
    part_path = Path(participants) if participants is not None else out.with_name("participants.csv")
    # every file's text first, then the writes: an error leaves nothing half-written
    texts = {out: rows_to_csv(responses, response_export_columns(item_ids))}
    if has_2afc:
        texts[out.with_name("comparisons.csv")] = rows_to_csv(comparisons, COMPARISON_EXPORT_COLUMNS)
    texts[part_path] = rows_to_csv(flagged, PARTICIPANT_COLUMNS)
    if demographics is not None:
        texts[Path(demographics)] = rows_to_csv(people, DEMOGRAPHIC_COLUMNS)
    for path, text in texts.items():
        _write(path, text)
    files = [str(path) for path in texts]
    summary = {
        "responses": len(responses),
        "comparisons": len(comparisons),
        "participants": len({r["participant_id"] for r in (*responses, *comparisons)}),
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
                comparisons=summary["comparisons"] if has_2afc else None,
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

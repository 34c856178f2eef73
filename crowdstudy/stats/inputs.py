"""Reading what ``crowdstudy analyze`` is given: responses.csv, its JSON sidecar and the
participants table of the study export, with errors that name the file.

- :func:`read_csv_file`: a CSV file as a DataFrame; an empty, binary or unparsable file is
  an error naming it.
- :func:`read_sidecar`: ``STEM.json`` beside ``STEM.csv`` (written by the simulators:
  ``{"simulated": true, "note": ...}``), or ``{}``.
- :func:`read_participants` / :func:`apply_exclusions`: ``participants.csv`` of the study
  export (columns ``participant``, ``excluded`` 0/1, ``exclusion_reason``: rule names
  separated by ";"); excluded participants are dropped before the analysis and counted per
  reason.
- :func:`load_responses`: all of the above for one analysis: the validated, complete
  responses with their source, simulated mark and exclusions (:class:`LoadedResponses`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Literal

import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import plain, row_label
from crowdstudy.stats.scoring import check_complete, validate_responses

__all__ = [
    "read_csv_file",
    "read_sidecar",
    "read_participants",
    "apply_exclusions",
    "Exclusions",
    "PARTICIPANT_COLUMNS",
    "LoadedResponses",
    "load_responses",
]

#: Columns participants.csv must have (others are kept and ignored).
PARTICIPANT_COLUMNS = ("participant", "excluded", "exclusion_reason")


def read_csv_file(path: str | Path, what: str) -> pd.DataFrame:
    """Read a CSV file; InvalidInputError naming ``what`` and the file when it does not
    exist, is empty, holds binary data (a NUL byte in its first 64 KiB) or does not parse."""
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"{what} file {str(path)!r} does not exist")
    with open(path, "rb") as fh:
        head = fh.read(65536)
    if not head.strip():
        raise InvalidInputError(f"{what} file {str(path)!r} is empty")
    if b"\x00" in head:
        raise InvalidInputError(f"{what} file {str(path)!r} is not a text CSV file (it holds binary data)")
    try:
        return pd.read_csv(path)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InvalidInputError(f"{what} file {str(path)!r} is not a readable CSV file ({reason})") from None


def read_sidecar(path: str | Path) -> dict:
    """The JSON sidecar ``STEM.json`` of ``STEM.csv`` as a dict, ``{}`` when there is none."""
    side = Path(path).with_suffix(".json")
    if not side.is_file():
        return {}
    try:
        data = json.loads(side.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InvalidInputError(f"sidecar {str(side)!r} is not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise InvalidInputError(f"sidecar {str(side)!r} must hold a JSON object, got {type(data).__name__}")
    return data


def read_participants(participants: str | Path | pd.DataFrame) -> pd.DataFrame:
    """participants.csv (a path, or the table itself) as a DataFrame with ``participant``
    (str), ``excluded`` (bool) and ``exclusion_reason`` (str, "" when none); errors name the
    file, column and 1-based row."""
    if isinstance(participants, pd.DataFrame):
        src, table = "participants", participants
    else:
        src, table = str(participants), read_csv_file(participants, "participants")
    missing = [c for c in PARTICIPANT_COLUMNS if c not in table.columns]
    if missing:
        raise InvalidInputError(
            f"{src}: missing column(s) {', '.join(map(repr, missing))}; have {', '.join(map(str, table.columns))}"
        )
    if table["participant"].isna().any():
        i = int(table["participant"].isna().to_numpy().nonzero()[0][0])
        raise InvalidInputError(f"{src}: column 'participant' {row_label(i)} is empty")
    ids = table["participant"].astype(str)
    dup = ids.duplicated().to_numpy()
    if dup.any():
        i = int(dup.nonzero()[0][0])
        raise InvalidInputError(f"{src}: participant {ids.iloc[i]!r} is listed twice ({row_label(i)})")
    flag = pd.to_numeric(table["excluded"], errors="coerce")
    bad = ~flag.isin([0, 1])
    if bad.any():
        i = int(bad.to_numpy().nonzero()[0][0])
        raise InvalidInputError(
            f"{src}: column 'excluded' {row_label(i)} (participant {ids.iloc[i]!r}) holds "
            f"{plain(table['excluded'].iloc[i])}; expected 0 or 1"
        )
    reason = table["exclusion_reason"].map(lambda v: "" if pd.isna(v) else str(v).strip())
    return pd.DataFrame({"participant": ids, "excluded": flag.astype(int).astype(bool), "exclusion_reason": reason})


@dataclasses.dataclass(frozen=True)
class Exclusions:
    """Who was dropped before the analysis: ``source`` (the participants file),
    ``listed`` (participants in it), ``excluded`` (ids, sorted), ``reasons`` (rule name ->
    number of excluded participants it names; a participant with two rules counts for
    both; ``"unspecified"`` when the reason is empty)."""

    source: str
    listed: int
    excluded: tuple[str, ...]
    reasons: dict[str, int]

    def as_dict(self) -> dict:
        return {
            "source": self.source,
            "listed": self.listed,
            "n_excluded": len(self.excluded),
            "excluded": list(self.excluded),
            "reasons": dict(self.reasons),
        }

    def text(self) -> str:
        """One line for the summary."""
        if not self.excluded:
            return f"Exclusions ({self.source}): none of {self.listed} participants excluded."
        why = ", ".join(f"{k}: {v}" for k, v in self.reasons.items())
        return (
            f"Exclusions ({self.source}): {len(self.excluded)} of {self.listed} participants excluded before "
            f"the analysis ({why})."
        )


def apply_exclusions(
    responses: pd.DataFrame, participants: pd.DataFrame, source: str
) -> tuple[pd.DataFrame, Exclusions]:
    """Drop the responses of excluded participants. Every participant of ``responses``
    must be listed in ``participants`` (else an error naming the first one missing)."""
    if "participant_id" not in responses.columns:
        raise InvalidInputError("responses: missing column 'participant_id'")
    ids = responses["participant_id"].astype(str)
    known = set(participants["participant"])
    unlisted = sorted(set(ids.dropna()) - known)
    if unlisted:
        raise InvalidInputError(
            f"{source}: participant {unlisted[0]!r} of the responses is not listed "
            f"({len(unlisted)} unlisted); every participant needs a row"
        )
    out = participants[participants["excluded"]]
    counts: dict[str, int] = {}
    for text in out["exclusion_reason"]:
        rules = sorted({r.strip() for r in text.split(";") if r.strip()}) or ["unspecified"]
        for r in rules:
            counts[r] = counts.get(r, 0) + 1
    reasons = dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
    dropped = set(out["participant"])
    kept = responses[~ids.isin(dropped).to_numpy()]
    if len(kept) == 0 and len(responses):
        raise InvalidInputError(f"{source}: every participant of the responses is excluded; nothing to analyse")
    return kept, Exclusions(
        source=source, listed=int(len(participants)), excluded=tuple(sorted(dropped)), reasons=reasons
    )


@dataclasses.dataclass(frozen=True)
class LoadedResponses:
    """Responses ready for the analysis: ``data`` validated against the design, excluded
    participants dropped, every stage present complete; ``source``: the file (or
    "responses" for a DataFrame); ``simulated`` and ``note``: from the sidecar (or the
    caller); ``exclusions``: None without a participants table."""

    data: pd.DataFrame
    source: str
    simulated: bool
    note: str
    exclusions: Exclusions | None


def load_responses(
    responses: pd.DataFrame | str | Path,
    design,
    *,
    participants: str | Path | pd.DataFrame | Literal[False] | None = None,
    simulated: bool | None = None,
    allow_empty: bool = False,
) -> LoadedResponses:
    """Read and check the responses of one analysis.

    ``responses``: a DataFrame in the responses.csv schema (``attrs["simulated"]`` marks
    it simulated) or a path to the CSV (its sidecar ``STEM.json`` is read). ``participants``:
    participants.csv (path or DataFrame; None: participants.csv beside a responses path
    when it exists; False: none). ``simulated``: overrides the sidecar. ``allow_empty``: a
    table without rows is returned empty (a design whose stages are all 2afc) instead of
    being an error.

    Each participant must answer each stimulus once (a repeated answer is an error naming
    participant, cell and rows) and every stage present must have all its design levels.
    """
    side: dict = {}
    source = "responses"
    path = None
    if isinstance(responses, (str, Path)):
        path = Path(responses)
        source = str(path)
        side = read_sidecar(path)
        responses = read_csv_file(path, "responses")
    elif not isinstance(responses, pd.DataFrame):
        raise InvalidInputError(f"responses must be a DataFrame or a path, got {type(responses).__name__}")
    else:
        side = {"simulated": True} if responses.attrs.get("simulated") else {}
    if participants is None and path is not None and (path.parent / "participants.csv").is_file():
        participants = path.parent / "participants.csv"
    is_sim = bool(side.get("simulated", False)) if simulated is None else bool(simulated)
    note = str(side["note"]) if side.get("note") else ""
    if allow_empty and len(responses) == 0:
        return LoadedResponses(data=responses, source=source, simulated=is_sim, note=note, exclusions=None)
    data = validate_responses(responses.reset_index(drop=True), design, source=source)
    excl = None
    if participants is not None and participants is not False:
        psrc = "participants" if isinstance(participants, pd.DataFrame) else str(participants)
        data, excl = apply_exclusions(data, read_participants(participants), psrc)
    check_complete(data, design, source=source)  # rows named by their index: the file's data rows
    return LoadedResponses(data=data, source=source, simulated=is_sim, note=note, exclusions=excl)

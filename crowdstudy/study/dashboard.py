"""The admin progress dashboard (one HTML page, values HTML-escaped)."""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence

__all__ = ["dashboard_html"]


def dashboard_html(progress: Sequence[Mapping], title: str) -> str:
    """A table of every participant's progress with links to the CSV exports (the links
    carry no token: the browser's admin cookie opens them).

    progress: rows of :meth:`StudyStore.progress`.
    """
    done = sum(1 for p in progress if p["completed_at"])
    answers = sum(int(p["answered"]) for p in progress)
    rows = []
    for p in progress:
        pct = 100.0 * p["answered"] / p["trials"] if p["trials"] else 0.0
        state = (
            "withdrawn"
            if p.get("withdrawn_at")
            else "screened out"
            if p.get("screened_out_at")
            else "completed"
            if p["completed_at"]
            else "in trials"
            if p["practice_at"]
            else "practice"
            if p["demographics_at"]
            else "demographics"
            if p["consented_at"]
            else "consent"
        )
        cells = [
            p["participant_id"],
            state,
            f"{p['answered']} / {p['trials']}",
            p["started_at"],
            p["completed_at"] or "",
        ]
        rows.append(
            "<tr>"
            + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
            + f'<td><progress max="100" value="{pct:.0f}"></progress></td></tr>'
        )
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta http-equiv="refresh" content="15">
<title>crowdstudy admin</title>
<style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:4px 8px;text-align:left}}</style></head>
<body><h1>{html.escape(title)}</h1>
<p>{len(progress)} participants, {done} completed, {answers} answers stored.
<a href="/admin/export/responses.csv">responses.csv</a> &middot;
<a href="/admin/export/demographics.csv">demographics.csv</a> &middot;
<a href="/admin/export/participants.csv">participants.csv</a> &middot;
<a href="/admin/progress.json">progress.json</a></p>
<form method="post" action="/admin/logout"><button type="submit">Log out</button></form>
<table><thead><tr><th>participant</th><th>state</th><th>answers</th><th>started</th><th>completed</th>
<th>progress</th></tr></thead><tbody>
{chr(10).join(rows)}
</tbody></table></body></html>
"""

"""Participants as the researcher manages them: status, listing, withdrawal with an audit line.

A participant's status follows from the stored timestamps: ``withdrawn`` (withdrawal
recorded), ``screened_out`` (failed the screen check before consent), ``completed``, else
``active``. Withdrawing (the participant's own button, or ``crowdstudy participants
withdraw``) deletes, in one transaction, the participant's answers (study and practice), the
refused duplicates, the schedule and the demographics (age, gender, browser user agent),
records ``withdrawn_at`` (from then on the participant API answers 410 to that id) and
appends one line to ``audit_log`` (time, action, id, who asked and the row counts deleted;
no answer data). The participant row itself stays, with the crowdsourcing platform's ids, so
the same id cannot register again and the submission can be returned on the platform, as
the consent text says.
"""

from __future__ import annotations

from crowdstudy.errors import InvalidInputError
from crowdstudy.study.storage import StudyStore, utc_now

__all__ = ["STATUSES", "status_of", "list_participants", "withdraw_participant", "audit_rows"]

STATUSES = ("active", "completed", "screened_out", "withdrawn")


def status_of(row) -> str:
    """The status (one of STATUSES) of a participants-table row (a mapping)."""
    if row.get("withdrawn_at"):
        return "withdrawn"
    if row.get("screened_out_at"):
        return "screened_out"
    if row.get("completed_at"):
        return "completed"
    return "active"


def list_participants(store: StudyStore) -> list[dict]:
    """One dict per participant (sorted by id): participant, status, started_at, answered,
    trials, completed_at, screened_out_at, withdrawn_at, completion_code and the Prolific ids."""
    import sqlalchemy as sa

    p, s, r = store.participants, store.schedule_t, store.responses
    n_trials = sa.select(s.c.participant_id, sa.func.count().label("n")).group_by(s.c.participant_id).subquery()
    n_ans = (
        sa.select(r.c.participant_id, sa.func.count().label("n"))
        .where(r.c.practice.is_(False))
        .group_by(r.c.participant_id)
        .subquery()
    )
    q = (
        sa.select(
            p, sa.func.coalesce(n_ans.c.n, 0).label("answered"), sa.func.coalesce(n_trials.c.n, 0).label("trials")
        )
        .outerjoin(n_ans, n_ans.c.participant_id == p.c.participant_id)
        .outerjoin(n_trials, n_trials.c.participant_id == p.c.participant_id)
        .order_by(p.c.participant_id)
    )
    with store.engine.connect() as conn:
        rows = [dict(x._mapping) for x in conn.execute(q)]
    keys = (
        "started_at",
        "answered",
        "trials",
        "completed_at",
        "screened_out_at",
        "withdrawn_at",
        "completion_code",
        "prolific_pid",
        "prolific_study_id",
        "prolific_session_id",
    )
    return [
        {"participant": row["participant_id"], "status": status_of(row), **{k: row[k] for k in keys}} for row in rows
    ]


def withdraw_participant(
    store: StudyStore, participant_id: str, *, by: str, reason: str = "", completion_code: str | None = None
) -> dict:
    """Withdraw ``participant_id`` (see the module docstring); returns the audit line as a dict.

    by: who asked ("participant", "admin", "cli"); reason: free text for the audit line
    (<= 200 characters); completion_code: the platform's code for withdrawn participants.
    A second withdrawal of the same participant changes nothing and returns the first line.
    Raises InvalidInputError for an unknown participant.
    """
    import sqlalchemy as sa

    if not isinstance(reason, str) or len(reason) > 200 or not reason.isprintable():
        raise InvalidInputError("--reason must be at most 200 printable characters")
    p, r, a = store.participants, store.responses, store.audit

    def job(conn):
        row = conn.execute(sa.select(p).where(p.c.participant_id == participant_id)).first()
        if row is None:
            return None
        if row.withdrawn_at is not None:
            first = conn.execute(
                sa.select(a).where(a.c.participant_id == participant_id, a.c.action == "withdraw").order_by(a.c.id)
            ).first()
            return (
                dict(first._mapping)
                if first is not None
                else {"participant_id": participant_id, "action": "withdraw", "at": row.withdrawn_at}
            )
        n_ans = conn.execute(sa.delete(r).where(r.c.participant_id == participant_id, r.c.practice.is_(False))).rowcount
        n_prac = conn.execute(sa.delete(r).where(r.c.participant_id == participant_id)).rowcount
        n_conf = conn.execute(
            sa.delete(store.conflicts).where(store.conflicts.c.participant_id == participant_id)
        ).rowcount
        conn.execute(sa.delete(store.schedule_t).where(store.schedule_t.c.participant_id == participant_id))
        at = utc_now()
        conn.execute(
            sa.update(p)
            .where(p.c.participant_id == participant_id)
            .values(
                age=None,
                gender=None,
                user_agent=None,
                withdrawn_at=at,
                completion_code=completion_code if completion_code is not None else row.completion_code,
            )
        )
        detail = (
            f"by {by}; deleted {n_ans} answers, {n_prac} practice answer(s), {n_conf} refused duplicates, "
            f"the schedule and the demographics" + (f"; reason: {reason}" if reason else "")
        )
        line = {"at": at, "action": "withdraw", "participant_id": participant_id, "detail": detail[:512]}
        conn.execute(sa.insert(a).values(**line))
        return line

    line = store._transact(job)
    if line is None:
        raise InvalidInputError(f"participant {participant_id!r} is not in the database {store.url}")
    return line


def audit_rows(store: StudyStore) -> list[dict]:
    """Every audit line, oldest first: at, action, participant_id, detail."""
    import sqlalchemy as sa

    a = store.audit
    with store.engine.connect() as conn:
        return [
            dict(x._mapping)
            for x in conn.execute(sa.select(a.c.at, a.c.action, a.c.participant_id, a.c.detail).order_by(a.c.id))
        ]

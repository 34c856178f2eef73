"""Durable storage of participant sessions: SQLAlchemy Core tables, any SQLAlchemy URL.

SQLite (the default, one file) runs in WAL mode with ``synchronous=FULL``, so an answer is
on disk when :meth:`StudyStore.record_answer` returns. SQLite allows one writer at a time
and each commit costs an fsync (slow on a virtual disk), so all writes go through
one writer thread that commits the jobs arriving together in one transaction ("group
commit"): each caller still returns only after the commit holding its write. Other
databases (PostgreSQL for multi-site studies) run ordinary concurrent transactions. Every
statement is built with SQLAlchemy expressions (bound parameters), never by formatting ids
into SQL text.

Tables
------
- ``stimuli``: the study's stimulus metadata (so the export needs only the database).
- ``participants``: one row per participant: secret hash, consent / demographics /
  practice / completion / screen-out / withdrawal timestamps, age, gender, completion code,
  the crowdsourcing platform's ids (Prolific ``PROLIFIC_PID``, ``STUDY_ID``, ``SESSION_ID``).
- ``schedule``: the participant's trial order, key (participant_id, trial_index), with the
  trial's ``task`` (``likert``, ``slider`` or ``2afc``; NULL in databases of earlier
  versions: ``likert``) and, for a 2afc trial, its right video ``stimulus_right``
  (``stimulus_id`` is the left one); ``check_value`` is set on the trials that carry an
  instructed-response attention check (what the check asks for: a Likert point, a slider
  end 0 or 100, a 2afc side 1 = left or 2 = right).
- ``responses``: one row per answer of any task, UNIQUE (participant_id, trial_index); the
  practice answers are stored with ``practice = true`` and ``trial_index`` -1 (Likert), -2
  (slider) or -3 (2afc) (:data:`PRACTICE_INDEX`). Answers store the real stimulus id(s) (the
  participant only ever sees the trial's token, :mod:`crowdstudy.study.blinding`), the
  ``task``, the ratings as JSON ``answers_json`` ({item id: value}; the paper's items are
  also kept in the columns ``Q1`` .. ``Q6``), a 2afc trial's ``choice`` (``left`` /
  ``right``) and the trial's data-quality record (video plays, time to the first complete
  play, tab switches and hidden time, fullscreen exits, the attention check's answer).
- ``answer_conflicts``: answers refused because their trial already had a different one
  (a second tab): kept for the record, never in the analysis.
- ``audit_log``: one line per administrative action (withdrawal), with no answer data.
- ``settings``: key/value pairs of the study; ``blinding_secret`` is the random key of the
  participants' trial tokens, schedules and media names (created once, so they survive
  server restarts and agree between server processes).

Databases created by an earlier version gain the new (nullable) columns at start-up.

Timestamps are ISO 8601 strings in UTC.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Iterable, Mapping, Sequence

from crowdstudy.errors import InvalidInputError
from crowdstudy.study.group_commit import GroupCommitWriter

__all__ = [
    "StudyStore",
    "answer_items",
    "ITEM_IDS",
    "PRACTICE_TRIAL_INDEX",
    "PRACTICE_INDEX",
    "QUALITY_FIELDS",
    "utc_now",
]

#: The paper's items, which also have columns of their own in ``responses``.
ITEM_IDS = ("Q1", "Q2", "Q3", "Q4", "Q5", "Q6")
PRACTICE_TRIAL_INDEX = -1
#: The ``trial_index`` of each task's practice answer.
PRACTICE_INDEX = {"likert": -1, "slider": -2, "2afc": -3}
#: Per-answer data-quality fields (nullable): complete plays of the video before the answer;
#: ms from the trial's display to the first complete play; times the page was hidden (tab
#: switch, minimised window) during the trial and ms hidden; exits from fullscreen during the
#: trial; the answer given to the trial's attention check (None: the trial had none).
_SCHEMA_LOCK = 7_250_315  # PostgreSQL advisory lock key of the schema set-up
QUALITY_FIELDS = ("video_plays", "first_play_ms", "hidden_count", "hidden_ms", "fullscreen_exits", "check_answer")


def utc_now() -> str:
    """Now as an ISO 8601 UTC string with milliseconds (``2026-01-08T09:00:00.123+00:00``)."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _answer_tables(metadata):
    """The ``responses`` and ``answer_conflicts`` tables (see the module docstring)."""
    import sqlalchemy as sa

    responses = sa.Table(
        "responses",
        metadata,
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("participant_id", sa.String(64), sa.ForeignKey("participants.participant_id"), nullable=False),
        sa.Column("trial_index", sa.Integer, nullable=False),
        sa.Column("practice", sa.Boolean, nullable=False, default=False),
        sa.Column("stimulus_id", sa.String(64), nullable=False),
        sa.Column("stage", sa.Integer, nullable=False),
        *[sa.Column(q, sa.SmallInteger, nullable=True) for q in ITEM_IDS],
        sa.Column("rt_ms", sa.Float, nullable=False),
        sa.Column("shown_at", sa.String(40), nullable=False),
        sa.Column("answered_at", sa.String(40), nullable=False),
        sa.Column("video_plays", sa.Integer, nullable=True),
        sa.Column("first_play_ms", sa.Float, nullable=True),
        sa.Column("hidden_count", sa.Integer, nullable=True),
        sa.Column("hidden_ms", sa.Float, nullable=True),
        sa.Column("fullscreen_exits", sa.Integer, nullable=True),
        sa.Column("check_answer", sa.SmallInteger, nullable=True),
        sa.Column("task", sa.String(8), nullable=True),
        sa.Column("stimulus_right", sa.String(64), nullable=True),
        sa.Column("choice", sa.String(8), nullable=True),
        sa.Column("answers_json", sa.Text, nullable=True),
        sa.UniqueConstraint("participant_id", "trial_index", name="uq_response_participant_trial"),
    )
    conflicts = sa.Table(
        "answer_conflicts",
        metadata,
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("participant_id", sa.String(64), nullable=False),
        sa.Column("trial_index", sa.Integer, nullable=False),
        sa.Column("stimulus_id", sa.String(64), nullable=False),
        *[sa.Column(q, sa.SmallInteger, nullable=True) for q in ITEM_IDS],
        sa.Column("rt_ms", sa.Float, nullable=False),
        sa.Column("received_at", sa.String(40), nullable=False),
        sa.Column("choice", sa.String(8), nullable=True),
        sa.Column("answers_json", sa.Text, nullable=True),
    )
    return responses, conflicts


def _tables(metadata):
    import sqlalchemy as sa

    stimuli = sa.Table(
        "stimuli",
        metadata,
        sa.Column("stimulus_id", sa.String(64), primary_key=True),
        sa.Column("stage", sa.Integer, nullable=False),
        sa.Column("scenario", sa.String(32), nullable=False),
        sa.Column("density_level", sa.String(16), nullable=False),
        sa.Column("density", sa.Float, nullable=False),
        sa.Column("viewpoint", sa.String(16), nullable=False),
        sa.Column("method", sa.String(32), nullable=False),
        sa.Column("characters", sa.Integer, nullable=True),
    )
    participants = sa.Table(
        "participants",
        metadata,
        sa.Column("participant_id", sa.String(64), primary_key=True),
        sa.Column("secret_hash", sa.String(64), nullable=False),
        sa.Column("schedule_seed", sa.BigInteger, nullable=False),
        sa.Column("started_at", sa.String(40), nullable=False),
        sa.Column("user_agent", sa.String(512), nullable=True),
        sa.Column("consented_at", sa.String(40), nullable=True),
        sa.Column("age", sa.Integer, nullable=True),
        sa.Column("gender", sa.String(32), nullable=True),
        sa.Column("demographics_at", sa.String(40), nullable=True),
        sa.Column("practice_at", sa.String(40), nullable=True),
        sa.Column("completed_at", sa.String(40), nullable=True),
        sa.Column("completion_code", sa.String(128), nullable=True),
        sa.Column("screened_out_at", sa.String(40), nullable=True),
        sa.Column("screen_reason", sa.String(256), nullable=True),
        sa.Column("withdrawn_at", sa.String(40), nullable=True),
        sa.Column("prolific_pid", sa.String(64), nullable=True),
        sa.Column("prolific_study_id", sa.String(64), nullable=True),
        sa.Column("prolific_session_id", sa.String(64), nullable=True),
    )
    schedule = sa.Table(
        "schedule",
        metadata,
        sa.Column("participant_id", sa.String(64), sa.ForeignKey("participants.participant_id"), primary_key=True),
        sa.Column("trial_index", sa.Integer, primary_key=True),
        sa.Column("stage", sa.Integer, nullable=False),
        sa.Column("stimulus_id", sa.String(64), sa.ForeignKey("stimuli.stimulus_id"), nullable=False),
        sa.Column("check_value", sa.SmallInteger, nullable=True),
        sa.Column("task", sa.String(8), nullable=True),
        sa.Column("stimulus_right", sa.String(64), nullable=True),
    )
    responses, conflicts = _answer_tables(metadata)
    audit = sa.Table(
        "audit_log",
        metadata,
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("at", sa.String(40), nullable=False),
        sa.Column("action", sa.String(32), nullable=False),
        sa.Column("participant_id", sa.String(64), nullable=False),
        sa.Column("detail", sa.String(512), nullable=False),
    )
    settings = sa.Table(
        "settings",
        metadata,
        sa.Column("key", sa.String(64), primary_key=True),
        sa.Column("value", sa.String(256), nullable=False),
    )
    return stimuli, participants, schedule, responses, conflicts, audit, settings


def _add_missing_columns(conn, metadata) -> None:
    """ALTER TABLE ... ADD COLUMN for the nullable columns a database of an earlier version
    lacks (the column definitions are this module's constants, never request values)."""
    import sqlalchemy as sa
    from sqlalchemy.schema import CreateColumn

    insp = sa.inspect(conn)
    names = set(insp.get_table_names())
    for table in metadata.sorted_tables:
        if table.name not in names:
            continue
        have = {c["name"] for c in insp.get_columns(table.name)}
        for col in table.columns:
            if col.name not in have and col.nullable:
                ddl = CreateColumn(col).compile(dialect=conn.dialect)
                conn.execute(sa.text(f"ALTER TABLE {table.name} ADD COLUMN {ddl}"))


class StudyStore:
    """The study database behind ``crowdstudy serve`` and ``crowdstudy export``.

    url: an SQLAlchemy URL (``sqlite:///study.db``, ``postgresql+psycopg://...``);
    create: create missing tables (False: the tables must exist, e.g. for export).
    """

    def __init__(self, url: str, *, create: bool = True):
        import sqlalchemy as sa
        from sqlalchemy import event
        from sqlalchemy.engine import make_url
        from sqlalchemy.exc import ArgumentError, NoSuchModuleError, OperationalError, ProgrammingError

        if not isinstance(url, str) or not url:
            raise InvalidInputError(f"--db must be an SQLAlchemy URL such as sqlite:///study.db, got {url!r}")
        try:
            parsed = make_url(url)
        except ArgumentError:
            raise InvalidInputError(f"--db: {url!r} is not an SQLAlchemy URL (e.g. sqlite:///study.db)") from None
        self.url = url
        self.is_sqlite = parsed.get_backend_name() == "sqlite"
        kwargs: dict = {}
        if self.is_sqlite:
            from sqlalchemy.pool import StaticPool

            kwargs["connect_args"] = {"check_same_thread": False, "timeout": 30}
            if parsed.database in (None, "", ":memory:"):
                kwargs["poolclass"] = StaticPool
            else:
                kwargs.update(pool_size=8, max_overflow=32)
        else:  # <= 20 connections per server process: 4 processes stay under PostgreSQL's default 100
            kwargs.update(pool_size=5, max_overflow=15, pool_recycle=1800)
        try:
            self.engine = sa.create_engine(url, **kwargs)
        except (ModuleNotFoundError, NoSuchModuleError) as exc:
            raise InvalidInputError(f"--db {url!r}: the database driver is not installed ({exc})") from None
        if self.is_sqlite:

            @event.listens_for(self.engine, "connect")
            def _pragmas(dbapi_connection, _record):
                cur = dbapi_connection.cursor()
                cur.execute("PRAGMA journal_mode=WAL")
                cur.execute("PRAGMA synchronous=FULL")
                cur.execute("PRAGMA foreign_keys=ON")
                cur.execute("PRAGMA busy_timeout=30000")
                cur.close()

        self.metadata = sa.MetaData()
        (
            self.stimuli,
            self.participants,
            self.schedule_t,
            self.responses,
            self.conflicts,
            self.audit,
            self.settings,
        ) = _tables(self.metadata)
        try:
            if not create:
                names = set(sa.inspect(self.engine).get_table_names())
                absent = [t for t in ("stimuli", "participants", "schedule", "responses") if t not in names]
                if absent:
                    raise InvalidInputError(
                        f"--db {url!r}: not a crowdstudy database (missing tables: {', '.join(absent)})"
                    )
            # new tables and columns of this version (a no-op on an up-to-date database); on
            # PostgreSQL an advisory lock serialises the server processes starting together
            with self.engine.begin() as conn:
                if parsed.get_backend_name() == "postgresql":
                    conn.execute(sa.select(sa.func.pg_advisory_xact_lock(_SCHEMA_LOCK)))
                self.metadata.create_all(conn)
                _add_missing_columns(conn, self.metadata)
        except (OperationalError, ProgrammingError) as exc:
            raise InvalidInputError(f"--db {url!r}: cannot open the database ({exc.orig})") from None
        self._writer = GroupCommitWriter(self.engine) if self.is_sqlite else None

    # -- plumbing -------------------------------------------------------------------
    def _transact(self, job):
        """Run ``job(connection)`` in a committed write transaction and return its result."""
        if self._writer is not None:
            return self._writer.submit(job)
        with self.engine.begin() as conn:
            return job(conn)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
        self.engine.dispose()

    # -- settings -------------------------------------------------------------------
    def blinding_secret(self) -> str:
        """The study's random blinding secret (64 hex digits), created on first use and stored,
        so every server process on this database derives the same trial tokens."""
        import secrets

        import sqlalchemy as sa
        from sqlalchemy.exc import IntegrityError

        t = self.settings
        fresh = secrets.token_hex(32)

        def job(conn):
            row = conn.execute(sa.select(t.c.value).where(t.c.key == "blinding_secret")).first()
            if row is not None:
                return row[0]
            conn.execute(sa.insert(t).values(key="blinding_secret", value=fresh))
            return fresh

        try:
            return self._transact(job)
        except IntegrityError:  # created concurrently by another process: read it back
            return self._transact(job)

    def sync_items(self, item_ids: Sequence[str], tasks: Sequence[str]) -> None:
        """Record the design's item ids (the export's columns) and check that this database
        can store the design's answers: a database of an earlier version has NOT NULL
        columns ``Q1`` .. ``Q6`` and so holds only the paper's items and no 2afc answer.
        A database already holding other item ids belongs to another study: an error."""
        import json

        import sqlalchemy as sa

        item_ids = tuple(item_ids)
        cols = {c["name"]: c for c in sa.inspect(self.engine).get_columns("responses")}
        strict = "Q1" in cols and not cols["Q1"]["nullable"]
        if strict and (item_ids != ITEM_IDS or "2afc" in tasks):
            what = "a 2afc stage" if "2afc" in tasks else f"the items {', '.join(item_ids)}"
            raise InvalidInputError(
                f"--db {self.url}: this database was made by an earlier crowdstudy, whose answers table holds "
                f"only the Likert items Q1..Q6; use a new database for a design with {what}"
            )
        t = self.settings
        value = json.dumps(list(item_ids))

        def job(conn):
            row = conn.execute(sa.select(t.c.value).where(t.c.key == "item_ids")).first()
            if row is None:
                conn.execute(sa.insert(t).values(key="item_ids", value=value))
                return value
            return row[0]

        from sqlalchemy.exc import IntegrityError

        try:
            stored = self._transact(job)
        except IntegrityError:  # written at the same moment by another process
            stored = self._transact(job)
        if stored != value:
            raise InvalidInputError(
                f"--db {self.url}: the database holds answers to the items {', '.join(json.loads(stored))}, "
                f"the design lists {', '.join(item_ids)}; use a new database for a different study"
            )

    def item_ids(self) -> tuple[str, ...]:
        """The study's item ids in the design's order (``Q1`` .. ``Q6`` for a database of an
        earlier version)."""
        import json

        import sqlalchemy as sa

        t = self.settings
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(t.c.value).where(t.c.key == "item_ids")).first()
        return ITEM_IDS if row is None else tuple(json.loads(row[0]))

    # -- stimuli --------------------------------------------------------------------
    def sync_stimuli(self, rows: Iterable[Mapping]) -> None:
        """Insert the study's stimuli; a stimulus already stored with other metadata is an
        error (a different study in the same database)."""
        import sqlalchemy as sa

        cols = ("stage", "scenario", "density_level", "density", "viewpoint", "method")
        rows = list(rows)

        def job(conn):
            existing = {r.stimulus_id: r for r in conn.execute(sa.select(self.stimuli))}
            for row in rows:
                old = existing.get(row["stimulus_id"])
                if old is None:
                    conn.execute(
                        sa.insert(self.stimuli).values(
                            stimulus_id=row["stimulus_id"],
                            characters=row.get("characters"),
                            **{c: row[c] for c in cols},
                        )
                    )
                    continue
                for c in cols:
                    a, b = getattr(old, c), row[c]
                    same = math.isclose(a, b, rel_tol=1e-9) if c == "density" else a == b
                    if not same:
                        raise InvalidInputError(
                            f"--db {self.url}: stimulus {row['stimulus_id']} is stored with {c}={a!r} but the "
                            f"stimulus set says {b!r}; use a new database for a different study"
                        )

        from sqlalchemy.exc import IntegrityError

        try:
            self._transact(job)
        except IntegrityError:  # another server process inserted them at the same moment
            self._transact(job)

    # -- participants -----------------------------------------------------------------
    def register(
        self,
        participant_id: str,
        secret_hash: str,
        schedule: Sequence,
        *,
        seed: int,
        user_agent: str | None = None,
        platform: Mapping[str, str] | None = None,
        checks: Mapping[int, int] | None = None,
        tasks: Mapping[int, str] | None = None,
    ) -> bool:
        """Create a participant with its schedule (ScheduledTrial items). False if the id exists.

        platform: {"prolific_pid", "prolific_study_id", "prolific_session_id"} (each optional);
        checks: {trial_index: what its attention check asks for}; tasks: {stage number: task}
        (default likert).
        """
        platform, checks, tasks = dict(platform or {}), dict(checks or {}), dict(tasks or {})
        import sqlalchemy as sa
        from sqlalchemy.exc import IntegrityError

        p = self.participants

        def job(conn):
            if conn.execute(sa.select(p.c.participant_id).where(p.c.participant_id == participant_id)).first():
                return False
            conn.execute(
                sa.insert(p).values(
                    participant_id=participant_id,
                    secret_hash=secret_hash,
                    schedule_seed=int(seed),
                    started_at=utc_now(),
                    user_agent=(user_agent or "")[:512],
                    **platform,
                )
            )
            conn.execute(
                sa.insert(self.schedule_t),
                [
                    {
                        "participant_id": participant_id,
                        "trial_index": t.trial_index,
                        "stage": t.stage,
                        "stimulus_id": t.stimulus_id,
                        "check_value": checks.get(t.trial_index),
                        "task": tasks.get(t.stage, "likert"),
                        "stimulus_right": t.stimulus_right,
                    }
                    for t in schedule
                ],
            )
            return True

        try:
            return self._transact(job)
        except IntegrityError:  # registered concurrently (non-SQLite databases)
            return False

    def replace_secret(self, participant_id: str, secret_hash: str) -> bool:
        """Give a participant a new secret hash (the old secret stops working). False if unknown."""
        import sqlalchemy as sa

        p = self.participants

        def job(conn):
            return (
                conn.execute(
                    sa.update(p).where(p.c.participant_id == participant_id).values(secret_hash=secret_hash)
                ).rowcount
                == 1
            )

        return self._transact(job)

    def participant(self, participant_id: str) -> dict | None:
        import sqlalchemy as sa

        with self.engine.connect() as conn:
            row = conn.execute(
                sa.select(self.participants).where(self.participants.c.participant_id == participant_id)
            ).first()
        return None if row is None else dict(row._mapping)

    def schedule(self, participant_id: str) -> list[dict]:
        """The participant's trials joined with stimulus metadata, by trial_index."""
        import sqlalchemy as sa

        s, st = self.schedule_t, self.stimuli
        right = st.alias("right_stimulus")
        q = (
            sa.select(
                s.c.trial_index,
                s.c.stage,
                sa.func.coalesce(s.c.task, "likert").label("task"),
                s.c.stimulus_id,
                s.c.stimulus_right,
                s.c.check_value,
                st.c.scenario,
                st.c.density_level,
                st.c.density,
                st.c.viewpoint,
                st.c.method,
                right.c.method.label("method_right"),
                st.c.characters,
            )
            .join(st, st.c.stimulus_id == s.c.stimulus_id)
            .outerjoin(right, right.c.stimulus_id == s.c.stimulus_right)
            .where(s.c.participant_id == participant_id)
            .order_by(s.c.trial_index)
        )
        with self.engine.connect() as conn:
            return [dict(r._mapping) for r in conn.execute(q)]

    def answered_indices(self, participant_id: str) -> list[int]:
        """trial_index of every stored study answer (practice excluded), ascending."""
        import sqlalchemy as sa

        r = self.responses
        with self.engine.connect() as conn:
            return [
                x
                for (x,) in conn.execute(
                    sa.select(r.c.trial_index)
                    .where(r.c.participant_id == participant_id, r.c.practice.is_(False))
                    .order_by(r.c.trial_index)
                )
            ]

    def _update_once(self, participant_id: str, column: str, values: dict) -> dict:
        """Set ``values`` unless ``column`` is already set; return the participant row."""
        import sqlalchemy as sa

        p = self.participants

        def job(conn):
            conn.execute(
                sa.update(p).where(p.c.participant_id == participant_id, p.c[column].is_(None)).values(**values)
            )
            return dict(conn.execute(sa.select(p).where(p.c.participant_id == participant_id)).first()._mapping)

        return self._transact(job)

    def set_consent(self, participant_id: str) -> dict:
        return self._update_once(participant_id, "consented_at", {"consented_at": utc_now()})

    def set_demographics(self, participant_id: str, age: int, gender: str) -> dict:
        return self._update_once(
            participant_id, "demographics_at", {"age": int(age), "gender": gender, "demographics_at": utc_now()}
        )

    def set_completed(self, participant_id: str, completion_code: str | None) -> dict:
        return self._update_once(
            participant_id, "completed_at", {"completed_at": utc_now(), "completion_code": completion_code}
        )

    def set_screened_out(self, participant_id: str, reason: str, completion_code: str | None) -> dict:
        """Mark a participant who failed the screen check before consent (kept: no answers)."""
        return self._update_once(
            participant_id,
            "screened_out_at",
            {"screened_out_at": utc_now(), "screen_reason": str(reason)[:256], "completion_code": completion_code},
        )

    # -- answers --------------------------------------------------------------------------
    def _answer_values(
        self, participant_id, trial_index, stimulus_id, stage, answers, rt_ms, shown_at, practice, quality, extra
    ) -> dict:
        """The row of one answer; extra: {"task", "choice", "stimulus_right"} (task default likert)."""
        import json

        answered_at = utc_now()
        q = {k: (None if quality is None else quality.get(k)) for k in QUALITY_FIELDS}
        task = extra.get("task") or "likert"
        items = {str(k): int(v) for k, v in (answers or {}).items()}
        return dict(
            task=task,
            choice=extra.get("choice"),
            stimulus_right=extra.get("stimulus_right"),
            answers_json=None if task == "2afc" else json.dumps(items, separators=(",", ":")),
            participant_id=participant_id,
            trial_index=int(trial_index),
            practice=bool(practice),
            stimulus_id=stimulus_id,
            stage=int(stage),
            rt_ms=float(rt_ms),
            answered_at=answered_at,
            shown_at=shown_at or _minus_ms(answered_at, rt_ms),
            **{k: items.get(k) for k in ITEM_IDS},
            **q,
        )

    def record_answer(
        self,
        participant_id: str,
        trial_index: int,
        stimulus_id: str,
        stage: int,
        answers: Mapping[str, int],
        rt_ms: float,
        shown_at: str | None,
        *,
        quality: Mapping | None = None,
        task: str = "likert",
        choice: str | None = None,
        stimulus_right: str | None = None,
    ) -> tuple[str, dict]:
        """Store one study answer, committed (and on SQLite fsynced) before returning.

        answers: {item id: value} of a Likert or slider trial (empty for 2afc); task: the
        trial's task; choice: a 2afc trial's ``left`` / ``right``; stimulus_right: its right
        video (``stimulus_id`` is the left one).

        Returns (status, row): "created"; "exists" (the same answer, i.e. the same stimulus,
        values (or choice) and rt_ms, was already stored: a resend); "conflict" (a different answer
        is stored for this trial; the stored one is kept and returned, the refused one goes to
        ``answer_conflicts`` in the same transaction); "out_of_order" (an earlier trial is
        unanswered; row = {"expected": index}). Study answers must arrive in trial order.
        shown_at: ISO 8601 UTC from the client, or None for answered_at - rt_ms; quality:
        {QUALITY_FIELDS name: value} (missing ones stored as NULL).
        """
        import sqlalchemy as sa
        from sqlalchemy.exc import IntegrityError

        r = self.responses
        extra = {"task": task, "choice": choice, "stimulus_right": stimulus_right}
        values = self._answer_values(
            participant_id, trial_index, stimulus_id, stage, answers, rt_ms, shown_at, False, quality, extra
        )

        ti = int(trial_index)

        def job(conn):
            # one indexed read: this trial's stored answer and its predecessor's. Answers are
            # only ever inserted after their predecessor, so "the previous trial is answered"
            # means "every earlier trial is" (and no later one is).
            near = {
                row.trial_index: row
                for row in conn.execute(
                    sa.select(r).where(
                        r.c.participant_id == participant_id,
                        r.c.practice.is_(False),
                        r.c.trial_index.in_([ti - 1, ti]) if ti > 0 else r.c.trial_index == ti,
                    )
                )
            }
            old = near.get(ti)
            if old is not None:
                old = dict(old._mapping)
                if _same_answer(old, values):
                    return "exists", old
                conn.execute(
                    sa.insert(self.conflicts).values(
                        participant_id=participant_id,
                        trial_index=ti,
                        stimulus_id=stimulus_id,
                        rt_ms=values["rt_ms"],
                        received_at=values["answered_at"],
                        choice=values["choice"],
                        answers_json=values["answers_json"],
                        **{k: values[k] for k in ITEM_IDS},
                    )
                )
                return "conflict", old
            if ti > 0 and (ti - 1) not in near:
                n = conn.execute(
                    sa.select(sa.func.count())
                    .select_from(r)
                    .where(r.c.participant_id == participant_id, r.c.practice.is_(False))
                ).scalar_one()
                return "out_of_order", {"expected": int(n)}
            conn.execute(sa.insert(r).values(**values))
            return "created", values

        try:
            return self._transact(job)
        except IntegrityError:  # a concurrent insert of the same key (non-SQLite): read it back
            return self._transact(job)

    def record_practice(
        self,
        participant_id: str,
        answers: Mapping[str, int],
        rt_ms: float,
        shown_at: str | None,
        quality: Mapping | None = None,
        *,
        task: str = "likert",
        choice: str | None = None,
    ) -> tuple[str, dict]:
        """Store a practice answer (one per task, at its PRACTICE_INDEX) and mark the practice
        done (``practice_at``: the first practice of any task) in ONE transaction.

        Returns ("created" | "exists", participant row). "exists": a practice answer was
        already stored (this one is dropped: practice answers are not analysed); the practice
        is then marked done if it was not (a database written by an earlier version, where a
        crash could fall between the two), so a participant can always move on.
        """
        import sqlalchemy as sa
        from sqlalchemy.exc import IntegrityError

        r, p = self.responses, self.participants
        index = PRACTICE_INDEX[task]
        values = self._answer_values(
            participant_id,
            index,
            "practice",
            0,
            answers,
            rt_ms,
            shown_at,
            True,
            quality,
            {"task": task, "choice": choice},
        )

        def job(conn):
            old = conn.execute(
                sa.select(r.c.id).where(r.c.participant_id == participant_id, r.c.trial_index == index)
            ).first()
            if old is None:
                conn.execute(sa.insert(r).values(**values))
            _mark_practice_done(conn, p, participant_id)
            row = conn.execute(sa.select(p).where(p.c.participant_id == participant_id)).first()
            return ("exists" if old is not None else "created"), dict(row._mapping)

        try:
            return self._transact(job)
        except IntegrityError:  # sent twice at once (non-SQLite): the other one was stored
            return self._transact(job)

    def has_task(self, task: str) -> bool:
        """Whether any participant's schedule holds a trial of ``task``."""
        import sqlalchemy as sa

        s = self.schedule_t
        with self.engine.connect() as conn:
            return conn.execute(sa.select(s.c.trial_index).where(s.c.task == task).limit(1)).first() is not None

    def practiced_tasks(self, participant_id: str) -> set[str]:
        """The tasks whose practice trial ``participant_id`` has answered."""
        import sqlalchemy as sa

        r = self.responses
        with self.engine.connect() as conn:
            idx = {
                x
                for (x,) in conn.execute(
                    sa.select(r.c.trial_index).where(r.c.participant_id == participant_id, r.c.practice.is_(True))
                )
            }
        return {task for task, k in PRACTICE_INDEX.items() if k in idx}

    # -- admin and export ------------------------------------------------------------------
    def progress(self) -> list[dict]:
        """Per participant: timestamps of each step, answers stored, trials scheduled."""
        import sqlalchemy as sa

        p, s, r = self.participants, self.schedule_t, self.responses
        n_trials = sa.select(s.c.participant_id, sa.func.count().label("n")).group_by(s.c.participant_id).subquery()
        n_ans = (
            sa.select(r.c.participant_id, sa.func.count().label("n"))
            .where(r.c.practice.is_(False))
            .group_by(r.c.participant_id)
            .subquery()
        )
        q = (
            sa.select(
                p.c.participant_id,
                p.c.started_at,
                p.c.consented_at,
                p.c.demographics_at,
                p.c.practice_at,
                p.c.completed_at,
                p.c.screened_out_at,
                p.c.withdrawn_at,
                sa.func.coalesce(n_ans.c.n, 0).label("answered"),
                sa.func.coalesce(n_trials.c.n, 0).label("trials"),
            )
            .outerjoin(n_ans, n_ans.c.participant_id == p.c.participant_id)
            .outerjoin(n_trials, n_trials.c.participant_id == p.c.participant_id)
            .order_by(p.c.started_at, p.c.participant_id)
        )
        with self.engine.connect() as conn:
            return [dict(x._mapping) for x in conn.execute(q)]

    def response_rows(self, participant_id: str | None = None) -> list[dict]:
        """Answered study trials (practice excluded) joined with stimulus metadata, sorted by
        participant and trial_index, in the responses.csv schema, plus QUALITY_FIELDS and the
        trial's attention-check value ``check_value``; every task: ``task``, the items' values
        by item id (from ``answers_json``, or the ``Q`` columns of an earlier version's rows),
        a 2afc trial's ``choice``, ``stimulus_right`` and ``method_right``."""
        import sqlalchemy as sa

        r, st, s = self.responses, self.stimuli, self.schedule_t
        right = st.alias("right_stimulus")
        q = (
            sa.select(
                r.c.participant_id,
                r.c.stage,
                st.c.scenario,
                sa.func.coalesce(r.c.task, "likert").label("task"),
                r.c.trial_index,
                r.c.stimulus_id,
                st.c.density_level,
                st.c.density,
                st.c.viewpoint,
                st.c.method,
                r.c.stimulus_right,
                right.c.method.label("method_right"),
                r.c.choice,
                r.c.answers_json,
                *[r.c[q] for q in ITEM_IDS],
                r.c.rt_ms,
                r.c.shown_at,
                r.c.answered_at,
                *[r.c[q] for q in QUALITY_FIELDS],
                s.c.check_value,
            )
            .join(st, st.c.stimulus_id == r.c.stimulus_id)
            .outerjoin(right, right.c.stimulus_id == r.c.stimulus_right)
            .outerjoin(s, sa.and_(s.c.participant_id == r.c.participant_id, s.c.trial_index == r.c.trial_index))
            .where(r.c.practice.is_(False))
            .order_by(r.c.participant_id, r.c.trial_index)
        )
        if participant_id is not None:
            q = q.where(r.c.participant_id == participant_id)
        with self.engine.connect() as conn:
            rows = [dict(x._mapping) for x in conn.execute(q)]
        for row in rows:
            row.update(answer_items(row))
        return rows

    def demographics_rows(self) -> list[dict]:
        """One row per participant in the demographics.csv schema."""
        import sqlalchemy as sa

        p = self.participants
        q = sa.select(
            p.c.participant_id, p.c.age, p.c.gender, p.c.started_at, p.c.completed_at, p.c.completion_code
        ).order_by(p.c.participant_id)
        with self.engine.connect() as conn:
            return [dict(x._mapping) for x in conn.execute(q)]


def _mark_practice_done(conn, participants, participant_id: str) -> None:
    import sqlalchemy as sa

    p = participants
    conn.execute(
        sa.update(p)
        .where(p.c.participant_id == participant_id, p.c.practice_at.is_(None))
        .values(practice_at=utc_now())
    )


def answer_items(row: Mapping) -> dict[str, int]:
    """{item id: value} of a stored answer row: its ``answers_json``, else (a row of an earlier
    version) its ``Q1`` .. ``Q6`` columns; empty for a 2afc answer."""
    import json

    if row.get("answers_json"):
        return {k: int(v) for k, v in json.loads(row["answers_json"]).items()}
    if (row.get("task") or "likert") == "2afc":
        return {}
    return {q: int(row[q]) for q in ITEM_IDS if row.get(q) is not None}


def _same_answer(old: Mapping, new: Mapping) -> bool:
    return (
        old["stimulus_id"] == new["stimulus_id"]
        and answer_items(old) == answer_items(new)
        and old.get("choice") == new.get("choice")
        and math.isclose(float(old["rt_ms"]), float(new["rt_ms"]), rel_tol=0, abs_tol=1e-6)
    )


def _minus_ms(iso: str, ms: float) -> str:
    t = _dt.datetime.fromisoformat(iso) - _dt.timedelta(milliseconds=float(ms))
    return t.isoformat(timespec="milliseconds")

"""Study-server benchmark: simulated participants against 1 or N server processes on loopback.

    crowdstudy bench study [--participants 50,200] [--databases sqlite,postgresql] [--processes 1,4]
                           [--think-time 5] [--answers 3] [--seed 7]

Each row: N participants at once (fake 1 s stimuli), each pausing ``--think-time`` s on
average (uniform 0..2x) before each of its first ``--answers`` answers, against a fresh
database (SQLite in WAL mode, or a throwaway PostgreSQL cluster with fsync on:
:mod:`crowdstudy.study.pg_local`) served by ``crowdstudy serve --workers P``. A real
participant watches a 20 s clip and answers six statements, so about 25 s pass between two
answers; the answer arrival rate N / think time is what loads the server, and the default
5 s makes each row 5x denser than that many real participants (200 here are 1,000 real
ones). Reported: the answer round trip p50 / p99 / max (ms, as the participants' HTTP
clients saw it: registration and the other steps are not counted), answers per second
during the run, whether every answer was stored exactly once, the load average and CPUs.
Latency is a benchmark, not a test: on a shared machine the round trip includes other
processes' time slices, and the load generator runs on the same CPUs as the servers.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

TOKEN = "bench-admin-token-0123456789abcdef"


def _stored_once(db_url: str, expected: int) -> bool:
    import sqlalchemy as sa

    from crowdstudy.study.storage import StudyStore

    store = StudyStore(db_url, create=False)
    try:
        r = store.responses
        with store.engine.connect() as conn:
            total = conn.execute(sa.select(sa.func.count()).select_from(r).where(r.c.practice.is_(False))).scalar_one()
            distinct = conn.execute(
                sa.select(sa.func.count()).select_from(
                    sa.select(r.c.participant_id, r.c.trial_index).where(r.c.practice.is_(False)).distinct().subquery()
                )
            ).scalar_one()
    finally:
        store.close()
    return total == distinct == expected


def run_row(n: int, database: str, processes: int, think_time: float, answers: int, seed: int, pg) -> dict:
    from crowdstudy.study.bots import run_simulation
    from crowdstudy.study.fake_stimuli import write_fake_stimuli
    from crowdstudy.study.local_server import LocalServer

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stim = write_fake_stimuli(tmp / "stim", n_files=3, seconds=1.0)
        if database == "sqlite":
            db = f"sqlite:///{tmp / 'bench.db'}"
        else:
            import sqlalchemy as sa

            name = f"bench_{n}_{processes}"
            eng = sa.create_engine(pg.url, isolation_level="AUTOCOMMIT")
            with eng.connect() as conn:
                conn.execute(sa.text(f"CREATE DATABASE {name}"))  # name built from integers only
            eng.dispose()
            db = pg.url.rsplit("/", 1)[0] + "/" + name
        with LocalServer(
            ["--stimuli", str(stim), "--db", db, "--workers", str(processes)], admin_token=TOKEN, startup_timeout=120
        ) as srv:
            res = run_simulation(
                srv.url,
                n,
                admin_token=TOKEN,
                concurrency=n,
                think_time=think_time,
                seed=seed,
                method_effect=1.0,
                noise_sd=0.9,
                max_answers=answers,
                timeout=120.0,
            )
        stored_once = _stored_once(db, res.answers)
    s = res.summary()
    span = think_time * 2.0 * answers  # the longest a bot can take, for a rate over the busy period
    return {
        "participants": n,
        "database": database,
        "processes": processes,
        "think_time_s": think_time,
        "answers": s["answers"],
        "answers_per_s": s["answers"] / max(s["wall_s"], 1e-9),
        "round_trip_p50_ms": s["latency_ms_p50"],
        "round_trip_p99_ms": s["latency_ms_p99"],
        "round_trip_max_ms": s["latency_ms_max"],
        "errors": len(res.errors),
        "stored_once": stored_once,
        "wall_s": s["wall_s"],
        "max_session_s": span,
        "load_average": os.getloadavg()[0],
        "cpus": os.cpu_count(),
    }


def main(argv: list[str]) -> int:
    from crowdstudy.bench import write_report
    from crowdstudy.tables import format_table

    parser = argparse.ArgumentParser(prog="crowdstudy bench study")
    parser.add_argument(
        "--participants", default="50,200", help="comma-separated participant counts (e.g. 50,200,1000)"
    )
    parser.add_argument("--databases", default="sqlite,postgresql", help="sqlite and/or postgresql")
    parser.add_argument("--processes", default="1,4", help="comma-separated server process counts")
    parser.add_argument("--think-time", type=float, default=5.0, help="mean pause before each answer, s")
    parser.add_argument("--answers", type=int, default=3, help="answers per participant (of the 60)")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)

    def ints(text, name):
        try:
            vals = [int(c) for c in text.split(",") if c.strip()]
        except ValueError:
            raise SystemExit(f"--{name}: expected counts like 50,200, got {text!r}") from None
        if not vals or min(vals) < 1:
            raise SystemExit(f"--{name}: expected positive counts, got {text!r}")
        return vals

    counts, procs = ints(args.participants, "participants"), ints(args.processes, "processes")
    dbs = [d.strip() for d in args.databases.split(",") if d.strip()]
    if not dbs or any(d not in ("sqlite", "postgresql") for d in dbs):
        raise SystemExit(f"--databases: expected sqlite and/or postgresql, got {args.databases!r}")
    if not 1 <= args.answers <= 60 or args.think_time < 0:
        raise SystemExit("--answers must be 1..60 and --think-time >= 0")
    rows = []
    pg = None
    try:
        if "postgresql" in dbs:
            from crowdstudy.study.pg_local import LocalPostgres

            pg = LocalPostgres(fsync=True, max_connections=300).start()
        for db in dbs:
            for p in procs:
                for n in counts:
                    rows.append(run_row(n, db, p, args.think_time, args.answers, args.seed, pg))
                    print(format_table([rows[-1]]), flush=True)
    finally:
        if pg is not None:
            pg.stop()
    path = write_report("study", rows, seed=args.seed)
    print(
        format_table(
            rows,
            [
                "participants",
                "database",
                "processes",
                "answers",
                "answers_per_s",
                "round_trip_p50_ms",
                "round_trip_p99_ms",
                "round_trip_max_ms",
                "errors",
                "stored_once",
            ],
        )
    )
    print(f"wrote {path}")
    return 0

"""Study-server benchmark: simulated participants against one server process on loopback.

    crowdstudy bench study [--participants 50,200] [--think-time 0.25] [--seed 7]

Each row: N participants answering the 60 trials at once (SQLite database, one server
process, fake 1 s stimuli), each pausing ``--think-time`` s on average before an answer (a
real participant takes about 20 s per video, so this is a much denser load). Reported: the
answer round trip p50 / p99 / max (ms, as the participants' HTTP clients saw it), the
server's own answer latency p99 (``/admin/metrics.json``), answers per second, the load
average while it ran, and whether every answer was stored exactly once. Latency is a
benchmark, not a test: on a shared machine the round trip includes other processes' time
slices.
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import tempfile
from pathlib import Path


def run_row(n: int, think_time: float, seed: int) -> dict:
    import httpx

    from crowdstudy.study.bots import run_simulation
    from crowdstudy.study.fake_stimuli import write_fake_stimuli
    from crowdstudy.study.local_server import LocalServer

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        stim = write_fake_stimuli(tmp / "stim", n_files=3, seconds=1.0)
        db = tmp / "bench.db"
        with LocalServer(["--stimuli", str(stim), "--db", f"sqlite:///{db}"]) as srv:
            res = run_simulation(srv.url, n, admin_token=srv.admin_token, concurrency=n, think_time=think_time,
                                 seed=seed, method_effect=1.0, noise_sd=0.9)
            server = httpx.get(srv.url + "/admin/metrics.json",
                               headers={"Authorization": f"Bearer {srv.admin_token}"}).json()
        with sqlite3.connect(db) as con:
            total, distinct = con.execute("SELECT COUNT(*), COUNT(DISTINCT participant_id || ':' || trial_index) "
                                          "FROM responses WHERE practice = 0").fetchone()
    s = res.summary()
    return {"participants": n, "database": "sqlite", "processes": 1, "think_time_s": think_time,
            "answers": s["answers"], "answers_per_s": s["answers"] / s["wall_s"],
            "round_trip_p50_ms": s["latency_ms_p50"], "round_trip_p99_ms": s["latency_ms_p99"],
            "round_trip_max_ms": s["latency_ms_max"],
            "server_p99_ms": server["server_answer_latency"]["latency_ms_p99"],
            "errors": len(res.errors), "stored_once": bool(total == distinct == s["answers"]),
            "load_average": os.getloadavg()[0], "cpus": os.cpu_count()}


def main(argv: list[str]) -> int:
    from crowdstudy.bench import format_table, write_report

    parser = argparse.ArgumentParser(prog="crowdstudy bench study")
    parser.add_argument("--participants", default="50,200", help="comma-separated participant counts")
    parser.add_argument("--think-time", type=float, default=0.25, help="mean pause before each answer, s")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    try:
        counts = [int(c) for c in args.participants.split(",") if c.strip()]
    except ValueError:
        raise SystemExit(f"--participants: expected counts like 50,200, got {args.participants!r}") from None
    if not counts or min(counts) < 1:
        raise SystemExit(f"--participants: expected positive counts, got {args.participants!r}")
    rows = []
    for n in counts:
        rows.append(run_row(n, args.think_time, args.seed))
        print(format_table([rows[-1]]), flush=True)
    path = write_report("study", rows, seed=args.seed)
    print(f"wrote {path}")
    return 0

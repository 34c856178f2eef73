"""Load: 50 simulated participants at once against one server process on loopback; every
answer stored exactly once, no error. Latency is printed here but measured by
``crowdstudy bench study`` (a timed assertion on a shared machine is a coin toss)."""

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from crowdstudy.study.bots import run_simulation
from crowdstudy.study.export import export_study
from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.local_server import LocalServer

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parent.parent
N_BOTS = 50
THINK_TIME = 0.25  # mean pause before each answer, s (a real participant takes ~20 s per video)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("load")
    stim = write_fake_stimuli(tmp / "stim", n_files=3, seconds=1.0)
    db = tmp / "load.db"
    with LocalServer(["--stimuli", str(stim), "--db", f"sqlite:///{db}"]) as srv:
        yield srv, db, tmp


def test_fifty_participants_at_once(server):
    import httpx

    srv, db, tmp = server
    res = run_simulation(
        srv.url,
        N_BOTS,
        admin_token=srv.admin_token,
        concurrency=N_BOTS,
        think_time=THINK_TIME,
        seed=7,
        method_effect=1.0,
        noise_sd=0.9,
    )
    metrics = httpx.get(srv.url + "/admin/metrics.json", headers={"Authorization": f"Bearer {srv.admin_token}"}).json()[
        "server_answer_latency"
    ]
    load = os.getloadavg()[0]
    s = res.summary()
    print(
        f"\n[load] {N_BOTS} bots x 60 answers, think time {THINK_TIME} s: {s['answers']} answers in "
        f"{s['wall_s']:.1f} s ({s['answers'] / s['wall_s']:.0f}/s); round-trip latency p50 {s['latency_ms_p50']} "
        f"ms, p95 {s['latency_ms_p95']} ms, p99 {s['latency_ms_p99']} ms, max {s['latency_ms_max']} ms; "
        f"in-server p99 {metrics['latency_ms_p99']} ms; load average {load:.1f} on {os.cpu_count()} CPUs"
    )
    assert res.errors == []
    assert len(res.participants) == N_BOTS and res.answers == N_BOTS * 60

    with sqlite3.connect(db) as con:
        total, distinct = con.execute(
            "SELECT COUNT(*), COUNT(DISTINCT participant_id || ':' || trial_index) FROM responses WHERE practice = 0"
        ).fetchone()
        per = con.execute(
            "SELECT MIN(n), MAX(n) FROM (SELECT COUNT(*) AS n FROM responses WHERE practice = 0 "
            "GROUP BY participant_id)"
        ).fetchone()
        completed = con.execute("SELECT COUNT(*) FROM participants WHERE completed_at IS NOT NULL").fetchone()[0]
        assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert total == distinct == N_BOTS * 60 and per == (60, 60) and completed == N_BOTS

    # the bots answer through ResponseModel: Ours beats Baseline by about method_effect on QCR
    out = tmp / "responses.csv"
    export_study(f"sqlite:///{db}", out)
    import pandas as pd

    df = pd.read_csv(out)
    assert len(df) == N_BOTS * 60 and not df.duplicated(["participant_id", "trial_index"]).any()
    qcr = (df["Q1"] + (7 - df["Q2"])) / 2
    diff = qcr[df["method"] == "Ours"].mean() - qcr[df["method"] == "Baseline"].mean()
    assert 0.7 < diff < 1.3, diff


def test_simulate_participants_cli(server, tmp_path):
    srv, db, _ = server
    out = tmp_path / "sim.json"
    env = {k: v for k, v in os.environ.items() if k != "CROWDSTUDY_ADMIN_TOKEN"}
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "crowdstudy",
            "simulate-participants",
            "--url",
            srv.url,
            "-n",
            "3",
            "--seed",
            "11",
            "--concurrency",
            "3",
            "--prefix",
            "cli",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        env={**env, "CROWDSTUDY_ADMIN_TOKEN": srv.admin_token},
    )
    assert p.returncode == 0, p.stdout + p.stderr
    assert "3/3 completed, 180 answers" in p.stdout
    summary = json.loads(out.read_text())
    assert summary["answers"] == 180 and summary["provenance"]["seed"] == 11
    # running the same bots again: their ids exist, so registration is refused (no duplicates)
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "crowdstudy",
            "simulate-participants",
            "--url",
            srv.url,
            "-n",
            "1",
            "--seed",
            "11",
            "--prefix",
            "cli",
            "--admin-token",
            srv.admin_token,
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        env=env,
    )
    assert p.returncode == 1 and "already registered" in p.stdout
    # the bots need the admin token (participants are blinded); a missing or wrong one is refused up front
    for extra in ([], ["--admin-token", "wrong-admin-token-000000"]):
        p = subprocess.run(
            [
                sys.executable,
                "-m",
                "crowdstudy",
                "simulate-participants",
                "--url",
                srv.url,
                "-n",
                "1",
                "--prefix",
                "noadmin",
                *extra,
            ],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=60,
            env=env,
        )
        assert p.returncode == 2 and "--admin-token" in p.stderr, p.stderr
    with sqlite3.connect(db) as con:
        assert (
            con.execute("SELECT COUNT(*) FROM responses WHERE participant_id LIKE 'cli-%' AND practice = 0").fetchone()[
                0
            ]
            == 180
        )
        assert con.execute("SELECT COUNT(*) FROM participants WHERE participant_id LIKE 'noadmin-%'").fetchone()[0] == 0
    p = subprocess.run(
        [sys.executable, "-m", "crowdstudy", "simulate-participants", "--url", "ftp://x", "-n", "1"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert p.returncode == 2 and "--url" in p.stderr

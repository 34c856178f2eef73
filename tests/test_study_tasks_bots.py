"""Bots through the real server API on a design with three methods and all three tasks:
every task answered, exported in the right files with the right rows."""

from __future__ import annotations

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.study.bots import run_simulation
from crowdstudy.study.cli_simulate_participants import parse_method_effects
from crowdstudy.study.export import export_study
from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.local_server import LocalServer

ROOT = Path(__file__).resolve().parent.parent
DESIGN = Path(__file__).resolve().parent / "data" / "three_tasks.toml"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bots3")
    stim = write_fake_stimuli(tmp / "stim", DESIGN, n_files=3, seconds=1.0)
    db = tmp / "study.db"
    with LocalServer(["--stimuli", str(stim), "--design", str(DESIGN), "--db", f"sqlite:///{db}"]) as srv:
        yield srv, db, tmp


def test_bots_answer_every_task_and_the_export_has_its_rows(server):
    import pandas as pd

    srv, db, tmp = server
    res = run_simulation(srv.url, 4, admin_token=srv.admin_token, seed=5, method_effects={"Physics": 1.0, "Stiff": 0.5})
    assert res.errors == [] and len(res.participants) == 4 and res.answers == 4 * 24
    out = tmp / "export" / "responses.csv"
    summary = export_study(f"sqlite:///{db}", out, online=DESIGN)
    assert summary["responses"] == 4 * 18 and summary["comparisons"] == 4 * 6
    r = pd.read_csv(out)
    c = pd.read_csv(out.with_name("comparisons.csv"))
    assert Counter(r["task"]) == {"likert": 4 * 12, "slider": 4 * 6}
    assert r.loc[r.task == "likert", ["R1", "R2", "R3"]].isin(range(1, 6)).all().all()
    assert r.loc[r.task == "slider", ["R1", "R2", "R3"]].isin(range(0, 101)).all().all()
    assert set(c["choice"]) <= {"left", "right"} and (c["task"] == "2afc").all()
    assert ((c.choice == "left") == (c.chosen_method == c.method_left)).all()
    assert Counter(frozenset(p) for p in zip(c.method_left, c.method_right, strict=True)) == {
        frozenset(p): 8 for p in (("Plain", "Physics"), ("Plain", "Stiff"), ("Physics", "Stiff"))
    }
    parts = pd.read_csv(out.with_name("participants.csv"))
    assert (parts["checks_failed"] == 0).all() and (parts["checks_total"] == 3).all()  # attentive bots
    assert (parts["comparison_trials"] == 6).all()


def test_a_method_the_study_lacks_is_refused(server):
    srv, _db, _tmp = server
    with pytest.raises(InvalidInputError, match=r"'Ours' is not a method of the study.*Plain, Physics, Stiff"):
        run_simulation(srv.url, 1, admin_token=srv.admin_token, method_effect=1.0)
    assert parse_method_effects(["0.5"]) == {"Ours": 0.5}
    assert parse_method_effects(["Stiff=0.25", "Physics=1"]) == {"Stiff": 0.25, "Physics": 1.0}
    for bad in (["Stiff=x"], ["=1"], ["Stiff=1", "Stiff=2"], ["nan"]):
        with pytest.raises(InvalidInputError, match="--method-effect"):
            parse_method_effects(bad)


def test_cli_names_the_unknown_method_and_exits_2(server):
    srv, _db, _tmp = server
    env = {**os.environ, "CROWDSTUDY_ADMIN_TOKEN": srv.admin_token}
    p = subprocess.run(
        [sys.executable, "-m", "crowdstudy", "simulate-participants", "--url", srv.url, "-n", "1",
         "--method-effect", "Stif=0.5"],
        capture_output=True, text=True, cwd=ROOT, timeout=120, env=env,
    )  # fmt: skip
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "'Stif' is not a method of the study" in p.stdout + p.stderr

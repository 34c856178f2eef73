"""Crowdsourcing ids, completion codes, withdrawal (API and `crowdstudy participants`), the
data-quality record of each answer, attention checks and the exclusion flags of the export."""

import csv
import subprocess
import sys
from pathlib import Path

import pytest
import sqlalchemy as sa
from study_fixtures import ADMIN, ANS, answer, check_answer, make_client, register

from crowdstudy.errors import InvalidInputError
from crowdstudy.study.export import export_study
from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.quality import load_online_config

pytestmark = [pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")]
ROOT = Path(__file__).resolve().parent.parent
ONLINE = """
[online]
min_width = 1280
min_height = 720
fullscreen = true
attention_checks = 3

[online.codes]
completed = "C-DONE"
screened_out = "C-SCREEN"
withdrawn = "C-WITHDRAWN"

[online.exclude]
max_failed_checks = 0
min_median_rt_ms = 1000
max_straightline_fraction = 0.8
max_hidden_trials = 2
"""


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("stim"), n_files=3, seconds=1.0)


@pytest.fixture
def served(stim_dir, tmp_path):
    online = tmp_path / "online.toml"
    online.write_text(ONLINE)
    client, cfg = make_client(stim_dir, f"sqlite:///{tmp_path / 'p.db'}", online=online)
    yield client, cfg, online
    cfg.store.close()


def _cli(capsys, *args):
    """`crowdstudy participants ARGS` in this process: (return code, stdout, stderr)."""
    from crowdstudy.cli import main

    capsys.readouterr()
    rc = main(["participants", *args])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_prolific_ids_stored_and_completion_codes(served):
    api, cfg, _ = served
    plat = {"PROLIFIC_PID": "5f0c1a2b3c4d5e6f7a8b9c0d", "STUDY_ID": "study01", "SESSION_ID": "sess_42"}
    h, state = register(api, "5f0c1a2b3c4d5e6f7a8b9c0d", platform=plat)
    people = {p["participant"]: p for p in api.get("/admin/participants.json", headers=ADMIN).json()["participants"]}
    me = people["5f0c1a2b3c4d5e6f7a8b9c0d"]
    assert (me["prolific_pid"], me["prolific_study_id"], me["prolific_session_id"]) == (
        "5f0c1a2b3c4d5e6f7a8b9c0d",
        "study01",
        "sess_42",
    )
    for bad in ({"STUDY_ID": "a b"}, {"OTHER": "x"}, "nope", {"SESSION_ID": 5}):
        r = api.post("/api/participants", json={"participant_id": "P_badplat", "platform": bad})
        assert r.status_code == 400 and "platform" in r.json()["error"]
    for t in state["trials"]:
        assert answer(api, "5f0c1a2b3c4d5e6f7a8b9c0d", h, t).status_code == 201
    done = api.post("/api/participants/5f0c1a2b3c4d5e6f7a8b9c0d/complete", headers=h).json()
    assert done["completion_code"] == "C-DONE" and done["status"] == "completed"
    # the screen check: a too small window ends the session with the screened-out code, before consent
    h2, _ = register(api, "P_small", ready=False)
    r = api.post("/api/participants/P_small/screen-out", json={"width": 1280, "height": 800}, headers=h2)
    assert r.status_code == 422  # that one passes
    r = api.post("/api/participants/P_small/screen-out", json={"width": 1024, "height": 600}, headers=h2)
    assert r.status_code == 200 and r.json()["completion_code"] == "C-SCREEN" and r.json()["status"] == "screened_out"
    assert api.post("/api/participants/P_small/consent", json={"consent": True}, headers=h2).status_code == 409
    info = api.get("/api/study").json()
    assert info["screen"] == {"min_width": 1280, "min_height": 720} and info["fullscreen"] is True


def test_participant_withdraws_everything_deleted_audit_kept(served, tmp_path):
    api, cfg, online = served
    h, state = register(api, "P_out")
    for t in state["trials"][:4]:
        assert answer(api, "P_out", h, t).status_code == 201
    answer(api, "P_out", h, state["trials"][0], answers={**ANS, "Q1": 1})  # a refused duplicate too
    assert api.post("/api/participants/P_out/withdraw", json={"confirm": "yes"}, headers=h).status_code == 422
    r = api.post("/api/participants/P_out/withdraw", json={"confirm": True}, headers=h)
    assert r.status_code == 200 and r.json()["completion_code"] == "C-WITHDRAWN"
    store = cfg.store
    with store.engine.connect() as conn:
        for table in (store.responses, store.conflicts, store.schedule_t):
            n = conn.execute(
                sa.select(sa.func.count()).select_from(table).where(table.c.participant_id == "P_out")
            ).scalar_one()
            assert n == 0, table.name
    row = store.participant("P_out")
    assert row["age"] is None and row["gender"] is None and row["user_agent"] is None and row["withdrawn_at"]
    assert api.get("/api/participants/P_out", headers=h).status_code == 410
    assert api.post("/api/participants", json={"participant_id": "P_out"}).status_code == 409  # no second life
    audit = store.audit
    with store.engine.connect() as conn:
        lines = [dict(x._mapping) for x in conn.execute(sa.select(audit))]
    assert (
        len(lines) == 1
        and lines[0]["participant_id"] == "P_out"
        and "deleted 4 answers, 1 practice answer(s), 1 refused" in lines[0]["detail"]
    )
    assert "by participant" in lines[0]["detail"] and "Q1" not in lines[0]["detail"]
    # the export lists them as withdrawn, with no answers
    out = tmp_path / "out" / "responses.csv"
    export_study(store.url, out, tmp_path / "out" / "demo.csv", online=online)
    assert "P_out" not in out.read_text()
    people = {p["participant"]: p for p in csv.DictReader((out.parent / "participants.csv").open())}
    assert people["P_out"]["status"] == "withdrawn" and people["P_out"]["excluded"] == "1"
    demo = {p["participant_id"]: p for p in csv.DictReader((tmp_path / "out" / "demo.csv").open())}
    assert demo["P_out"]["age"] == "" and demo["P_out"]["gender"] == ""


def test_participants_cli_list_and_withdraw(served, capsys):
    api, cfg, _ = served
    h, state = register(api, "P_cli1", platform={"PROLIFIC_PID": "P_cli1"})
    register(api, "P_cli2", ready=False)
    for t in state["trials"][:3]:
        answer(api, "P_cli1", h, t)
    url = cfg.store.url
    rc, out, err = _cli(capsys, "list", "--db", url)
    assert rc == 0, err
    line = next(ln for ln in out.splitlines() if ln.split()[:1] == ["P_cli1"])
    assert "active" in line and " 3 " in f" {line} " and "60" in line
    rc, out, err = _cli(capsys, "withdraw", "--db", url, "P_cli1", "--reason", "e-mail of 2026-01-08")
    assert rc == 0 and "withdrew P_cli1" in out and "deleted 3 answers" in out, err
    assert _cli(capsys, "withdraw", "--db", url, "P_cli1")[0] == 0  # again: nothing more to do
    rc, out, _ = _cli(capsys, "audit", "--db", url)
    assert out.count("withdraw  P_cli1") == 1 and "reason: e-mail of 2026-01-08" in out
    rc, out, _ = _cli(capsys, "list", "--db", url, "--status", "withdrawn")
    assert "P_cli1" in out and "P_cli2" not in out
    assert api.get("/api/participants/P_cli1", headers=h).status_code == 410  # the running server agrees
    rc, _, err = _cli(capsys, "withdraw", "--db", url, "P_nobody")
    assert rc == 2 and "P_nobody" in err
    rc, _, err = _cli(capsys, "list", "--db", "sqlite:////nonexistent/x.db")
    assert rc == 2 and "does not exist" in err
    # the command itself, once as a subprocess
    p = subprocess.run(
        [sys.executable, "-m", "crowdstudy", "participants", "list", "--db", url],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert p.returncode == 0 and "withdrawn" in p.stdout


def test_quality_record_attention_checks_and_exclusions(served, tmp_path):
    api, cfg, online = served
    # every participant has 3 checks on distinct trials, placed differently per participant
    checks = {}
    for pid in ("P_good", "P_fast", "P_flat", "P_careless", "P_tabs"):
        h, state = register(api, pid)
        checks[pid] = (h, state, [t["trial_index"] for t in state["trials"] if "check" in t])
        assert len(checks[pid][2]) == 3
    assert len({tuple(c[2]) for c in checks.values()}) > 1
    h, state, idx = checks["P_good"]
    t = state["trials"][idx[0]]
    assert (
        api.post(
            "/api/participants/P_good/responses",
            headers=h,
            json={"trial_index": 0, "token": state["trials"][0]["token"], "answers": ANS, "rt_ms": 5, "check": 2}
            if idx[0] != 0
            else {"trial_index": 0, "token": t["token"], "answers": ANS, "rt_ms": 5},
        ).status_code
        == 422
    )  # check missing, or not expected
    varied = [{f"Q{i}": (k + i) % 6 + 1 for i in range(1, 7)} for k in range(60)]
    for pid, (h, state, _idx) in checks.items():
        for k, t in enumerate(state["trials"]):
            kw = {
                "answers": varied[k],
                "rt": 5000.0,
                "video_plays": 1,
                "first_play_ms": 1000.0 + k,
                "hidden_count": 0,
                "hidden_ms": 0.0,
                "fullscreen_exits": 0,
            }
            if pid == "P_fast":
                kw["rt"] = 300.0
            if pid == "P_flat":
                kw["answers"] = ANS
            if pid == "P_careless" and "check" in t:
                kw["check"] = check_answer(t) % 6 + 1
            if pid == "P_tabs" and k < 4:
                kw.update(hidden_count=2, hidden_ms=15000.0, fullscreen_exits=1)
            r = answer(api, pid, h, t, **kw)
            assert r.status_code == 201, r.text
    r = answer(api, "P_good", checks["P_good"][0], checks["P_good"][1]["trials"][0], video_plays=-1)
    assert r.status_code == 422 and "video_plays" in r.json()["error"]
    out = tmp_path / "responses.csv"
    summary = export_study(cfg.store.url, out, online=online)
    rows = list(csv.DictReader(out.open()))
    good = [r for r in rows if r["participant_id"] == "P_good"]
    assert good[3]["video_plays"] == "1" and float(good[3]["first_play_ms"]) == 1003.0
    assert sum(1 for r in good if r["check_value"]) == 3 and all(
        r["check_answer"] == r["check_value"] for r in good if r["check_value"]
    )
    tabs = [r for r in rows if r["participant_id"] == "P_tabs"]
    assert (
        tabs[0]["hidden_count"] == "2" and float(tabs[0]["hidden_ms"]) == 15000.0 and tabs[0]["fullscreen_exits"] == "1"
    )
    people = {p["participant"]: p for p in csv.DictReader((tmp_path / "participants.csv").open())}
    assert {k: (v["excluded"], v["exclusion_reason"]) for k, v in people.items()} == {
        "P_good": ("0", ""),
        "P_fast": ("1", "too_fast"),
        "P_flat": ("1", "straight_lining"),
        "P_careless": ("1", "failed_attention_check"),
        "P_tabs": ("1", "tab_switching"),
    }
    assert summary["excluded"] == 4
    # the same database with rules off: nobody flagged
    relaxed = tmp_path / "relaxed.toml"
    relaxed.write_text("[online]\nattention_checks = 0\n")
    export_study(cfg.store.url, tmp_path / "r2.csv", online=relaxed)
    assert {p["excluded"] for p in csv.DictReader((tmp_path / "participants.csv").open())} == {"0"}


def test_online_config_validation(tmp_path):
    cfg = load_online_config()
    assert cfg.min_width == 1280 and cfg.min_height == 720 and cfg.attention_checks == 2
    bad = tmp_path / "bad.toml"
    for text, fragment in (
        ("[online]\nmin_width = -1\n", "min_width"),
        ("[online]\nspeed = 1\n", "unknown key"),
        ("[online.exclude]\nmax_straightline_fraction = 2\n", "max_straightline_fraction"),
        ("[online.codes]\nfinished = 'x'\n", "codes"),
        ("x = 1\n", "[online]"),
    ):
        bad.write_text(text)
        with pytest.raises(InvalidInputError, match=fragment.replace("[", r"\[").replace("]", r"\]")):
            load_online_config(bad)

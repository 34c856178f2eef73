"""Slider and 2afc trials on the study server: schedule, answers, practice, checks, export,
withdrawal and blinding, on a design with three methods and one stage per task."""

from __future__ import annotations

import csv
import json
import sys
from collections import Counter
from pathlib import Path

import pytest

from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.study.fake_stimuli import write_fake_stimuli

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_fixtures import ADMIN, make_client  # noqa: E402

DESIGN = Path(__file__).resolve().parent / "data" / "three_tasks.toml"
RATE = {"R1": 2, "R2": 4, "R3": 5}
SLIDE = {"R1": 10, "R2": 55, "R3": 100}

pytestmark = [
    pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`"),
    pytest.mark.filterwarnings("ignore:Setting per-request cookies"),
]


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("stim3"), DESIGN, n_files=3, seconds=1.0)


@pytest.fixture
def server(stim_dir, tmp_path):
    client, cfg = make_client(stim_dir, f"sqlite:///{tmp_path / 'study.db'}", design=DESIGN)
    yield client, cfg, tmp_path / "study.db"
    cfg.store.close()


def _ready(api, pid, tasks=("likert", "slider", "2afc")):
    r = api.post("/api/participants", json={"participant_id": pid})
    assert r.status_code == 201, r.text
    h = {"X-Participant-Secret": r.json()["secret"]}
    assert api.post(f"/api/participants/{pid}/consent", json={"consent": True}, headers=h).status_code == 200
    assert (
        api.post(f"/api/participants/{pid}/demographics", json={"age": 30, "gender": "female"}, headers=h).status_code
        == 200
    )
    practice = {"likert": {"answers": RATE}, "slider": {"answers": SLIDE}, "2afc": {"choice": "left"}}
    for task in tasks:
        body = {"task": task, **practice[task], "rt_ms": 900.0}
        r = api.post(f"/api/participants/{pid}/practice", json=body, headers=h)
        assert r.status_code == 201 and r.json()["task"] == task, r.text
    return h, api.get(f"/api/participants/{pid}", headers=h).json()


def _body(trial, choice="right"):
    body = {"trial_index": trial["trial_index"], "token": trial["token"], "rt_ms": 1500.0, "video_plays": 2}
    if trial["task"] == "2afc":
        body["choice"] = choice
    else:
        body["answers"] = RATE if trial["task"] == "likert" else SLIDE
    if "check" in trial:
        text = trial["check"]["text"]
        if trial["task"] == "2afc":
            body["check"] = "left" if "left video" in text else "right"
        elif trial["task"] == "slider":
            body["check"] = 0 if "left end" in text else 100
        else:
            body["check"] = int(text.split("choose (")[1].split(")")[0])
    return body


def _answer_all(api, pid, h, state, choice="right"):
    for t in state["trials"]:
        r = api.post(f"/api/participants/{pid}/responses", json=_body(t, choice), headers=h)
        assert r.status_code == 201, r.text
    assert api.post(f"/api/participants/{pid}/complete", headers=h).status_code == 200


def test_schedule_has_each_stage_by_its_task(server):
    api, _cfg, _ = server
    study = api.get("/api/study").json()
    assert [(s["task"], s["n_trials"]) for s in study["stages"]] == [("likert", 12), ("slider", 6), ("2afc", 6)]
    assert study["comparison"].startswith("In which video") and study["slider"] == {
        "left": "Not at all",
        "right": "Completely",
    }
    _h, state = _ready(api, "T1")
    trials = state["trials"]
    assert [t["task"] for t in trials] == ["likert"] * 12 + ["slider"] * 6 + ["2afc"] * 6
    assert all(("video_url_right" in t) == (t["task"] == "2afc") for t in trials)
    assert all(t["video_url"] != t["video_url_right"] for t in trials if t["task"] == "2afc")
    full = api.get("/admin/participants/T1/schedule", headers=ADMIN).json()["trials"]
    pairs = Counter(frozenset((t["method"], t["method_right"])) for t in full if t["task"] == "2afc")
    # every pair of methods in every cell (2 densities x 1 viewpoint) once
    assert pairs == {frozenset(p): 2 for p in (("Plain", "Physics"), ("Plain", "Stiff"), ("Physics", "Stiff"))}
    cells = {(t["density_level"], t["viewpoint"], t["method"], t["method_right"]) for t in full if t["task"] == "2afc"}
    assert len(cells) == 6


def test_sides_are_counterbalanced_within_each_participant(server):
    api, _cfg, _ = server
    orders = set()
    for k in range(6):
        pid = f"C{k}"
        api.post("/api/participants", json={"participant_id": pid})
        full = api.get(f"/admin/participants/{pid}/schedule", headers=ADMIN).json()["trials"]
        comps = [t for t in full if t["task"] == "2afc"]
        design = load_design(DESIGN)
        for a, b in design.stage("compare").pairs:
            left = Counter(t["method"] for t in comps if {t["method"], t["method_right"]} == {a, b})
            assert left[a] == left[b] == 1  # two cells: each method on the left once
        orders.add(tuple(t["stimulus_id"] + t["stimulus_right"] for t in comps))
    assert len(orders) > 1  # order and sides shuffled per participant


def test_answers_of_each_task_are_stored_and_exported(server, tmp_path):
    from crowdstudy.study.export import export_study

    api, _cfg, db = server
    h, state = _ready(api, "T2")
    _answer_all(api, "T2", h, state)
    own = api.get("/api/participants/T2/responses", headers=h).json()["responses"]
    assert own[0]["R3"] == 5 and own[12]["R3"] == 100 and own[-1]["choice"] == "right" and "R1" not in own[-1]
    summary = export_study(f"sqlite:///{db}", tmp_path / "out" / "responses.csv", online=DESIGN)
    assert summary["responses"] == 18 and summary["comparisons"] == 6
    rows = list(csv.DictReader(open(tmp_path / "out" / "responses.csv", encoding="utf-8")))
    assert list(rows[0])[:14] == [
        "participant_id", "stage", "scenario", "task", "trial_index", "stimulus_id", "density_level",
        "density", "viewpoint", "method", "R1", "R2", "R3", "rt_ms",
    ]  # fmt: skip
    assert Counter(r["task"] for r in rows) == {"likert": 12, "slider": 6}
    assert {r["R2"] for r in rows if r["task"] == "slider"} == {"55"}
    comps = list(csv.DictReader(open(tmp_path / "out" / "comparisons.csv", encoding="utf-8")))
    assert len(comps) == 6 and all(r["task"] == "2afc" and r["choice"] == "right" for r in comps)
    assert all(r["chosen_method"] == r["method_right"] and r["stimulus_left"].endswith(r["method_left"]) for r in comps)
    parts = list(csv.DictReader(open(tmp_path / "out" / "participants.csv", encoding="utf-8")))
    (p,) = parts
    # always the right video: flagged by the same_side rule; the checks were all passed
    assert p["same_side_fraction"] == "1.0" and p["exclusion_reason"] == "same_side" and p["checks_failed"] == "0"
    admin_csv = api.get("/admin/export/comparisons.csv", headers=ADMIN).text
    assert admin_csv == (tmp_path / "out" / "comparisons.csv").read_text(encoding="utf-8")


def test_bad_bodies_are_refused_naming_the_field(server):
    api, _cfg, _ = server
    h, state = _ready(api, "T3")
    trials = state["trials"]
    url = "/api/participants/T3/responses"
    for t in trials[:12]:
        assert api.post(url, json=_body(t), headers=h).status_code == 201
    slider = trials[12]
    for patch, field in (
        ({"answers": {**SLIDE, "R1": 101}}, "answers.R1"),
        ({"answers": {**SLIDE, "R2": 5.5}}, "answers.R2"),
        ({"answers": {"R1": 1, "R2": 2}}, "answers.R3"),
        ({"answers": {**SLIDE, "Q1": 3}}, "unknown item"),
        ({"choice": "left"}, "choice"),
    ):
        r = api.post(url, json={**_body(slider), **patch}, headers=h)
        assert r.status_code == 422 and field in r.json()["error"], (patch, r.text)
    for t in trials[12:18]:
        assert api.post(url, json=_body(t), headers=h).status_code == 201
    comp = trials[18]
    for patch, field in (
        ({"choice": "middle"}, "choice"),
        ({"choice": None}, "choice"),
        ({"answers": RATE}, "answers"),
    ):
        r = api.post(url, json={**_body(comp), **patch}, headers=h)
        assert r.status_code == 422 and field in r.json()["error"], (patch, r.text)
    r = api.post("/api/participants/T3/practice", json={"task": "ranking", "choice": "left", "rt_ms": 1}, headers=h)
    assert r.status_code == 422 and "task" in r.json()["error"]


def test_a_task_needs_its_practice_first(server):
    api, _cfg, _ = server
    h, state = _ready(api, "T4", tasks=("likert",))
    url = "/api/participants/T4/responses"
    for t in state["trials"][:12]:
        assert api.post(url, json=_body(t), headers=h).status_code == 201
    r = api.post(url, json=_body(state["trials"][12]), headers=h)
    assert r.status_code == 409 and "practice" in r.json()["error"] and "slider" in r.json()["error"]
    body = {"task": "slider", "answers": SLIDE, "rt_ms": 10.0}
    assert api.post("/api/participants/T4/practice", json=body, headers=h).status_code == 201
    assert api.post("/api/participants/T4/practice", json=body, headers=h).status_code == 200  # once
    assert api.get("/api/participants/T4", headers=h).json()["practiced"] == ["likert", "slider"]
    assert api.post(url, json=_body(state["trials"][12]), headers=h).status_code == 201


def test_withdrawal_deletes_every_task_s_answers(server):
    api, cfg, _ = server
    h, state = _ready(api, "T5")
    _answer_all(api, "T5", h, state, choice="left")
    assert len(cfg.store.response_rows("T5")) == 24
    r = api.post("/api/participants/T5/withdraw", json={"confirm": True}, headers=h)
    assert r.status_code == 200
    import sqlalchemy as sa

    with cfg.store.engine.connect() as conn:
        left = conn.execute(sa.select(cfg.store.responses).where(cfg.store.responses.c.participant_id == "T5"))
        assert left.first() is None


def test_the_browser_never_sees_a_method_or_stimulus_id(server):
    api, cfg, _ = server
    design = cfg.design
    words = {s.stimulus_id for s in design.stimuli()} | set(design.methods) | set(design.densities)
    seen = [api.get("/api/study").text]
    h, state = _ready(api, "T6")
    seen.append(json.dumps(state))
    for t in state["trials"]:
        r = api.post("/api/participants/T6/responses", json=_body(t), headers=h)
        seen.append(r.text)
    seen.append(api.get("/api/participants/T6/responses", headers=h).text)
    seen.append(api.post("/api/participants/T6/complete", headers=h).text)
    leaks = [w for w in words for text in seen if f'"{w}"' in text or f"/{w}" in text or f"{w}." in text]
    assert not leaks
    assert all(k in {"trial_index", "stage", "task", "token", "video_url", "video_url_right", "check"}
               for t in state["trials"] for k in t)  # fmt: skip


def test_serve_refuses_a_folder_without_a_method_the_design_names(stim_dir, tmp_path):
    import shutil

    from crowdstudy.study.stimulus_set import load_stimulus_set

    folder = tmp_path / "stim"
    shutil.copytree(stim_dir, folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["stimuli"] = [r for r in manifest["stimuli"] if r["method"] != "Stiff"]
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(InvalidInputError, match=r"method 'Stiff'.*stages 1, 2, 3"):
        load_stimulus_set(folder, load_design(DESIGN))


def test_an_earlier_version_s_database_is_refused_for_a_2afc_design(stim_dir, tmp_path):
    import sqlite3

    db = tmp_path / "old.db"
    con = sqlite3.connect(db)
    qs = ", ".join(f"Q{i} SMALLINT NOT NULL" for i in range(1, 7))
    con.execute(
        "CREATE TABLE responses (id INTEGER PRIMARY KEY, participant_id VARCHAR(64) NOT NULL, trial_index INTEGER "
        f"NOT NULL, practice BOOLEAN NOT NULL, stimulus_id VARCHAR(64) NOT NULL, stage INTEGER NOT NULL, {qs}, "
        "rt_ms FLOAT NOT NULL, shown_at VARCHAR(40) NOT NULL, answered_at VARCHAR(40) NOT NULL)"
    )
    con.commit()
    con.close()
    with pytest.raises(InvalidInputError, match="earlier crowdstudy.*2afc"):
        make_client(stim_dir, f"sqlite:///{db}", design=DESIGN)


def test_slider_and_2afc_bodies_are_checked_in_one_place():
    from crowdstudy.study import bodies
    from crowdstudy.study.webio import ApiError

    assert bodies.parse_task_answer({"choice": "left"}, "2afc", ("A",), 6) == ({}, "left")
    assert bodies.parse_task_answer({"answers": {"A": 0}}, "slider", ("A",), 6) == ({"A": 0}, None)
    assert bodies.parse_check({"check": "right"}, 3, True, 6, "2afc") == 2
    with pytest.raises(ApiError, match="check must be 'left' or 'right'"):
        bodies.parse_check({"check": 1}, 3, True, 6, "2afc")
    with pytest.raises(ApiError, match="answers.A must be an integer 0..100"):
        bodies.parse_task_answer({"answers": {"A": True}}, "slider", ("A",), 6)


def test_resume_keeps_the_position_and_the_practised_tasks(server):
    api, _cfg, _ = server
    h, state = _ready(api, "T7", tasks=("likert", "slider"))
    for t in state["trials"][:14]:
        assert api.post("/api/participants/T7/responses", json=_body(t), headers=h).status_code == 201
    again = api.post("/api/participants", json={"participant_id": "T7", "secret": h["X-Participant-Secret"]})
    assert again.status_code == 200 and again.json()["resumed"]
    st = again.json()["state"]
    assert st["next_trial_index"] == 14 and st["practiced"] == ["likert", "slider"]
    assert st["trials"][14]["task"] == "slider" and st["trials"][18]["task"] == "2afc"


def test_slider_straight_lines_and_failed_checks_are_flagged():
    from crowdstudy.study.quality import OnlineConfig, check_passed, flag_participants

    rows = [
        {"participant_id": "A", "task": "slider", "R1": 40, "R2": 40, "R3": 40, "rt_ms": 9000.0},
        {"participant_id": "A", "task": "slider", "R1": 40, "R2": 40, "R3": 40, "rt_ms": 9000.0,
         "check_value": 100, "check_answer": 95},
        {"participant_id": "A", "task": "2afc", "choice": "left", "rt_ms": 9000.0, "check_value": 2, "check_answer": 1},
    ]  # fmt: skip
    cfg = OnlineConfig(max_failed_checks=0, max_straightline_fraction=0.8, max_same_side_fraction=1.0)
    (a,) = flag_participants([{"participant": "A", "status": "completed"}], rows, cfg, ("R1", "R2", "R3"))
    assert a["straightline_trials"] == 2 and a["checks_total"] == 2 and a["checks_failed"] == 1
    assert a["exclusion_reason"] == "failed_attention_check;straight_lining;same_side"
    assert check_passed("slider", 0, 10) and not check_passed("slider", 0, 11) and check_passed("2afc", 1, 1)


def test_serve_exits_2_with_one_line_naming_the_missing_method(stim_dir, tmp_path):
    import shutil
    import subprocess
    import sys

    folder = tmp_path / "stim"
    shutil.copytree(stim_dir, folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["stimuli"] = [r for r in manifest["stimuli"] if r["method"] != "Physics"]
    (folder / "manifest.json").write_text(json.dumps(manifest))
    p = subprocess.run(
        [sys.executable, "-m", "crowdstudy", "serve", "--stimuli", str(folder), "--design", str(DESIGN),
         "--db", f"sqlite:///{tmp_path / 'x.db'}"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    err = (p.stdout + p.stderr).strip()
    assert p.returncode == 2 and "Traceback" not in err and len(err.splitlines()) == 1
    assert "no video of method 'Physics'" in err and not (tmp_path / "x.db").exists()

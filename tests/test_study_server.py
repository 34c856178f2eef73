"""The study server's JSON API, storage, schedule, export and access control (in-process)."""

import csv
import json
import re
import shutil
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import pytest

from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.study.consent import markdown_to_html
from crowdstudy.study.export import RESPONSE_COLUMNS, export_study
from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.schedule import make_schedule
from crowdstudy.study.stimulus_set import load_stimulus_set

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_fixtures import register  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TOKEN = "test-admin-token-0123456789abcdef"
ANS = {f"Q{i}": 3 for i in range(1, 7)}

pytestmark = [
    pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`"),
    pytest.mark.filterwarnings("ignore:Setting per-request cookies"),
]


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("stim"), n_files=3, seconds=1.0)


def _client(stim_dir, db_url, **kwargs):
    from starlette.testclient import TestClient

    from crowdstudy.study.app import create_app
    from crowdstudy.study.server import build_config

    cfg = build_config(stim_dir, db=db_url, admin_token=TOKEN, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return TestClient(create_app(cfg)), cfg


@pytest.fixture
def api(stim_dir, tmp_path):
    db = tmp_path / "study.db"
    client, cfg = _client(stim_dir, f"sqlite:///{db}", completion_code="DONE-1")
    yield client
    cfg.store.close()


def _register(api, pid="P001", *, ready=True):
    return register(api, pid, ready=ready)


def check_answer(trial):
    """The point an attention-check trial's extra statement asks for (parsed from its text)."""
    import re

    return int(re.search(r"choose \((\d+)\)", trial["check"]["text"]).group(1))


def _answer(api, pid, h, trial, answers=ANS, rt=1234.5, **extra):
    body = {"trial_index": trial["trial_index"], "token": trial["token"], "answers": answers, "rt_ms": rt, **extra}
    if "check" in trial and "check" not in extra:
        body["check"] = check_answer(trial)
    return api.post(f"/api/participants/{pid}/responses", headers=h, json=body)


ADMIN = {"Authorization": f"Bearer {TOKEN}"}


def _admin_schedule(api, pid):
    r = api.get(f"/admin/participants/{pid}/schedule", headers=ADMIN)
    assert r.status_code == 200, r.text
    return r.json()["trials"]


# -- schedule --------------------------------------------------------------------------------
def test_schedule_is_deterministic_per_participant_and_stage_blocked():
    design = load_design()
    by_stage = {}
    for s in design.stimuli():
        by_stage.setdefault(s.stage, []).append(s.stimulus_id)
    a1 = make_schedule(by_stage, "alice", design.seed)
    a2 = make_schedule({k: list(reversed(v)) for k, v in by_stage.items()}, "alice", design.seed)
    b = make_schedule(by_stage, "bob", design.seed)
    assert a1 == a2
    assert [t.stimulus_id for t in a1] != [t.stimulus_id for t in b]
    assert [t.trial_index for t in a1] == list(range(60))
    assert [t.stage for t in a1] == [1] * 40 + [2] * 20
    assert sorted(t.stimulus_id for t in a1[:40]) == sorted(by_stage[1])
    assert sorted(t.stimulus_id for t in a1[40:]) == sorted(by_stage[2])
    with pytest.raises(InvalidInputError, match="participant_id"):
        make_schedule(by_stage, "../etc/passwd", 1)


# -- the happy path, idempotency, resume -----------------------------------------------------
def test_session_flow_idempotent_resend_and_conflict(api):
    h, state = _register(api, "P001")
    assert state["n_trials"] == 60 and state["next_trial_index"] == 0
    t0 = state["trials"][0]
    r1 = _answer(api, "P001", h, t0)
    assert r1.status_code == 201
    r2 = _answer(api, "P001", h, t0)  # a resend of the same answer
    assert r2.status_code == 200 and r2.json()["answer"] == r1.json()["answer"]
    r3 = _answer(api, "P001", h, t0, answers={**ANS, "Q4": 5})  # a different answer for the same trial
    assert r3.status_code == 409 and "different answer" in r3.json()["error"]
    rows = api.get("/api/participants/P001/responses", headers=h).json()["responses"]
    assert len(rows) == 1 and rows[0]["Q4"] == 3
    # answers must come in order
    r = _answer(api, "P001", h, state["trials"][2])
    assert r.status_code == 409 and "trial 1" in r.json()["error"]
    # completion needs every trial
    r = api.post("/api/participants/P001/complete", headers=h)
    assert r.status_code == 409 and "59 trials" in r.json()["error"]
    for t in state["trials"][1:]:
        assert _answer(api, "P001", h, t).status_code == 201
    r = api.post("/api/participants/P001/complete", headers=h)
    assert r.status_code == 200 and r.json()["completion_code"] == "DONE-1" and r.json()["completed"]


def test_resume_after_server_restart_keeps_order_and_progress(stim_dir, tmp_path):
    url = f"sqlite:///{tmp_path / 'resume.db'}"
    api1, cfg1 = _client(stim_dir, url)
    h, state = _register(api1, "P_resume")
    for t in state["trials"][:5]:
        assert _answer(api1, "P_resume", h, t).status_code == 201
    cfg1.store.close()
    api2, cfg2 = _client(stim_dir, url)  # a new server process on the same database
    reg = api2.post("/api/participants", json={"participant_id": "P_resume", "secret": h["X-Participant-Secret"]})
    assert reg.status_code == 200 and reg.json()["resumed"]
    st = reg.json()["state"]
    assert st["next_trial_index"] == 5 and st["n_answered"] == 5
    # the same order and the same tokens (the blinding secret lives in the database)
    assert st["trials"] == state["trials"]
    assert st["consented"] and st["demographics"] and st["practice_done"] and not st["completed"]
    assert _answer(api2, "P_resume", h, st["trials"][5]).status_code == 201
    cfg2.store.close()


def test_concurrent_resends_store_exactly_one_row(api):
    h, state = _register(api, "P_conc")
    t0 = state["trials"][0]
    codes = []

    def send():
        codes.append(_answer(api, "P_conc", h, t0).status_code)

    threads = [threading.Thread(target=send) for _ in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert sorted(codes) == [200] * 7 + [201]
    assert len(api.get("/api/participants/P_conc/responses", headers=h).json()["responses"]) == 1


# -- rejected input -----------------------------------------------------------------------
@pytest.mark.parametrize(
    "answers, fragment",
    [
        ({**ANS, "Q1": 0}, "answers.Q1 must be an integer 1..6"),
        ({**ANS, "Q2": 7}, "answers.Q2 must be an integer 1..6"),
        ({**ANS, "Q3": 3.5}, "answers.Q3 must be an integer"),
        ({**ANS, "Q4": "3"}, "answers.Q4 must be an integer"),
        ({**ANS, "Q5": True}, "answers.Q5 must be an integer"),
        ({**ANS, "Q6": None}, "answers.Q6 must be an integer"),
        ({k: v for k, v in ANS.items() if k != "Q3"}, "answers.Q3 is missing"),
        ({**ANS, "Q7": 2}, "unknown item 'Q7'"),
        ([3, 3, 3, 3, 3, 3], "answers must be an object"),
    ],
)
def test_rejects_bad_answers(api, answers, fragment):
    h, state = _register(api, "P_bad")
    r = _answer(api, "P_bad", h, state["trials"][0], answers=answers)
    assert r.status_code == 422 and fragment in r.json()["error"]
    assert api.get("/api/participants/P_bad/responses", headers=h).json()["responses"] == []


@pytest.mark.parametrize(
    "patch, fragment",
    [
        ({"trial_index": -1}, "trial_index must be an integer 0..59"),
        ({"trial_index": 60}, "trial_index must be an integer 0..59"),
        ({"trial_index": "0"}, "trial_index must be an integer"),
        ({"trial_index": 0.0}, "trial_index must be an integer"),
        ({"token": "0123456789abcdef0123"}, "not in this participant's schedule"),
        ({"token": "../../manifest.json"}, "token must be"),
        ({"token": "x' OR '1'='1"}, "token must be"),
        ({"token": "0123456789ABCDEF0123"}, "token must be"),
        ({"token": None}, "token must be"),
        ({"token": 12}, "token must be"),
        ({"stimulus_id": "S1-D1-V1-Ours"}, "not a stimulus_id"),
        ({"rt_ms": -5}, "rt_ms must be"),
        ({"rt_ms": "fast"}, "rt_ms must be"),
        ({"shown_at": "yesterday"}, "shown_at must be an ISO 8601"),
    ],
)
def test_rejects_bad_trial_fields(api, patch, fragment):
    h, state = _register(api, "P_fields")
    t = state["trials"][0]
    body = {"trial_index": 0, "token": t["token"], "answers": ANS, "rt_ms": 100, **patch}
    r = api.post("/api/participants/P_fields/responses", json=body, headers=h)
    assert r.status_code == 422 and fragment in r.json()["error"], r.text


def test_rejects_token_of_another_trial(api):
    h, state = _register(api, "P_swap")
    body = {"trial_index": 0, "token": state["trials"][1]["token"], "answers": ANS, "rt_ms": 100}
    r = api.post("/api/participants/P_swap/responses", json=body, headers=h)
    assert r.status_code == 422 and "belongs to trial 1, not to trial_index 0" in r.json()["error"]


def test_rejects_unknown_participant_and_bad_ids(api):
    h, state = _register(api, "P_real")
    body = {"trial_index": 0, "token": state["trials"][0]["token"], "answers": ANS, "rt_ms": 1}
    # an unknown id answers exactly like a wrong secret (no way to probe which ids exist)
    r = api.post("/api/participants/P_ghost/responses", json=body, headers=h)
    wrong = api.post("/api/participants/P_real/responses", json=body, headers={"X-Participant-Secret": "nope"})
    assert r.status_code == wrong.status_code == 403 and r.json() == wrong.json()
    assert api.get("/api/participants/P_ghost", headers=h).status_code == 403
    assert api.get("/api/participants/P_ghost").status_code == api.get("/api/participants/P_real").status_code == 401
    for bad in ["", "a b", "x" * 65, "-lead", "p%2F..%2Fx", "é"]:
        r = api.post("/api/participants", json={"participant_id": bad})
        assert r.status_code == 400 and "participant_id" in r.json()["error"], bad
    assert api.post("/api/participants", json={"participant_id": 12}).status_code == 400
    assert api.get("/api/participants/a%20b", headers=h).status_code == 400


def test_rejects_malformed_bodies(api):
    h, _ = _register(api, "P_body")
    url = "/api/participants/P_body/responses"
    r = api.post(url, content=b"{not json", headers={**h, "Content-Type": "application/json"})
    assert r.status_code == 400 and "not valid JSON" in r.json()["error"]
    r = api.post(url, content=b"[1, 2]", headers={**h, "Content-Type": "application/json"})
    assert r.status_code == 400 and "JSON object" in r.json()["error"]
    r = api.post(url, content=b"{" + b" " * 20000 + b"}", headers={**h, "Content-Type": "application/json"})
    assert r.status_code == 413


def test_flow_order_and_demographics_validation(api):
    h, state = _register(api, "P_order", ready=False)
    pid = "P_order"
    r = _answer(api, pid, h, state["trials"][0])
    assert r.status_code == 409 and "consent" in r.json()["error"]
    r = api.post(f"/api/participants/{pid}/demographics", json={"age": 30, "gender": "male"}, headers=h)
    assert r.status_code == 409 and "consent" in r.json()["error"]
    r = api.post(f"/api/participants/{pid}/practice", json={"answers": ANS, "rt_ms": 1}, headers=h)
    assert r.status_code == 409
    r = api.post(f"/api/participants/{pid}/consent", json={"consent": "yes"}, headers=h)
    assert r.status_code == 422 and "consent must be true" in r.json()["error"]
    assert api.post(f"/api/participants/{pid}/consent", json={"consent": True}, headers=h).status_code == 200
    for body, fragment in [
        ({"age": 17, "gender": "male"}, "age must be an integer 18..120"),
        ({"age": 121, "gender": "male"}, "age must be"),
        ({"age": 30.5, "gender": "male"}, "age must be"),
        ({"age": "abc", "gender": "male"}, "age must be"),
        ({"age": True, "gender": "male"}, "age must be"),
        ({"age": 30, "gender": "robot"}, "gender must be one of"),
        ({"age": 30}, "gender must be one of"),
    ]:
        r = api.post(f"/api/participants/{pid}/demographics", json=body, headers=h)
        assert r.status_code == 422 and fragment in r.json()["error"], body
    assert (
        api.post(f"/api/participants/{pid}/demographics", json={"age": "44", "gender": "female"}, headers=h).status_code
        == 200
    )
    r = _answer(api, pid, h, state["trials"][0])
    assert r.status_code == 409 and "practice" in r.json()["error"]


# -- blinding: participants never see stimulus ids or conditions -----------------------------
def _condition_words(design):
    """Every stimulus id, method name and density level of the design (what must stay hidden)."""
    words = {s.stimulus_id for s in design.stimuli()} | set(design.methods) | set(design.densities)
    return sorted(words, key=len, reverse=True)


def _leaks(text: str, words) -> list[str]:
    import re

    return [w for w in words if re.search(rf"(?<![A-Za-z0-9]){re.escape(w)}(?![A-Za-z0-9])", text)]


def test_participant_facing_responses_never_reveal_the_condition(api):
    words = _condition_words(api.app.state.config.design)
    assert {"Ours", "Baseline", "D3", "S1-D3-V2-Ours"} <= set(words)
    seen = []  # every response body the participant's browser could receive

    def call(method, url, **kw):
        r = api.request(method, url, **kw)
        seen.append((f"{method} {url} -> {r.status_code}", r.text))
        return r

    pid = "P_blind"
    reg = call("POST", "/api/participants", json={"participant_id": pid})
    h = {"X-Participant-Secret": reg.json()["secret"]}
    state = reg.json()["state"]
    assert all(set(t) - {"check"} == {"trial_index", "stage", "task", "token", "video_url"} for t in state["trials"])
    assert len({t["token"] for t in state["trials"]}) == 60
    call("GET", "/api/study")
    call("POST", f"/api/participants/{pid}/consent", json={"consent": True}, headers=h)
    call("POST", f"/api/participants/{pid}/demographics", json={"age": 30, "gender": "male"}, headers=h)
    call("POST", f"/api/participants/{pid}/practice", json={"answers": ANS, "rt_ms": 10}, headers=h)
    trials = state["trials"]
    body = {"trial_index": 0, "token": trials[0]["token"], "answers": ANS, "rt_ms": 100}
    if "check" in trials[0]:
        body["check"] = check_answer(trials[0])
    assert call("POST", f"/api/participants/{pid}/responses", json=body, headers=h).status_code == 201
    assert call("POST", f"/api/participants/{pid}/responses", json=body, headers=h).status_code == 200
    assert (
        call(
            "POST", f"/api/participants/{pid}/responses", json={**body, "answers": {**ANS, "Q1": 1}}, headers=h
        ).status_code
        == 409
    )
    for patch in (
        {"trial_index": 1},
        {"trial_index": 2, "token": trials[2]["token"]},
        {"trial_index": 1, "token": trials[3]["token"]},
        {"token": "0" * 20},
        {"token": "bad"},
    ):
        assert call("POST", f"/api/participants/{pid}/responses", json={**body, **patch}, headers=h).status_code in (
            409,
            422,
        )
    for t in trials[1:]:
        extra = {"check": check_answer(t)} if "check" in t else {}
        assert (
            call(
                "POST",
                f"/api/participants/{pid}/responses",
                headers=h,
                json={"trial_index": t["trial_index"], "token": t["token"], "answers": ANS, "rt_ms": 100, **extra},
            ).status_code
            == 201
        )
    own = call("GET", f"/api/participants/{pid}/responses", headers=h).json()["responses"]
    assert [r["token"] for r in own] == [t["token"] for t in trials]
    call("GET", f"/api/participants/{pid}", headers=h)
    assert call("POST", f"/api/participants/{pid}/complete", headers=h).status_code == 200
    call("POST", "/api/participants", json={"participant_id": pid, "secret": h["X-Participant-Secret"]})
    for what, text in seen:
        assert not _leaks(text, words), (what, _leaks(text, words), text[:300])
    # the video responses carry no name either
    r = api.get(trials[0]["video_url"])
    assert r.status_code == 200 and not _leaks(str(r.headers), words)
    # ... while the server stored the real stimulus ids and the admin export shows the conditions
    admin = _admin_schedule(api, pid)
    assert [t["token"] for t in admin] == [t["token"] for t in trials]
    rows = list(csv.DictReader(api.get("/admin/export/responses.csv", headers=ADMIN).text.splitlines()))
    assert [r["stimulus_id"] for r in rows] == [t["stimulus_id"] for t in admin]
    assert {r["method"] for r in rows} == {"Baseline", "Ours"}


def test_token_of_participant_a_is_rejected_for_b(api):
    ha, sa_ = _register(api, "P_tokA")
    hb, sb = _register(api, "P_tokB")
    a, b = _admin_schedule(api, "P_tokA"), _admin_schedule(api, "P_tokB")
    # the same stimulus has a different token for each participant
    tok_a = {t["stimulus_id"]: t["token"] for t in a}
    tok_b = {t["stimulus_id"]: t["token"] for t in b}
    assert set(tok_a) == set(tok_b) and all(tok_a[k] != tok_b[k] for k in tok_a)
    assert not set(tok_a.values()) & set(tok_b.values())
    # B sends A's token of B's own first stimulus, then A's token of A's first trial: both refused
    sid_b0 = b[0]["stimulus_id"]
    for token in (tok_a[sid_b0], sa_["trials"][0]["token"]):
        r = api.post(
            "/api/participants/P_tokB/responses",
            headers=hb,
            json={"trial_index": 0, "token": token, "answers": ANS, "rt_ms": 100},
        )
        assert r.status_code == 422 and "not in this participant's schedule" in r.json()["error"]
    assert api.get("/api/participants/P_tokB/responses", headers=hb).json()["responses"] == []
    # a trial token is no video name
    assert api.get(f"/media/{sa_['trials'][0]['token']}").status_code == 404
    assert api.get(sa_["trials"][0]["video_url"]).status_code == 200
    assert _answer(api, "P_tokB", hb, sb["trials"][0]).status_code == 201


def test_admin_schedule_endpoint(api):
    _, state = _register(api, "P_sched", ready=False)
    url = "/admin/participants/P_sched/schedule"
    assert api.get(url).status_code == 401
    assert api.get(url, headers={"Authorization": "Bearer wrong-token"}).status_code == 403
    assert api.get(url, headers={"X-Participant-Secret": "x"}).status_code == 401
    assert api.get("/admin/participants/P_nobody/schedule", headers=ADMIN).status_code == 404
    assert api.get("/admin/participants/a%20b/schedule", headers=ADMIN).status_code == 400
    trials = _admin_schedule(api, "P_sched")
    assert [t["token"] for t in trials] == [t["token"] for t in state["trials"]]
    design = api.app.state.config.design
    by_id = {s.stimulus_id: s for s in design.stimuli()}
    for t in trials:
        s = by_id[t["stimulus_id"]]
        assert (t["stage"], t["scenario"], t["density_level"], t["viewpoint"], t["method"]) == (
            s.stage,
            s.scenario,
            s.density_level,
            s.viewpoint,
            s.method,
        )
        assert t["density"] == pytest.approx(s.density)


def test_blinding_tokens():
    from crowdstudy.study.blinding import TOKEN_LENGTH, TOKEN_PATTERN, stimulus_token, token_table

    key = "k" * 64
    t = stimulus_token(key, "P1", "S1-D3-V2-Ours")
    assert TOKEN_PATTERN.fullmatch(t) and len(t) == TOKEN_LENGTH
    assert t == stimulus_token(key.encode(), "P1", "S1-D3-V2-Ours")
    assert (
        len(
            {
                t,
                stimulus_token(key, "P2", "S1-D3-V2-Ours"),
                stimulus_token(key, "P1", "S1-D3-V2-Baseline"),
                stimulus_token("j" * 64, "P1", "S1-D3-V2-Ours"),
            }
        )
        == 4
    )
    table = token_table(key, "P1", [s.stimulus_id for s in load_design().stimuli()])
    assert len(set(table.values())) == 60
    with pytest.raises(InvalidInputError, match="secret"):
        stimulus_token("short", "P1", "S1")


# -- access control ---------------------------------------------------------------------------
def test_participant_cannot_read_or_write_another(api):
    ha, sa = _register(api, "P_alice")
    hb, sb = _register(api, "P_bob")
    _answer(api, "P_alice", ha, sa["trials"][0])
    assert api.get("/api/participants/P_alice/responses", headers=hb).status_code == 403
    assert api.get("/api/participants/P_alice", headers=hb).status_code == 403
    assert api.get("/api/participants/P_alice/responses").status_code == 401
    assert _answer(api, "P_alice", hb, sa["trials"][1]).status_code == 403
    # re-registering an existing id needs its secret
    r = api.post("/api/participants", json={"participant_id": "P_alice"})
    assert r.status_code == 409 and "already registered" in r.json()["error"]
    r = api.post("/api/participants", json={"participant_id": "P_alice", "secret": hb["X-Participant-Secret"]})
    assert r.status_code == 403
    mine = api.get("/api/participants/P_alice/responses", headers=ha).json()["responses"]
    assert [x["participant_id"] for x in mine] == ["P_alice"]


def test_admin_resume_link_moves_the_session(api):
    h, state = _register(api, "P_move")
    _answer(api, "P_move", h, state["trials"][0])
    assert api.post("/admin/participants/P_move/resume-link").status_code == 401
    assert (
        api.post("/admin/participants/P_nobody/resume-link", headers={"Authorization": f"Bearer {TOKEN}"}).status_code
        == 404
    )
    r = api.post("/admin/participants/P_move/resume-link", headers={"Authorization": f"Bearer {TOKEN}"})
    assert r.status_code == 200 and r.json()["url"].startswith("/?participant=P_move&resume=")
    new_secret = r.json()["url"].split("resume=")[1]
    assert api.get("/api/participants/P_move", headers=h).status_code == 403  # the old browser is locked out
    reg = api.post("/api/participants", json={"participant_id": "P_move", "secret": new_secret})
    assert reg.status_code == 200 and reg.json()["state"]["next_trial_index"] == 1


@pytest.mark.parametrize(
    "path",
    [
        "/admin",
        "/admin/progress.json",
        "/admin/metrics.json",
        "/admin/study.json",
        "/admin/participants.json",
        "/admin/export/responses.csv",
        "/admin/export/demographics.csv",
        "/admin/export/participants.csv",
    ],
)
def test_admin_endpoints_need_the_token(api, path):
    assert api.get(path).status_code == 401
    assert api.get(path, headers={"Authorization": "Bearer wrong-token"}).status_code == 403
    assert api.get(path, headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200
    # never in the URL (logs, history): refused even when right
    assert api.get(f"{path}?token={TOKEN}").status_code in (400, 401)
    assert api.get(path, cookies={"crowdstudy_admin": "forged"}).status_code in (401, 403)


def test_admin_login_cookie(api):
    page = api.get("/admin")
    assert page.status_code == 401 and 'name="token"' in page.text and TOKEN not in page.text
    r = api.post("/admin/login", data={"token": "wrong-token-000000"}, follow_redirects=False)
    assert r.status_code == 403 and "set-cookie" not in r.headers
    r = api.post("/admin/login", data={"token": TOKEN}, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/admin"
    cookie = r.headers["set-cookie"]
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/admin" in cookie and TOKEN not in cookie
    value = cookie.split(";")[0].split("=", 1)[1]
    jar = {"crowdstudy_admin": value}
    page = api.get("/admin", cookies=jar)
    assert page.status_code == 200 and "participants" in page.text and TOKEN not in page.text
    assert api.get("/admin/export/responses.csv", cookies=jar).status_code == 200
    # the cookie opens pages, not actions: a cross-site POST carrying it changes nothing
    _register(api, "P_cookie", ready=False)
    assert api.post("/admin/participants/P_cookie/resume-link", cookies=jar).status_code == 401
    assert api.post("/admin/participants/P_cookie/withdraw", cookies=jar).status_code == 401
    r = api.post("/admin/logout", cookies=jar, follow_redirects=False)
    assert "Max-Age=0" in r.headers["set-cookie"]


def test_admin_export_and_dashboard(api):
    h, state = _register(api, "P_exp")
    for t in state["trials"][:3]:
        _answer(api, "P_exp", h, t)
    text = api.get("/admin/export/responses.csv", headers=ADMIN).text
    rows = list(csv.DictReader(text.splitlines()))
    assert list(rows[0])[: len(RESPONSE_COLUMNS)] == list(RESPONSE_COLUMNS) and len(rows) == 3
    page = api.get("/admin", headers=ADMIN).text
    assert "P_exp" in page and "3 / 60" in page and "token=" not in page
    prog = api.get("/admin/progress.json", headers={"Authorization": f"Bearer {TOKEN}"}).json()
    assert prog["participants"][0]["answered"] == 3


# -- videos and static files -----------------------------------------------------------------
def test_videos_support_range_requests_and_never_paths(api, stim_dir):
    _, state = _register(api, "P_video", ready=False)
    t = state["trials"][0]
    assert re.fullmatch(r"/media/[0-9a-f]{32}\.mp4", t["video_url"]), t["video_url"]
    r = api.get(t["video_url"], headers={"Range": "bytes=0-99"})
    assert r.status_code == 206 and len(r.content) == 100 and r.headers["content-range"].startswith("bytes 0-99/")
    assert r.headers["content-type"] == "video/mp4"
    # an If-Range (no validator can match) gets the whole file, not a 500
    r = api.get(t["video_url"], headers={"Range": "bytes=0-99", "If-Range": '"x"'})
    assert r.status_code == 200
    # the name resolves, through the media table, to that trial's own file
    sid = _admin_schedule(api, "P_video")[0]["stimulus_id"]
    rel = {m["stimulus_id"]: m["file"] for m in json.loads((stim_dir / "manifest.json").read_text())["stimuli"]}[sid]
    assert api.get(t["video_url"]).content == (stim_dir / rel).read_bytes()
    full = api.get(state["practice"]["video_url"])
    assert full.status_code == 200 and full.content[4:8] == b"ftyp"
    for bad in [
        "/media/manifest.json",
        "/media/..%2Fmanifest.json",
        "/media/S1-D3-V2-Ours",
        f"/media/{sid}",
        f"/media/{sid}.mp4",
        "/media/" + "0" * 32 + ".mp4",
        t["video_url"] + "x",
        "/media/practice",
        "/videos/practice",
        f"/videos/P_video/{t['token']}",
    ]:
        assert api.get(bad).status_code == 404, bad
    assert api.get("/lib/jspsych/dist/index.browser.min.js").status_code == 200
    assert api.get("/lib/jspsych/package.json").status_code == 404
    page = api.get("/")
    assert page.status_code == 200 and "plugin-video-likert-loop.js" in page.text
    info = api.get("/api/study").json()
    assert [it["id"] for it in info["items"]] == ["Q1", "Q2", "Q3", "Q4", "Q5", "Q6"]
    assert info["labels"][0] == "I strongly disagree" and info["labels"][-1] == "I fully agree"
    assert [s["n_trials"] for s in info["stages"]] == [40, 20]


# -- stimulus set, consent, export CLI -------------------------------------------------------
def test_stimulus_manifest_validation(stim_dir, tmp_path):
    design = load_design()
    bad = tmp_path / "bad"
    shutil.copytree(stim_dir / "videos", bad / "videos")
    manifest = json.loads((stim_dir / "manifest.json").read_text())
    manifest["stimuli"][0]["file"] = "../outside.mp4"
    (bad / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(InvalidInputError, match="relative path inside"):
        load_stimulus_set(bad, design)
    manifest["stimuli"] = manifest["stimuli"][1:]
    (bad / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(InvalidInputError, match="have no row"):
        load_stimulus_set(bad, design)
    with pytest.raises(InvalidInputError, match="manifest.json is missing"):
        load_stimulus_set(tmp_path, design)


def test_consent_markdown_is_escaped():
    out = markdown_to_html("# Title\n\nSome **bold** <script>alert(1)</script>\n\n- one\n- two\n")
    assert "<h2>Title</h2>" in out and "<strong>bold</strong>" in out
    assert "<script>" not in out and "&lt;script&gt;" in out
    assert "<ul>\n<li>one</li>\n<li>two</li>\n</ul>" in out


def test_export_cli_and_errors(api, tmp_path):
    h, state = _register(api, "P_cli")
    for t in state["trials"][:2]:
        _answer(api, "P_cli", h, t)
    db_url = api.app.state.config.store.url
    out = tmp_path / "r.csv"
    summary = export_study(db_url, out, tmp_path / "d.csv")
    assert summary["responses"] == 2
    rows = list(csv.DictReader(out.open()))
    assert [r["stimulus_id"] for r in rows] == [t["stimulus_id"] for t in _admin_schedule(api, "P_cli")[:2]]
    assert rows[0]["scenario"] == "concert" and rows[0]["stage"] == "1"
    assert json.loads((tmp_path / "r.csv.provenance.json").read_text())["responses"] == 2
    demo = list(csv.DictReader((tmp_path / "d.csv").open()))
    assert demo[0]["participant_id"] == "P_cli" and demo[0]["age"] == "30"
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "crowdstudy",
            "export",
            "--db",
            f"sqlite:///{tmp_path}/none.db",
            "--out",
            str(tmp_path / "x.csv"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert p.returncode == 2 and "does not exist" in p.stderr


def test_serve_config_errors(stim_dir, tmp_path):
    from crowdstudy.study.server import build_config

    with pytest.raises(InvalidInputError, match="--redirect-url"):
        build_config(stim_dir, db=f"sqlite:///{tmp_path}/a.db", redirect_url="javascript:alert(1)")
    with pytest.raises(InvalidInputError, match="--admin-token"):
        build_config(stim_dir, db=f"sqlite:///{tmp_path}/a.db", admin_token="short")
    with pytest.raises(InvalidInputError, match="--consent"):
        build_config(stim_dir, db=f"sqlite:///{tmp_path}/a.db", consent=tmp_path / "none.md")
    with pytest.raises(InvalidInputError, match="--db"):
        build_config(stim_dir, db="not a url")

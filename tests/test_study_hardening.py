"""Robustness and web hygiene of the study server (issue 15): each failure found, tried again."""

import asyncio
import json

import pytest
import sqlalchemy as sa
from study_fixtures import ADMIN, ANS, answer, make_client, register

from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.webio import MAX_BODY_BYTES

pytestmark = [pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")]


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("stim"), n_files=3, seconds=1.0)


@pytest.fixture
def served(stim_dir, tmp_path):
    client, cfg = make_client(stim_dir, f"sqlite:///{tmp_path / 'h.db'}")
    yield client, cfg
    cfg.store.close()


@pytest.fixture
def api(served):
    return served[0]


def test_deeply_nested_json_is_a_400_not_a_500(api):
    h, state = register(api, "P_nest")
    deep = b"[" * 1000 + b"]" * 1000
    for url, headers in (("/api/participants", {}), ("/api/participants/P_nest/responses", h)):
        r = api.post(url, content=deep, headers={**headers, "Content-Type": "application/json"})
        assert r.status_code == 400 and "nested deeper" in r.json()["error"], r.text
    body = json.dumps(
        {"trial_index": 0, "token": state["trials"][0]["token"], "answers": ANS, "rt_ms": 5, "x": [[[[[[[[[[1]]]]]]]]]]}
    ).encode()
    r = api.post("/api/participants/P_nest/responses", content=body, headers={**h, "Content-Type": "application/json"})
    assert r.status_code == 400
    # brackets inside strings do not count
    r = api.post(
        "/api/participants", json={"participant_id": "P_str", "secret": None, "platform": {}} | {"z": "[[[[[[[[[[["}
    )
    assert r.status_code == 201


def test_streamed_body_is_capped_while_it_arrives(served):
    """A chunked body without Content-Length: the server answers 413 after ~16 kB, without
    reading the rest (here 300 chunks of 1 kB offered, at most 17 taken)."""
    app = served[0].app
    taken = []
    sent = []

    async def receive():
        taken.append(1)
        if len(taken) > 300:
            return {"type": "http.request", "body": b"", "more_body": False}
        return {"type": "http.request", "body": b" " * 1024, "more_body": True}

    async def send(message):
        sent.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": "/api/participants",
        "raw_path": b"/api/participants",
        "query_string": b"",
        "root_path": "",
        "headers": [
            (b"content-type", b"application/json"),
            (b"transfer-encoding", b"chunked"),
            (b"host", b"testserver"),
        ],
        "client": ("127.0.0.1", 1),
        "server": ("testserver", 80),
    }
    asyncio.run(app(scope, receive, send))
    assert sent[0]["status"] == 413
    assert len(taken) <= MAX_BODY_BYTES // 1024 + 1


def test_practice_answer_is_atomic_and_resumable(served, monkeypatch):
    api, cfg = served
    h, _ = register(api, "P_prac", ready=False)
    assert api.post("/api/participants/P_prac/consent", json={"consent": True}, headers=h).status_code == 200
    assert (
        api.post("/api/participants/P_prac/demographics", json={"age": 40, "gender": "female"}, headers=h).status_code
        == 200
    )
    store = cfg.store
    r = store.responses

    def practice_rows():
        with store.engine.connect() as conn:
            return conn.execute(
                sa.select(sa.func.count()).select_from(r).where(r.c.participant_id == "P_prac", r.c.practice.is_(True))
            ).scalar_one()

    # a crash after the insert, before the timestamp: the whole transaction is rolled back
    import crowdstudy.study.storage as storage

    def crash(*_a, **_k):
        raise RuntimeError("simulated crash between the practice answer and its timestamp")

    monkeypatch.setattr(storage, "_mark_practice_done", crash)
    with pytest.raises(RuntimeError, match="simulated crash"):
        api.post("/api/participants/P_prac/practice", json={"answers": ANS, "rt_ms": 10}, headers=h)
    assert practice_rows() == 0 and store.participant("P_prac")["practice_at"] is None
    monkeypatch.undo()
    # a database left by the old two-transaction code: the answer stored, no timestamp; the
    # participant (who reloads and answers the practice differently) moves on
    with store.engine.begin() as conn:
        conn.execute(
            sa.insert(r).values(
                participant_id="P_prac",
                trial_index=-1,
                practice=True,
                stimulus_id="practice",
                stage=0,
                rt_ms=10.0,
                shown_at="2026-01-01T00:00:00.000+00:00",
                answered_at="2026-01-01T00:00:01.000+00:00",
                **ANS,
            )
        )
    res = api.post("/api/participants/P_prac/practice", json={"answers": {**ANS, "Q1": 6}, "rt_ms": 99}, headers=h)
    assert res.status_code == 200, res.text
    assert api.get("/api/participants/P_prac", headers=h).json()["practice_done"]
    assert practice_rows() == 1


def test_a_second_tab_is_told_and_its_answer_kept_aside(served):
    api, cfg = served
    h, state = register(api, "P_tabs")
    t0 = state["trials"][0]
    assert answer(api, "P_tabs", h, t0).status_code == 201  # tab 1
    r = answer(api, "P_tabs", h, t0, answers={**ANS, "Q2": 6}, rt=777.0)  # tab 2, same trial, other answer
    assert r.status_code == 409 and "another tab" in r.json()["error"]
    c = cfg.store.conflicts
    with cfg.store.engine.connect() as conn:
        rows = [dict(x._mapping) for x in conn.execute(sa.select(c))]
    assert len(rows) == 1 and rows[0]["Q2"] == 6 and rows[0]["rt_ms"] == 777.0 and rows[0]["trial_index"] == 0
    # the analysed answer is the first one
    mine = api.get("/api/participants/P_tabs/responses", headers=h).json()["responses"]
    assert len(mine) == 1 and mine[0]["Q2"] == 3


@pytest.mark.parametrize("path", ["/", "/api/study", "/healthz", "/admin", "/nope", "/js/study.js"])
def test_security_headers(api, path):
    r = api.get(path)
    csp = r.headers["content-security-policy"]
    assert "default-src 'self'" in csp and "frame-ancestors 'none'" in csp and "script-src 'self';" in csp
    assert "unsafe-eval" not in csp and "'unsafe-inline'" not in csp.split("script-src", 1)[1].split(";")[0]
    assert r.headers["x-frame-options"] == "DENY"
    assert r.headers["x-content-type-options"] == "nosniff"
    assert r.headers["referrer-policy"] == "no-referrer"


def test_endpoints_take_json_only(served):
    """No cross-site form post: text/plain, form-encoded and multipart bodies are refused."""
    api, cfg = served
    for ctype, body in (
        ("text/plain", '{"participant_id": "P_form"}'),
        ("application/x-www-form-urlencoded", "participant_id=P_form"),
        ("multipart/form-data; boundary=x", "--x--"),
        ("", '{"participant_id": "P_form"}'),
    ):
        r = api.post("/api/participants", content=body.encode(), headers={"Content-Type": ctype} if ctype else {})
        assert r.status_code == 415, (ctype, r.status_code)
    assert cfg.store.participant("P_form") is None
    h, _ = register(api, "P_json", ready=False)
    r = api.post(
        "/api/participants/P_json/consent", content=b'{"consent": true}', headers={**h, "Content-Type": "text/plain"}
    )
    assert r.status_code == 415 and cfg.store.participant("P_json")["consented_at"] is None


def test_second_demographics_post_is_refused_unless_identical(api):
    h, _ = register(api, "P_demo", ready=False)
    url = "/api/participants/P_demo/demographics"
    assert api.post("/api/participants/P_demo/consent", json={"consent": True}, headers=h).status_code == 200
    assert api.post(url, json={"age": 33, "gender": "female"}, headers=h).status_code == 200
    assert api.post(url, json={"age": 33, "gender": "female"}, headers=h).status_code == 200  # a resend
    r = api.post(url, json={"age": 50, "gender": "male"}, headers=h)
    assert r.status_code == 409 and "already given" in r.json()["error"]
    rows = api.get("/admin/export/demographics.csv", headers=ADMIN).text
    assert "P_demo,33,female" in rows


def test_no_stale_auth_state_between_server_processes(stim_dir, tmp_path):
    """A secret replaced (resume link) or a participant withdrawn through one process is
    refused at once by another process on the same database."""
    db = f"sqlite:///{tmp_path / 'two.db'}"
    a, cfg_a = make_client(stim_dir, db)
    b, cfg_b = make_client(stim_dir, db)
    h, state = register(a, "P_two")
    assert answer(b, "P_two", h, state["trials"][0]).status_code == 201  # B knows the secret now
    link = a.post("/admin/participants/P_two/resume-link", headers=ADMIN).json()["url"]
    new = {"X-Participant-Secret": link.split("resume=")[1]}
    assert b.get("/api/participants/P_two", headers=h).status_code == 403  # the old secret, on B
    assert answer(b, "P_two", new, state["trials"][1]).status_code == 201
    assert a.post("/admin/participants/P_two/withdraw", headers=ADMIN).status_code == 200
    r = b.get("/api/participants/P_two", headers=new)
    assert r.status_code == 410 and "withdrawn" in r.json()["error"]
    assert answer(b, "P_two", new, state["trials"][2]).status_code == 410
    for cfg in (cfg_a, cfg_b):
        cfg.store.close()

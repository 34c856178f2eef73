"""The study server's structure: route tables, handlers reading app.state, the answer-latency
log, the session's schedule cache, and the request-body parsers on their own."""

import inspect
import sys
from pathlib import Path

import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.study import bodies, routes_admin, routes_participant, routes_static
from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.webio import ApiError

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_fixtures import ADMIN, answer, make_client, register  # noqa: E402

pytestmark = [pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")]
TABLES = {
    routes_participant: routes_participant.ROUTES,
    routes_static: routes_static.ROUTES,
    routes_admin: routes_admin.ROUTES,
}


@pytest.fixture(scope="module")
def stim_dir(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("stim"), n_files=3, seconds=0.5, width=64, height=36)


@pytest.fixture
def api(stim_dir, tmp_path):
    client, cfg = make_client(stim_dir, f"sqlite:///{tmp_path / 'study.db'}")
    yield client
    cfg.store.close()


def test_the_app_serves_exactly_the_route_tables(api):
    from starlette.routing import Mount, Route

    listed = [(spec.path, method) for table in TABLES.values() for spec in table for method in spec.methods]
    assert len(listed) == len(set(listed)), "a (path, method) is listed twice"
    served = {(r.path, m) for r in api.app.routes if isinstance(r, Route) for m in r.methods if m != "HEAD"}
    assert served == set(listed)
    mounts = {r.path for r in api.app.routes if isinstance(r, Mount)}
    assert mounts == {"/js", "/css", "/lib/jspsych/dist", "/lib/jspsych/css"} | {
        f"/lib/{p}" for p in routes_static.UI_PLUGINS
    }


def test_handlers_are_module_level_coroutines_without_closures():
    for module, table in TABLES.items():
        for spec in table:
            h = spec.handler
            assert inspect.iscoroutinefunction(h), spec
            assert h.__closure__ is None and h.__qualname__ == h.__name__, spec
            assert getattr(module, h.__name__) is h and h.__name__ in module.__all__, spec


def test_metrics_count_every_answer_post_of_this_app(api, stim_dir, tmp_path):
    h, state = register(api, "P_lat")
    for t in state["trials"][:3]:
        assert answer(api, "P_lat", h, t).status_code == 201
    assert answer(api, "P_lat", h, state["trials"][5]).status_code == 409  # timed too: a POST answered
    assert api.get("/api/participants/P_lat/responses", headers=h).status_code == 200  # not an answer
    summary = api.get("/admin/metrics.json", headers=ADMIN).json()["server_answer_latency"]
    assert summary["answers_timed"] == 4 and summary["latency_ms_max"] >= summary["latency_ms_p50"] >= 0
    assert api.app.state.answer_latency.summary() == summary
    other, cfg = make_client(stim_dir, f"sqlite:///{tmp_path / 'other.db'}")  # another process: its own log
    assert other.get("/admin/metrics.json", headers=ADMIN).json()["server_answer_latency"] == {"answers_timed": 0}
    cfg.store.close()


def test_withdrawals_drop_the_cached_schedule(api):
    study = api.app.state.study
    register(api, "P_a", ready=False)
    h_b, _ = register(api, "P_b", ready=False)
    for pid in ("P_a", "P_b"):
        cached = study.schedule(pid)
        assert study.schedule(pid) is cached
        study.forget_schedule(pid)
        again = study.schedule(pid)
        assert again is not cached and again == cached
    before_a, before_b = study.schedule("P_a"), study.schedule("P_b")
    assert api.post("/admin/participants/P_a/withdraw", headers=ADMIN).status_code == 200
    assert study.schedule("P_a") is not before_a
    r = api.post("/api/participants/P_b/withdraw", json={"confirm": True}, headers=h_b)
    assert r.status_code == 200 and study.schedule("P_b") is not before_b


def test_errors_raised_in_handlers_become_json(api, monkeypatch):
    def broken():
        raise InvalidInputError("design study.toml: items must be listed")

    monkeypatch.setattr(api.app.state.study, "scoring", broken)
    r = api.get("/admin/study.json", headers=ADMIN)
    assert r.status_code == 422 and r.json() == {"error": "design study.toml: items must be listed"}
    assert r.headers["cache-control"] == "no-store" and "content-security-policy" in r.headers
    r = api.post("/admin/participants/P_nobody/withdraw", headers=ADMIN)
    assert r.status_code == 404 and r.json() == {"error": "unknown participant 'P_nobody'"}


# -- the body parsers, without a server --------------------------------------------------------
def test_parse_registration_and_platform():
    reg = bodies.parse_registration({"participant_id": "P1", "platform": {"PROLIFIC_PID": "abc", "STUDY_ID": "s-1"}})
    assert reg == ("P1", None, {"prolific_pid": "abc", "prolific_study_id": "s-1"})
    with pytest.raises(ApiError) as e:
        bodies.parse_registration({"participant_id": "P1", "platform": {"EVIL": "x"}})
    assert e.value.status == 400 and "EVIL" in e.value.message
    with pytest.raises(ApiError) as e:
        bodies.parse_registration({"participant_id": "P1", "secret": 5})
    assert e.value.status == 400 and "secret" in e.value.message


def test_parse_timing_normalises_and_names_the_field():
    t = bodies.parse_timing({"rt_ms": 1500, "shown_at": "2026-01-08T10:00:00+01:00", "video_plays": 2})
    assert t.rt_ms == 1500.0 and t.shown_at == "2026-01-08T09:00:00.000+00:00"
    assert t.quality == {
        "video_plays": 2,
        "hidden_count": None,
        "fullscreen_exits": None,
        "first_play_ms": None,
        "hidden_ms": None,
    }
    assert bodies.parse_timing({"rt_ms": 1, "shown_at": "2026-01-08T09:00:00"}).shown_at.endswith("+00:00")
    for body, field in [
        ({"rt_ms": True}, "rt_ms"),
        ({"rt_ms": 1, "hidden_ms": -1}, "hidden_ms"),
        ({"rt_ms": 1, "video_plays": 1.5}, "video_plays"),
        ({"rt_ms": 1, "shown_at": 7}, "shown_at"),
    ]:
        with pytest.raises(ApiError) as e:
            bodies.parse_timing(body)
        assert e.value.status == 422 and e.value.message.startswith(field), body


def test_parse_likert_check_and_trial_ref():
    items = ("Q1", "Q2")
    assert bodies.parse_likert({"answers": {"Q1": 1, "Q2": 4}}, items, 4) == {"Q1": 1, "Q2": 4}
    with pytest.raises(ApiError, match="answers.Q2 must be an integer 1..4"):
        bodies.parse_likert({"answers": {"Q1": 1, "Q2": 5}}, items, 4)
    assert bodies.parse_check({}, 3, False, 6) is None
    assert bodies.parse_check({"check": 2}, 3, True, 6) == 2
    with pytest.raises(ApiError, match="trial 3 has no attention check"):
        bodies.parse_check({"check": 2}, 3, False, 6)
    assert bodies.parse_trial_ref({"trial_index": 1, "token": "a" * 20}, 2) == (1, "a" * 20)
    with pytest.raises(ApiError, match="trial_index must be an integer 0..1"):
        bodies.parse_trial_ref({"trial_index": 2, "token": "a" * 20}, 2)
    assert bodies.parse_demographics({"age": " 40 ", "gender": "other"}) == (40, "other")
    assert bodies.parse_viewport({"width": 800, "height": 600}) == (800, 600)

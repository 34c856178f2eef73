"""Helpers of the study-server tests: an in-process server on a database, a participant
walked to the trials, and the headless Chromium the browser tests drive."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--headless",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def require_study_browser() -> None:
    """Skip the calling test unless Debian's Chromium and the front end's npm packages
    (``make setup``) are installed."""
    if not Path(CHROMIUM).exists():
        pytest.skip("Debian chromium is not installed")
    from crowdstudy.study.server import default_ui_dir

    if not (default_ui_dir() / "node_modules" / "jspsych").is_dir():
        pytest.skip("ui/node_modules missing (run make setup)")


TOKEN = "test-admin-token-0123456789abcdef"
ADMIN = {"Authorization": f"Bearer {TOKEN}"}
ANS = {f"Q{i}": 3 for i in range(1, 7)}


def make_client(stim_dir, db_url, **kwargs):
    """(TestClient, StudyConfig) of a study server on ``db_url`` (a new "process": its own state)."""
    from starlette.testclient import TestClient

    from crowdstudy.study.app import create_app
    from crowdstudy.study.server import build_config

    cfg = build_config(stim_dir, db=db_url, admin_token=TOKEN, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return TestClient(create_app(cfg)), cfg


def check_answer(trial) -> int:
    """The point an attention-check trial's extra statement asks for (parsed from its text)."""
    return int(re.search(r"choose \((\d+)\)", trial["check"]["text"]).group(1))


def register(api, pid, *, ready=True, **body):
    """Register ``pid`` (and give consent, demographics, practice); returns (headers, state)."""
    r = api.post("/api/participants", json={"participant_id": pid, **body})
    assert r.status_code == 201, r.text
    h = {"X-Participant-Secret": r.json()["secret"]}
    if ready:
        assert api.post(f"/api/participants/{pid}/consent", json={"consent": True}, headers=h).status_code == 200
        assert (
            api.post(f"/api/participants/{pid}/demographics", json={"age": 30, "gender": "male"}, headers=h).status_code
            == 200
        )
        assert (
            api.post(f"/api/participants/{pid}/practice", json={"answers": ANS, "rt_ms": 10}, headers=h).status_code
            == 201
        )
    return h, r.json()["state"]


def answer(api, pid, h, trial, answers=ANS, rt=1234.5, **extra):
    """POST the answer to ``trial`` (the attention check answered as asked unless ``check`` given)."""
    body = {"trial_index": trial["trial_index"], "token": trial["token"], "answers": answers, "rt_ms": rt, **extra}
    if "check" in trial and "check" not in extra:
        body["check"] = check_answer(trial)
    return api.post(f"/api/participants/{pid}/responses", headers=h, json=body)

"""End-to-end: a whole participant session in headless Chromium against a real server
process, with a page reload mid-stage and a server kill -9 + restart; then the export must
hold exactly the answers given. Throughout, the participant is blinded: no page content,
request URL, request body, jsPsych data or stored browser state names a stimulus id, a
method or a density level."""

import csv
import json
import re
import sqlite3
from pathlib import Path

import pytest
from study_fixtures import CHROMIUM, CHROMIUM_ARGS, require_study_browser

from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.local_server import LocalServer, write_small_design

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ROOT = Path(__file__).resolve().parent.parent
PID = "E2E_browser-01"
CODE = "CS-COMPLETE-42"


def _answers_for(k: int) -> dict:
    """Distinct, checkable answers for the k-th study trial."""
    return {f"Q{i}": (k + i) % 6 + 1 for i in range(1, 7)}


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    require_study_browser()
    tmp = tmp_path_factory.mktemp("study_e2e")
    design = write_small_design(tmp / "small.toml")
    write_fake_stimuli(tmp / "stim", design, n_files=2, seconds=1.0)
    return tmp, design


def _answer_trial(page, answers: dict, timeout: float = 20000) -> str:
    """Fill the six scales of the visible trial, wait for the button, click; returns the progress text."""
    page.wait_for_selector(".cs-trial .cs-next", timeout=timeout)
    progress = page.inner_text(".cs-progress")
    for q, v in answers.items():
        page.check(f'input[name="{q}"][value="{v}"]')
    check = page.query_selector('tr[data-item="cs-check"] th')
    if check is not None:  # an attention check: do what it asks
        asked = re.search(r"choose \((\d+)\)", check.inner_text()).group(1)
        page.check(f'input[name="cs-check"][value="{asked}"]')
    page.wait_for_selector(".cs-next:not([disabled])", timeout=timeout)  # needs one full play of the video
    page.click(".cs-next")
    return progress


def _wait_gone(page, progress: str, timeout: float = 30000) -> None:
    """Wait until the trial showing ``progress`` has been replaced (its answer is stored)."""
    page.wait_for_function(
        "p => !document.querySelector('.cs-progress') || document.querySelector('.cs-progress').innerText !== p",
        arg=progress,
        timeout=timeout,
    )


def _hidden_words(design_path: Path) -> list[str]:
    """Every stimulus id, method name and density level of the design: the participant must see none."""
    from crowdstudy.design import load_design

    design = load_design(design_path)
    words = {s.stimulus_id for s in design.stimuli()} | set(design.methods) | set(design.densities)
    return sorted(words, key=len, reverse=True)


def _leaks(text: str, words) -> list[str]:
    return [w for w in words if re.search(rf"(?<![A-Za-z0-9]){re.escape(w)}(?![A-Za-z0-9])", text or "")]


def _db_answers(db: Path) -> int:
    with sqlite3.connect(db) as con:
        return con.execute("SELECT COUNT(*) FROM responses WHERE practice = 0").fetchone()[0]


def test_full_session_reload_and_server_crash(small_study):
    import httpx
    from playwright.sync_api import sync_playwright

    tmp, design = small_study
    db = tmp / "e2e.db"
    server = LocalServer(
        ["--stimuli", str(tmp / "stim"), "--design", str(design), "--db", f"sqlite:///{db}", "--completion-code", CODE]
    )
    given = {}  # trial_index -> answers
    words = _hidden_words(design)
    assert {"Ours", "Baseline", "D1", "D2", "S1-D1-V1-Ours"} <= set(words)
    requests = []  # (url, body) of every request any page made
    snapshots = []  # (where, page HTML) of every study trial shown

    def watch(context):
        context.on("request", lambda req: requests.append((req.url, req.post_data)))
        return context

    def answer_trial(page, answers):
        page.wait_for_selector(".cs-trial .cs-next")
        snapshots.append((page.inner_text(".cs-progress"), page.content()))
        return _answer_trial(page, answers)

    with server, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = watch(browser.new_context(viewport={"width": 1280, "height": 800})).new_page()
            page.goto(f"{server.url}/?PROLIFIC_PID={PID}")
            # consent (text from the study folder's consent.md)
            page.wait_for_selector("text=Informed consent")
            assert "perception of animated crowds" in page.inner_text(".cs-consent")
            page.click("button:has-text('I agree')")
            # demographics
            page.wait_for_selector("#cs-age")
            page.fill("#cs-age", "34")
            page.select_option("#cs-gender", "female")
            page.click("#jspsych-survey-html-form-next")
            # instructions (2 pages) then the practice trial
            page.click("#jspsych-instructions-next")
            page.click("#jspsych-instructions-next")
            page.wait_for_selector("text=Practice video")
            # the button stays disabled until all six are answered
            page.check('input[name="Q1"][value="2"]')
            assert page.is_disabled(".cs-next")
            prog = _answer_trial(page, {f"Q{i}": 4 for i in range(1, 7)})
            _wait_gone(page, prog)
            page.click("button:has-text('Start')")

            # stage 1: two trials, then reload mid-stage
            for k in range(2):
                given[k] = _answers_for(k)
                prog = answer_trial(page, given[k])
                assert f"video {k + 1} of 4" in prog and "Part 1 of 2" in prog
                _wait_gone(page, prog)
            page.reload()
            page.wait_for_selector(".cs-trial .cs-next")
            assert "Part 1 of 2 · video 3 of 4" in page.inner_text(".cs-progress"), "resume at trial index 2"
            given[2] = _answers_for(2)
            _wait_gone(page, answer_trial(page, given[2]))
            assert _db_answers(db) == 3

            # server crash (kill -9) while the participant answers trial 3: the send fails,
            # a notice appears, the answer goes through once the server is back
            page.wait_for_selector(".cs-trial .cs-next")
            server.kill()
            given[3] = _answers_for(3)
            prog = answer_trial(page, given[3])
            page.wait_for_selector("#cs-notice:not([hidden])", timeout=15000)
            assert "retrying" in page.inner_text("#cs-notice")
            server.start()
            page.wait_for_selector("text=Break", timeout=30000)
            assert page.is_hidden("#cs-notice")
            assert _db_answers(db) == 4
            page.click("button:has-text('Continue')")

            # stage 2 to the end
            for k in range(4, 8):
                given[k] = _answers_for(k)
                prog = answer_trial(page, given[k])
                assert "Part 2 of 2" in prog
                _wait_gone(page, prog)
            page.wait_for_selector("text=Thank you!")
            assert CODE in page.inner_text(".cs-debrief")
            # stage-2 trials after the first came from the in-memory copy preloaded during the previous trial
            preloaded = page.evaluate(
                "crowdstudy.jsPsych.data.get().filter({trial_type: 'video-likert-loop'}).select('preloaded').values"
            )
            assert preloaded[-3:] == [True, True, True], preloaded
            secret = page.evaluate(f"localStorage.getItem('crowdstudy:secret:{PID}')")
            # blinding: what the browser holds (jsPsych data, the session state, local storage,
            # the final page) names no stimulus id, method or density level
            held = {
                "jspsych data": page.evaluate("crowdstudy.jsPsych.data.get().json()"),
                "session": page.evaluate("JSON.stringify(crowdstudy.session)"),
                "localStorage": page.evaluate("JSON.stringify(Object.assign({}, localStorage))"),
                "debrief page": page.content(),
            }
            assert '"token"' in held["session"] and "/media/" in held["jspsych data"]
            for where, text in [*held.items(), *snapshots]:
                assert not _leaks(text, words), (where, _leaks(text, words))

            # without an id in the URL the page asks for one (and rejects a malformed one)
            other = watch(browser.new_context()).new_page()
            other.goto(server.url + "/")
            other.wait_for_selector("text=Please enter your participant ID")
            other.fill("#input-0", "bad id!")
            other.click("#jspsych-survey-text-next")
            other.wait_for_selector("text=An ID has 1-64 letters")
            other.fill("#input-0", "typed-02")
            other.click("#jspsych-survey-text-next")
            other.wait_for_selector("text=Informed consent")

            # an admin-issued resume link continues the session in another browser (here: at the debriefing)
            link = httpx.post(
                f"{server.url}/admin/participants/{PID}/resume-link",
                headers={"Authorization": f"Bearer {server.admin_token}"},
            ).json()["url"]
            third = watch(browser.new_context()).new_page()
            third.goto(server.url + link)
            third.wait_for_selector("text=Thank you!")
            assert "resume=" not in third.url
            secret = link.split("resume=")[1]
        finally:
            browser.close()

        # the participant's schedule (the same order throughout) and the stored answers
        state = httpx.get(f"{server.url}/api/participants/{PID}", headers={"X-Participant-Secret": secret}).json()
        assert state["completed"] and state["n_answered"] == 8
        admin = httpx.get(
            f"{server.url}/admin/participants/{PID}/schedule", headers={"Authorization": f"Bearer {server.admin_token}"}
        ).json()["trials"]
        assert [t["token"] for t in admin] == [t["token"] for t in state["trials"]]
        schedule = {t["trial_index"]: t["stimulus_id"] for t in admin}

    # blinding on the wire: every request URL and body the pages sent
    assert len(snapshots) == 8 and len(requests) > 30
    for url, body in requests:
        assert not _leaks(url, words) and not _leaks(body, words), (url, body)
    videos = sorted({u.split("/media/", 1)[1] for u, _ in requests if "/media/" in u})
    assert len(videos) == 9, videos  # the practice clip + 8 trials, each under its opaque name
    assert all(re.fullmatch(r"[0-9a-f]{32}\.mp4", v) for v in videos), videos
    posted = [json.loads(b) for u, b in requests if u.endswith("/responses") and b]
    quality = {"video_plays", "first_play_ms", "hidden_count", "hidden_ms", "fullscreen_exits"}
    assert posted and all(
        set(b) - {"check"} == {"trial_index", "token", "answers", "rt_ms", "shown_at"} | quality for b in posted
    )
    assert all(b["video_plays"] >= 1 and b["first_play_ms"] > 500 for b in posted)
    assert {b["token"] for b in posted} == {t["token"] for t in admin}

    out = tmp / "responses.csv"
    demo = tmp / "demographics.csv"
    import subprocess
    import sys

    subprocess.run(
        [
            sys.executable,
            "-m",
            "crowdstudy",
            "export",
            "--db",
            f"sqlite:///{db}",
            "--out",
            str(out),
            "--demographics",
            str(demo),
        ],
        check=True,
        cwd=ROOT,
    )
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 8
    assert [int(r["trial_index"]) for r in rows] == list(range(8))
    for r in rows:
        k = int(r["trial_index"])
        assert r["participant_id"] == PID
        assert r["stimulus_id"] == schedule[k]
        assert {q: int(r[q]) for q in given[k]} == given[k]
        assert int(r["stage"]) == (1 if k < 4 else 2)
        assert float(r["rt_ms"]) > 500  # each trial needed a full play of the 1 s clip
    people = {p["participant_id"]: p for p in csv.DictReader(demo.open())}
    assert set(people) == {PID, "typed-02"}  # the second one only reached the consent page
    me = people[PID]
    assert (me["age"], me["gender"], me["completion_code"]) == ("34", "female", CODE)
    assert me["started_at"] < me["completed_at"]
    assert people["typed-02"]["age"] == "" and people["typed-02"]["completed_at"] == ""

"""A participant session in headless Chromium through a design with a Likert, a slider and a
2afc stage (three methods): instructions and one practice trial per task, answers with the
mouse and the keyboard, attention checks of each kind, blinding of both 2afc videos, and the
export's rows. Screenshots of each trial type go to ``$CROWDSTUDY_SCREENSHOTS`` when set."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from study_fixtures import CHROMIUM, CHROMIUM_ARGS, require_study_browser

from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.local_server import LocalServer

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ROOT = Path(__file__).resolve().parent.parent
DESIGN = Path(__file__).resolve().parent / "data" / "three_tasks.toml"
PID = "E2E_tasks-01"


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    require_study_browser()
    tmp = tmp_path_factory.mktemp("study_tasks")
    # a shorter session: one density, one viewpoint per stage (3 + 3 + 3 trials)
    text = DESIGN.read_text(encoding="utf-8").replace("High = 5.55\n", "")
    text = text.replace('viewpoints = ["Front", "Top"]', 'viewpoints = ["Front"]')
    design = tmp / "tasks.toml"
    design.write_text(text, encoding="utf-8")
    write_fake_stimuli(tmp / "stim", design, n_files=3, seconds=1.0)
    return tmp, design


def _shot(page, tmp: Path, name: str) -> None:
    path = tmp / f"{name}.png"
    page.screenshot(path=str(path))
    out = os.environ.get("CROWDSTUDY_SCREENSHOTS")
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, Path(out) / path.name)


def _progress(page) -> str:
    return page.inner_text(".cs-progress")


def _next_trial(page, before: str) -> None:
    page.wait_for_function(
        "p => !document.querySelector('.cs-progress') || document.querySelector('.cs-progress').innerText !== p",
        arg=before,
        timeout=30000,
    )


def _likert(page, value: int) -> str:
    page.wait_for_selector(".cs-trial .cs-likert")
    prog = _progress(page)
    for row in page.query_selector_all("tr[data-item]"):
        item = row.get_attribute("data-item")
        v = value
        if item == "cs-check":
            v = int(re.search(r"choose \((\d+)\)", row.inner_text()).group(1))
        page.check(f'input[name="{item}"][value="{v}"]')
    page.wait_for_selector(".cs-next:not([disabled])", timeout=20000)
    page.click(".cs-next")
    return prog


def _slider(page, fraction: float, keyboard: bool, shot=None) -> str:
    """Place every slider: a click at ``fraction`` of the track, or (keyboard) focus + End
    then Left x 10 (90); an attention-check slider goes where it asks."""
    page.wait_for_selector(".cs-trial .cs-slider")
    prog = _progress(page)
    assert page.is_disabled(".cs-next")
    for row in page.query_selector_all(".cs-slider-row"):
        item = row.get_attribute("data-item")
        target = fraction
        if item == "cs-check":
            target = 0.0 if "left end" in row.inner_text() else 1.0
        box = row.query_selector("input.cs-vas").bounding_box()
        if keyboard and item != "cs-check":
            page.focus(f'input[name="{item}"]')
            page.keyboard.press("End")
            for _ in range(10):
                page.keyboard.press("ArrowLeft")
        else:
            x = box["x"] + 10 + (box["width"] - 20) * target  # the thumb's centre runs 10 px inside the ends
            page.mouse.click(x, box["y"] + box["height"] / 2)
    page.wait_for_selector(".cs-next:not([disabled])", timeout=20000)
    if shot is not None:
        shot(page)
    page.click(".cs-next")
    return prog


def _choose(page, side: str, keyboard: bool) -> str:
    page.wait_for_selector(".cs-pair-trial")
    prog = _progress(page)
    if keyboard:
        page.keyboard.press("ArrowLeft" if side == "left" else "ArrowRight")
    else:
        page.click(f'.cs-pair-pane[data-side="{side}"] video')
    check = page.query_selector(".cs-pair-check")
    if check is not None:
        asked = "left" if "left video" in check.inner_text() else "right"
        page.check(f'input[name="cs-check"][value="{asked}"]')
    page.wait_for_selector(".cs-next:not([disabled])", timeout=20000)
    if keyboard:
        page.keyboard.press("Enter")
    else:
        page.click(".cs-next")
    return prog


def _hidden_words(design: Path) -> list[str]:
    from crowdstudy.design import load_design

    d = load_design(design)
    return sorted({s.stimulus_id for s in d.stimuli()} | set(d.methods) | set(d.densities), key=len, reverse=True)


def _leaks(text: str, words) -> list[str]:
    return [w for w in words if re.search(rf"(?<![A-Za-z0-9]){re.escape(w)}(?![A-Za-z0-9])", text or "")]


def test_a_session_through_likert_slider_and_2afc_stages(study):
    from playwright.sync_api import sync_playwright

    tmp, design = study
    db = tmp / "tasks.db"
    server = LocalServer(["--stimuli", str(tmp / "stim"), "--design", str(design), "--db", f"sqlite:///{db}"])
    words = _hidden_words(design)
    requests, pages = [], []
    with server, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            context = browser.new_context(viewport={"width": 1400, "height": 900})
            context.on("request", lambda req: requests.append((req.url, req.post_data)))
            page = context.new_page()
            page.goto(f"{server.url}/?participant={PID}")
            page.click("button:has-text('I agree')")
            page.fill("#cs-age", "41")
            page.select_option("#cs-gender", "non-binary")
            page.click("#jspsych-survey-html-form-next")
            assert "choose how much you agree" in page.inner_text(".cs-page")
            page.click("#jspsych-instructions-next")
            page.click("#jspsych-instructions-next")
            page.wait_for_selector("text=Practice video")
            _next_trial(page, _likert(page, 3))
            page.click("button:has-text('Start')")
            # stage 1: Likert (mouse)
            for k in range(3):
                page.wait_for_selector(".cs-trial .cs-likert")
                if k == 0:
                    _shot(page, tmp, "trial-likert")
                pages.append(page.content())
                _next_trial(page, _likert(page, k + 2))
            # break, then the slider's instructions and practice
            page.wait_for_selector("text=This part asks something different")
            page.click("button:has-text('Continue')")
            page.wait_for_selector("text=click on the line where your opinion lies")
            page.click("#jspsych-instructions-next")
            page.wait_for_selector(".cs-slider")
            assert "Practice video" in _progress(page)
            _shot(page, tmp, "trial-slider-untouched")
            _next_trial(page, _slider(page, 0.5, keyboard=False))
            page.click("button:has-text('Start')")
            for k in range(3):
                page.wait_for_selector(".cs-trial .cs-slider")
                pages.append(page.content())
                shot = (lambda p: _shot(p, tmp, "trial-slider-answered")) if k == 0 else None
                _next_trial(page, _slider(page, 0.25, keyboard=k == 1, shot=shot))
            # break, then the 2afc instructions and practice
            page.wait_for_selector("text=This part asks something different")
            page.click("button:has-text('Continue')")
            page.wait_for_selector("text=Choose the video that fits it better")
            page.click("#jspsych-instructions-next")
            page.wait_for_selector(".cs-pair-trial")
            _next_trial(page, _choose(page, "left", keyboard=False))
            page.click("button:has-text('Start')")
            for k in range(3):
                page.wait_for_selector(".cs-pair-trial")
                page.wait_for_function("() => document.querySelectorAll('.cs-pair video')[1].currentTime > 0.3")
                if k == 0:
                    page.click('.cs-pair-pane[data-side="right"] .cs-pick')
                    _shot(page, tmp, "trial-2afc")
                pages.append(page.content())
                _next_trial(page, _choose(page, "right" if k != 1 else "left", keyboard=k == 1))
            page.wait_for_selector("text=Thank you!")
            held = page.evaluate("crowdstudy.jsPsych.data.get().json()") + page.evaluate(
                "JSON.stringify(crowdstudy.session)"
            )
        finally:
            if pages is not None and "page" in locals():
                page.screenshot(path=str(tmp / "last.png"))  # what the page showed last (a failure's state)
            browser.close()

    for text in [*pages, held]:
        assert not _leaks(text, words), _leaks(text, words)
    for url, body in requests:
        assert not _leaks(url, words) and not _leaks(body, words), (url, body)
    posted = [json.loads(b) for u, b in requests if u.endswith("/responses") and b]
    assert len(posted) == 9
    assert all("choice" in b and "answers" not in b for b in posted[6:])
    practice = [json.loads(b)["task"] for u, b in requests if u.endswith("/practice") and b]
    assert practice == ["likert", "slider", "2afc"]

    out = tmp / "out" / "responses.csv"
    subprocess.run(
        [sys.executable, "-m", "crowdstudy", "export", "--db", f"sqlite:///{db}", "--out", str(out),
         "--online", str(design)],
        check=True, cwd=ROOT,
    )  # fmt: skip
    rows = list(csv.DictReader(out.open()))
    assert [r["task"] for r in rows] == ["likert"] * 3 + ["slider"] * 3
    assert [r["R1"] for r in rows[:3]] == ["2", "3", "4"]
    sliders = [int(r[q]) for r in rows[3:] for q in ("R1", "R2", "R3")]
    assert all(20 <= v <= 30 for v in sliders[:3] + sliders[6:]), sliders  # clicked at a quarter
    assert sliders[3:6] == [90, 90, 90]  # End, then ten steps left
    comps = list(csv.DictReader(out.with_name("comparisons.csv").open()))
    assert [c["choice"] for c in comps] == ["right", "left", "right"]
    assert all(c["chosen_method"] == c["method_" + c["choice"]] for c in comps)
    parts = list(csv.DictReader(out.with_name("participants.csv").open()))
    assert parts[0]["checks_failed"] == "0" and int(parts[0]["checks_total"]) == 3

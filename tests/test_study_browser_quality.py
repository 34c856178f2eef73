"""The front end's data-quality controls and failure handling in headless Chromium (videos
from the published, size-padded copies): the screen check before consent, a save error that
stays under the video, a second tab told of its refused answer, tab switches recorded with
the answer, withdrawal, and no CSP violation."""

import re
import sqlite3

import pytest
from study_fixtures import CHROMIUM, CHROMIUM_ARGS, require_study_browser

from crowdstudy.study.fake_stimuli import write_fake_stimuli
from crowdstudy.study.local_server import LocalServer, write_small_design

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ANS = {f"Q{i}": 4 for i in range(1, 7)}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    require_study_browser()
    tmp = tmp_path_factory.mktemp("study_quality")
    design = write_small_design(tmp / "small.toml")
    write_fake_stimuli(tmp / "stim", design, n_files=2, seconds=1.0)
    (tmp / "online.toml").write_text(
        "[online]\nmin_width = 1200\nmin_height = 700\nfullscreen = true\n"
        'attention_checks = 0\n[online.codes]\nscreened_out = "SCREEN-7"\n'
        'withdrawn = "WD-9"\n'
    )
    db = tmp / "q.db"
    with LocalServer(
        [
            "--stimuli",
            str(tmp / "stim"),
            "--design",
            str(design),
            "--db",
            f"sqlite:///{db}",
            "--online",
            str(tmp / "online.toml"),
            "--media-dir",
            str(tmp / "media"),
        ]
    ) as srv:
        yield srv, db


def _fill(page, answers=ANS):
    page.wait_for_selector(".cs-trial .cs-next")
    for q, v in answers.items():
        page.check(f'input[name="{q}"][value="{v}"]')
    page.wait_for_selector(".cs-next:not([disabled])", timeout=20000)


def _to_trials(page, url):
    page.goto(url)
    page.click("button:has-text('I agree')")
    page.fill("#cs-age", "29")
    page.select_option("#cs-gender", "male")
    page.click("#jspsych-survey-html-form-next")
    page.click("#jspsych-instructions-next")
    page.click("#jspsych-instructions-next")
    _fill(page)
    page.click(".cs-next")
    page.click("button:has-text('Start')")
    page.wait_for_selector(".cs-trial .cs-next")


def _one(db, sql, *args):
    with sqlite3.connect(db) as con:
        return con.execute(sql, args).fetchone()


def test_quality_controls_in_the_browser(server):
    import httpx
    from playwright.sync_api import sync_playwright

    srv, db = server
    admin = {"Authorization": f"Bearer {srv.admin_token}"}
    csp_errors = []

    def watch(page):
        page.on("console", lambda m: csp_errors.append(m.text) if "Content Security Policy" in m.text else None)
        return page

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            # 1. the screen check: a small window is told, then screened out with its code
            small = watch(browser.new_context(viewport={"width": 1000, "height": 600}).new_page())
            small.goto(f"{srv.url}/?PROLIFIC_PID=Q_small&STUDY_ID=st1&SESSION_ID=se1")
            small.wait_for_selector("text=Your browser window is too small")
            assert "1000 x 600" in small.inner_text("#cs-target")
            small.click("button:has-text('I cannot')")
            small.wait_for_selector("text=SCREEN-7")
            assert _one(
                db,
                "SELECT screened_out_at IS NOT NULL, consented_at, prolific_study_id, prolific_session_id "
                "FROM participants WHERE participant_id = 'Q_small'",
            ) == (1, None, "st1", "se1")

            # 2. two tabs of one participant; a tab switch during a trial is recorded with its answer
            ctx = browser.new_context(viewport={"width": 1280, "height": 800})
            a = watch(ctx.new_page())
            _to_trials(a, f"{srv.url}/?participant=Q_tabs")
            b = watch(ctx.new_page())
            b.goto(f"{srv.url}/?participant=Q_tabs")  # same browser: resumes with the stored secret
            b.wait_for_selector(".cs-trial .cs-next")
            a.evaluate("""() => {
                Object.defineProperty(document, 'hidden', {configurable: true, get: () => true});
                document.dispatchEvent(new Event('visibilitychange'));
                Object.defineProperty(document, 'hidden', {configurable: true, get: () => false});
                document.dispatchEvent(new Event('visibilitychange'));
            }""")
            _fill(a)
            a.click(".cs-next")
            a.wait_for_function(
                "() => document.querySelector('.cs-progress') && "
                "document.querySelector('.cs-progress').innerText.includes('video 2 of')"
            )
            assert _one(
                db,
                "SELECT hidden_count, video_plays >= 1 FROM responses WHERE participant_id = 'Q_tabs' "
                "AND trial_index = 0",
            ) == (1, 1)
            _fill(b, {**ANS, "Q1": 1})  # tab b still shows trial 0; a different answer
            b.click(".cs-next")
            b.wait_for_selector("#cs-warning:not([hidden])")
            assert "already been answered in another tab" in b.inner_text("#cs-warning")
            b.wait_for_function(
                "() => document.querySelector('.cs-progress') && "
                "document.querySelector('.cs-progress').innerText.includes('video 2 of')"
            )
            assert _one(db, "SELECT COUNT(*), MIN(Q1) FROM answer_conflicts WHERE participant_id = 'Q_tabs'") == (1, 1)
            assert _one(db, "SELECT Q1 FROM responses WHERE participant_id = 'Q_tabs' AND trial_index = 0") == (4,)

            # 3. a save error stays under the video (here: the secret replaced by an admin resume link)
            link = httpx.post(f"{srv.url}/admin/participants/Q_tabs/resume-link", headers=admin).json()["url"]
            assert "resume=" in link
            _fill(a)
            a.click(".cs-next")
            a.wait_for_selector(".cs-error:not([hidden])")
            text = a.inner_text(".cs-error")
            assert "could not be saved" in text and "wrong participant secret" in text
            a.wait_for_timeout(2600)  # more than two loops of the 1 s clip
            assert a.is_visible(".cs-error") and a.inner_text(".cs-error") == text
            b.close()
            a.close()

            # 4. withdrawal from the trial page: answers deleted on the server, the code shown
            w = watch(browser.new_context(viewport={"width": 1280, "height": 800}).new_page())
            _to_trials(w, f"{srv.url}/?participant=Q_leave")
            _fill(w)
            w.click(".cs-next")
            w.wait_for_function(
                "() => document.querySelector('.cs-progress') && "
                "document.querySelector('.cs-progress').innerText.includes('video 2 of')"
            )
            assert _one(db, "SELECT COUNT(*) FROM responses WHERE participant_id = 'Q_leave'") == (2,)  # + practice
            w.click("#cs-withdraw")
            w.click("#cs-withdraw-yes")
            w.wait_for_selector("text=You have withdrawn")
            assert "WD-9" in w.inner_text("body")
            assert _one(db, "SELECT COUNT(*) FROM responses WHERE participant_id = 'Q_leave'") == (0,)
            assert _one(
                db, "SELECT age, withdrawn_at IS NOT NULL FROM participants WHERE participant_id = 'Q_leave'"
            ) == (None, 1)
            w.reload()
            w.wait_for_selector("text=You have withdrawn from this study")
        finally:
            browser.close()
    assert not csp_errors, csp_errors[:3]
    action, detail = _one(db, "SELECT action, detail FROM audit_log WHERE participant_id = 'Q_leave'")
    assert action == "withdraw" and re.match(r"by participant; deleted 1 answers, 1 practice", detail)

"""Fig. 7: the questionnaire page (a looping stimulus video beside the six Likert items).

Starts ``crowdstudy serve`` on a free loopback port, walks headless Chromium through
consent, demographics, instructions and the practice trial to the first study trial,
answers some items, and screenshots the page to ``paper_figs/out/fig7_questionnaire.png``.

Stimuli: ``--stimuli DIR`` if given, else ``stimuli/videos`` when it holds a manifest
(the rendered study videos), else a short crowd clip rendered on the spot (a D3 concert
Baseline from viewpoint V2) behind a temporary stimulus folder; ``--quick`` uses
test-pattern clips instead.

    python paper_figs/fig7_questionnaire.py [--quick] [--stimuli DIR] [--out PNG]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
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


def screenshot(url: str, out: Path, *, width: int, height: int, video_timeout_ms: float) -> dict:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(f"{url}/?participant=FIG7-screenshot")
            page.click("button:has-text('I agree')")
            page.fill("#cs-age", "30")
            page.select_option("#cs-gender", "prefer not to say")
            page.click("#jspsych-survey-html-form-next")
            page.click("#jspsych-instructions-next")
            page.click("#jspsych-instructions-next")
            page.wait_for_selector(".cs-trial .cs-next")
            for q in range(1, 7):
                page.check(f'input[name="Q{q}"][value="4"]')
            page.wait_for_selector(".cs-next:not([disabled])", timeout=video_timeout_ms)
            page.click(".cs-next")
            page.click("button:has-text('Start')")
            page.wait_for_selector(".cs-trial .cs-next")
            for q, v in (("Q1", 5), ("Q2", 2), ("Q3", 4), ("Q4", 3)):
                page.check(f'input[name="{q}"][value="{v}"]')
            # the furthest the looping video has played, from its timeupdate events: a single
            # sample of currentTime can land just after the loop's wrap on a loaded machine
            page.evaluate(VIDEO_WATCH)
            page.wait_for_function("() => window.csVideoPlayed > 0.3", timeout=video_timeout_ms)
            out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(out), full_page=False)
            return page.evaluate(PAGE_STATE)
        finally:
            browser.close()


#: Records in ``window.csVideoPlayed`` the furthest time (s) the trial's video has reached.
VIDEO_WATCH = """() => {
  const video = document.querySelector('.cs-video');
  window.csVideoPlayed = video.currentTime;
  video.addEventListener('timeupdate', () => {
    window.csVideoPlayed = Math.max(window.csVideoPlayed, video.currentTime);
  });
}"""

#: What the screenshot shows, read from the page (written to the figure's JSON sidecar):
#: boxes [left, top, width, height] in CSS pixels, the checked answer of each item.
PAGE_STATE = """() => {
  const box = (e) => { const b = e.getBoundingClientRect(); return [b.left, b.top, b.width, b.height]; };
  const video = document.querySelector('.cs-video');
  const answers = {};
  for (const input of document.querySelectorAll('.cs-likert input[type=radio]')) {
    if (!(input.name in answers)) answers[input.name] = null;
    if (input.checked) answers[input.name] = Number(input.value);
  }
  return {video: box(video), questions: box(document.querySelector('.cs-questions')),
          statements: [...document.querySelectorAll('.cs-statement')].map((e) => e.textContent.trim()),
          answers, video_time: video.currentTime, video_played: window.csVideoPlayed,
          video_paused: video.paused, video_loop: video.loop,
          video_size: [video.videoWidth, video.videoHeight],
          next_disabled: document.querySelector('.cs-next').disabled,
          progress: (document.querySelector('.cs-progress') || {}).textContent || '',
          viewport: [window.innerWidth, window.innerHeight]};
}"""


def _render_crowd_clips(stim: Path, size: tuple[int, int]) -> None:
    """Replace the test-pattern clips of a fake stimulus folder by a rendered crowd clip."""
    import json
    import shutil

    from crowdstudy.design import load_design
    from crowdstudy.motion import build_baseline
    from crowdstudy.render import render_video
    from crowdstudy.render.video import sha256_file

    design = load_design()
    clip = stim / "crowd.mp4"
    render_video(
        build_baseline(design, "stationary", "D3", duration=2.0),
        "V2",
        clip,
        width=size[0],
        height=size[1],
        design=design,
        progress=False,
    )
    digest = sha256_file(clip)
    manifest = json.loads((stim / "manifest.json").read_text())
    for row in manifest["stimuli"]:
        shutil.copyfile(clip, stim / row["file"])
        row["sha256"] = digest
    (stim / "manifest.json").write_text(json.dumps(manifest, indent=2))
    for practice in stim.glob("practice*.mp4"):
        shutil.copyfile(clip, practice)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller window (1280x720) and test-pattern clips")
    parser.add_argument("--stimuli", type=Path, help="stimulus folder with manifest.json")
    parser.add_argument("--out", type=Path, default=ROOT / "paper_figs" / "out" / "fig7_questionnaire.png")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from crowdstudy.study.fake_stimuli import write_fake_stimuli
    from crowdstudy.study.local_server import LocalServer

    if not Path(CHROMIUM).exists():
        print(f"fig7: {CHROMIUM} not found (apt-get install chromium)", file=sys.stderr)
        return 2
    width, height = (1280, 720) if args.quick else (1600, 900)
    with tempfile.TemporaryDirectory(prefix="fig7-") as tmp:
        stim = args.stimuli
        if stim is None and not args.quick and (ROOT / "stimuli" / "videos" / "manifest.json").is_file():
            stim = ROOT / "stimuli" / "videos"
        if stim is None:
            size = (320, 180) if args.quick else (1280, 720)
            stim = write_fake_stimuli(Path(tmp) / "stim", n_files=2, seconds=1.0, width=size[0], height=size[1])
            if not args.quick:
                _render_crowd_clips(stim, size)
        serve_args = ["--stimuli", str(stim), "--db", f"sqlite:///{tmp}/fig7.db"]
        with LocalServer(serve_args) as srv:
            state = screenshot(srv.url, args.out, width=width, height=height, video_timeout_ms=90_000)
    import json

    from crowdstudy.provenance import provenance

    args.out.with_suffix(".json").write_text(
        json.dumps({"figure": args.out.name, "page": state, "provenance": provenance(None)}, indent=1, default=str)
    )
    print(f"fig7: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

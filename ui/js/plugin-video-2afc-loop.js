/**
 * jsPsych 8 plugin "video-2afc-loop" (crowdstudy).
 *
 * A two-alternative forced choice between two videos of the same scene: both loop side by
 * side (muted, no controls, playsinline) and start together from their first frame once both
 * can play. One statement asks which video; the participant picks the left or the right one
 * by clicking a video or its button, or with the Left / Right arrow keys, then confirms with
 * the button (or Enter). The button is enabled once a video is chosen AND both videos have
 * played through at least once. `save(data, notify)` is awaited (the POST of the answer with
 * its retries) before the trial ends. `check` adds an instructed-response question (attention
 * check: "please choose the left video here") answered with its own two buttons. The
 * data-quality record is the Likert trial's, with plays counted for the two videos together
 * (complete plays of the video that has played fewer times).
 *
 * Loaded as a classic script after jsPsych's browser build and `video-trial-kit.js`: defines
 * the global `jsPsychVideo2afcLoop`.
 */
var jsPsychVideo2afcLoop = (function (jspsych) {
  "use strict";

  const ParameterType = jspsych.ParameterType;
  const Kit = CrowdstudyVideoKit;
  const SIDES = ["left", "right"];

  const info = {
    name: "video-2afc-loop",
    version: "0.1.0",
    parameters: {
      /** URL of the left video (MP4). */
      stimulus_left: { type: ParameterType.VIDEO, default: undefined },
      /** URL of the right video (MP4). */
      stimulus_right: { type: ParameterType.VIDEO, default: undefined },
      /** The statement the choice answers (the design's [questionnaire.comparison] text). */
      statement: { type: ParameterType.HTML_STRING, default: undefined },
      /** Names of the two videos as the participant sees them. */
      side_labels: { type: ParameterType.STRING, array: true, default: ["Left video", "Right video"] },
      /** Text shown above the videos (e.g. "Part 3 of 3 · pair 2 of 6"). */
      progress_text: { type: ParameterType.HTML_STRING, default: "" },
      /** Label of the answer button. */
      button_label: { type: ParameterType.STRING, default: "Next" },
      /** Whether the button stays disabled until both videos have played through once. */
      require_full_view: { type: ParameterType.BOOL, default: true },
      /** Video URLs to download in the background for later trials. */
      preload: { type: ParameterType.VIDEO, array: true, default: [] },
      /** async function(data, notify) awaited before the trial ends; a rejection shows its message. */
      save: { type: ParameterType.FUNCTION, default: null },
      /** Attention check {text}: a question answered with its own Left / Right buttons, or null. */
      check: { type: ParameterType.COMPLEX, default: null },
    },
    data: {
      /** The two video URLs shown (opaque /media/<name>.mp4 URLs, never stimulus ids). */
      stimulus_left: { type: ParameterType.STRING },
      stimulus_right: { type: ParameterType.STRING },
      /** The video chosen: "left" or "right". */
      choice: { type: ParameterType.STRING },
      /** Milliseconds from the trial's display to the confirmation. */
      rt: { type: ParameterType.FLOAT },
      /** Milliseconds from the display until both videos had played through once. */
      first_play_ms: { type: ParameterType.FLOAT },
      /** Complete plays before the answer (of the video that has played fewer times). */
      video_plays: { type: ParameterType.INT },
      /** ISO 8601 UTC time the trial appeared. */
      shown_at: { type: ParameterType.STRING },
      /** Whether both videos came from preloaded (in-memory) copies. */
      preloaded: { type: ParameterType.BOOL },
      /** The attention check's answer, "left" or "right" (null without a check). */
      check: { type: ParameterType.STRING },
      /** Times the page was hidden during the trial, and for how many milliseconds in all. */
      hidden_count: { type: ParameterType.INT },
      hidden_ms: { type: ParameterType.FLOAT },
      /** Times fullscreen was left during the trial. */
      fullscreen_exits: { type: ParameterType.INT },
    },
  };

  class Video2afcLoopPlugin {
    constructor(jsPsych) { this.jsPsych = jsPsych; }

    trial(display_element, trial) {
      const t0 = performance.now();
      const shownAt = new Date().toISOString();
      const esc = Kit.escapeHtml;
      const urls = [trial.stimulus_left, trial.stimulus_right];
      const srcs = urls.map((u) => Kit.source(u));
      const labels = trial.side_labels;
      const pane = (k) => `
        <div class="cs-pair-pane" data-side="${SIDES[k]}">
          <video class="cs-video cs-pair-video" muted playsinline disablepictureinpicture preload="auto"></video>
          <label class="cs-pick"><input type="radio" name="cs-choice" value="${SIDES[k]}"> ${esc(labels[k])}</label>
        </div>`;
      const checkRow = trial.check ? `
        <div class="cs-pair-check" data-item="cs-check">
          <div class="cs-statement">${esc(trial.check.text)}</div>
          ${SIDES.map((s, k) => `<label class="cs-pick-small"><input type="radio" name="cs-check" value="${s}"> ${esc(labels[k])}</label>`).join(" ")}
        </div>` : "";
      display_element.innerHTML = `
        <form class="cs-pair-trial" novalidate>
          <div class="cs-progress">${trial.progress_text || ""}</div>
          <div class="cs-pair-statement">${trial.statement}</div>
          <div class="cs-pair">${pane(0)}${pane(1)}</div>
          <div class="cs-video-status" aria-live="polite"></div>
          <div class="cs-error" role="alert" hidden></div>
          ${checkRow}
          <div class="cs-actions">
            <button type="submit" class="jspsych-btn cs-next" disabled>${esc(trial.button_label)}</button>
            <div class="cs-hint" aria-live="polite">Choose a video with the mouse or the Left / Right arrow keys.</div>
          </div>
        </form>`;

      const form = display_element.querySelector("form");
      const videos = Array.from(display_element.querySelectorAll("video"));
      const button = display_element.querySelector(".cs-next");
      const hint = display_element.querySelector(".cs-hint");
      const status = display_element.querySelector(".cs-video-status");
      const errorBox = display_element.querySelector(".cs-error");
      const plays = [0, 0];
      let firstPlay = null, saving = false;
      const quality = Kit.watchQuality();

      // both videos start together from their first frame once both can play
      let ready = 0;
      const playBoth = () => Promise.all(videos.map((v) => v.play())).then(() => { status.textContent = ""; })
        .catch(() => { status.textContent = "Click a video to start them."; });
      videos.forEach((v, k) => {
        Kit.setUpVideo(v, srcs[k], status);
        v.addEventListener("canplay", () => {
          ready += 1;
          if (ready === 2) { for (const w of videos) w.currentTime = 0; playBoth(); }
        }, { once: true });
        Kit.countPlays(v, () => {
          plays[k] += 1;
          if (firstPlay === null && Math.min(...plays) >= 1) firstPlay = performance.now() - t0;
          update();
        });
      });

      const choiceOf = (name) => {
        const el = form.querySelector(`input[name="${name}"]:checked`);
        return el ? el.value : null;
      };
      const pick = (side) => {
        if (saving) return;
        form.querySelector(`input[name="cs-choice"][value="${side}"]`).checked = true;
        update();
      };
      videos.forEach((v, k) => v.addEventListener("click", () => {
        if (videos.some((w) => w.paused)) playBoth();
        pick(SIDES[k]);
      }));
      const onKey = (e) => {
        if (saving || e.target.closest && e.target.closest(".cs-pair-check")) return;
        if (e.key === "ArrowLeft" || e.key === "ArrowRight") {
          e.preventDefault();
          pick(e.key === "ArrowLeft" ? "left" : "right");
        } else if (e.key === "Enter" && !button.disabled) {
          e.preventDefault();
          form.requestSubmit();
        }
      };
      document.addEventListener("keydown", onKey);

      function update() {
        if (saving) return;
        const chosen = choiceOf("cs-choice");
        for (const p of form.querySelectorAll(".cs-pair-pane")) p.classList.toggle("cs-chosen", p.dataset.side === chosen);
        const needCheck = trial.check && choiceOf("cs-check") === null;
        const needVideo = trial.require_full_view && Math.min(...plays) < 1;
        button.disabled = chosen === null || needCheck || needVideo;
        hint.textContent = chosen === null ? "Choose a video with the mouse or the Left / Right arrow keys."
          : needCheck ? "Please answer the extra question too."
          : needVideo ? "Please watch both videos until the end at least once." : "";
      }
      form.addEventListener("change", update);
      update();

      for (const url of trial.preload || []) Kit.prefetch(url);

      const finish = (data) => {
        quality.stop();
        document.removeEventListener("keydown", onKey);
        Kit.tearDown(videos, urls);
        display_element.innerHTML = "";
        this.jsPsych.finishTrial(data);
      };

      form.addEventListener("submit", async (ev) => {
        ev.preventDefault();
        if (button.disabled || saving) return;
        errorBox.hidden = true;
        const now = performance.now();
        const data = {
          stimulus_left: trial.stimulus_left, stimulus_right: trial.stimulus_right, choice: choiceOf("cs-choice"),
          rt: Math.round((now - t0) * 10) / 10,
          first_play_ms: firstPlay === null ? null : Math.round(firstPlay * 10) / 10, video_plays: Math.min(...plays),
          shown_at: shownAt, preloaded: srcs.every((s, k) => s !== urls[k]),
          check: trial.check ? choiceOf("cs-check") : null,
          ...quality.snapshot(now),
        };
        saving = true;
        saving = await Kit.saveThenFinish({ form, button, hint, errorBox, save: trial.save, data, finish });
      });
    }
  }
  Video2afcLoopPlugin.info = info;
  return Video2afcLoopPlugin;
})(jsPsychModule);

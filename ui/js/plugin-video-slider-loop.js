/**
 * jsPsych 8 plugin "video-slider-loop" (crowdstudy).
 *
 * Shows a stimulus video looping (muted, no controls, autoplay, playsinline) beside a set of
 * statements, each answered on a 0-100 visual analogue scale: a bare track whose two ends are
 * labelled (`left_label`, `right_label`), with no number shown. The handle appears only where
 * the participant first touches the track (click, tap, or a key: arrows, Page Up/Down,
 * Home/End), so no default position is ever recorded. Every statement is required; the button
 * is enabled once every slider was touched AND the video has played through at least once.
 * When the participant clicks, `save(data, notify)` is awaited (the POST of the answer with its
 * retries) before the trial ends. `check` adds an instructed-response slider (attention
 * check) at a given row position. The data-quality record is the Likert trial's: complete
 * plays, time to the first complete play, tab switches and hidden time, fullscreen exits.
 *
 * Loaded as a classic script after jsPsych's browser build and `video-trial-kit.js`: defines
 * the global `jsPsychVideoSliderLoop`.
 */
var jsPsychVideoSliderLoop = (function (jspsych) {
  "use strict";

  const ParameterType = jspsych.ParameterType;
  const Kit = CrowdstudyVideoKit;

  const info = {
    name: "video-slider-loop",
    version: "0.1.0",
    parameters: {
      /** URL of the video (MP4). It loops muted, without controls, while the participant answers. */
      stimulus: { type: ParameterType.VIDEO, default: undefined },
      /** Statements: array of {id: "Q1", text: "..."}; each gets its own slider. */
      items: { type: ParameterType.COMPLEX, array: true, default: undefined },
      /** Label of the scale's left end (value 0). */
      left_label: { type: ParameterType.STRING, default: "I strongly disagree" },
      /** Label of the scale's right end (value 100). */
      right_label: { type: ParameterType.STRING, default: "I fully agree" },
      /** HTML shown above the statements. */
      prompt: { type: ParameterType.HTML_STRING, default: "Please place each slider where it matches your opinion about the video." },
      /** Text shown above the video (e.g. "Video 3 of 40"). */
      progress_text: { type: ParameterType.HTML_STRING, default: "" },
      /** Label of the answer button. */
      button_label: { type: ParameterType.STRING, default: "Next" },
      /** Whether the button stays disabled until the video has played through once. */
      require_full_view: { type: ParameterType.BOOL, default: true },
      /** Video URLs to download in the background for later trials. */
      preload: { type: ParameterType.VIDEO, array: true, default: [] },
      /** async function(data, notify) awaited before the trial ends; a rejection shows its message. */
      save: { type: ParameterType.FUNCTION, default: null },
      /** Attention check {text, position}: one more slider, answered like the others, or null. */
      check: { type: ParameterType.COMPLEX, default: null },
    },
    data: {
      /** The video URL shown (an opaque /media/<name>.mp4 URL, never a stimulus id). */
      stimulus: { type: ParameterType.STRING },
      /** Answers keyed by item id, integers 0 (left end) .. 100 (right end). */
      responses: { type: ParameterType.OBJECT },
      /** Milliseconds from the trial's display to the click on the button. */
      rt: { type: ParameterType.FLOAT },
      /** Milliseconds from the display until the video had played through once. */
      first_play_ms: { type: ParameterType.FLOAT },
      /** Number of complete plays of the video before the click. */
      video_plays: { type: ParameterType.INT },
      /** ISO 8601 UTC time the trial appeared. */
      shown_at: { type: ParameterType.STRING },
      /** Whether the video came from a preloaded (in-memory) copy. */
      preloaded: { type: ParameterType.BOOL },
      /** The attention check's slider position 0..100 (null without a check). */
      check: { type: ParameterType.INT },
      /** Times the page was hidden during the trial, and for how many milliseconds in all. */
      hidden_count: { type: ParameterType.INT },
      hidden_ms: { type: ParameterType.FLOAT },
      /** Times fullscreen was left during the trial. */
      fullscreen_exits: { type: ParameterType.INT },
    },
  };

  const MOVE_KEYS = new Set(["ArrowLeft", "ArrowRight", "ArrowUp", "ArrowDown", "PageUp", "PageDown", "Home", "End"]);

  class VideoSliderLoopPlugin {
    constructor(jsPsych) { this.jsPsych = jsPsych; }

    trial(display_element, trial) {
      const t0 = performance.now();
      const shownAt = new Date().toISOString();
      const esc = Kit.escapeHtml;
      const items = trial.items || [];
      const src = Kit.source(trial.stimulus);
      const CHECK = "cs-check";
      const shown = items.slice();
      if (trial.check) {
        const at = Math.max(0, Math.min(shown.length, trial.check.position | 0));
        shown.splice(at, 0, { id: CHECK, text: trial.check.text });
      }
      const rows = shown.map((it) => `
        <div class="cs-slider-row" data-item="${esc(it.id)}">
          <div class="cs-statement">${esc(it.text)}</div>
          <div class="cs-slider-scale">
            <span class="cs-end cs-end-left" aria-hidden="true">${esc(trial.left_label)}</span>
            <input type="range" class="cs-vas cs-untouched" name="${esc(it.id)}" min="0" max="100" step="1" value="50"
              aria-label="${esc(it.text)} (from ${esc(trial.left_label)} to ${esc(trial.right_label)})"
              aria-valuetext="not answered yet">
            <span class="cs-end cs-end-right" aria-hidden="true">${esc(trial.right_label)}</span>
          </div>
        </div>`).join("");
      display_element.innerHTML = `
        <div class="cs-trial">
          <div class="cs-video-pane">
            <div class="cs-progress">${trial.progress_text || ""}</div>
            <video class="cs-video" muted autoplay playsinline disablepictureinpicture preload="auto"></video>
            <div class="cs-video-status" aria-live="polite"></div>
            <div class="cs-error" role="alert" hidden></div>
          </div>
          <form class="cs-questions cs-slider" novalidate>
            <div class="cs-prompt">${trial.prompt}</div>
            ${rows}
            <div class="cs-actions">
              <button type="submit" class="jspsych-btn cs-next" disabled>${esc(trial.button_label)}</button>
              <div class="cs-hint" aria-live="polite"></div>
            </div>
          </form>
        </div>`;

      const video = display_element.querySelector("video");
      const form = display_element.querySelector("form");
      const button = display_element.querySelector(".cs-next");
      const hint = display_element.querySelector(".cs-hint");
      const status = display_element.querySelector(".cs-video-status");
      const errorBox = display_element.querySelector(".cs-error");
      const touched = new Set();
      let plays = 0, firstPlay = null, saving = false;
      const quality = Kit.watchQuality();

      Kit.setUpVideo(video, src, status);
      const tryPlay = () => video.play().then(() => { status.textContent = ""; }).catch(() => {
        status.textContent = "Click the video to start it.";
      });
      video.addEventListener("click", tryPlay);
      video.addEventListener("canplay", tryPlay, { once: true });
      Kit.countPlays(video, () => {
        plays += 1;
        if (firstPlay === null) firstPlay = performance.now() - t0;
        update();
      });

      const touch = (input) => {
        if (saving) return;
        touched.add(input.name);
        input.classList.remove("cs-untouched");
        input.setAttribute("aria-valuetext", "answered");
        update();
      };
      for (const input of form.querySelectorAll("input.cs-vas")) {
        input.addEventListener("pointerdown", () => touch(input));
        input.addEventListener("input", () => touch(input));
        input.addEventListener("keydown", (e) => { if (MOVE_KEYS.has(e.key)) touch(input); });
      }

      const answers = () => {
        const out = {};
        for (const it of items) {
          if (touched.has(it.id)) out[it.id] = parseInt(form.elements[it.id].value, 10);
        }
        return out;
      };

      function update() {
        if (saving) return;
        const missing = shown.filter((it) => !touched.has(it.id)).length;
        const needVideo = trial.require_full_view && plays < 1;
        button.disabled = missing > 0 || needVideo;
        for (const row of form.querySelectorAll(".cs-slider-row")) {
          row.classList.toggle("cs-answered", touched.has(row.dataset.item));
        }
        hint.textContent = missing > 0 ? `Please place all ${shown.length} sliders (${missing} left).`
          : needVideo ? "Please watch the video until the end at least once." : "";
      }
      update();

      for (const url of trial.preload || []) Kit.prefetch(url);

      const finish = (data) => {
        quality.stop();
        Kit.tearDown([video], [trial.stimulus]);
        display_element.innerHTML = "";
        this.jsPsych.finishTrial(data);
      };

      form.addEventListener("submit", async (ev) => {
        ev.preventDefault();
        if (button.disabled || saving) return;
        errorBox.hidden = true;
        const now = performance.now();
        const data = {
          stimulus: trial.stimulus, responses: answers(), rt: Math.round((now - t0) * 10) / 10,
          first_play_ms: firstPlay === null ? null : Math.round(firstPlay * 10) / 10, video_plays: plays,
          shown_at: shownAt, preloaded: src !== trial.stimulus,
          check: trial.check ? parseInt(form.elements[CHECK].value, 10) : null,
          ...quality.snapshot(now),
        };
        saving = true;
        saving = await Kit.saveThenFinish({ form, button, hint, errorBox, save: trial.save, data, finish });
      });
    }
  }
  VideoSliderLoopPlugin.info = info;
  return VideoSliderLoopPlugin;
})(jsPsychModule);

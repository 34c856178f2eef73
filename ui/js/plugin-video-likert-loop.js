/**
 * jsPsych 8 plugin "video-likert-loop" (crowdstudy).
 *
 * Shows a stimulus video looping (muted, no controls, autoplay, playsinline) beside a set
 * of statements, each rated on a Likert scale whose points are labelled "(1) ..." to "(k) ...".
 * Every statement is required; the button is enabled only once every statement is answered
 * AND the video has played through at least once. When the participant clicks, the
 * optional `save(data, notify)` function is awaited (it returns a Promise, e.g. the POST of
 * the answer with its retries) before the trial ends, so the next trial appears only once
 * the answer is stored. `preload` lists video URLs to download ahead (the next trial's).
 * A save error stays under the video until the participant acts (answers again or clicks).
 * `check` adds an instructed-response statement (attention check) at a given row position.
 * The trial also records its data-quality measures: complete plays of the video, time to the
 * first complete play, how often and how long the page was hidden (tab switches) and how
 * often fullscreen was left.
 *
 * Loaded as a classic script after jsPsych's browser build and `video-trial-kit.js` (the
 * download-ahead cache shared by the trial types): defines the global `jsPsychVideoLikertLoop`.
 */
var jsPsychVideoLikertLoop = (function (jspsych) {
  "use strict";

  const ParameterType = jspsych.ParameterType;

  const info = {
    name: "video-likert-loop",
    version: "0.1.0",
    parameters: {
      /** URL of the video (MP4). It loops muted, without controls, while the participant answers. */
      stimulus: { type: ParameterType.VIDEO, default: undefined },
      /** Statements: array of {id: "Q1", text: "..."}; each gets its own scale row. */
      items: { type: ParameterType.COMPLEX, array: true, default: undefined },
      /** Scale point labels, first = 1; the number of labels is the number of points. */
      labels: { type: ParameterType.STRING, array: true, default: ["I strongly disagree", "I disagree",
        "I somewhat disagree", "I somewhat agree", "I agree", "I fully agree"] },
      /** HTML shown above the statements. */
      prompt: { type: ParameterType.HTML_STRING, default: "Please rate each statement about the video." },
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
      /** Width of the video in CSS pixels (0: fit the layout). */
      video_width: { type: ParameterType.INT, default: 0 },
      /** Attention check {text, position}: one more statement, answered like the others, or null. */
      check: { type: ParameterType.COMPLEX, default: null },
    },
    data: {
      /** The video URL shown (crowdstudy passes opaque /media/<name>.mp4 URLs, never stimulus ids). */
      stimulus: { type: ParameterType.STRING },
      /** Answers keyed by item id, integers 1..points. */
      responses: { type: ParameterType.OBJECT },
      /** Milliseconds from the trial's display to the click on the button. */
      rt: { type: ParameterType.FLOAT },
      /** Milliseconds from the display until the video had played through once. */
      first_play_ms: { type: ParameterType.FLOAT },
      /** Number of complete plays of the video before the click. */
      video_plays: { type: ParameterType.INT },
      /** ISO 8601 UTC time the trial appeared. */
      shown_at: { type: ParameterType.STRING },
      /** Whether the answer came from a preloaded (in-memory) copy of the video. */
      preloaded: { type: ParameterType.BOOL },
      /** The attention check's answer (null without a check). */
      check: { type: ParameterType.INT },
      /** Times the page was hidden during the trial, and for how many milliseconds in all. */
      hidden_count: { type: ParameterType.INT },
      hidden_ms: { type: ParameterType.FLOAT },
      /** Times fullscreen was left during the trial. */
      fullscreen_exits: { type: ParameterType.INT },
    },
  };

  // the download-ahead cache is shared with the other trial types (video-trial-kit.js)
  const prefetch = CrowdstudyVideoKit.prefetch;
  const release = CrowdstudyVideoKit.release;

  function escapeHtml(s) {
    return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
  }

  class VideoLikertLoopPlugin {
    constructor(jsPsych) { this.jsPsych = jsPsych; }

    trial(display_element, trial) {
      const t0 = performance.now();
      const shownAt = new Date().toISOString();
      const items = trial.items || [];
      const labels = trial.labels;
      const src = CrowdstudyVideoKit.source(trial.stimulus);

      const head = labels.map((l, k) => `<th scope="col">(${k + 1})<br>${escapeHtml(l)}</th>`).join("");
      const CHECK = "cs-check";
      const shown = items.slice();
      if (trial.check) {
        const at = Math.max(0, Math.min(shown.length, trial.check.position | 0));
        shown.splice(at, 0, { id: CHECK, text: trial.check.text });
      }
      const rows = shown.map((it) => {
        const cells = labels.map((l, k) => `<td><input type="radio" name="${escapeHtml(it.id)}" value="${k + 1}"` +
          ` aria-label="${escapeHtml(it.id)}: (${k + 1}) ${escapeHtml(l)}"></td>`).join("");
        return `<tr data-item="${escapeHtml(it.id)}"><th scope="row" class="cs-statement">${escapeHtml(it.text)}</th>${cells}</tr>`;
      }).join("");
      const width = trial.video_width > 0 ? ` style="width:${trial.video_width}px"` : "";
      display_element.innerHTML = `
        <div class="cs-trial">
          <div class="cs-video-pane">
            <div class="cs-progress">${trial.progress_text || ""}</div>
            <video class="cs-video" muted autoplay playsinline disablepictureinpicture preload="auto"${width}></video>
            <div class="cs-video-status" aria-live="polite"></div>
            <div class="cs-error" role="alert" hidden></div>
          </div>
          <form class="cs-questions" novalidate>
            <div class="cs-prompt">${trial.prompt}</div>
            <table class="cs-likert"><thead><tr><th></th>${head}</tr></thead><tbody>${rows}</tbody></table>
            <div class="cs-actions">
              <button type="submit" class="jspsych-btn cs-next" disabled>${escapeHtml(trial.button_label)}</button>
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
      let plays = 0, firstPlay = null, last = 0, saving = false;
      // a save error stays until the participant acts on it (a click on the button)
      const showError = (msg) => { errorBox.textContent = msg; errorBox.hidden = false; };
      const clearError = () => { errorBox.hidden = true; errorBox.textContent = ""; };

      // data quality: tab switches (page hidden) and fullscreen exits during this trial
      let hiddenCount = 0, hiddenMs = 0, hiddenSince = document.hidden ? performance.now() : null, fsExits = 0;
      const onVisibility = () => {
        if (document.hidden) { hiddenCount += 1; hiddenSince = performance.now(); }
        else if (hiddenSince !== null) { hiddenMs += performance.now() - hiddenSince; hiddenSince = null; }
      };
      const onFullscreen = () => { if (!document.fullscreenElement) fsExits += 1; };
      document.addEventListener("visibilitychange", onVisibility);
      document.addEventListener("fullscreenchange", onFullscreen);

      video.muted = true;
      video.defaultMuted = true;
      video.loop = true;
      video.playsInline = true;
      video.controls = false;
      video.src = src;
      const tryPlay = () => video.play().then(() => { status.textContent = ""; }).catch(() => {
        status.textContent = "Click the video to start it.";
      });
      video.addEventListener("click", tryPlay);
      video.addEventListener("canplay", tryPlay, { once: true });
      video.addEventListener("contextmenu", (e) => e.preventDefault());

      const played = () => {
        plays += 1;
        if (firstPlay === null) firstPlay = performance.now() - t0;
        update();
      };
      // With `loop` set, browsers do not fire "ended": a play-through shows as a wrap of currentTime.
      video.addEventListener("timeupdate", () => {
        const t = video.currentTime;
        if (t + 0.05 < last) played();
        last = t;
      });
      video.addEventListener("seeking", () => { if (video.currentTime < 0.05 && last > 0.05) { played(); last = 0; } });
      video.addEventListener("ended", () => { played(); video.currentTime = 0; tryPlay(); });
      video.addEventListener("error", () => { status.textContent = "The video could not be loaded; please reload the page."; });

      const valueOf = (id) => {
        const el = form.querySelector(`input[name="${CSS.escape(id)}"]:checked`);
        return el ? parseInt(el.value, 10) : null;
      };
      const answers = () => {
        const out = {};
        for (const it of items) {
          const v = valueOf(it.id);
          if (v !== null) out[it.id] = v;
        }
        return out;
      };

      function update() {
        if (saving) return;
        const a = answers();
        if (trial.check && valueOf(CHECK) !== null) a[CHECK] = valueOf(CHECK);
        const missing = shown.filter((it) => !(it.id in a)).length;
        const needVideo = trial.require_full_view && plays < 1;
        button.disabled = missing > 0 || needVideo;
        for (const row of form.querySelectorAll("tr[data-item]")) {
          row.classList.toggle("cs-answered", row.dataset.item in a);
        }
        hint.textContent = missing > 0 ? `Please answer all ${shown.length} statements (${missing} left).`
          : needVideo ? "Please watch the video until the end at least once." : "";
      }
      form.addEventListener("change", update);
      update();

      for (const url of trial.preload || []) prefetch(url);

      const finish = (data) => {
        document.removeEventListener("visibilitychange", onVisibility);
        document.removeEventListener("fullscreenchange", onFullscreen);
        video.pause();
        video.removeAttribute("src");
        video.load();
        release(trial.stimulus);
        display_element.innerHTML = "";
        this.jsPsych.finishTrial(data);
      };


      form.addEventListener("submit", async (ev) => {
        ev.preventDefault();
        if (button.disabled || saving) return;
        clearError();
        const now = performance.now();
        const data = {
          stimulus: trial.stimulus, responses: answers(), rt: Math.round((now - t0) * 10) / 10,
          first_play_ms: firstPlay === null ? null : Math.round(firstPlay * 10) / 10, video_plays: plays,
          shown_at: shownAt, preloaded: src !== trial.stimulus, check: trial.check ? valueOf(CHECK) : null,
          hidden_count: hiddenCount,
          hidden_ms: Math.round((hiddenMs + (hiddenSince !== null ? now - hiddenSince : 0)) * 10) / 10,
          fullscreen_exits: fsExits,
        };
        saving = true;
        saving = await CrowdstudyVideoKit.saveThenFinish({ form, button, hint, errorBox, save: trial.save, data, finish });
      });
    }
  }
  VideoLikertLoopPlugin.info = info;
  return VideoLikertLoopPlugin;
})(jsPsychModule);

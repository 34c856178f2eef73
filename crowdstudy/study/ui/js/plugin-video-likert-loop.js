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
 *
 * Loaded as a classic script after jsPsych's browser build: defines the global
 * `jsPsychVideoLikertLoop`.
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
    },
    data: {
      /** The video URL shown (crowdstudy passes opaque /videos/<participant>/<token> URLs, never stimulus ids). */
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
    },
  };

  /** url -> {promise, objectUrl}: videos downloaded ahead of the trial that needs them. */
  const cache = new Map();

  function prefetch(url) {
    if (!url || cache.has(url)) return;
    const entry = { objectUrl: null, promise: null };
    entry.promise = fetch(url, { credentials: "same-origin" })
      .then((r) => { if (!r.ok) throw new Error("HTTP " + r.status); return r.blob(); })
      .then((blob) => { entry.objectUrl = URL.createObjectURL(blob); return entry.objectUrl; })
      .catch(() => { cache.delete(url); return null; });
    cache.set(url, entry);
  }

  function release(url) {
    const entry = cache.get(url);
    if (entry) {
      if (entry.objectUrl) URL.revokeObjectURL(entry.objectUrl);
      cache.delete(url);
    }
  }

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
      const cached = cache.get(trial.stimulus);
      const src = cached && cached.objectUrl ? cached.objectUrl : trial.stimulus;

      const head = labels.map((l, k) => `<th scope="col">(${k + 1})<br>${escapeHtml(l)}</th>`).join("");
      const rows = items.map((it) => {
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
      let plays = 0, firstPlay = null, last = 0, saving = false;

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

      const answers = () => {
        const out = {};
        for (const it of items) {
          const el = form.querySelector(`input[name="${CSS.escape(it.id)}"]:checked`);
          if (el) out[it.id] = parseInt(el.value, 10);
        }
        return out;
      };

      function update() {
        if (saving) return;
        const a = answers();
        const missing = items.filter((it) => !(it.id in a)).length;
        const needVideo = trial.require_full_view && plays < 1;
        button.disabled = missing > 0 || needVideo;
        for (const row of form.querySelectorAll("tr[data-item]")) {
          row.classList.toggle("cs-answered", row.dataset.item in a);
        }
        hint.textContent = missing > 0 ? `Please answer all ${items.length} statements (${missing} left).`
          : needVideo ? "Please watch the video until the end at least once." : "";
      }
      form.addEventListener("change", update);
      update();

      for (const url of trial.preload || []) prefetch(url);

      const finish = (data) => {
        video.pause();
        video.removeAttribute("src");
        video.load();
        release(trial.stimulus);
        display_element.innerHTML = "";
        this.jsPsych.finishTrial(data);
      };

      const notify = (msg) => { hint.textContent = msg || "Saving..."; };

      form.addEventListener("submit", async (ev) => {
        ev.preventDefault();
        if (button.disabled || saving) return;
        const data = {
          stimulus: trial.stimulus, responses: answers(), rt: Math.round((performance.now() - t0) * 10) / 10,
          first_play_ms: firstPlay === null ? null : Math.round(firstPlay * 10) / 10, video_plays: plays,
          shown_at: shownAt, preloaded: src !== trial.stimulus,
        };
        saving = true;
        button.disabled = true;
        for (const input of form.querySelectorAll("input")) input.disabled = true;
        hint.textContent = "Saving...";
        try {
          if (trial.save) await trial.save(data, notify);
          finish(data);
        } catch (err) {
          saving = false;
          for (const input of form.querySelectorAll("input")) input.disabled = false;
          hint.textContent = "Your answer could not be saved: " + (err && err.message ? err.message : err) +
            ". Please try again.";
          button.disabled = false;
        }
      });
    }
  }
  VideoLikertLoopPlugin.info = info;
  return VideoLikertLoopPlugin;
})(jsPsychModule);

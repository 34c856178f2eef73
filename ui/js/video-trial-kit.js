/**
 * crowdstudy: what every video trial plugin shares (loaded before the plugins; defines the
 * global `CrowdstudyVideoKit`).
 *
 * - a cache of videos downloaded ahead of the trial that shows them (`prefetch`, `source`,
 *   `release`), shared by all trial types, so a Likert trial can preload the next trial's
 *   videos whatever its type;
 * - `watchQuality()`: the data-quality record of one trial (tab switches and hidden time,
 *   fullscreen exits), stopped when the trial ends;
 * - `countPlays(video, onPlay)`: counts complete plays of a looping video (browsers fire no
 *   "ended" with `loop` set: a play-through shows as a wrap of currentTime);
 * - `setUpVideo(video, src, status)`: muted, looping, inline, no controls, no context menu;
 *   click to start where autoplay is refused.
 */
var CrowdstudyVideoKit = (function () {
  "use strict";

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

  /** The in-memory copy of `url` if it has arrived, else `url` itself. */
  function source(url) {
    const entry = cache.get(url);
    return entry && entry.objectUrl ? entry.objectUrl : url;
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

  /** Tab switches (page hidden) and fullscreen exits from now until `stop()`. */
  function watchQuality() {
    let hiddenCount = 0, hiddenMs = 0, fsExits = 0;
    let hiddenSince = document.hidden ? performance.now() : null;
    const onVisibility = () => {
      if (document.hidden) { hiddenCount += 1; hiddenSince = performance.now(); }
      else if (hiddenSince !== null) { hiddenMs += performance.now() - hiddenSince; hiddenSince = null; }
    };
    const onFullscreen = () => { if (!document.fullscreenElement) fsExits += 1; };
    document.addEventListener("visibilitychange", onVisibility);
    document.addEventListener("fullscreenchange", onFullscreen);
    return {
      snapshot(now) {
        return {
          hidden_count: hiddenCount,
          hidden_ms: Math.round((hiddenMs + (hiddenSince !== null ? now - hiddenSince : 0)) * 10) / 10,
          fullscreen_exits: fsExits,
        };
      },
      stop() {
        document.removeEventListener("visibilitychange", onVisibility);
        document.removeEventListener("fullscreenchange", onFullscreen);
      },
    };
  }

  function countPlays(video, onPlay) {
    let last = 0;
    video.addEventListener("timeupdate", () => {
      const t = video.currentTime;
      if (t + 0.05 < last) onPlay();
      last = t;
    });
    video.addEventListener("seeking", () => { if (video.currentTime < 0.05 && last > 0.05) { onPlay(); last = 0; } });
    video.addEventListener("ended", () => { onPlay(); video.currentTime = 0; video.play().catch(() => {}); });
  }

  function setUpVideo(video, src, status) {
    video.muted = true;
    video.defaultMuted = true;
    video.loop = true;
    video.playsInline = true;
    video.controls = false;
    video.src = src;
    video.addEventListener("contextmenu", (e) => e.preventDefault());
    video.addEventListener("error", () => { status.textContent = "A video could not be loaded; please reload the page."; });
  }

  /** Stop and unload the videos of a finished trial and drop their cached copies. */
  function tearDown(videos, urls) {
    for (const v of videos) { v.pause(); v.removeAttribute("src"); v.load(); }
    for (const u of urls) release(u);
  }

  /** Save a trial's answer before the trial ends (every trial type does it the same way): the
   * form is disabled, `save(data, notify)` awaited (the POST that commits the answer), then
   * `finish(data)`. On a rejection the form comes back with the message, so the participant
   * can try again with the answer still on the page. Returns true once finished. */
  async function saveThenFinish({ form, button, hint, errorBox, save, data, finish }) {
    const setInputs = (on) => { for (const input of form.querySelectorAll("input")) input.disabled = !on; };
    button.disabled = true;
    setInputs(false);
    hint.textContent = "Saving...";
    try {
      if (save) await save(data, (msg) => { hint.textContent = msg || "Saving..."; });
      finish(data);
      return true;
    } catch (err) {
      setInputs(true);
      hint.textContent = "";
      errorBox.textContent = "Your answer could not be saved: " + (err && err.message ? err.message : err) +
        ". Please try again.";
      errorBox.hidden = false;
      button.disabled = false;
      return false;
    }
  }

  return { prefetch, source, release, escapeHtml, watchQuality, countPlays, setUpVideo, tearDown, saveThenFinish };
})();

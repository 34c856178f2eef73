/*
 * crowdstudy session flow (jsPsych 8):
 * participant id -> screen check -> consent -> demographics -> instructions + one practice
 * trial -> (fullscreen) stage 1 (randomised per participant) -> break -> stage 2 -> debriefing.
 * Each stage has a task (the design's): Likert statements, 0-100 sliders, or a choice between
 * two videos (2afc); before the first stage of each task come its instructions and one
 * practice trial of that kind (shown once).
 * A "Withdraw" button is always there after consent: it deletes the answers on the server.
 * Prolific's PROLIFIC_PID, STUDY_ID and SESSION_ID URL parameters are sent at registration.
 *
 * The server holds the schedule and every answer; this page keeps only the participant id
 * and the session secret (localStorage), so a reload, a closed browser or a restarted server
 * resumes at the first unanswered trial. Participants are blinded: the page knows each trial
 * only by its index, its stage and an opaque token (the video has an opaque name too),
 * never by the stimulus id or its conditions; an answer is sent with the index and the token.
 * Each answer is POSTed when given and the next trial appears only once the server has
 * committed it; failed sends retry with exponential backoff while a notice tells the
 * participant.
 */
(function () {
  "use strict";

  const ID_PARAMS = ["PROLIFIC_PID", "participant", "participant_id", "workerId", "PID", "pid", "SONA_ID", "id"];
  const ID_RE = /^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$/;
  const S = { pid: null, secret: null, study: null, state: null, declined: false, demo: null,
              breakShown: {}, completion: null, screenFailed: false, practiced: [] };

  const storage = {
    get(k) { try { return window.localStorage.getItem(k); } catch (e) { return null; } },
    set(k, v) { try { window.localStorage.setItem(k, v); } catch (e) { /* private mode: resume needs the URL id */ } },
  };
  const secretKey = (pid) => "crowdstudy:secret:" + pid;
  const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
  const esc = (s) => String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));

  const noticeEl = () => document.getElementById("cs-notice");
  function showNotice(msg) { const n = noticeEl(); n.textContent = msg; n.hidden = false; }
  function hideNotice() { const n = noticeEl(); n.hidden = true; n.textContent = ""; }
  /** A warning that stays until the participant clicks OK (not cleared by the retry notices). */
  function showWarning(msg) {
    document.getElementById("cs-warning-text").textContent = msg;
    document.getElementById("cs-warning").hidden = false;
  }
  document.getElementById("cs-warning-ok").addEventListener("click", () => {
    document.getElementById("cs-warning").hidden = true;
  });

  class ApiError extends Error {
    constructor(status, message) { super(message); this.status = status; }
  }

  /** fetch JSON; network errors, 5xx, 408 and 429 are retried with exponential backoff (forever). */
  async function api(method, path, body) {
    let delay = 500;
    for (let attempt = 1; ; attempt++) {
      let resp = null;
      try {
        const headers = { "Accept": "application/json" };
        if (body !== undefined) headers["Content-Type"] = "application/json";
        if (S.secret) headers["X-Participant-Secret"] = S.secret;
        resp = await fetch(path, { method, headers, cache: "no-store",
                                   body: body === undefined ? undefined : JSON.stringify(body) });
      } catch (e) { resp = null; }
      if (resp && resp.status < 500 && resp.status !== 408 && resp.status !== 429) {
        if (attempt > 1) hideNotice();
        let data = {};
        try { data = await resp.json(); } catch (e) { data = {}; }
        if (!resp.ok) throw new ApiError(resp.status, data.error || ("HTTP " + resp.status));
        return data;
      }
      const wait = Math.round(delay * (0.8 + 0.4 * Math.random()));
      showNotice(`Cannot reach the study server (attempt ${attempt}). Your answers are kept; ` +
                 `retrying in ${Math.max(1, Math.round(wait / 1000))} s. Please keep this page open.`);
      await sleep(wait);
      delay = Math.min(delay * 2, 15000);
    }
  }

  /** An admin-issued resume link carries ?resume=<secret>: keep it, then drop it from the address bar. */
  function takeResumeSecret(pid) {
    const q = new URLSearchParams(window.location.search);
    const secret = q.get("resume");
    if (!secret || !pid) return;
    storage.set(secretKey(pid), secret);
    S.resumeSecret = secret;
    q.delete("resume");
    const rest = q.toString();
    window.history.replaceState(null, "", window.location.pathname + (rest ? "?" + rest : ""));
  }

  /** Prolific's study and session ids (and the participant's), as the registration sends them. */
  function platformFromUrl() {
    const q = new URLSearchParams(window.location.search);
    const out = {};
    for (const k of ["PROLIFIC_PID", "STUDY_ID", "SESSION_ID"]) {
      const v = (q.get(k) || "").trim();
      if (/^[A-Za-z0-9_-]{1,64}$/.test(v)) out[k] = v;
    }
    return out;
  }

  function idFromUrl() {
    const q = new URLSearchParams(window.location.search);
    for (const k of ID_PARAMS) {
      const v = q.get(k);
      if (v && ID_RE.test(v.trim())) return v.trim();
    }
    return null;
  }

  const cur = () => S.state.trials[S.state.next_trial_index];
  const nextTrial = () => S.state.trials[S.state.next_trial_index + 1];
  const taskOf = (t) => (t && t.task) || "likert";
  const videosOf = (t) => (t ? [t.video_url, t.video_url_right].filter(Boolean) : []);
  const stageInfo = (n) => S.study.stages.find((s) => s.number === n) || { number: n, description: "" };

  async function refreshState() {
    S.state = await api("GET", `/api/participants/${encodeURIComponent(S.pid)}`);
  }

  async function main() {
    S.study = await api("GET", "/api/study");
    S.pid = idFromUrl() || storage.get("crowdstudy:last");
    takeResumeSecret(S.pid);
    const jsPsych = initJsPsych({ display_element: "cs-target" });
    window.crowdstudy = { jsPsych, session: S };  // for debugging and the end-to-end test
    const abort = (html) => jsPsych.abortExperiment(`<div class="cs-page">${html}</div>`);
    const callAsync = (fn) => ({
      type: jsPsychCallFunction, async: true,
      func: (done) => { fn().then(() => done(null), (err) => { abort(`<p>${esc(err.message || err)}</p>`); }); },
    });
    const timeline = [];

    // Participant id, when the URL does not carry one.
    timeline.push({
      conditional_function: () => !S.pid,
      timeline: [{
        timeline: [{
          type: jsPsychSurveyText,
          preamble: () => `<div class="cs-page"><h2>${esc(S.study.name)}</h2>` +
            (S.idError ? `<p style="color:#a33">${esc(S.idError)}</p>` : "") + "</div>",
          questions: [{ prompt: "Please enter your participant ID", name: "pid", required: true }],
          button_label: "Continue",
          on_finish: (data) => {
            const v = String(data.response.pid || "").trim();
            if (ID_RE.test(v)) { S.pid = v; S.idError = null; }
            else S.idError = "An ID has 1-64 letters, digits, '_' or '-'.";
          },
        }],
        loop_function: () => !S.pid,
      }],
    });

    // Registration, or resumption with the stored secret.
    timeline.push(callAsync(async () => {
      const stored = S.resumeSecret || storage.get(secretKey(S.pid));
      let reg;
      try {
        reg = await api("POST", "/api/participants", stored ? { participant_id: S.pid, secret: stored }
                                                           : { participant_id: S.pid, platform: platformFromUrl() });
      } catch (err) {
        if (err.status === 410) throw new Error("You have withdrawn from this study; your answers were deleted.");
        if (err.status === 409 || err.status === 403) {
          throw new Error("This participant ID has already started the study in another browser. " +
                          "Please continue there, or contact the researchers.");
        }
        throw err;
      }
      S.secret = reg.secret;
      storage.set(secretKey(S.pid), reg.secret);
      storage.set("crowdstudy:last", S.pid);
      S.state = reg.state;
      S.practiced = (reg.state.practiced || []).slice();
    }));

    // Screen check (before consent): the browser window must be large enough for the videos.
    const screenOk = () => window.innerWidth >= S.study.screen.min_width && window.innerHeight >= S.study.screen.min_height;
    timeline.push({
      conditional_function: () => !S.state.consented && !S.state.screened_out && !screenOk(),
      timeline: [{
        timeline: [{
          type: jsPsychHtmlButtonResponse,
          stimulus: () => `<div class="cs-page cs-screen"><h2>Your browser window is too small</h2>
            <p>This study shows videos that need a window of at least ${S.study.screen.min_width} x
            ${S.study.screen.min_height} pixels; yours is ${window.innerWidth} x ${window.innerHeight}.</p>
            <p>Please maximise the window (or use a larger screen) and click "Check again". If you cannot,
            click "I cannot" to end here.</p></div>`,
          choices: ["Check again", "I cannot"],
          on_finish: (data) => { S.screenFailed = data.response === 1; },
        }],
        loop_function: () => !S.screenFailed && !screenOk(),
      }, callAsync(async () => {
        if (!S.screenFailed) return;
        S.state = await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/screen-out`,
                            { width: window.innerWidth, height: window.innerHeight });
      })],
    });
    timeline.push({
      conditional_function: () => S.state.screened_out,
      timeline: [{
        type: jsPsychHtmlButtonResponse,
        stimulus: () => `<div class="cs-page cs-debrief"><h2>Thank you</h2><p>This study cannot run in a window this
          small, so it ends here.</p>` + (S.state.completion_code ? `<p>Your code: <span class="cs-code">` +
          `${esc(S.state.completion_code)}</span></p>` : "") + "</div>",
        choices: () => (S.state.redirect_url ? ["Return"] : []),
        on_finish: () => { if (S.state.redirect_url) window.location.href = S.state.redirect_url; },
      }, callAsync(async () => { abort("<p>The study has ended. You may close this page.</p>"); })],
    });

    // Fullscreen for the trials (requested on the "Start" click, or with the button beside
    // "Withdraw" after a reload); leaving it is counted per trial by the trial plugin.
    const enterFullscreen = () => {
      const el = document.documentElement;
      if (S.study.fullscreen && !document.fullscreenElement && el.requestFullscreen) el.requestFullscreen().catch(() => {});
    };
    const fsButton = document.getElementById("cs-fullscreen");
    fsButton.hidden = !S.study.fullscreen;
    fsButton.addEventListener("click", enterFullscreen);
    document.addEventListener("fullscreenchange", () => { fsButton.disabled = !!document.fullscreenElement; });

    // Withdrawal, possible at any time after consent: answers and demographics are deleted.
    const bar = document.getElementById("cs-withdraw-bar");
    const showWithdraw = () => { bar.hidden = false; };
    document.getElementById("cs-withdraw").addEventListener("click", () => {
      document.getElementById("cs-withdraw-confirm").hidden = false;
    });
    document.getElementById("cs-withdraw-no").addEventListener("click", () => {
      document.getElementById("cs-withdraw-confirm").hidden = true;
    });
    document.getElementById("cs-withdraw-yes").addEventListener("click", async () => {
      try {
        const r = await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/withdraw`, { confirm: true });
        bar.hidden = true;
        let html = "<h2>You have withdrawn</h2><p>Your answers and details were deleted. Thank you for your time.</p>";
        if (r.completion_code) html += `<p>Your code: <span class="cs-code">${esc(r.completion_code)}</span></p>`;
        if (document.fullscreenElement) document.exitFullscreen().catch(() => {});
        abort(html);
      } catch (err) {
        showWarning("Withdrawal failed: " + (err.message || err) + ". Please try again.");
      }
    });

    // Informed consent.
    timeline.push({
      conditional_function: () => !S.state.consented,
      timeline: [{
        type: jsPsychHtmlButtonResponse,
        stimulus: () => `<div class="cs-page"><h1>Informed consent</h1><div class="cs-consent">${S.study.consent_html}</div></div>`,
        choices: ["I agree", "I do not agree"],
        on_finish: (data) => { S.declined = data.response !== 0; },
      }, callAsync(async () => {
        if (S.declined) {
          abort("<p>You chose not to take part. Thank you for your time; you may close this page.</p>");
          return;
        }
        S.state = await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/consent`, { consent: true });
      })],
    });
    timeline.push(callAsync(async () => { showWithdraw(); }));

    // Demographics.
    const genderOptions = () => S.study.genders.map((g) => `<option value="${esc(g)}">${esc(g)}</option>`).join("");
    timeline.push({
      conditional_function: () => !S.state.demographics,
      timeline: [{
        timeline: [{
          type: jsPsychSurveyHtmlForm,
          preamble: () => `<div class="cs-page"><h2>About you</h2>` +
            (S.demoError ? `<p style="color:#a33">${esc(S.demoError)}</p>` : "") + "</div>",
          html: () => `<div class="cs-page cs-form">
              <label for="cs-age">Age (years)</label>
              <input id="cs-age" name="age" type="number" min="${S.study.age_range[0]}" max="${S.study.age_range[1]}" step="1" required>
              <label for="cs-gender">Gender</label>
              <select id="cs-gender" name="gender" required><option value="" selected disabled>Choose...</option>${genderOptions()}</select>
            </div>`,
          button_label: "Continue",
          on_finish: (data) => { S.demo = data.response; },
        }, callAsync(async () => {
          try {
            S.state = await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/demographics`,
                                { age: parseInt(S.demo.age, 10), gender: S.demo.gender });
            S.demoError = null;
          } catch (err) {
            if (err.status !== 422) throw err;
            S.demoError = err.message;
          }
        })],
        loop_function: () => !S.state.demographics,
      }],
    });

    // Instructions and one practice trial of each task (stored flagged as practice): the first
    // stage's before the study starts, a later stage's task before that stage.
    const likertParams = () => ({ items: S.study.items.map((it) => ({ id: it.id, text: it.text })), labels: S.study.labels });
    const firstTask = () => (S.study.stages[0] && S.study.stages[0].task) || "likert";
    const nItems = () => S.study.items.length;
    const taskInstructions = (task) => {
      const L = S.study.labels, sl = S.study.slider || { left: L[0], right: L[L.length - 1] };
      if (task === "2afc") {
        return `<p>You will see two short silent videos of animated crowds side by side; both repeat in a loop.
          Below them is one statement:</p><p class="cs-quote">${esc(S.study.comparison || "")}</p>
          <p>Choose the video that fits it better: click that video (or the button under it), or use the Left and
          Right arrow keys, then click "Next" (or press Enter). The button becomes available once both videos have
          played through at least once.</p>`;
      }
      if (task === "slider") {
        return `<p>You will watch short silent videos of animated crowds. Each video repeats in a loop. Beside it,
          ${nItems()} statements describe the crowd. Under each statement is a line from "${esc(sl.left)}" to
          "${esc(sl.right)}": click on the line where your opinion lies. A marker appears where you click; drag
          it, or use the arrow keys, to adjust it. There are no numbers: any point on the line is an answer.</p>
          <p>Answer every statement. The button to go on becomes available once every line has a marker and the
          video has played through at least once.</p>`;
      }
      return `<p>You will watch short silent videos of animated crowds. Each video repeats in a loop. Beside it,
        ${nItems()} statements describe the crowd: for each one, choose how much you agree, from (1)
        "${esc(L[0])}" to (${L.length}) "${esc(L[L.length - 1])}".</p>
        <p>Answer every statement. The button to go on becomes available once all statements are answered and
        the video has played through at least once.</p>`;
    };
    const savePractice = (task) => async (data) => {
      const body = { task, rt_ms: data.rt, shown_at: data.shown_at, video_plays: data.video_plays,
                     first_play_ms: data.first_play_ms };
      if (task === "2afc") body.choice = data.choice; else body.answers = data.responses;
      await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/practice`, body);
      if (!S.practiced.includes(task)) S.practiced.push(task);
    };
    /** One trial node per task, shown when `task()` is its task (the practice or a study trial)
     * and `guard()` holds. */
    const taskTrials = (task, make, guard = () => true) => ["likert", "slider", "2afc"].map((kind) => ({
      conditional_function: () => guard() && task() === kind, timeline: [make(kind)],
    }));
    const trialOf = (kind, p) => {
      const common = { progress_text: p.progress_text, preload: p.preload, save: p.save, data: p.data || {} };
      if (kind === "2afc") {
        return { type: jsPsychVideo2afcLoop, ...common, stimulus_left: p.videos(0), stimulus_right: p.videos(1),
                 statement: () => esc(S.study.comparison || ""), check: p.check || null };
      }
      if (kind === "slider") {
        const sl = () => S.study.slider || { left: S.study.labels[0], right: S.study.labels[S.study.labels.length - 1] };
        return { type: jsPsychVideoSliderLoop, ...common, stimulus: p.videos(0), items: () => likertParams().items,
                 left_label: () => sl().left, right_label: () => sl().right, check: p.check || null };
      }
      return { type: jsPsychVideoLikertLoop, ...common, stimulus: p.videos(0), items: () => likertParams().items,
               labels: () => likertParams().labels, check: p.check || null };
    };
    const practiceOf = (task) => taskTrials(task, (kind) => trialOf(kind, {
      videos: () => () => S.state.practice.video_url,
      progress_text: "Practice video",
      preload: () => videosOf(cur()),
      save: savePractice(kind),
    }));
    timeline.push({
      conditional_function: () => !S.state.practice_done,
      timeline: [{
        type: jsPsychInstructions,
        pages: () => [
          `<div class="cs-page"><h2>Instructions</h2>${taskInstructions(firstTask())}</div>`,
          `<div class="cs-page"><h2>Practice</h2><p>There are ${S.study.stages.length} parts, with a short break in
           between. We start with one practice video so you can get used to the page; its answers are not part of
           the study.</p></div>`,
        ],
        show_clickable_nav: true, button_label_next: "Continue", button_label_previous: "Back",
      }, ...practiceOf(firstTask), {
        type: jsPsychHtmlButtonResponse,
        stimulus: `<div class="cs-page"><h2>The study begins</h2><p>The practice is over. The videos of the
          study now follow.</p></div>`,
        choices: ["Start"],
        on_finish: () => { S.state.practice_done = true; enterFullscreen(); },  // a click: browsers grant fullscreen only on one
      }],
    });
    // Stage trials with a break screen between stages.
    const needsBreak = () => {
      const i = S.state.next_trial_index;
      return i > 0 && i < S.state.n_trials && S.state.trials[i].stage !== S.state.trials[i - 1].stage &&
        !S.breakShown[S.state.trials[i].stage];
    };
    const stagePosition = () => {
      const t = cur();
      const same = S.state.trials.filter((x) => x.stage === t.stage);
      const k = same.findIndex((x) => x.trial_index === t.trial_index) + 1;
      const stages = S.study.stages.map((s) => s.number);
      const unit = taskOf(t) === "2afc" ? "pair" : "video";
      return `Part ${stages.indexOf(t.stage) + 1} of ${stages.length} &middot; ${unit} ${k} of ${same.length}`;
    };
    async function saveAnswer(data) {
      const t = cur();
      const body = { trial_index: t.trial_index, token: t.token,
                     rt_ms: data.rt, shown_at: data.shown_at, video_plays: data.video_plays,
                     first_play_ms: data.first_play_ms, hidden_count: data.hidden_count, hidden_ms: data.hidden_ms,
                     fullscreen_exits: data.fullscreen_exits };
      if (taskOf(t) === "2afc") body.choice = data.choice; else body.answers = data.responses;
      if (t.check) body.check = data.check;
      try {
        await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/responses`, body);
        S.state.next_trial_index = t.trial_index + 1;
        S.state.n_answered += 1;
      } catch (err) {
        if (err.status !== 409) throw err;
        // answered meanwhile in another tab or window: say so, then continue where the server is
        await refreshState();
        showWarning("This video had already been answered in another tab or window, so the first answer is " +
                    "kept (this one was recorded separately). Please use only one window; you continue at video " +
                    (S.state.next_trial_index + 1) + ".");
      }
    }
    timeline.push({
      conditional_function: () => S.state.next_trial_index < S.state.n_trials,
      timeline: [{
        timeline: [{
          // each pass of the loop shows ONE study trial: the trial nodes run only while the
          // trial this pass started with is unanswered (see taskTrials' guard below)
          conditional_function: () => { S.passIndex = S.state.next_trial_index; return needsBreak(); },
          timeline: [{
            type: jsPsychHtmlButtonResponse,
            stimulus: () => {
              const st = stageInfo(cur().stage);
              const k = S.study.stages.findIndex((s) => s.number === st.number) + 1;
              const prev = S.state.trials[S.state.next_trial_index - 1];
              const same = taskOf(prev) === taskOf(cur());
              return `<div class="cs-page"><h2>Break</h2><p>Part ${k - 1} is complete, thank you! Take a short
                break if you like.</p><p>Part ${k} of ${S.study.stages.length}: ${esc(st.description || "")}.
                ${same ? "The questions stay the same." : "This part asks something different: its instructions follow."}</p></div>`;
            },
            choices: ["Continue"],
            on_finish: () => { S.breakShown[cur().stage] = true; },
          }],
        }, {
          // the first stage of a task other than the practised ones: its instructions and practice
          conditional_function: () => !S.practiced.includes(taskOf(cur())),
          timeline: [{
            type: jsPsychInstructions,
            pages: () => [`<div class="cs-page"><h2>Instructions</h2>${taskInstructions(taskOf(cur()))}
              <p>One practice trial comes first; its answer is not part of the study.</p></div>`],
            show_clickable_nav: true, button_label_next: "Continue",
          }, ...practiceOf(() => taskOf(cur())), {
            type: jsPsychHtmlButtonResponse,
            stimulus: `<div class="cs-page"><h2>The part begins</h2><p>The practice is over. The videos of this
              part now follow.</p></div>`,
            choices: ["Start"],
            on_finish: () => enterFullscreen(),
          }],
        }, ...taskTrials(() => taskOf(cur()), (kind) => trialOf(kind, {
          videos: (k) => () => videosOf(cur())[k],
          progress_text: stagePosition,
          preload: () => videosOf(nextTrial()),
          check: () => cur().check || null,
          save: saveAnswer,
          data: { phase: "trial" },
        }), () => S.state.next_trial_index === S.passIndex)],
        loop_function: () => S.state.next_trial_index < S.state.n_trials,
      }],
    });

    // Completion and debriefing.
    timeline.push(callAsync(async () => {
      S.completion = await api("POST", `/api/participants/${encodeURIComponent(S.pid)}/complete`, {});
      bar.hidden = true;
      if (document.fullscreenElement) document.exitFullscreen().catch(() => {});
    }));
    timeline.push({
      type: jsPsychHtmlButtonResponse,
      stimulus: () => {
        const c = S.completion || {};
        let html = `<div class="cs-page cs-debrief"><h2>Thank you!</h2><p>You have completed the study. All your
          answers are saved.</p><p>The videos showed crowds animated with and without a method that removes
          the overlaps between characters' bodies; your ratings tell us how much this affects how realistic
          the crowds look.</p>`;
        if (c.completion_code) html += `<p>Your completion code: <span class="cs-code">${esc(c.completion_code)}</span></p>`;
        if (c.redirect_url) html += `<p>Click the button to return to the recruitment platform.</p>`;
        return html + "</div>";
      },
      choices: () => (S.completion && S.completion.redirect_url ? ["Return"] : []),
      on_load: () => {
        if (S.completion && S.completion.redirect_url) {
          setTimeout(() => { window.location.href = S.completion.redirect_url; }, 15000);
        }
      },
      on_finish: () => {
        if (S.completion && S.completion.redirect_url) window.location.href = S.completion.redirect_url;
      },
    });

    await jsPsych.run(timeline);
  }

  main().catch((err) => {
    document.getElementById("cs-target").innerHTML =
      `<div class="cs-page"><p>The study could not start: ${esc(err.message || err)}. Please reload the page.</p></div>`;
  });
})();

"""The study server: a Starlette ASGI application.

Blinding
--------
Participants never see a stimulus id (``S1-D3-V2-Ours`` names the density, viewpoint and
method). Everything the participant API and the page return names a trial by its
``trial_index``, its ``stage`` and an opaque per-participant ``token``
(:mod:`crowdstudy.study.blinding`); the video URL is ``/videos/<participant_id>/<token>``,
resolved on the server through that participant's stored schedule and the stimulus
manifest. An answer carries ``trial_index`` and ``token``; the server checks the token
against that trial of that participant's schedule and stores the real stimulus id, which
only the admin endpoints (export, ``/admin/participants/<id>/schedule``) reveal.

Routes
------
Participant front end (no authentication):
    ``GET /``                     the jsPsych page (``ui/index.html``)
    ``GET /js/*, /css/*``         the page's own scripts and styles (``ui/js``, ``ui/css``)
    ``GET /lib/<package>/*``      jsPsych and its plugins' ``dist`` files from ``ui/node_modules``
    ``GET /videos/<id>/<token>``  a trial's video (HTTP range requests); ``/videos/practice``
    ``GET /api/study``            items, scale labels, consent HTML, stage sizes
JSON API of one participant (header ``X-Participant-Secret`` from registration):
    ``POST /api/participants``                        register, or resume with the secret
    ``GET  /api/participants/<id>``                   state: trials ``{trial_index, stage, token,
                                                      video_url}``, next unanswered trial
    ``POST /api/participants/<id>/consent``           ``{"consent": true}``
    ``POST /api/participants/<id>/demographics``      ``{"age": 31, "gender": "female"}``
    ``POST /api/participants/<id>/practice``          ``{"answers": {...}, "rt_ms": ...}``
    ``POST /api/participants/<id>/responses``         ``{"trial_index", "token", "answers", "rt_ms", "shown_at"}``
    ``GET  /api/participants/<id>/responses``         the participant's own answers (by token)
    ``POST /api/participants/<id>/complete``          completion code / redirect URL
Admin (``Authorization: Bearer <token>`` or ``?token=<token>``):
    ``GET /admin``, ``/admin/progress.json``, ``/admin/metrics.json`` (server-side answer
    latency percentiles), ``/admin/export/responses.csv``, ``/admin/export/demographics.csv``;
    ``GET /admin/participants/<id>/schedule``: that participant's trials with token, stimulus
    id and conditions (what the simulated participants answer from);
    ``POST /admin/participants/<id>/resume-link``: a new secret and the URL that continues
    that participant's session in another browser (the old browser's secret stops working)

Errors are JSON ``{"error": message}`` with a 4xx status: 400 malformed request, 401/403
missing or wrong secret/token, 404 unknown participant or video, 409 a conflicting or
out-of-order answer, 413 body too large, 422 a value out of range. Every answer is
committed to the database before the response is sent.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import hmac
import json
import math
import secrets
from pathlib import Path
from typing import Any

from crowdstudy.design import StudyDesign
from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.study.blinding import TOKEN_LENGTH, TOKEN_PATTERN, token_table
from crowdstudy.study.schedule import PARTICIPANT_ID_PATTERN, make_schedule
from crowdstudy.study.stimulus_set import StimulusSet
from crowdstudy.study.storage import ITEM_IDS, PRACTICE_TRIAL_INDEX, StudyStore

__all__ = ["StudyConfig", "create_app", "AnswerTimer", "UI_PLUGINS", "GENDERS", "AGE_RANGE", "MAX_BODY_BYTES",
           "hash_secret"]

#: npm packages of ui/node_modules served under /lib/<name>/ (their dist folder).
UI_PLUGINS = ("plugin-call-function", "plugin-html-button-response", "plugin-instructions",
              "plugin-survey-html-form", "plugin-survey-text")
GENDERS = ("female", "male", "non-binary", "other", "prefer not to say")
AGE_RANGE = (18, 120)
MAX_BODY_BYTES = 16 * 1024
_MAX_RT_MS = 24 * 3600 * 1000.0


@dataclasses.dataclass
class StudyConfig:
    """Everything the server needs.

    design: the study design; stimuli: its videos; store: the database; consent_html: the
    consent page body; admin_token: the admin secret; ui_dir: the ``ui/`` folder (with
    ``node_modules`` installed); completion_code / redirect_url: shown on the debrief page.
    """
    design: StudyDesign
    stimuli: StimulusSet
    store: StudyStore
    consent_html: str
    admin_token: str
    ui_dir: Path
    completion_code: str | None = None
    redirect_url: str | None = None


class ApiError(Exception):
    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


def hash_secret(secret: str) -> str:
    """SHA-256 hex digest of a participant secret (the database stores only this)."""
    return hashlib.sha256(secret.encode("utf-8")).hexdigest()


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _parse_time(value, name: str) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or len(value) > 40:
        raise ApiError(422, f"{name} must be an ISO 8601 timestamp string")
    try:
        t = _dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
    except ValueError:
        raise ApiError(422, f"{name} must be an ISO 8601 timestamp, got {value!r}") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.timezone.utc)
    return t.astimezone(_dt.timezone.utc).isoformat(timespec="milliseconds")


class _Study:
    """Request handlers bound to one StudyConfig (the blocking parts run in a thread pool)."""

    def __init__(self, config: StudyConfig):
        self.cfg = config
        self.store = config.store
        self.points = int(config.design.likert_points)
        self.item_ids = tuple(it.id for it in config.design.items)
        if self.item_ids != ITEM_IDS:
            raise InvalidInputError(f"design {config.design.source}: the server stores items {', '.join(ITEM_IDS)}, "
                                    f"the design lists {', '.join(self.item_ids)}")
        self.by_stage = config.stimuli.by_stage()
        self.seed = int(config.design.seed)
        self._schedules: dict[str, list[dict]] = {}
        self._public: dict[str, list[dict]] = {}
        self._secret = config.store.blinding_secret()
        self._auth: dict[str, str] = {}
        self._ready: set[str] = set()
        self.store.sync_stimuli(config.stimuli.rows.values())
        self.study_info = {
            "name": config.design.name,
            "items": [{"id": it.id, "text": it.text, "reverse": it.reverse} for it in config.design.items],
            "labels": list(config.design.likert_labels), "points": self.points,
            "composites": {k: list(v) for k, v in config.design.composites.items()},
            "consent_html": config.consent_html,
            "stages": [{"number": st.number, "scenario": st.scenario, "description": st.description,
                        "n_trials": len(self.by_stage.get(st.number, []))} for st in config.design.stages],
            "genders": list(GENDERS), "age_range": list(AGE_RANGE),
            "practice_video_url": "/videos/practice",
        }

    # -- participants -----------------------------------------------------------------
    def check_pid(self, pid) -> str:
        if not isinstance(pid, str) or not PARTICIPANT_ID_PATTERN.fullmatch(pid):
            raise ApiError(400, "participant_id must be 1-64 letters, digits, '_' or '-' starting with a letter "
                                "or digit")
        return pid

    def authenticate(self, pid: str, secret: str | None) -> None:
        self.check_pid(pid)
        stored = self._auth.get(pid)
        if stored is None:
            row = self.store.participant(pid)
            if row is None:
                raise ApiError(404, f"unknown participant {pid!r}; register first (POST /api/participants)")
            stored = self._auth[pid] = row["secret_hash"]
        if not secret:
            raise ApiError(401, "missing X-Participant-Secret header (the secret returned at registration)")
        if not hmac.compare_digest(hash_secret(secret), stored):
            raise ApiError(403, "wrong participant secret")

    def schedule(self, pid: str) -> list[dict]:
        """The participant's trials with the REAL stimulus id and conditions plus each trial's
        ``token`` and ``video_url`` (server side and admin only; [] for an unknown id)."""
        sched = self._schedules.get(pid)
        if sched is None:
            sched = self.store.schedule(pid)
            tokens = token_table(self._secret, pid, [row["stimulus_id"] for row in sched])
            for row in sched:
                row["token"] = tokens[row["stimulus_id"]]
                row["video_url"] = f"/videos/{pid}/{row['token']}"
            if sched:  # the public view first: a cached schedule always has one
                self._public[pid] = [{k: row[k] for k in ("trial_index", "stage", "token", "video_url")}
                                     for row in sched]
                self._schedules[pid] = sched
        return sched

    def public_trials(self, pid: str) -> list[dict]:
        """The participant's trials as the browser sees them: trial_index, stage, token, video_url."""
        self.schedule(pid)
        return self._public.get(pid, [])

    def video_file(self, pid: str, token: str) -> Path | None:
        """The video file of ``token`` in participant ``pid``'s schedule (None if there is none)."""
        if not PARTICIPANT_ID_PATTERN.fullmatch(pid) or not TOKEN_PATTERN.fullmatch(token):
            return None
        trial = next((t for t in self.schedule(pid) if t["token"] == token), None)
        return None if trial is None else self.cfg.stimuli.files.get(trial["stimulus_id"])

    def state(self, pid: str) -> dict:
        row = self.store.participant(pid)
        sched = self.public_trials(pid)
        answered = self.store.answered_indices(pid)
        done = set(answered)
        nxt = next((t["trial_index"] for t in sched if t["trial_index"] not in done), len(sched))
        completed = row["completed_at"] is not None
        return {
            "participant_id": pid, "consented": row["consented_at"] is not None,
            "demographics": row["demographics_at"] is not None, "practice_done": row["practice_at"] is not None,
            "completed": completed, "n_trials": len(sched), "n_answered": len(done), "next_trial_index": nxt,
            "trials": sched, "practice": {"video_url": "/videos/practice"},
            "completion_code": row["completion_code"] if completed else None,
            "redirect_url": self.cfg.redirect_url if completed else None,
        }

    def register(self, body: dict, user_agent: str | None) -> tuple[int, dict]:
        pid = self.check_pid(body.get("participant_id"))
        secret = body.get("secret")
        if secret is not None and (not isinstance(secret, str) or len(secret) > 128):
            raise ApiError(400, "secret must be a string")
        if self.store.participant(pid) is not None:
            if not secret:
                raise ApiError(409, f"participant {pid!r} is already registered; resume from the browser that "
                                    "started the session (it holds the session secret)")
            self.authenticate(pid, secret)
            return 200, {"participant_id": pid, "secret": secret, "resumed": True, "state": self.state(pid)}
        secret = secrets.token_urlsafe(24)
        sched = make_schedule(self.by_stage, pid, self.seed)
        if not self.store.register(pid, hash_secret(secret), sched, seed=self.seed, user_agent=user_agent):
            raise ApiError(409, f"participant {pid!r} was registered concurrently; resume with its secret")
        return 201, {"participant_id": pid, "secret": secret, "resumed": False, "state": self.state(pid)}

    def consent(self, pid: str, body: dict) -> dict:
        if body.get("consent") is not True:
            raise ApiError(422, "consent must be true (a participant who declines is not registered further)")
        self.store.set_consent(pid)
        return self.state(pid)

    def demographics(self, pid: str, body: dict) -> dict:
        row = self.store.participant(pid)
        if row["consented_at"] is None:
            raise ApiError(409, "give consent before the demographics")
        age, gender = body.get("age"), body.get("gender")
        if isinstance(age, str) and age.strip().isdigit():
            age = int(age.strip())
        if not _is_int(age) or not AGE_RANGE[0] <= age <= AGE_RANGE[1]:
            raise ApiError(422, f"age must be an integer {AGE_RANGE[0]}..{AGE_RANGE[1]}, got {age!r:.40}")
        if gender not in GENDERS:
            raise ApiError(422, f"gender must be one of {', '.join(GENDERS)}, got {gender!r:.40}")
        self.store.set_demographics(pid, age, gender)
        return self.state(pid)

    def parse_answers(self, body: dict) -> tuple[dict, float, str | None]:
        answers = body.get("answers")
        if not isinstance(answers, dict):
            raise ApiError(422, "answers must be an object {\"Q1\": 1..6, ...}")
        for q in self.item_ids:
            if q not in answers:
                raise ApiError(422, f"answers.{q} is missing (all {len(self.item_ids)} items are required)")
            v = answers[q]
            if not _is_int(v) or not 1 <= v <= self.points:
                raise ApiError(422, f"answers.{q} must be an integer 1..{self.points}, got {v!r:.40}")
        extra = sorted(set(answers) - set(self.item_ids))
        if extra:
            raise ApiError(422, f"answers has unknown item {extra[0]!r:.40}")
        rt = body.get("rt_ms")
        if isinstance(rt, bool) or not isinstance(rt, (int, float)) or not math.isfinite(rt) or \
                not 0 <= rt <= _MAX_RT_MS:
            raise ApiError(422, f"rt_ms must be a number of milliseconds 0..{_MAX_RT_MS:.0f}, got {rt!r:.40}")
        return answers, float(rt), _parse_time(body.get("shown_at"), "shown_at")

    def practice(self, pid: str, body: dict) -> tuple[int, dict]:
        row = self.store.participant(pid)
        if row["demographics_at"] is None:
            raise ApiError(409, "give consent and the demographics before the practice trial")
        answers, rt, shown = self.parse_answers(body)
        status, _ = self.store.record_answer(pid, PRACTICE_TRIAL_INDEX, "practice", 0, answers, rt, shown,
                                             practice=True)
        if status == "conflict":
            raise ApiError(409, "a different practice answer is already stored")
        self.store.set_practice_done(pid)
        return (201 if status == "created" else 200), {"stored": True, "practice": True}

    def answer(self, pid: str, body: dict) -> tuple[int, dict]:
        if pid not in self._ready:
            row = self.store.participant(pid)
            if row["practice_at"] is None or row["demographics_at"] is None:
                raise ApiError(409, "complete consent, demographics and the practice trial first")
            self._ready.add(pid)
        sched = self.schedule(pid)
        ti = body.get("trial_index")
        if not _is_int(ti) or not 0 <= ti < len(sched):
            raise ApiError(422, f"trial_index must be an integer 0..{len(sched) - 1}, got {ti!r:.40}")
        if "stimulus_id" in body:
            raise ApiError(422, "send the trial's token, not a stimulus_id (participants never see stimulus ids)")
        token = body.get("token")
        if not isinstance(token, str) or not TOKEN_PATTERN.fullmatch(token):
            raise ApiError(422, f"token must be the trial's {TOKEN_LENGTH}-digit lowercase hex token from the "
                                "participant's state")
        trial = sched[ti]
        if trial["token"] != token:
            other = next((t["trial_index"] for t in sched if t["token"] == token), None)
            if other is None:
                raise ApiError(422, f"token {token} is not in this participant's schedule")
            raise ApiError(422, f"token {token} belongs to trial {other}, not to trial_index {ti}")
        answers, rt, shown = self.parse_answers(body)
        status, row = self.store.record_answer(pid, ti, trial["stimulus_id"], trial["stage"], answers, rt, shown)
        if status == "out_of_order":
            raise ApiError(409, f"trial {row['expected']} is not answered yet; answers arrive in trial order")
        if status == "conflict":
            raise ApiError(409, f"trial {ti} already has a different answer; the first one is kept")
        return (201 if status == "created" else 200), {"stored": True, "trial_index": ti,
                                                       "answer": _public_answer(row, token)}

    def own_responses(self, pid: str) -> dict:
        """The participant's stored answers, each naming its trial by token (no conditions)."""
        tokens = {t["trial_index"]: t["token"] for t in self.schedule(pid)}
        return {"participant_id": pid,
                "responses": [{"participant_id": pid, "stage": row["stage"],
                               **_public_answer(row, tokens[row["trial_index"]])}
                              for row in self.store.response_rows(pid)]}

    def complete(self, pid: str) -> dict:
        st = self.state(pid)
        missing = st["n_trials"] - st["n_answered"]
        if missing:
            raise ApiError(409, f"{missing} trials are not answered yet (next: trial {st['next_trial_index']})")
        self.store.set_completed(pid, self.cfg.completion_code)
        return self.state(pid)

    # -- admin ------------------------------------------------------------------------------
    def admin_schedule(self, pid: str) -> dict:
        """Participant ``pid``'s trials with token, stimulus id and conditions (admin only: this
        is the token -> stimulus mapping the participant must not see)."""
        self.check_pid(pid)
        sched = self.schedule(pid)
        if not sched:
            raise ApiError(404, f"unknown participant {pid!r}")
        return {"participant_id": pid, "trials": [dict(t) for t in sched]}

    def resume_link(self, pid: str) -> dict:
        """A new secret for ``pid`` (e.g. to continue on another device); the old one stops working."""
        self.check_pid(pid)
        secret = secrets.token_urlsafe(24)
        if not self.store.replace_secret(pid, hash_secret(secret)):
            raise ApiError(404, f"unknown participant {pid!r}")
        self._auth.pop(pid, None)
        return {"participant_id": pid, "url": f"/?participant={pid}&resume={secret}"}

    def check_admin(self, request) -> None:
        auth = request.headers.get("authorization", "")
        token = auth[7:].strip() if auth.lower().startswith("bearer ") else request.query_params.get("token", "")
        if not token:
            raise ApiError(401, "admin token required (Authorization: Bearer <token> or ?token=<token>)")
        if not hmac.compare_digest(token.encode(), self.cfg.admin_token.encode()):
            raise ApiError(403, "wrong admin token")


def _public_answer(row: dict, token: str) -> dict:
    """A stored answer as its participant may see it: the trial's token, never the stimulus id."""
    return {"trial_index": row["trial_index"], "token": token,
            **{k: row[k] for k in (*ITEM_IDS, "rt_ms", "shown_at", "answered_at")}}


class _SecurityHeaders:
    """ASGI middleware adding ``nosniff`` and ``no-referrer`` headers to every response."""

    _EXTRA = ((b"x-content-type-options", b"nosniff"), (b"referrer-policy", b"no-referrer"))

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {k.lower() for k, _ in headers}
                headers += [h for h in self._EXTRA if h[0] not in present]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


class AnswerTimer:
    """ASGI middleware timing every answer POST inside the server (first byte of the request
    handled to the last byte of the response handed to the server), milliseconds; keeps the
    last ``maxlen`` values for ``/admin/metrics.json``."""

    def __init__(self, app, maxlen: int = 200_000):
        import collections
        self.app = app
        self.values: "collections.deque[float]" = collections.deque(maxlen=maxlen)

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "POST" or not scope["path"].endswith("/responses"):
            await self.app(scope, receive, send)
            return
        import time
        t0 = time.perf_counter()

        async def timed_send(message):
            await send(message)
            if message["type"] == "http.response.body" and not message.get("more_body", False):
                self.values.append((time.perf_counter() - t0) * 1000.0)

        await self.app(scope, receive, timed_send)

    def summary(self) -> dict:
        vals = sorted(self.values)
        if not vals:
            return {"answers_timed": 0}

        def pct(q):
            return round(vals[min(len(vals) - 1, int(math.ceil(q / 100.0 * len(vals))) - 1)], 3)
        return {"answers_timed": len(vals), "latency_ms_p50": pct(50), "latency_ms_p95": pct(95),
                "latency_ms_p99": pct(99), "latency_ms_max": round(vals[-1], 3)}


def create_app(config: StudyConfig):
    """The ASGI application of one study."""
    try:
        from starlette.applications import Starlette
        from starlette.concurrency import run_in_threadpool
        from starlette.middleware import Middleware
        from starlette.requests import Request
        from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response
        from starlette.routing import Mount, Route
        from starlette.staticfiles import StaticFiles
    except ModuleNotFoundError as exc:  # pragma: no cover
        raise MissingDependencyError(f"the study server needs the 'web' extra: pip install 'crowdstudy[web]' "
                                     f"({exc.name} missing)") from None
    from crowdstudy.study.dashboard import dashboard_html
    from crowdstudy.study.export import DEMOGRAPHIC_COLUMNS, RESPONSE_COLUMNS, rows_to_csv

    ui = Path(config.ui_dir).resolve()
    modules = ui / "node_modules"
    needed = [ui / "index.html", ui / "js", ui / "css", modules / "jspsych" / "dist"] + \
        [modules / "@jspsych" / p / "dist" for p in UI_PLUGINS]
    absent = [str(p) for p in needed if not p.exists()]
    if absent:
        raise MissingDependencyError(f"the questionnaire front end is incomplete ({absent[0]} missing); run "
                                     f"`make setup` or `cd {ui} && npm ci`")
    study = _Study(config)
    practice_video = config.stimuli.practice_file
    no_store = {"Cache-Control": "no-store"}

    def error(status: int, message: str) -> JSONResponse:
        return JSONResponse({"error": message}, status_code=status, headers=no_store)

    async def body_of(request: Request) -> dict:
        length = request.headers.get("content-length")
        if length is not None and (not length.isdigit() or int(length) > MAX_BODY_BYTES):
            raise ApiError(413, f"request body larger than {MAX_BODY_BYTES} bytes")
        raw = await request.body()
        if len(raw) > MAX_BODY_BYTES:
            raise ApiError(413, f"request body larger than {MAX_BODY_BYTES} bytes")
        try:
            data = json.loads(raw)
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise ApiError(400, "request body is not valid JSON") from None
        if not isinstance(data, dict):
            raise ApiError(400, "request body must be a JSON object")
        return data

    def endpoint(handler, *, auth: bool = True, body: bool = False):
        """Wrap a blocking handler(pid?, body?) -> (status, payload) | payload."""
        async def run(request: Request):
            try:
                args: list[Any] = []
                if auth:
                    args.append(request.path_params["pid"])
                if body:
                    args.append(await body_of(request))
                secret = request.headers.get("x-participant-secret")

                def call():  # one trip to the thread pool: authenticate, then the handler
                    if auth:
                        study.authenticate(args[0], secret)
                    return handler(*args)
                result = await run_in_threadpool(call)
            except ApiError as exc:
                return error(exc.status, exc.message)
            except InvalidInputError as exc:
                return error(422, str(exc))
            status, payload = result if isinstance(result, tuple) else (200, result)
            return JSONResponse(payload, status_code=status, headers=no_store)
        return run

    async def register(request: Request):
        try:
            data = await body_of(request)
            status, payload = await run_in_threadpool(study.register, data, request.headers.get("user-agent"))
        except ApiError as exc:
            return error(exc.status, exc.message)
        return JSONResponse(payload, status_code=status, headers=no_store)

    async def study_info(_request: Request):
        return JSONResponse(study.study_info, headers=no_store)

    async def index(_request: Request):
        return FileResponse(ui / "index.html", media_type="text/html", headers=no_store)

    def video_response(path: Path | None):
        if path is None:
            return error(404, "no such video")
        return FileResponse(path, media_type="video/mp4", headers={"Cache-Control": "private, max-age=3600"})

    async def practice_video_file(_request: Request):
        return video_response(practice_video)

    async def trial_video(request: Request):
        # token -> stimulus id through the participant's stored schedule -> the manifest's
        # file: dictionary lookups, never a path join with a request value
        pid, token = request.path_params["pid"], request.path_params["token"]
        return video_response(await run_in_threadpool(study.video_file, pid, token))

    async def health(_request: Request):
        return JSONResponse({"ok": True})

    def admin(handler):
        async def run(request: Request):
            try:
                study.check_admin(request)
                return await run_in_threadpool(handler, request)
            except ApiError as exc:
                return error(exc.status, exc.message)
        return run

    def admin_schedule(request):
        return JSONResponse(study.admin_schedule(request.path_params["pid"]), headers=no_store)

    def admin_resume_link(request):
        return JSONResponse(study.resume_link(request.path_params["pid"]), headers=no_store)

    def admin_progress(_request):
        return JSONResponse({"participants": study.store.progress(), "n_trials": sum(map(len, study.by_stage.values()))},
                            headers=no_store)

    def admin_dashboard(request):
        token = request.query_params.get("token", "")
        return HTMLResponse(dashboard_html(study.store.progress(), config.design.name, token), headers=no_store)

    def admin_responses(_request):
        return Response(rows_to_csv(study.store.response_rows(), RESPONSE_COLUMNS), media_type="text/csv",
                        headers={**no_store, "Content-Disposition": 'attachment; filename="responses.csv"'})

    def admin_demographics(_request):
        return Response(rows_to_csv(study.store.demographics_rows(), DEMOGRAPHIC_COLUMNS), media_type="text/csv",
                        headers={**no_store, "Content-Disposition": 'attachment; filename="demographics.csv"'})

    timer_box: dict = {}

    def timer_factory(inner):
        timer_box["timer"] = AnswerTimer(inner)
        return timer_box["timer"]

    def admin_metrics(_request):
        timer = timer_box.get("timer")
        return JSONResponse({"server_answer_latency": timer.summary() if timer else {"answers_timed": 0}},
                            headers=no_store)

    lib_mounts = [Mount("/lib/jspsych/dist", StaticFiles(directory=modules / "jspsych" / "dist")),
                  Mount("/lib/jspsych/css", StaticFiles(directory=modules / "jspsych" / "css"))]
    lib_mounts += [Mount(f"/lib/{p}", StaticFiles(directory=modules / "@jspsych" / p / "dist")) for p in UI_PLUGINS]
    routes = [
        Route("/", index),
        Route("/healthz", health),
        Route("/api/study", study_info),
        Route("/api/participants", register, methods=["POST"]),
        Route("/api/participants/{pid}", endpoint(study.state), methods=["GET"]),
        Route("/api/participants/{pid}/consent", endpoint(study.consent, body=True), methods=["POST"]),
        Route("/api/participants/{pid}/demographics", endpoint(study.demographics, body=True), methods=["POST"]),
        Route("/api/participants/{pid}/practice", endpoint(study.practice, body=True), methods=["POST"]),
        Route("/api/participants/{pid}/responses", endpoint(study.answer, body=True), methods=["POST"]),
        Route("/api/participants/{pid}/responses", endpoint(study.own_responses), methods=["GET"]),
        Route("/api/participants/{pid}/complete", endpoint(study.complete), methods=["POST"]),
        Route("/videos/practice", practice_video_file),
        Route("/videos/{pid}/{token}", trial_video),
        Route("/admin", admin(admin_dashboard)),
        Route("/admin/progress.json", admin(admin_progress)),
        Route("/admin/metrics.json", admin(admin_metrics)),
        Route("/admin/participants/{pid}/resume-link", admin(admin_resume_link), methods=["POST"]),
        Route("/admin/participants/{pid}/schedule", admin(admin_schedule)),
        Route("/admin/export/responses.csv", admin(admin_responses)),
        Route("/admin/export/demographics.csv", admin(admin_demographics)),
        Mount("/js", StaticFiles(directory=ui / "js")),
        Mount("/css", StaticFiles(directory=ui / "css")),
        *lib_mounts,
    ]
    app = Starlette(routes=routes, middleware=[Middleware(_SecurityHeaders), Middleware(timer_factory)])
    app.state.study = study
    app.state.config = config
    return app

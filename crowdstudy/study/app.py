"""The study server: a Starlette ASGI application (handlers: :mod:`crowdstudy.study.session`).

Blinding
--------
Participants never see a stimulus id (``S1-D3-V2-Ours`` names the density, viewpoint and
method), the trial order's key, the scoring metadata (which items are reversed, how they
pair into composites) or a video's file date. Everything the participant API returns names
a trial by ``trial_index``, ``stage`` and an opaque per-participant ``token``
(:mod:`crowdstudy.study.blinding`); the order is shuffled with the study's secret key
(:mod:`crowdstudy.study.schedule`); videos have opaque per-deployment names
(:mod:`crowdstudy.study.media`) and are served without Last-Modified / ETag. Only the admin
endpoints reveal the mapping.

Several server processes may share one database (PostgreSQL, or SQLite on one machine):
they keep no state that another process could change (:mod:`crowdstudy.study.session`).

Routes
------
Participant front end (no authentication):
    ``GET /``                     the jsPsych page (``ui/index.html``)
    ``GET /js/*, /css/*``         the page's own scripts and styles (``ui/js``, ``ui/css``)
    ``GET /lib/<package>/*``      jsPsych and its plugins' ``dist`` files from ``ui/node_modules``
    ``GET /media/<name>.mp4``     a video under its opaque name (HTTP range requests)
    ``GET /api/study``            items (text only), scale labels, consent HTML, stage sizes, screen rules
JSON API of one participant (header ``X-Participant-Secret`` from registration; every POST
body is JSON sent as ``application/json``):
    ``POST /api/participants``                        register ({participant_id, platform?}) or resume (+ secret)
    ``GET  /api/participants/<id>``                   state: trials ``{trial_index, stage, token, video_url,
                                                      check?}``, next unanswered trial, status
    ``POST /api/participants/<id>/screen-out``        ``{"width", "height"}``: failed the screen check
    ``POST /api/participants/<id>/consent``           ``{"consent": true}``
    ``POST /api/participants/<id>/demographics``      ``{"age": 31, "gender": "female"}``
    ``POST /api/participants/<id>/practice``          ``{"answers": {...}, "rt_ms": ...}``
    ``POST /api/participants/<id>/responses``         ``{"trial_index", "token", "answers", "rt_ms", "shown_at",
                                                      "video_plays", "first_play_ms", "hidden_count", "hidden_ms",
                                                      "fullscreen_exits", "check"?}``
    ``GET  /api/participants/<id>/responses``         the participant's own answers (by token)
    ``POST /api/participants/<id>/complete``          completion code / redirect URL
    ``POST /api/participants/<id>/withdraw``          ``{"confirm": true}``: answers and demographics deleted
Admin (``Authorization: Bearer <token>``, or the cookie of a login on ``/admin`` for GET;
:mod:`crowdstudy.study.admin`):
    ``GET /admin`` (login form, then the dashboard), ``POST /admin/login``, ``POST /admin/logout``,
    ``/admin/progress.json``, ``/admin/participants.json``, ``/admin/metrics.json`` (this
    process's answer latency percentiles), ``/admin/study.json`` (scoring metadata),
    ``/admin/export/responses.csv``, ``/admin/export/demographics.csv``, ``/admin/export/participants.csv``;
    ``GET /admin/participants/<id>/schedule``: trials with token, stimulus id and conditions;
    ``POST /admin/participants/<id>/resume-link``: a new secret and the URL that continues
    the session in another browser; ``POST /admin/participants/<id>/withdraw``.

Errors are JSON ``{"error": message}`` with a 4xx status: 400 malformed request, 401/403
missing or wrong secret/token (the same for an unknown participant), 404 unknown video, 409 a
conflicting or out-of-order answer, 410 withdrawn, 413 body too large, 415 not JSON, 422 a
value out of range. Every answer is committed to the database before the response is sent.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from crowdstudy.design import StudyDesign
from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.study.quality import OnlineConfig
from crowdstudy.study.stimulus_set import StimulusSet
from crowdstudy.study.storage import StudyStore

__all__ = ["StudyConfig", "create_app", "UI_PLUGINS"]

#: npm packages of ui/node_modules served under /lib/<name>/ (their dist folder).
UI_PLUGINS = ("plugin-call-function", "plugin-html-button-response", "plugin-instructions",
              "plugin-survey-html-form", "plugin-survey-text")


@dataclasses.dataclass
class StudyConfig:
    """Everything the server needs.

    design: the study design; stimuli: its videos; store: the database; consent_html: the
    consent page body; admin_token: the admin secret; ui_dir: the ``ui/`` folder (with
    ``node_modules`` installed); completion_code / redirect_url: shown on the debrief page
    (completion_code overrides the online config's ``codes.completed``); online: the
    data-quality controls (:mod:`crowdstudy.study.quality`); media_dir: where to publish the
    videos under their opaque names (None: served from the stimulus folder by this server);
    media_url: the URL prefix the browser loads videos from (default ``/media``).
    """
    design: StudyDesign
    stimuli: StimulusSet
    store: StudyStore
    consent_html: str
    admin_token: str
    ui_dir: Path
    completion_code: str | None = None
    redirect_url: str | None = None
    online: OnlineConfig = dataclasses.field(default_factory=OnlineConfig)
    media_dir: Path | None = None
    media_url: str | None = None


def create_app(config: StudyConfig):
    """The ASGI application of one study."""
    try:
        from starlette.applications import Starlette
        from starlette.concurrency import run_in_threadpool
        from starlette.middleware import Middleware
        from starlette.requests import Request
        from starlette.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
        from starlette.routing import Mount, Route
        from starlette.staticfiles import StaticFiles
    except ModuleNotFoundError as exc:  # pragma: no cover
        raise MissingDependencyError(f"the study server needs the 'web' extra: pip install 'crowdstudy[web]' "
                                     f"({exc.name} missing)") from None
    from crowdstudy.study import admin as admin_auth
    from crowdstudy.study.dashboard import dashboard_html
    from crowdstudy.study.export import DEMOGRAPHIC_COLUMNS, RESPONSE_EXPORT_COLUMNS, participants_rows, rows_to_csv
    from crowdstudy.study.media import blind_file_response, publish_media
    from crowdstudy.study.quality import PARTICIPANT_COLUMNS
    from crowdstudy.study.roster import list_participants, withdraw_participant
    from crowdstudy.study.session import StudySession
    from crowdstudy.study.webio import AnswerTimer, ApiError, SecurityHeaders, read_json_body

    ui = Path(config.ui_dir).resolve()
    modules = ui / "node_modules"
    needed = [ui / "index.html", ui / "js", ui / "css", modules / "jspsych" / "dist"] + \
        [modules / "@jspsych" / p / "dist" for p in UI_PLUGINS]
    absent = [str(p) for p in needed if not p.exists()]
    if absent:
        raise MissingDependencyError(f"the questionnaire front end is incomplete ({absent[0]} missing); run "
                                     f"`make setup` or `cd {ui} && npm ci`")
    study = StudySession(config)
    if config.media_dir is not None:  # published copies: /media serves them too (same sizes as the CDN's)
        folder = publish_media(study.media, config.media_dir)
        study.media_files = {name: folder / name for name in study.media_files}
    media_origin = ""
    if config.media_url and urlsplit(config.media_url).scheme:
        u = urlsplit(config.media_url)
        media_origin = f"{u.scheme}://{u.netloc}"
    no_store = {"Cache-Control": "no-store"}

    def error(status: int, message: str) -> JSONResponse:
        return JSONResponse({"error": message}, status_code=status, headers=no_store)

    def endpoint(handler, *, auth: bool = True, body: bool = False):
        """Wrap a blocking handler(pid, row, body?) -> (status, payload) | payload."""
        async def run(request: Request):
            try:
                args: list[Any] = []
                if body:
                    args.append(await read_json_body(request))
                pid = request.path_params["pid"]
                secret = request.headers.get("x-participant-secret")

                def call():  # one trip to the thread pool: authenticate (a database read), then the handler
                    row = study.authenticate(pid, secret)
                    return handler(pid, row, *args)
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
            data = await read_json_body(request)
            status, payload = await run_in_threadpool(study.register, data, request.headers.get("user-agent"))
        except ApiError as exc:
            return error(exc.status, exc.message)
        return JSONResponse(payload, status_code=status, headers=no_store)

    async def study_info(_request: Request):
        return JSONResponse(study.study_info, headers=no_store)

    async def index(_request: Request):
        return FileResponse(ui / "index.html", media_type="text/html", headers=no_store)

    async def media(request: Request):
        # a dictionary lookup of the opaque name, never a path join with a request value
        path = study.media_files.get(request.path_params["name"])
        if path is None:
            return error(404, "no such video")
        return blind_file_response(path, {"Cache-Control": "public, max-age=3600"})

    async def health(_request: Request):
        return JSONResponse({"ok": True})

    def admin(handler, *, page: bool = False):
        async def run(request: Request):
            try:
                admin_auth.check_admin(request, config.admin_token)
            except ApiError as exc:
                if page and exc.status in (401, 403):
                    return HTMLResponse(admin_auth.login_page(config.design.name), status_code=exc.status,
                                        headers=no_store)
                return error(exc.status, exc.message)
            try:
                return await run_in_threadpool(handler, request)
            except ApiError as exc:
                return error(exc.status, exc.message)
            except InvalidInputError as exc:
                return error(422, str(exc))
        return run

    async def admin_login(request: Request):
        try:
            token = await admin_auth.read_login_form(request)
        except ApiError as exc:
            return error(exc.status, exc.message)
        import hmac
        if not hmac.compare_digest(token.encode(), config.admin_token.encode()):
            return HTMLResponse(admin_auth.login_page(config.design.name, "Wrong admin token."), status_code=403,
                                headers=no_store)
        resp = RedirectResponse("/admin", status_code=303, headers=no_store)
        resp.headers["set-cookie"] = admin_auth.cookie_header(request, config.admin_token)
        return resp

    async def admin_logout(request: Request):
        resp = RedirectResponse("/admin", status_code=303, headers=no_store)
        resp.headers["set-cookie"] = admin_auth.cookie_header(request, None)
        return resp

    def csv_response(text: str, name: str) -> Response:
        return Response(text, media_type="text/csv",
                        headers={**no_store, "Content-Disposition": f'attachment; filename="{name}"'})

    def json_ok(payload) -> JSONResponse:
        return JSONResponse(payload, headers=no_store)

    timer_box: dict = {}

    def timer_factory(inner):
        timer_box["timer"] = AnswerTimer(inner)
        return timer_box["timer"]

    def admin_metrics(_request):
        timer = timer_box.get("timer")
        return json_ok({"server_answer_latency": timer.summary() if timer else {"answers_timed": 0}})

    def admin_withdraw(request):
        pid = study.check_pid(request.path_params["pid"])
        if study.store.participant(pid) is None:
            raise ApiError(404, f"unknown participant {pid!r}")
        line = withdraw_participant(study.store, pid, by="admin", completion_code=config.online.code("withdrawn"))
        study._schedules.pop(pid, None)
        return json_ok(line)

    def export_participants(_request):
        return csv_response(rows_to_csv(participants_rows(study.store, config.online, study.item_ids),
                                        PARTICIPANT_COLUMNS), "participants.csv")

    lib_mounts = [Mount("/lib/jspsych/dist", StaticFiles(directory=modules / "jspsych" / "dist")),
                  Mount("/lib/jspsych/css", StaticFiles(directory=modules / "jspsych" / "css"))]
    lib_mounts += [Mount(f"/lib/{p}", StaticFiles(directory=modules / "@jspsych" / p / "dist")) for p in UI_PLUGINS]
    api = "/api/participants/{pid}"
    routes = [
        Route("/", index),
        Route("/healthz", health),
        Route("/api/study", study_info),
        Route("/api/participants", register, methods=["POST"]),
        Route(api, endpoint(study.state_of), methods=["GET"]),
        Route(api + "/screen-out", endpoint(study.screen_out, body=True), methods=["POST"]),
        Route(api + "/consent", endpoint(study.consent, body=True), methods=["POST"]),
        Route(api + "/demographics", endpoint(study.demographics, body=True), methods=["POST"]),
        Route(api + "/practice", endpoint(study.practice, body=True), methods=["POST"]),
        Route(api + "/responses", endpoint(study.answer, body=True), methods=["POST"]),
        Route(api + "/responses", endpoint(study.own_responses), methods=["GET"]),
        Route(api + "/complete", endpoint(study.complete), methods=["POST"]),
        Route(api + "/withdraw", endpoint(study.withdraw, body=True), methods=["POST"]),
        Route("/media/{name}", media),
        Route("/admin", admin(lambda r: HTMLResponse(dashboard_html(study.store.progress(), config.design.name),
                                                      headers=no_store), page=True)),
        Route("/admin/login", admin_login, methods=["POST"]),
        Route("/admin/logout", admin_logout, methods=["POST"]),
        Route("/admin/progress.json", admin(lambda r: json_ok({"participants": study.store.progress(),
                                                              "n_trials": study.n_trials}))),
        Route("/admin/participants.json", admin(lambda r: json_ok({"participants": list_participants(study.store)}))),
        Route("/admin/metrics.json", admin(admin_metrics)),
        Route("/admin/study.json", admin(lambda r: json_ok(study.scoring()))),
        Route("/admin/participants/{pid}/resume-link",
              admin(lambda r: json_ok(study.resume_link(r.path_params["pid"]))), methods=["POST"]),
        Route("/admin/participants/{pid}/withdraw", admin(admin_withdraw), methods=["POST"]),
        Route("/admin/participants/{pid}/schedule",
              admin(lambda r: json_ok(study.admin_schedule(r.path_params["pid"])))),
        Route("/admin/export/responses.csv", admin(lambda r: csv_response(
            rows_to_csv(study.store.response_rows(), RESPONSE_EXPORT_COLUMNS), "responses.csv"))),
        Route("/admin/export/demographics.csv", admin(lambda r: csv_response(
            rows_to_csv(study.store.demographics_rows(), DEMOGRAPHIC_COLUMNS), "demographics.csv"))),
        Route("/admin/export/participants.csv", admin(export_participants)),
        Mount("/js", StaticFiles(directory=ui / "js")),
        Mount("/css", StaticFiles(directory=ui / "css")),
        *lib_mounts,
    ]
    app = Starlette(routes=routes, middleware=[Middleware(SecurityHeaders, media_origin=media_origin),
                                               Middleware(timer_factory)])
    app.state.study = study
    app.state.config = config
    return app

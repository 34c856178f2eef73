"""The admin's routes: the dashboard, progress, exports, and the actions on a participant.

Authentication (:mod:`crowdstudy.study.admin`): ``Authorization: Bearer <token>``, or for GET
the cookie of a login on ``/admin``; an action that changes data needs the header.

``GET /admin``
    the login form, then the progress dashboard
``POST /admin/login``, ``POST /admin/logout``
    the login form's target (sets the cookie), and its removal
``GET /admin/progress.json``, ``/admin/participants.json``
    every participant's progress; the roster with status and exclusion flags
``GET /admin/metrics.json``
    this process's answer latency percentiles
``GET /admin/study.json``
    the scoring metadata (reversed items, composites, methods, each stage's task and pairs)
``GET /admin/export/responses.csv``, ``/admin/export/comparisons.csv`` (2afc trials),
``/admin/export/demographics.csv``, ``/admin/export/participants.csv``
    the analysis input
``GET /admin/participants/<id>/schedule``
    the participant's trials with token, stimulus id and conditions
``POST /admin/participants/<id>/resume-link``
    a new secret and the URL that continues the session in another browser
``POST /admin/participants/<id>/withdraw``
    answers and demographics deleted, an audit line kept

Every handler checks the admin first (:func:`admin_session`), then does its blocking work
(the database) in the thread pool.
"""

from __future__ import annotations

import hmac
from typing import TYPE_CHECKING

from crowdstudy.study import admin as admin_auth
from crowdstudy.study.bodies import parse_participant_id
from crowdstudy.study.dashboard import dashboard_html
from crowdstudy.study.export import (
    COMPARISON_EXPORT_COLUMNS,
    DEMOGRAPHIC_COLUMNS,
    participants_rows,
    response_export_columns,
    rows_to_csv,
    split_rows,
)
from crowdstudy.study.quality import PARTICIPANT_COLUMNS
from crowdstudy.study.roster import list_participants, withdraw_participant
from crowdstudy.study.session import StudySession
from crowdstudy.study.webio import NO_STORE, ApiError, RouteSpec, csv_response, html_response, in_thread, json_response

if TYPE_CHECKING:
    from starlette.requests import Request
    from starlette.responses import Response

__all__ = [
    "ROUTES",
    "admin_session",
    "dashboard",
    "login",
    "logout",
    "progress",
    "participants",
    "metrics",
    "scoring",
    "export_responses",
    "export_comparisons",
    "export_demographics",
    "export_participants",
    "schedule",
    "resume_link",
    "withdraw",
]


def admin_session(request: Request) -> StudySession:
    """The study session, once ``request`` is the admin's (ApiError 400/401/403 otherwise)."""
    admin_auth.check_admin(request, request.app.state.config.admin_token)
    return request.app.state.study


def _title(request: Request) -> str:
    return request.app.state.config.design.name


# -- the browser's pages --------------------------------------------------------------------
def _dashboard_page(study: StudySession, title: str) -> str:
    return dashboard_html(study.store.progress(), title)


async def dashboard(request: Request) -> Response:
    """The dashboard, or the login form (401/403) to a browser that is not logged in."""
    try:
        study = admin_session(request)
    except ApiError as exc:
        if exc.status in (401, 403):
            return html_response(admin_auth.login_page(_title(request)), exc.status)
        raise
    return html_response(await in_thread(_dashboard_page, study, _title(request)))


async def login(request: Request) -> Response:
    """The login form's POST: the cookie and a redirect to the dashboard, or the form again."""
    from starlette.responses import RedirectResponse

    token = await admin_auth.read_login_form(request)
    admin_token = request.app.state.config.admin_token
    if not hmac.compare_digest(token.encode(), admin_token.encode()):
        return html_response(admin_auth.login_page(_title(request), "Wrong admin token."), 403)
    resp = RedirectResponse("/admin", status_code=303, headers=NO_STORE)
    resp.headers["set-cookie"] = admin_auth.cookie_header(request, admin_token)
    return resp


async def logout(request: Request) -> Response:
    """The cookie removed, and a redirect to the login form."""
    from starlette.responses import RedirectResponse

    resp = RedirectResponse("/admin", status_code=303, headers=NO_STORE)
    resp.headers["set-cookie"] = admin_auth.cookie_header(request, None)
    return resp


# -- JSON and CSV -----------------------------------------------------------------------------
def _progress(study: StudySession) -> dict:
    return {"participants": study.store.progress(), "n_trials": study.n_trials}


async def progress(request: Request) -> Response:
    return json_response(await in_thread(_progress, admin_session(request)))


def _participants(study: StudySession) -> dict:
    return {"participants": list_participants(study.store)}


async def participants(request: Request) -> Response:
    return json_response(await in_thread(_participants, admin_session(request)))


async def metrics(request: Request) -> Response:
    admin_session(request)
    summary = await in_thread(request.app.state.answer_latency.summary)
    return json_response({"server_answer_latency": summary})


async def scoring(request: Request) -> Response:
    return json_response(await in_thread(admin_session(request).scoring))


def _responses_csv(study: StudySession) -> str:
    return rows_to_csv(split_rows(study.store.response_rows())[0], response_export_columns(study.item_ids))


def _comparisons_csv(study: StudySession) -> str:
    return rows_to_csv(split_rows(study.store.response_rows())[1], COMPARISON_EXPORT_COLUMNS)


def _demographics_csv(study: StudySession) -> str:
    return rows_to_csv(study.store.demographics_rows(), DEMOGRAPHIC_COLUMNS)


def _participants_csv(study: StudySession) -> str:
    return rows_to_csv(participants_rows(study.store, study.online, study.item_ids), PARTICIPANT_COLUMNS)


async def export_responses(request: Request) -> Response:
    return csv_response(await in_thread(_responses_csv, admin_session(request)), "responses.csv")


async def export_comparisons(request: Request) -> Response:
    return csv_response(await in_thread(_comparisons_csv, admin_session(request)), "comparisons.csv")


async def export_demographics(request: Request) -> Response:
    return csv_response(await in_thread(_demographics_csv, admin_session(request)), "demographics.csv")


async def export_participants(request: Request) -> Response:
    return csv_response(await in_thread(_participants_csv, admin_session(request)), "participants.csv")


# -- one participant ------------------------------------------------------------------------
async def schedule(request: Request) -> Response:
    study = admin_session(request)
    return json_response(await in_thread(study.admin_schedule, request.path_params["pid"]))


async def resume_link(request: Request) -> Response:
    study = admin_session(request)
    return json_response(await in_thread(study.resume_link, request.path_params["pid"]))


def _withdraw(study: StudySession, pid: str) -> dict:
    pid = parse_participant_id(pid)
    if study.store.participant(pid) is None:
        raise ApiError(404, f"unknown participant {pid!r}")
    line = withdraw_participant(study.store, pid, by="admin", completion_code=study.online.code("withdrawn"))
    study.forget_schedule(pid)
    return line


async def withdraw(request: Request) -> Response:
    study = admin_session(request)
    return json_response(await in_thread(_withdraw, study, request.path_params["pid"]))


_ONE = "/admin/participants/{pid}"

#: The admin's routes (module docstring).
ROUTES: tuple[RouteSpec, ...] = (
    RouteSpec("/admin", dashboard),
    RouteSpec("/admin/login", login, ("POST",)),
    RouteSpec("/admin/logout", logout, ("POST",)),
    RouteSpec("/admin/progress.json", progress),
    RouteSpec("/admin/participants.json", participants),
    RouteSpec("/admin/metrics.json", metrics),
    RouteSpec("/admin/study.json", scoring),
    RouteSpec(_ONE + "/resume-link", resume_link, ("POST",)),
    RouteSpec(_ONE + "/withdraw", withdraw, ("POST",)),
    RouteSpec(_ONE + "/schedule", schedule),
    RouteSpec("/admin/export/responses.csv", export_responses),
    RouteSpec("/admin/export/comparisons.csv", export_comparisons),
    RouteSpec("/admin/export/demographics.csv", export_demographics),
    RouteSpec("/admin/export/participants.csv", export_participants),
)

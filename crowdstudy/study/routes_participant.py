"""The participants' JSON API: what the questionnaire page (``ui/js/study.js``) calls.

No authentication to read the study or to register; afterwards every request carries the
header ``X-Participant-Secret`` (the secret returned at registration), and every POST body
is a JSON object sent as ``application/json`` (:func:`crowdstudy.study.webio.read_json_body`).

``GET  /api/study``
    items (text only), scale labels, consent HTML, stage sizes, screen rules
``POST /api/participants``
    ``{"participant_id", "platform"?}``: register (201), or resume with ``"secret"`` (200)
``GET  /api/participants/<id>``
    state: trials ``{trial_index, stage, token, video_url, check?}``, next unanswered trial, status
``POST /api/participants/<id>/screen-out``
    ``{"width", "height"}``: failed the screen check
``POST /api/participants/<id>/consent``
    ``{"consent": true}``
``POST /api/participants/<id>/demographics``
    ``{"age": 31, "gender": "female"}``
``POST /api/participants/<id>/practice``
    ``{"answers": {...}, "rt_ms": ...}``
``POST /api/participants/<id>/responses``
    ``{"trial_index", "token", "answers", "rt_ms", "shown_at", "video_plays", "first_play_ms",
    "hidden_count", "hidden_ms", "fullscreen_exits", "check"?}``
``GET  /api/participants/<id>/responses``
    the participant's own answers (by token)
``POST /api/participants/<id>/complete``
    completion code / redirect URL
``POST /api/participants/<id>/withdraw``
    ``{"confirm": true}``: answers and demographics deleted

Each handler is a few lines: :func:`participant_call` reads the body, authenticates the
participant (a database read) and runs one :class:`~crowdstudy.study.session.StudySession`
method in the thread pool; the method checks the body (:mod:`crowdstudy.study.bodies`) and
commits to the database before the response is sent. A new trial type adds its answer route
to :data:`ROUTES` (under "trials") and its method to the session.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from crowdstudy.study.session import StudySession
from crowdstudy.study.webio import RouteSpec, in_thread, json_response, read_json_body

if TYPE_CHECKING:
    from starlette.requests import Request
    from starlette.responses import Response

__all__ = [
    "ROUTES",
    "participant_call",
    "study_info",
    "register",
    "participant_state",
    "screen_out",
    "consent",
    "demographics",
    "practice",
    "answer",
    "own_responses",
    "complete",
    "withdraw",
]

#: A session method behind a participant's route: (session, pid, row[, body]) -> payload or (status, payload).
SessionMethod = Callable[..., Any]


def _authenticated_call(study: StudySession, method: SessionMethod, pid: str, secret: str | None, args: list) -> Any:
    # one trip to the thread pool: authenticate (a database read), then the method
    row = study.authenticate(pid, secret)
    return method(study, pid, row, *args)


async def participant_call(request: Request, method: SessionMethod, *, body: bool = False) -> Response:
    """Answer ``request`` with ``method(session, pid, row[, body])`` for the participant of
    the URL, authenticated by ``X-Participant-Secret``. A method returns its JSON payload
    (200) or ``(status, payload)``; it raises ApiError for a refusal."""
    args = [await read_json_body(request)] if body else []
    study: StudySession = request.app.state.study
    result = await in_thread(
        _authenticated_call,
        study,
        method,
        request.path_params["pid"],
        request.headers.get("x-participant-secret"),
        args,
    )
    status, payload = result if isinstance(result, tuple) else (200, result)
    return json_response(payload, status)


async def study_info(request: Request) -> Response:
    """The study as the page shows it (no scoring metadata, no stimulus ids)."""
    return json_response(request.app.state.study.study_info)


async def register(request: Request) -> Response:
    """A new participant, or a resumed session (no secret header: the body carries it)."""
    data = await read_json_body(request)
    status, payload = await in_thread(request.app.state.study.register, data, request.headers.get("user-agent"))
    return json_response(payload, status)


async def participant_state(request: Request) -> Response:
    return await participant_call(request, StudySession.state_of)


async def screen_out(request: Request) -> Response:
    return await participant_call(request, StudySession.screen_out, body=True)


async def consent(request: Request) -> Response:
    return await participant_call(request, StudySession.consent, body=True)


async def demographics(request: Request) -> Response:
    return await participant_call(request, StudySession.demographics, body=True)


async def practice(request: Request) -> Response:
    return await participant_call(request, StudySession.practice, body=True)


async def answer(request: Request) -> Response:
    return await participant_call(request, StudySession.answer, body=True)


async def own_responses(request: Request) -> Response:
    return await participant_call(request, StudySession.own_responses)


async def complete(request: Request) -> Response:
    return await participant_call(request, StudySession.complete)


async def withdraw(request: Request) -> Response:
    return await participant_call(request, StudySession.withdraw, body=True)


_ONE = "/api/participants/{pid}"

#: The participants' routes (module docstring), in the order of a session.
ROUTES: tuple[RouteSpec, ...] = (
    RouteSpec("/api/study", study_info),
    RouteSpec("/api/participants", register, ("POST",)),
    RouteSpec(_ONE, participant_state),
    RouteSpec(_ONE + "/screen-out", screen_out, ("POST",)),
    RouteSpec(_ONE + "/consent", consent, ("POST",)),
    RouteSpec(_ONE + "/demographics", demographics, ("POST",)),
    # trials: the practice trial, then one answer per scheduled trial
    RouteSpec(_ONE + "/practice", practice, ("POST",)),
    RouteSpec(_ONE + "/responses", answer, ("POST",)),
    RouteSpec(_ONE + "/responses", own_responses),
    RouteSpec(_ONE + "/complete", complete, ("POST",)),
    RouteSpec(_ONE + "/withdraw", withdraw, ("POST",)),
)

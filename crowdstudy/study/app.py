"""The study server: a Starlette ASGI application (:func:`create_app`) of one :class:`StudyConfig`.

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
Three route tables, by audience: the participants' JSON API
(:mod:`crowdstudy.study.routes_participant`, ``/api/...``), the files their browser loads
(:mod:`crowdstudy.study.routes_static`: ``/``, ``/js``, ``/css``, ``/lib``, ``/media``) and
the admin's dashboard, exports and actions (:mod:`crowdstudy.study.routes_admin`,
``/admin...``). Each module's docstring lists its routes. The handlers are module-level
functions that find everything in ``request.app.state``:

* ``study``: the :class:`~crowdstudy.study.session.StudySession` (the API's logic);
* ``config``: the :class:`StudyConfig`;
* ``ui_dir``: the front end's folder, resolved;
* ``answer_latency``: the :class:`~crowdstudy.study.webio.LatencyLog` of this process.

Errors are JSON ``{"error": message}`` with a 4xx status: 400 malformed request, 401/403
missing or wrong secret/token (the same for an unknown participant), 404 unknown video, 409 a
conflicting or out-of-order answer, 410 withdrawn, 413 body too large, 415 not JSON, 422 a
value out of range. A handler raises :class:`~crowdstudy.study.webio.ApiError` (or
:class:`~crowdstudy.errors.InvalidInputError`, a 422) and the application's exception
handlers write that JSON. Every answer is committed to the database before the response is
sent.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from urllib.parse import urlsplit

from crowdstudy.design import StudyDesign
from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.study.quality import OnlineConfig
from crowdstudy.study.stimulus_set import StimulusSet
from crowdstudy.study.storage import StudyStore

__all__ = ["StudyConfig", "create_app"]


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


def _origin(url: str | None) -> str:
    """``scheme://host[:port]`` of an absolute media URL (the CSP must allow it), else ""."""
    parts = urlsplit(url) if url else None
    return f"{parts.scheme}://{parts.netloc}" if parts and parts.scheme else ""


async def _api_error(_request, exc):
    from crowdstudy.study.webio import error_response

    return error_response(exc.status, exc.message)


async def _invalid_input(_request, exc):
    from crowdstudy.study.webio import error_response

    return error_response(422, str(exc))


def create_app(config: StudyConfig):
    """The ASGI application of one study: the three route tables and the front end's
    folders, the security headers and the answer timer, the session in ``app.state``."""
    try:
        from starlette.applications import Starlette
        from starlette.middleware import Middleware
        from starlette.routing import Route
    except ModuleNotFoundError as exc:  # pragma: no cover
        raise MissingDependencyError(
            f"the study server needs the 'web' extra: pip install 'crowdstudy[web]' ({exc.name} missing)"
        ) from None
    from crowdstudy.study import routes_admin, routes_participant, routes_static
    from crowdstudy.study.media import publish_media
    from crowdstudy.study.session import StudySession
    from crowdstudy.study.webio import AnswerTimer, ApiError, LatencyLog, SecurityHeaders

    ui = routes_static.check_ui(config.ui_dir)
    study = StudySession(config)
    if config.media_dir is not None:  # published copies: /media serves them too (same sizes as the CDN's)
        folder = publish_media(study.media, config.media_dir)
        study.media_files = {name: folder / name for name in study.media_files}
    specs = (*routes_participant.ROUTES, *routes_static.ROUTES, *routes_admin.ROUTES)
    routes = [Route(spec.path, spec.handler, methods=list(spec.methods)) for spec in specs]
    latency = LatencyLog()
    app = Starlette(
        routes=[*routes, *routes_static.ui_mounts(ui)],
        middleware=[
            Middleware(SecurityHeaders, media_origin=_origin(config.media_url)),
            Middleware(AnswerTimer, log=latency),
        ],
        exception_handlers={ApiError: _api_error, InvalidInputError: _invalid_input},
    )
    app.state.study = study
    app.state.config = config
    app.state.ui_dir = ui
    app.state.answer_latency = latency
    return app

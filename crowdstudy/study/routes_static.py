"""The files a participant's browser loads: the page, its scripts and styles, jsPsych, videos.

``GET /``
    the jsPsych page (``ui/index.html``)
``GET /js/*``, ``/css/*``
    the page's own scripts and styles (``ui/js``, ``ui/css``)
``GET /lib/<package>/*``
    jsPsych and its plugins' ``dist`` files from ``ui/node_modules``
``GET /media/<name>.mp4``
    a video under its opaque name (HTTP range requests; no Last-Modified or ETag:
    :mod:`crowdstudy.study.media`)
``GET /healthz``
    ``{"ok": true}`` (for a load balancer)

The front end's folder (``app.state.ui_dir``) is checked once, when the application is built
(:func:`check_ui`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from crowdstudy.errors import MissingDependencyError
from crowdstudy.study.media import blind_file_response
from crowdstudy.study.webio import NO_STORE, RouteSpec, error_response

if TYPE_CHECKING:
    from starlette.requests import Request
    from starlette.responses import Response
    from starlette.routing import Mount

__all__ = ["ROUTES", "UI_PLUGINS", "check_ui", "ui_mounts", "index", "media", "health"]

#: npm packages of ui/node_modules served under /lib/<name>/ (their dist folder).
UI_PLUGINS = (
    "plugin-call-function",
    "plugin-html-button-response",
    "plugin-instructions",
    "plugin-survey-html-form",
    "plugin-survey-text",
)
#: Videos may be cached by the browser for an hour (their names change with the deployment).
_MEDIA_HEADERS = {"Cache-Control": "public, max-age=3600"}


def check_ui(ui_dir: str | Path) -> Path:
    """The front end's folder, resolved; MissingDependencyError naming the first missing
    file when the page, its scripts or the npm packages (``make setup``) are not there."""
    ui = Path(ui_dir).resolve()
    modules = ui / "node_modules"
    needed = [ui / "index.html", ui / "js", ui / "css", modules / "jspsych" / "dist"] + [
        modules / "@jspsych" / p / "dist" for p in UI_PLUGINS
    ]
    absent = [str(p) for p in needed if not p.exists()]
    if absent:
        raise MissingDependencyError(
            f"the questionnaire front end is incomplete ({absent[0]} missing); run `make setup` or `cd {ui} && npm ci`"
        )
    return ui


def ui_mounts(ui: Path) -> list[Mount]:
    """The static folders of the front end ``ui`` (checked by :func:`check_ui`)."""
    from starlette.routing import Mount
    from starlette.staticfiles import StaticFiles

    modules = ui / "node_modules"
    folders = {
        "/js": ui / "js",
        "/css": ui / "css",
        "/lib/jspsych/dist": modules / "jspsych" / "dist",
        "/lib/jspsych/css": modules / "jspsych" / "css",
        **{f"/lib/{p}": modules / "@jspsych" / p / "dist" for p in UI_PLUGINS},
    }
    return [Mount(prefix, StaticFiles(directory=folder)) for prefix, folder in folders.items()]


async def index(request: Request) -> Response:
    """The questionnaire page."""
    from starlette.responses import FileResponse

    return FileResponse(request.app.state.ui_dir / "index.html", media_type="text/html", headers=NO_STORE)


async def media(request: Request) -> Response:
    """A video by its opaque name: a dictionary lookup, never a path join with a request value."""
    path = request.app.state.study.media_files.get(request.path_params["name"])
    if path is None:
        return error_response(404, "no such video")
    return blind_file_response(path, _MEDIA_HEADERS)


async def health(_request: Request) -> Response:
    """Liveness: the process answers (no database access)."""
    from starlette.responses import JSONResponse

    return JSONResponse({"ok": True})


#: The routes of this module (the static folders are :func:`ui_mounts`).
ROUTES: tuple[RouteSpec, ...] = (
    RouteSpec("/", index),
    RouteSpec("/healthz", health),
    RouteSpec("/media/{name}", media),
)

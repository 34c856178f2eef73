"""HTTP plumbing of the study server: routes, request bodies, responses, security headers,
answer timing.

* :class:`RouteSpec`: one row of a route table (path, handler, methods); the tables live in
  :mod:`crowdstudy.study.routes_participant`, :mod:`~crowdstudy.study.routes_static` and
  :mod:`~crowdstudy.study.routes_admin`, and :func:`crowdstudy.study.app.create_app` turns
  them into Starlette routes.
* :class:`ApiError`: a refused request; the application's exception handler answers it
  with :func:`error_response` (JSON ``{"error": message}``, the status, ``no-store``).
* :func:`in_thread`: a handler's blocking work (database, files) off the event loop.

* :func:`read_json_body`: the only way a handler gets a body. It insists on
  ``Content-Type: application/json`` (415 otherwise: an HTML form on another site cannot
  send that type without a CORS preflight, which this server never grants), reads the body
  as a stream and stops at :data:`MAX_BODY_BYTES` whether or not a ``Content-Length`` was
  sent (chunked uploads included), and refuses JSON nested deeper than :data:`MAX_JSON_DEPTH`
  before parsing it (no recursion error, no traceback).
* :class:`SecurityHeaders`: Content-Security-Policy (own origin only, plus the media origin;
  no inline scripts; no framing), X-Frame-Options DENY, X-Content-Type-Options nosniff,
  Referrer-Policy no-referrer, Cross-Origin-Opener-Policy same-origin, Permissions-Policy.
* :class:`AnswerTimer`: in-server latency of each answer POST, kept in a
  :class:`LatencyLog` (``/admin/metrics.json``).

Starlette is imported inside the functions (it is the ``web`` extra's).
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable
from typing import Any, NamedTuple, TypeVar

__all__ = [
    "ApiError",
    "RouteSpec",
    "NO_STORE",
    "read_json_body",
    "in_thread",
    "json_response",
    "error_response",
    "html_response",
    "csv_response",
    "SecurityHeaders",
    "LatencyLog",
    "AnswerTimer",
    "MAX_BODY_BYTES",
    "MAX_JSON_DEPTH",
    "content_security_policy",
]

MAX_BODY_BYTES = 16 * 1024
MAX_JSON_DEPTH = 8
#: The headers of every answer that must not be cached (JSON, pages, exports).
NO_STORE = {"Cache-Control": "no-store"}

_T = TypeVar("_T")


class ApiError(Exception):
    """A request refused with HTTP ``status`` and a one-line ``message``."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


class RouteSpec(NamedTuple):
    """One route: ``path`` (Starlette syntax, ``{pid}`` a path parameter), the async
    ``handler(request)`` and its HTTP ``methods`` (GET also answers HEAD)."""

    path: str
    handler: Callable[..., Any]
    methods: tuple[str, ...] = ("GET",)


def _json_depth(raw: bytes) -> int:
    """Deepest nesting of [ and { in ``raw`` (outside strings), stopping early past the limit."""
    depth = best = 0
    in_str = esc = False
    for b in raw:
        if in_str:
            if esc:
                esc = False
            elif b == 0x5C:  # backslash
                esc = True
            elif b == 0x22:
                in_str = False
        elif b == 0x22:
            in_str = True
        elif b in (0x5B, 0x7B):
            depth += 1
            if depth > best:
                best = depth
                if best > MAX_JSON_DEPTH:
                    return best
        elif b in (0x5D, 0x7D):
            depth -= 1
    return best


async def read_json_body(request) -> dict:
    """The request's JSON object body (see the module docstring); raises ApiError 400/413/415."""
    import json

    ctype = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if ctype != "application/json":
        raise ApiError(415, "the body must be JSON, sent with Content-Type: application/json")
    length = request.headers.get("content-length")
    if length is not None and (not length.isdigit() or int(length) > MAX_BODY_BYTES):
        raise ApiError(413, f"request body larger than {MAX_BODY_BYTES} bytes")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY_BYTES:
            raise ApiError(413, f"request body larger than {MAX_BODY_BYTES} bytes")
        chunks.append(chunk)
    raw = b"".join(chunks)
    if _json_depth(raw) > MAX_JSON_DEPTH:
        raise ApiError(400, f"request body is nested deeper than {MAX_JSON_DEPTH} levels")
    try:
        data = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError):
        raise ApiError(400, "request body is not valid JSON") from None
    if not isinstance(data, dict):
        raise ApiError(400, "request body must be a JSON object")
    return data


async def in_thread(fn: Callable[..., _T], *args: Any) -> _T:
    """``fn(*args)`` run in the server's thread pool (blocking work: the database, files)."""
    from starlette.concurrency import run_in_threadpool

    return await run_in_threadpool(fn, *args)


def json_response(payload: Any, status: int = 200):
    """A JSON answer that is never cached."""
    from starlette.responses import JSONResponse

    return JSONResponse(payload, status_code=status, headers=NO_STORE)


def error_response(status: int, message: str):
    """The JSON error ``{"error": message}`` with HTTP ``status``."""
    return json_response({"error": message}, status)


def html_response(text: str, status: int = 200):
    """An HTML page that is never cached."""
    from starlette.responses import HTMLResponse

    return HTMLResponse(text, status_code=status, headers=NO_STORE)


def csv_response(text: str, name: str):
    """A CSV download named ``name``, never cached."""
    from starlette.responses import Response

    return Response(
        text, media_type="text/csv", headers={**NO_STORE, "Content-Disposition": f'attachment; filename="{name}"'}
    )


def content_security_policy(media_origin: str = "") -> str:
    """The page's CSP: scripts, styles, fetches and media from this origin (and ``media_origin``,
    e.g. ``https://cdn.example.org``, where the videos live), media also from ``blob:`` (the
    preloaded copies); no plugins, no framing, no foreign form targets."""
    extra = f" {media_origin}" if media_origin else ""
    return (
        "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
        "img-src 'self' data:; font-src 'self' data:; "
        f"media-src 'self' blob:{extra}; connect-src 'self'{extra}; object-src 'none'; base-uri 'none'; "
        "form-action 'self'; frame-ancestors 'none'"
    )


class SecurityHeaders:
    """ASGI middleware adding the security headers (module docstring) to every response."""

    def __init__(self, app, media_origin: str = ""):
        self.app = app
        self.extra = (
            (b"content-security-policy", content_security_policy(media_origin).encode()),
            (b"x-frame-options", b"DENY"),
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"no-referrer"),
            (b"cross-origin-opener-policy", b"same-origin"),
            (b"permissions-policy", b"camera=(), microphone=(), geolocation=(), fullscreen=(self)"),
        )

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                present = {k.lower() for k, _ in headers}
                headers += [h for h in self.extra if h[0] not in present]
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


class LatencyLog:
    """The last ``maxlen`` answer latencies of this process, milliseconds, and their summary."""

    def __init__(self, maxlen: int = 200_000):
        self.values: collections.deque[float] = collections.deque(maxlen=maxlen)

    def add(self, ms: float) -> None:
        self.values.append(ms)

    def summary(self) -> dict:
        """``answers_timed`` and the p50/p95/p99/max latencies (ms) of the values kept."""
        vals = sorted(self.values)
        if not vals:
            return {"answers_timed": 0}

        def pct(q):
            return round(vals[min(len(vals) - 1, int(math.ceil(q / 100.0 * len(vals))) - 1)], 3)

        return {
            "answers_timed": len(vals),
            "latency_ms_p50": pct(50),
            "latency_ms_p95": pct(95),
            "latency_ms_p99": pct(99),
            "latency_ms_max": round(vals[-1], 3),
        }


class AnswerTimer:
    """ASGI middleware timing every answer POST inside the server (first byte of the request
    handled to the last byte of the response handed to the server), milliseconds, into
    ``log`` (the application keeps it in ``app.state.answer_latency`` for
    ``/admin/metrics.json``)."""

    def __init__(self, app, log: LatencyLog):
        self.app = app
        self.log = log

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "POST" or not scope["path"].endswith("/responses"):
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()

        async def timed_send(message):
            await send(message)
            if message["type"] == "http.response.body" and not message.get("more_body", False):
                self.log.add((time.perf_counter() - t0) * 1000.0)

        await self.app(scope, receive, timed_send)

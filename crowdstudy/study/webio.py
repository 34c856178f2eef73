"""HTTP plumbing of the study server: request bodies, security headers, answer timing.

* :func:`read_json_body`: the only way a handler gets a body. It insists on
  ``Content-Type: application/json`` (415 otherwise: an HTML form on another site cannot
  send that type without a CORS preflight, which this server never grants), reads the body
  as a stream and stops at :data:`MAX_BODY_BYTES` whether or not a ``Content-Length`` was
  sent (chunked uploads included), and refuses JSON nested deeper than :data:`MAX_JSON_DEPTH`
  before parsing it (no recursion error, no traceback).
* :class:`SecurityHeaders`: Content-Security-Policy (own origin only, plus the media origin;
  no inline scripts; no framing), X-Frame-Options DENY, X-Content-Type-Options nosniff,
  Referrer-Policy no-referrer, Cross-Origin-Opener-Policy same-origin, Permissions-Policy.
* :class:`AnswerTimer`: in-server latency of each answer POST (``/admin/metrics.json``).
"""

from __future__ import annotations

import collections
import math
import time

__all__ = ["ApiError", "read_json_body", "SecurityHeaders", "AnswerTimer", "MAX_BODY_BYTES", "MAX_JSON_DEPTH",
           "content_security_policy"]

MAX_BODY_BYTES = 16 * 1024
MAX_JSON_DEPTH = 8


class ApiError(Exception):
    """A request refused with HTTP ``status`` and a one-line ``message``."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


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


def content_security_policy(media_origin: str = "") -> str:
    """The page's CSP: scripts, styles, fetches and media from this origin (and ``media_origin``,
    e.g. ``https://cdn.example.org``, where the videos live), media also from ``blob:`` (the
    preloaded copies); no plugins, no framing, no foreign form targets."""
    extra = f" {media_origin}" if media_origin else ""
    return ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; font-src 'self' data:; "
            f"media-src 'self' blob:{extra}; connect-src 'self'{extra}; object-src 'none'; base-uri 'none'; "
            "form-action 'self'; frame-ancestors 'none'")


class SecurityHeaders:
    """ASGI middleware adding the security headers (module docstring) to every response."""

    def __init__(self, app, media_origin: str = ""):
        self.app = app
        self.extra = ((b"content-security-policy", content_security_policy(media_origin).encode()),
                      (b"x-frame-options", b"DENY"), (b"x-content-type-options", b"nosniff"),
                      (b"referrer-policy", b"no-referrer"), (b"cross-origin-opener-policy", b"same-origin"),
                      (b"permissions-policy", b"camera=(), microphone=(), geolocation=(), fullscreen=(self)"))

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


class AnswerTimer:
    """ASGI middleware timing every answer POST inside the server (first byte of the request
    handled to the last byte of the response handed to the server), milliseconds; keeps the
    last ``maxlen`` values of this process for ``/admin/metrics.json``."""

    def __init__(self, app, maxlen: int = 200_000):
        self.app = app
        self.values: "collections.deque[float]" = collections.deque(maxlen=maxlen)

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "POST" or not scope["path"].endswith("/responses"):
            await self.app(scope, receive, send)
            return
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

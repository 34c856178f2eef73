"""Admin authentication of the study server: a header or a cookie, never the URL.

Scripts send ``Authorization: Bearer <token>``. A browser logs in once on ``/admin`` (a form
POSTed to ``/admin/login``) and then carries the cookie :data:`COOKIE`: an HMAC of the admin
token (so every server process recognises it without shared state, and changing the token
ends every session), ``HttpOnly``, ``SameSite=Strict``, ``Path=/admin``, ``Secure`` behind
HTTPS. The cookie opens only GET pages and exports; an action that changes data (a resume
link, a withdrawal) needs the header, so a cross-site request cannot trigger one. A token in
the query string is refused: URLs end up in logs and browser history.
"""

from __future__ import annotations

import hashlib
import hmac
import html
from urllib.parse import parse_qs

from crowdstudy.study.webio import ApiError

__all__ = [
    "COOKIE",
    "session_value",
    "admin_authorized",
    "check_admin",
    "login_page",
    "read_login_form",
    "cookie_header",
]

COOKIE = "crowdstudy_admin"
_SESSION_S = 12 * 3600


def session_value(admin_token: str) -> str:
    """The cookie value of an admin browser session (hex HMAC-SHA256 of the token)."""
    return hmac.new(admin_token.encode("utf-8"), b"crowdstudy-admin-session", hashlib.sha256).hexdigest()


def admin_authorized(request, admin_token: str) -> bool:
    """Whether ``request`` carries the admin token (Bearer header) or, for GET/HEAD, the cookie."""
    auth = request.headers.get("authorization", "")
    if auth.lower().startswith("bearer "):
        return hmac.compare_digest(auth[7:].strip().encode(), admin_token.encode())
    cookie = request.cookies.get(COOKIE, "")
    if cookie and request.method in ("GET", "HEAD"):
        return hmac.compare_digest(cookie.encode(), session_value(admin_token).encode())
    return False


def check_admin(request, admin_token: str) -> None:
    """Raise ApiError 401 (nothing sent) / 403 (wrong) unless the request is the admin's."""
    if "token" in request.query_params:
        raise ApiError(
            400, "the admin token is never accepted in the URL; send Authorization: Bearer <token> or log in on /admin"
        )
    has_header = request.headers.get("authorization", "").lower().startswith("bearer ")
    has_cookie = bool(request.cookies.get(COOKIE)) and request.method in ("GET", "HEAD")
    if not has_header and not has_cookie:
        raise ApiError(401, "admin authentication required (Authorization: Bearer <token>, or log in on /admin)")
    if not admin_authorized(request, admin_token):
        raise ApiError(403, "wrong admin token")


def cookie_header(request, admin_token: str | None) -> str:
    """The Set-Cookie value logging in (token given) or out (None)."""
    secure = request.url.scheme == "https" or request.headers.get("x-forwarded-proto", "") == "https"
    value, age = (session_value(admin_token), _SESSION_S) if admin_token else ("", 0)
    return f"{COOKIE}={value}; Max-Age={age}; Path=/admin; HttpOnly; SameSite=Strict" + ("; Secure" if secure else "")


async def read_login_form(request) -> str:
    """The ``token`` field of the login form (urlencoded, <= 2 kB)."""
    ctype = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if ctype != "application/x-www-form-urlencoded":
        raise ApiError(415, "log in with the form on /admin")
    raw, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > 2048:
            raise ApiError(413, "login form larger than 2048 bytes")
        raw.append(chunk)
    fields = parse_qs(b"".join(raw).decode("utf-8", "replace"), max_num_fields=4)
    return (fields.get("token") or [""])[0]


def login_page(title: str, message: str = "") -> str:
    """The admin login form (no script: it works under the page's CSP)."""
    note = f'<p style="color:#a33">{html.escape(message)}</p>' if message else ""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>crowdstudy admin</title>
<style>body{{font-family:sans-serif;margin:2em}}</style></head>
<body><h1>{html.escape(title)}</h1>{note}
<form method="post" action="/admin/login"><label>Admin token <input type="password" name="token"
autocomplete="current-password" required></label> <button type="submit">Log in</button></form></body></html>
"""

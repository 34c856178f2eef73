"""``crowdstudy serve``: run the browser questionnaire for participant sessions.

``--workers N`` runs N server processes on one port (uvicorn's process manager); they share
the database and keep no state of their own that could go stale
(:mod:`crowdstudy.study.session`), so they may also run on several machines behind one
proxy when the database is PostgreSQL.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

__all__ = ["configure", "run", "app_from_environment"]

_ENV = "CROWDSTUDY_SERVE_CONFIG"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--stimuli",
        required=True,
        metavar="DIR",
        help="stimulus folder with manifest.json (written by `crowdstudy stimuli`)",
    )
    parser.add_argument(
        "--design", metavar="TOML", help="study design (default: the manifest's, else stimuli/study.toml)"
    )
    parser.add_argument(
        "--db",
        metavar="URL",
        default="sqlite:///study.db",
        help="SQLAlchemy database URL (default: sqlite:///study.db, SQLite in WAL mode; "
        "postgresql+psycopg://USER@HOST/DB for several processes or machines)",
    )
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    parser.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    parser.add_argument("--workers", type=int, default=1, help="server processes on this port (default 1)")
    parser.add_argument(
        "--consent", metavar="FILE", help="consent text (Markdown; default consent.md beside the design)"
    )
    parser.add_argument("--practice", metavar="FILE", help="practice clip, relative to --stimuli")
    parser.add_argument(
        "--online",
        metavar="TOML",
        help="data-quality controls and completion codes (default: the design's [online] table, "
        "online.toml beside it, else the toolkit's)",
    )
    parser.add_argument("--completion-code", metavar="CODE", help="code shown on the debrief page (e.g. Prolific's)")
    parser.add_argument("--redirect-url", metavar="URL", help="where the debrief page sends the participant")
    parser.add_argument(
        "--media-dir", metavar="DIR", help="publish the videos here under opaque names, for nginx or a CDN to serve"
    )
    parser.add_argument(
        "--media-url",
        metavar="URL",
        help="URL prefix the browser loads the videos from (default /media, served by this server)",
    )
    parser.add_argument(
        "--admin-token",
        metavar="TOKEN",
        help="admin token (default: $CROWDSTUDY_ADMIN_TOKEN, else a random one printed at start-up)",
    )
    parser.add_argument("--log-level", default="warning", choices=("critical", "error", "warning", "info", "debug"))


_CONFIG_KEYS = (
    "stimuli",
    "design",
    "db",
    "consent",
    "practice",
    "admin_token",
    "completion_code",
    "redirect_url",
    "online",
    "media_dir",
    "media_url",
)


def _build(values: dict):
    from crowdstudy.study.server import build_config

    return build_config(values["stimuli"], **{k: values[k] for k in _CONFIG_KEYS if k != "stimuli"})


def app_from_environment():
    """The ASGI app of one worker process, configured from ``$CROWDSTUDY_SERVE_CONFIG`` (JSON
    written by :func:`run` for ``--workers`` > 1)."""
    from crowdstudy.study.app import create_app

    return create_app(_build(json.loads(os.environ[_ENV])))


def run(args: argparse.Namespace) -> int:
    from crowdstudy.errors import InvalidInputError, MissingDependencyError
    from crowdstudy.study.app import create_app
    from crowdstudy.study.server import ADMIN_TOKEN_ENV

    if not 0 < args.port < 65536:
        raise InvalidInputError(f"--port must be 1..65535, got {args.port}")
    if not 1 <= args.workers <= 64:
        raise InvalidInputError(f"--workers must be 1..64, got {args.workers}")
    try:
        import uvicorn
    except ModuleNotFoundError:  # pragma: no cover
        raise MissingDependencyError("crowdstudy serve needs uvicorn: pip install 'crowdstudy[web]'") from None
    values = {k: getattr(args, k) for k in _CONFIG_KEYS}
    config = _build(values)  # validates everything (and creates the tables) before any worker starts
    base = f"http://{args.host if args.host not in ('0.0.0.0', '::') else '127.0.0.1'}:{args.port}"
    n = len(config.stimuli.rows)
    print(
        f"crowdstudy serve: {config.design.name} ({n} videos, database {config.store.url}, "
        f"{args.workers} process{'es' if args.workers > 1 else ''})",
        flush=True,
    )
    if config.stimuli.practice_note:
        print(f"crowdstudy serve: warning: {config.stimuli.practice_note}", flush=True)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(
            f"crowdstudy serve: warning: listening on {args.host}: reachable from other machines; put it behind "
            "an HTTPS reverse proxy for online studies",
            flush=True,
        )
    print(
        f"Participant URL: {base}/?PROLIFIC_PID=<ID>&STUDY_ID=<ID>&SESSION_ID=<ID>   (or ?participant=<ID>; "
        "without one the page asks)",
        flush=True,
    )
    print(f"Admin token: {config.admin_token}", flush=True)
    print(f"Admin dashboard: {base}/admin (log in with the admin token)", flush=True)
    print(
        f"Export: `crowdstudy export --db {config.store.url} --out responses.csv` or "
        f"{base}/admin/export/responses.csv (Authorization: Bearer <token>)",
        flush=True,
    )
    try:
        if args.workers == 1:
            uvicorn.run(create_app(config), host=args.host, port=args.port, log_level=args.log_level, access_log=False)
        else:
            config.store.close()
            values["admin_token"] = config.admin_token
            os.environ[_ENV] = json.dumps(values)
            os.environ.setdefault(ADMIN_TOKEN_ENV, config.admin_token)
            uvicorn.run(
                "crowdstudy.study.cli_serve:app_from_environment",
                factory=True,
                host=args.host,
                port=args.port,
                workers=args.workers,
                log_level=args.log_level,
                access_log=False,
            )
    finally:
        config.store.close()
    return 0


if __name__ == "__main__":  # pragma: no cover
    from crowdstudy.cli import main

    sys.exit(main(["serve", *sys.argv[1:]]))

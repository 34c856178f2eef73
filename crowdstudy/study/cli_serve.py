"""``crowdstudy serve``: run the browser questionnaire for participant sessions."""

from __future__ import annotations

import argparse
import sys

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--stimuli", required=True, metavar="DIR",
                        help="stimulus folder with manifest.json (written by `crowdstudy stimuli`)")
    parser.add_argument("--design", metavar="TOML", help="study design (default: the manifest's, else stimuli/study.toml)")
    parser.add_argument("--db", metavar="URL", default="sqlite:///study.db",
                        help="SQLAlchemy database URL (default: sqlite:///study.db, SQLite in WAL mode)")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    parser.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    parser.add_argument("--consent", metavar="FILE", help="consent text (Markdown; default consent.md beside the design)")
    parser.add_argument("--practice", metavar="FILE", help="practice clip, relative to --stimuli")
    parser.add_argument("--completion-code", metavar="CODE", help="code shown on the debrief page (e.g. Prolific's)")
    parser.add_argument("--redirect-url", metavar="URL", help="where the debrief page sends the participant")
    parser.add_argument("--admin-token", metavar="TOKEN",
                        help="admin token (default: $CROWDSTUDY_ADMIN_TOKEN, else a random one printed at start-up)")
    parser.add_argument("--log-level", default="warning", choices=("critical", "error", "warning", "info", "debug"))


def run(args: argparse.Namespace) -> int:
    from crowdstudy.errors import InvalidInputError, MissingDependencyError
    from crowdstudy.study.app import create_app
    from crowdstudy.study.server import build_config

    if not 0 < args.port < 65536:
        raise InvalidInputError(f"--port must be 1..65535, got {args.port}")
    try:
        import uvicorn
    except ModuleNotFoundError:  # pragma: no cover
        raise MissingDependencyError("crowdstudy serve needs uvicorn: pip install 'crowdstudy[web]'") from None
    config = build_config(args.stimuli, design=args.design, db=args.db, consent=args.consent, practice=args.practice,
                          admin_token=args.admin_token, completion_code=args.completion_code,
                          redirect_url=args.redirect_url)
    app = create_app(config)
    base = f"http://{args.host if args.host not in ('0.0.0.0', '::') else '127.0.0.1'}:{args.port}"
    n = len(config.stimuli.rows)
    print(f"crowdstudy serve: {config.design.name} ({n} videos, database {config.store.url})", flush=True)
    if config.stimuli.practice_note:
        print(f"crowdstudy serve: warning: {config.stimuli.practice_note}", flush=True)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"crowdstudy serve: warning: listening on {args.host}: reachable from other machines; put it behind "
              "an HTTPS reverse proxy for online studies", flush=True)
    print(f"Participant URL: {base}/?participant=<ID>   (or ?PROLIFIC_PID=<ID>; without one the page asks)",
          flush=True)
    print(f"Admin token: {config.admin_token}", flush=True)
    print(f"Admin dashboard: {base}/admin?token={config.admin_token}", flush=True)
    print(f"Export: {base}/admin/export/responses.csv (Authorization: Bearer <token>) or "
          f"`crowdstudy export --db {config.store.url} --out responses.csv`", flush=True)
    try:
        uvicorn.run(app, host=args.host, port=args.port, log_level=args.log_level, access_log=False)
    finally:
        config.store.close()
    return 0


if __name__ == "__main__":  # pragma: no cover
    from crowdstudy.cli import main
    sys.exit(main(["serve", *sys.argv[1:]]))

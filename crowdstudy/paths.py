"""Where crowdstudy keeps files it makes for itself: one per-user cache folder.

Caches (converted body models, Warp kernels, downloaded assets) never go into the installed
package or the source tree. The folder is, in order of precedence:

1. ``$CROWDSTUDY_CACHE`` when set (tests and CI point it at a temporary or build folder);
2. ``$XDG_CACHE_HOME/crowdstudy`` when ``XDG_CACHE_HOME`` is set;
3. ``~/.cache/crowdstudy``.

Each kind of cached data lives in its own sub-folder, created on first use.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_root", "cache_dir"]


def cache_root() -> Path:
    """The per-user cache folder (not created)."""
    env = os.environ.get("CROWDSTUDY_CACHE")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "crowdstudy"


def cache_dir(kind: str) -> Path:
    """The cache sub-folder for one kind of data (``"body-cache"``, ``"warp-cache"``, ...),
    created if missing. ``kind`` must be a plain folder name."""
    if not kind or "/" in kind or "\\" in kind or kind in (".", ".."):
        raise ValueError(f"cache kind must be a plain folder name, got {kind!r}")
    path = cache_root() / kind
    path.mkdir(parents=True, exist_ok=True)
    return path

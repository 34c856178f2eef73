"""Where crowdstudy keeps files it makes for itself: one per-user cache folder.

Caches (converted body models, Warp kernels, downloaded assets) never go into the installed
package or the source tree. The folder is, in order of precedence:

1. ``$CROWDSTUDY_CACHE`` when set (tests and CI point it at a temporary or build folder);
2. ``$XDG_CACHE_HOME/crowdstudy`` when ``XDG_CACHE_HOME`` is set;
3. ``~/.cache/crowdstudy``.

Each kind of cached data lives in its own sub-folder, created on first use.

:func:`check_output_path` checks, before a long run, that an output file can be written
(:func:`check_output_dir` the same for an output folder);
:func:`timings_path` names the JSON sidecar that holds a run's timings (run-dependent values
never go into the output file itself: same input, same bytes).
"""

from __future__ import annotations

import os
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["cache_root", "cache_dir", "check_output_path", "check_output_dir", "timings_path"]


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


def _writable_folder(folder: Path, what: str) -> None:
    """Create ``folder`` (and its parents) and check it is writable; errors name ``what``."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidInputError(
            f"{what}: cannot create the output folder {str(folder)!r} ({exc.strerror}); choose a writable location"
        ) from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InvalidInputError(
            f"{what}: the output folder {str(folder)!r} is not writable; fix its permissions or choose another location"
        )


def check_output_path(path: str | Path, what: str = "out") -> Path:
    """Create the parent folder of the output file ``path`` and check it is writable (and
    that ``path`` is not a folder); return ``path``. Errors name ``what`` (the argument)
    and the path, so a long run can fail at once instead of at the end."""
    path = Path(path)
    _writable_folder(path.parent, what)
    if path.exists() and path.is_dir():
        raise InvalidInputError(f"{what}: {str(path)!r} is a folder, expected a file path")
    return path


def check_output_dir(path: str | Path, what: str = "out") -> Path:
    """Create the output folder ``path`` (and its parents) and check it is a writable folder
    (not a file); return ``path``. Errors name ``what`` (the argument) and the path."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"{what}: {str(path)!r} is a file, expected a folder")
    _writable_folder(path, what)
    return path


def timings_path(output: str | Path) -> Path:
    """The timings sidecar of an output file: ``NAME.timings.json`` beside ``NAME.npz``
    (the suffix replaced, like the stimulus set's ``NAME.metrics.json``)."""
    output = Path(output)
    return (
        output.with_name(output.stem + ".timings.json")
        if output.suffix
        else output.with_name(output.name + ".timings.json")
    )

"""Progress bars on a terminal only.

A tqdm bar redraws itself with carriage returns: on a terminal that is one line that moves,
in a log file (``make demo > log 2>&1``, a pipe, a batch job) it is hundreds of kilobytes of
``\\r`` lines. :func:`progress_bar` therefore draws only where the bar's stream is a terminal,
unless the environment variable :data:`PROGRESS_ENV` forces it: ``1`` draws always, ``0``
never (``crowdstudy --progress`` / ``--no-progress`` set it). Being an environment variable,
the choice reaches every process a command starts (worker processes, the demo's
subcommands). Every progress bar of the toolkit goes through this module.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import IO, TYPE_CHECKING, Any, Literal

from crowdstudy.errors import InvalidInputError

if TYPE_CHECKING:
    from tqdm import tqdm

__all__ = ["PROGRESS_ENV", "ProgressMode", "progress_mode", "set_progress_mode", "progress_enabled", "progress_bar"]

#: the environment variable that forces the bars on (``1``) or off (``0``); unset or empty:
#: bars on a terminal only
PROGRESS_ENV = "CROWDSTUDY_PROGRESS"

#: ``"auto"``: a bar where its stream is a terminal; ``"on"``/``"off"``: always/never
ProgressMode = Literal["auto", "on", "off"]

_VALUES: dict[str, ProgressMode] = {"": "auto", "1": "on", "0": "off"}


def progress_mode() -> ProgressMode:
    """The mode :data:`PROGRESS_ENV` sets (``"auto"`` when it is unset or empty)."""
    value = os.environ.get(PROGRESS_ENV, "").strip()
    if value not in _VALUES:
        raise InvalidInputError(
            f"environment variable {PROGRESS_ENV}: expected 1 (bars on), 0 (bars off) or "
            f"unset (bars on a terminal only), got {value!r}"
        )
    return _VALUES[value]


def set_progress_mode(mode: ProgressMode) -> None:
    """Set :data:`PROGRESS_ENV` for this process and the processes it starts."""
    if mode == "auto":
        os.environ.pop(PROGRESS_ENV, None)
    elif mode in ("on", "off"):
        os.environ[PROGRESS_ENV] = "1" if mode == "on" else "0"
    else:
        raise InvalidInputError(f"mode: expected 'auto', 'on' or 'off', got {mode!r}")


def progress_enabled(stream: IO[str] | None = None) -> bool:
    """Whether a bar on ``stream`` (default ``sys.stderr``) is drawn: forced by
    :data:`PROGRESS_ENV`, else where the stream is a terminal."""
    mode = progress_mode()
    if mode != "auto":
        return mode == "on"
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream is not None and stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def progress_bar(iterable: Iterable[Any] | None = None, *, enabled: bool = True, **kwargs: Any) -> tqdm:
    """A tqdm bar (``kwargs``: tqdm's ``total``, ``desc``, ``unit``, ``leave``, ``file`` ...)
    that draws when ``enabled`` and :func:`progress_enabled` for its stream, and is otherwise
    a silent tqdm (``disable=True``: iterating, ``update``, ``close`` and ``write`` still
    work, nothing is drawn)."""
    from tqdm import tqdm

    if "disable" in kwargs:
        raise TypeError("progress_bar() takes enabled=, not tqdm's disable=")
    show = enabled and progress_enabled(kwargs.get("file"))
    return tqdm(iterable, disable=not show, **kwargs)

"""The clips shipped with the toolkit: motion capture (the default) and procedural motion.

* ``source="mocap"`` (default): the CMU takes of :mod:`crowdstudy.motion.mocap_library`,
  cleaned and stored in the package: 11 dances (10 in the default concert), 3 idles and 6
  walking loops from 0.4 to 1.9 m/s;
* ``source="procedural"``: 15 dances and 4 walks generated on first use by
  :mod:`crowdstudy.motion.dance` and :mod:`crowdstudy.motion.walk` (no data files).

Clip names are unique across both; :func:`load_clip` finds either (cached for the life of
the process).
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import TYPE_CHECKING

from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.mocap_library import load_mocap, mocap_names

if TYPE_CHECKING:  # the procedural generators load with the first clip they make
    from crowdstudy.motion.dance import DanceSpec
    from crowdstudy.motion.walk import WalkSpec

__all__ = ["SOURCES", "library_digest", "list_clips", "load_clip", "walk_clips"]

_KINDS = ("dance", "idle", "walk")
#: Where clips come from: motion capture (default) or generated.
SOURCES = ("mocap", "procedural")


def _specs() -> dict[str, tuple[str, DanceSpec | WalkSpec]]:
    from crowdstudy.motion.dance import DANCES
    from crowdstudy.motion.walk import WALKS

    out: dict[str, tuple[str, DanceSpec | WalkSpec]] = {d.name: ("dance", d) for d in DANCES}
    out.update({w.name: ("walk", w) for w in WALKS})
    return out


def _check_source(source: str) -> None:
    if source not in SOURCES:
        raise InvalidInputError(f"source: expected one of {SOURCES}, got {source!r}")


def list_clips(kind: str | None = None, source: str = "mocap", *, default_only: bool = False) -> list[str]:
    """Names of the shipped clips of ``kind`` ("dance", "idle", "walk" or None for all) from
    ``source``; ``default_only`` keeps the motion-captured takes of the default crowds
    (e.g. the concert's 10 dances). Procedural: 15 dances and 4 walks (slowest first)."""
    if kind is not None and kind not in _KINDS:
        raise InvalidInputError(f"kind: expected one of {_KINDS} or None, got {kind!r}")
    _check_source(source)
    if source == "mocap":
        return mocap_names(kind, default_only=default_only)
    return [name for name, (k, _) in _specs().items() if kind is None or k == kind]


@functools.cache
def load_clip(name: str) -> MotionClip:
    """The shipped clip called ``name`` (see :func:`list_clips`, either source)."""
    specs = _specs()
    if name in specs:
        from crowdstudy.motion.dance import DanceSpec, generate_dance
        from crowdstudy.motion.walk import generate_walk

        spec = specs[name][1]  # a dance's spec is a DanceSpec, a walk's a WalkSpec
        return generate_dance(spec) if isinstance(spec, DanceSpec) else generate_walk(spec)
    if name in mocap_names():
        return load_mocap(name)
    raise InvalidInputError(
        f"clip name: unknown clip {name!r}; expected one of {', '.join(mocap_names() + list(specs))}"
    )


def walk_clips(source: str = "mocap") -> list[MotionClip]:
    """The walking clips of ``source``, slowest first (6 motion-captured loops or 4 procedural)."""
    _check_source(source)
    clips = [load_clip(n) for n in list_clips("walk", source)]
    return sorted(clips, key=lambda c: c.walk_speed)


@functools.lru_cache(maxsize=1)
def library_digest() -> str:
    """SHA-256 (hex) of everything that determines the shipped clips: the source of the
    motion package and its data files. A stimulus manifest stores it, so any change of the
    motion re-renders the videos made with it."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file() and p.suffix in (".py", ".npz", ".json")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()

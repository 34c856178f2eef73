"""The clips shipped with the toolkit: 15 dances and 4 walks, generated on first use.

The clips are produced deterministically by :mod:`crowdstudy.motion.dance` and
:mod:`crowdstudy.motion.walk` (no data files, nothing downloaded) and cached for the
life of the process.
"""

from __future__ import annotations

import functools

from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip

__all__ = ["list_clips", "load_clip", "walk_clips"]

_KINDS = ("dance", "walk")


def _specs() -> dict[str, tuple[str, object]]:
    from crowdstudy.motion.dance import DANCES
    from crowdstudy.motion.walk import WALKS

    out: dict[str, tuple[str, object]] = {d.name: ("dance", d) for d in DANCES}
    out.update({w.name: ("walk", w) for w in WALKS})
    return out


def list_clips(kind: str | None = None) -> list[str]:
    """Names of the shipped clips: ``kind`` "dance" (15), "walk" (4, slowest first) or None (all)."""
    if kind is not None and kind not in _KINDS:
        raise InvalidInputError(f"kind: expected one of {_KINDS} or None, got {kind!r}")
    return [name for name, (k, _) in _specs().items() if kind is None or k == kind]


@functools.lru_cache(maxsize=None)
def load_clip(name: str) -> MotionClip:
    """The shipped clip called ``name`` (see :func:`list_clips`)."""
    specs = _specs()
    if name not in specs:
        raise InvalidInputError(f"clip name: unknown clip {name!r}; expected one of {', '.join(specs)}")
    kind, spec = specs[name]
    if kind == "dance":
        from crowdstudy.motion.dance import generate_dance

        return generate_dance(spec)
    from crowdstudy.motion.walk import generate_walk

    return generate_walk(spec)


def walk_clips() -> list[MotionClip]:
    """The 4 walking clips, slowest first."""
    clips = [load_clip(n) for n in list_clips("walk")]
    return sorted(clips, key=lambda c: c.speed)

"""Per-participant trial order: each stage shuffled on its own, stages in design order.

The order is a pure function of (seed, participant id, stimulus ids and, on the server, the
study's secret key), so the same participant always gets the same schedule; the server also
stores it at registration, so a later change of the stimulus set never reorders a running
session. The design seed and the code are public, so the server passes ``secret`` (the
random key kept in its database, :meth:`crowdstudy.study.storage.StudyStore.blinding_secret`):
the stage shuffles are then keyed with HMAC-SHA256 and a participant holding the source
cannot recompute their own order (and so the condition of each trial).

>>> s = make_schedule({1: ["a", "b", "c"], 2: ["d", "e"]}, "P01", seed=7)
>>> [t.stage for t in s], sorted(t.stimulus_id for t in s[:3])
([1, 1, 1, 2, 2], ['a', 'b', 'c'])
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import random
import re
from collections.abc import Mapping, Sequence

from crowdstudy.errors import InvalidInputError

__all__ = [
    "ScheduledTrial",
    "make_schedule",
    "PARTICIPANT_ID_PATTERN",
    "STIMULUS_ID_PATTERN",
    "check_participant_id",
    "check_stimulus_id",
]

#: Participant ids: letters, digits, ``_`` and ``-``, 1..64 characters, starting with a letter
#: or digit (Prolific, MTurk and SONA ids all fit). Never used in a path or in SQL text.
PARTICIPANT_ID_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
#: Stimulus ids (``S1-D3-V2-Ours``): letters, digits, ``_ . -``, 1..64 characters.
STIMULUS_ID_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


@dataclasses.dataclass(frozen=True)
class ScheduledTrial:
    """One trial of a participant: ``trial_index`` counts from 0 over the whole session
    (practice excluded)."""

    trial_index: int
    stage: int
    stimulus_id: str


def check_participant_id(value, name: str = "participant_id") -> str:
    """Return ``value`` if it is a valid participant id, else raise InvalidInputError."""
    if not isinstance(value, str) or not PARTICIPANT_ID_PATTERN.fullmatch(value):
        raise InvalidInputError(
            f"{name} must be 1-64 characters of letters, digits, '_' or '-' "
            f"starting with a letter or digit, got {value!r:.80}"
        )
    return value


def check_stimulus_id(value, name: str = "stimulus_id") -> str:
    """Return ``value`` if it is a valid stimulus id, else raise InvalidInputError."""
    if not isinstance(value, str) or not STIMULUS_ID_PATTERN.fullmatch(value):
        raise InvalidInputError(
            f"{name} must be 1-64 characters of letters, digits, '_', '.' or '-', got {value!r:.80}"
        )
    return value


def _stage_rng(seed: int, participant_id: str, stage: int, key: bytes | None) -> random.Random:
    msg = f"crowdstudy-schedule\x00{int(seed)}\x00{participant_id}\x00{int(stage)}".encode()
    digest = hashlib.sha256(msg).digest() if key is None else hmac.new(key, msg, hashlib.sha256).digest()
    return random.Random(int.from_bytes(digest[:16], "big"))


def make_schedule(
    stimuli_by_stage: Mapping[int, Sequence[str]], participant_id: str, seed: int, *, secret: str | bytes | None = None
) -> list[ScheduledTrial]:
    """The participant's trials: stage by stage (ascending stage number), each stage's
    stimulus ids in a random order drawn from ``seed``, ``participant_id`` and ``secret``.

    stimuli_by_stage: {stage number: stimulus ids}; the order given does not matter (ids are
        sorted before shuffling, so the result depends only on the set).
    secret: the study's secret key (>= 16 characters; what the server always passes), or
        None for an order anyone can recompute from the seed (simulations, examples).
    """
    check_participant_id(participant_id)
    if not isinstance(seed, int) or isinstance(seed, bool):
        raise InvalidInputError(f"seed must be an integer, got {seed!r}")
    key = None
    if secret is not None:
        key = secret.encode("utf-8") if isinstance(secret, str) else secret
        if not isinstance(key, bytes) or len(key) < 16:
            raise InvalidInputError("secret must be a str or bytes of at least 16 characters (the study's key)")
    out: list[ScheduledTrial] = []
    seen: set[str] = set()
    for stage in sorted(stimuli_by_stage):
        ids = sorted(stimuli_by_stage[stage])
        for sid in ids:
            check_stimulus_id(sid)
            if sid in seen:
                raise InvalidInputError(f"stimuli_by_stage lists stimulus {sid!r} twice")
            seen.add(sid)
        _stage_rng(seed, participant_id, stage, key).shuffle(ids)
        base = len(out)
        out.extend([ScheduledTrial(base + k, int(stage), sid) for k, sid in enumerate(ids)])
    return out

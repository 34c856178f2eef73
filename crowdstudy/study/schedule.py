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

A ``2afc`` stage's trials are pairs of videos of one cell (``comparisons``: per stage, per
method pair, one (video of the pair's first method, video of its second) per cell). Every
pair is shown once per cell; the sides are counterbalanced WITHIN each participant: for each
method pair, the participant's cells are shuffled and the first half shows the pair's first
method on the left, the rest on the right (with an odd number of cells the extra one falls
to either side at random, so across participants each side is as likely). Sides and order are
drawn from the same keyed generator as a Likert stage's order.

>>> c = make_schedule({}, "P01", seed=7, comparisons={1: {"A-B": [("a1", "b1"), ("a2", "b2")]}})
>>> sorted((t.stimulus_id[0], t.stimulus_right[0]) for t in c)
[('a', 'b'), ('b', 'a')]
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
    #: a 2afc trial's right video (``stimulus_id`` is then its left one); None otherwise
    stimulus_right: str | None = None

    @property
    def key(self) -> str:
        """What names the trial in its participant's schedule: the stimulus id, or for a
        2afc trial ``LEFT~RIGHT`` (a stimulus may appear in several comparisons)."""
        return self.stimulus_id if self.stimulus_right is None else f"{self.stimulus_id}~{self.stimulus_right}"


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


def _check_key(secret: str | bytes | None) -> bytes | None:
    if secret is None:
        return None
    key = secret.encode("utf-8") if isinstance(secret, str) else secret
    if not isinstance(key, bytes) or len(key) < 16:
        raise InvalidInputError("secret must be a str or bytes of at least 16 characters (the study's key)")
    return key


def _pair_trials(pairs: Mapping[str, Sequence[tuple[str, str]]], rng: random.Random) -> list[tuple[str, str]]:
    """(left, right) of every comparison of one stage, sides counterbalanced per method pair
    across its cells (see the module docstring), in a shuffled order."""
    out: list[tuple[str, str]] = []
    for name in sorted(pairs):
        cells = sorted(tuple(c) for c in pairs[name])
        rng.shuffle(cells)
        n_first = len(cells) // 2 + (rng.random() < 0.5 if len(cells) % 2 else 0)
        out.extend([(a, b) if k < n_first else (b, a) for k, (a, b) in enumerate(cells)])
    out.sort()
    rng.shuffle(out)
    return out


def make_schedule(
    stimuli_by_stage: Mapping[int, Sequence[str]],
    participant_id: str,
    seed: int,
    *,
    secret: str | bytes | None = None,
    comparisons: Mapping[int, Mapping[str, Sequence[tuple[str, str]]]] | None = None,
) -> list[ScheduledTrial]:
    """The participant's trials: stage by stage (ascending stage number), each stage's
    stimulus ids in a random order drawn from ``seed``, ``participant_id`` and ``secret``.

    stimuli_by_stage: {stage number: stimulus ids} of the Likert and slider stages; the order
        given does not matter (ids are sorted before shuffling, so the result depends only
        on the set).
    secret: the study's secret key (>= 16 characters; what the server always passes), or
        None for an order anyone can recompute from the seed (simulations, examples).
    comparisons: {stage number: {method pair name: [(video of the pair's first method,
        video of its second), one per cell]}} of the 2afc stages (a stage is in one of the
        two mappings); each becomes one trial with its sides counterbalanced.
    """
    check_participant_id(participant_id)
    if not isinstance(seed, int) or isinstance(seed, bool):
        raise InvalidInputError(f"seed must be an integer, got {seed!r}")
    key = _check_key(secret)
    comparisons = comparisons or {}
    both = sorted(set(stimuli_by_stage) & set(comparisons))
    if both:
        raise InvalidInputError(f"stage {both[0]} is listed both with stimuli and with comparisons")
    out: list[ScheduledTrial] = []
    seen: set[str] = set()
    for stage in sorted({*stimuli_by_stage, *comparisons}):
        rng = _stage_rng(seed, participant_id, stage, key)
        if stage in comparisons:
            units = _pair_trials(comparisons[stage], rng)
            trials = [ScheduledTrial(len(out) + k, int(stage), a, b) for k, (a, b) in enumerate(units)]
        else:
            ids = sorted(stimuli_by_stage[stage])
            rng.shuffle(ids)
            trials = [ScheduledTrial(len(out) + k, int(stage), sid) for k, sid in enumerate(ids)]
        for t in trials:
            for sid in (t.stimulus_id, t.stimulus_right):
                if sid is not None:
                    check_stimulus_id(sid)
            if t.key in seen:
                raise InvalidInputError(f"the schedule lists trial {t.key!r} twice")
            seen.add(t.key)
        out.extend(trials)
    return out

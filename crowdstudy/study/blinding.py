"""Blinding: participants see opaque per-participant tokens, never stimulus ids.

A stimulus id such as ``S1-D3-V2-Ours`` spells out the condition (density, viewpoint and
method), so nothing the participant's browser receives may contain it. Each trial is
instead named by a token: the HMAC-SHA256 of (study secret, participant id, stimulus id),
truncated to :data:`TOKEN_LENGTH` lowercase hex digits. The study secret is random and kept
in the database (:meth:`crowdstudy.study.storage.StudyStore.blinding_secret`), so tokens
stay the same across server restarts and across server processes sharing one database,
differ between participants for the same stimulus, and cannot be computed or inverted
without the secret. The server maps a token back to the stimulus id through the
participant's stored schedule; only the admin API reveals that mapping.

>>> a = stimulus_token("0" * 64, "P01", "S1-D3-V2-Ours")
>>> len(a), a == stimulus_token("0" * 64, "P02", "S1-D3-V2-Ours")
(20, False)
"""

from __future__ import annotations

import hashlib
import hmac
import re
from collections.abc import Iterable

from crowdstudy.errors import InvalidInputError

__all__ = ["TOKEN_LENGTH", "TOKEN_PATTERN", "stimulus_token", "token_table"]

#: Hex digits of a trial token (80 bits: collisions within a schedule are out of reach).
TOKEN_LENGTH = 20
#: A well-formed trial token: exactly TOKEN_LENGTH lowercase hex digits.
TOKEN_PATTERN = re.compile(rf"[0-9a-f]{{{TOKEN_LENGTH}}}")


def _key(secret: str | bytes) -> bytes:
    key = secret.encode("utf-8") if isinstance(secret, str) else secret
    if not isinstance(key, bytes) or len(key) < 16:
        raise InvalidInputError("secret must be a str or bytes of at least 16 characters (the study's blinding secret)")
    return key


def stimulus_token(secret: str | bytes, participant_id: str, stimulus_id: str) -> str:
    """The opaque token that names ``stimulus_id`` to participant ``participant_id``.

    secret: the study's blinding secret (>= 16 characters); returns TOKEN_LENGTH lowercase
    hex digits.
    """
    if not isinstance(participant_id, str) or not isinstance(stimulus_id, str):
        raise InvalidInputError("participant_id and stimulus_id must be strings")
    msg = f"crowdstudy-trial-token\x00{participant_id}\x00{stimulus_id}".encode()
    return hmac.new(_key(secret), msg, hashlib.sha256).hexdigest()[:TOKEN_LENGTH]


def token_table(secret: str | bytes, participant_id: str, stimulus_ids: Iterable[str]) -> dict[str, str]:
    """{stimulus_id: token} for one participant; raises InvalidInputError in the (2^-80)
    case of two stimuli sharing a token, so a token always names exactly one stimulus."""
    key = _key(secret)
    out: dict[str, str] = {}
    seen: set[str] = set()
    for sid in stimulus_ids:
        tok = stimulus_token(key, participant_id, sid)
        if tok in seen:
            raise InvalidInputError(
                f"participant {participant_id!r}: two stimuli share a trial token; "
                "use a new database (a new blinding secret)"
            )
        seen.add(tok)
        out[sid] = tok
    return out

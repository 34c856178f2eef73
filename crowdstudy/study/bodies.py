"""What the participant API accepts: one parse function per request field set.

Every check of a value the browser sends lives here, pure (no database, no session state):
each function takes the request's JSON object (or a path value), returns the typed values,
and raises :class:`~crowdstudy.study.webio.ApiError` naming the field (400 a malformed
request, 422 a value out of range). :mod:`crowdstudy.study.session` calls them at the point
of each request where the value matters, after the checks of the participant's progress that
come first (so a request out of order is a 409 whatever its body).

Each trial type has its own ``parse_<type>`` (:func:`parse_likert`, :func:`parse_slider`,
:func:`parse_choice`), chosen by the trial's task in :func:`parse_task_answer`, and reuses
:func:`parse_trial_ref`, :func:`parse_timing` and :func:`parse_check`.
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from typing import Any, NamedTuple, TypeGuard

from crowdstudy.schema import CHOICES
from crowdstudy.study.blinding import TOKEN_LENGTH, TOKEN_PATTERN
from crowdstudy.study.schedule import PARTICIPANT_ID_PATTERN
from crowdstudy.study.webio import ApiError

__all__ = [
    "GENDERS",
    "AGE_RANGE",
    "PLATFORM_FIELDS",
    "MAX_RT_MS",
    "Registration",
    "Timing",
    "parse_participant_id",
    "parse_registration",
    "parse_viewport",
    "parse_consent",
    "parse_demographics",
    "parse_likert",
    "parse_slider",
    "parse_choice",
    "parse_task_answer",
    "parse_practice_task",
    "SLIDER_RANGE",
    "parse_timing",
    "parse_trial_ref",
    "parse_check",
    "parse_withdrawal",
]

GENDERS = ("female", "male", "non-binary", "other", "prefer not to say")
AGE_RANGE = (18, 120)
#: Crowdsourcing-platform ids accepted at registration: {request key: database column}.
PLATFORM_FIELDS = {"PROLIFIC_PID": "prolific_pid", "STUDY_ID": "prolific_study_id", "SESSION_ID": "prolific_session_id"}
#: The slider's answers: integers from its left end to its right end.
SLIDER_RANGE = (0, 100)
#: The longest response time accepted (milliseconds): one day.
MAX_RT_MS = 24 * 3600 * 1000.0
_PLATFORM_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
_QUALITY_INTS = ("video_plays", "hidden_count", "fullscreen_exits")
_QUALITY_MS = ("first_play_ms", "hidden_ms")
_MAX_VIEWPORT = 100000


class Registration(NamedTuple):
    """The body of ``POST /api/participants``: the id, the secret of a resumed session (or
    None) and the platform ids as {database column: value}."""

    participant_id: str
    secret: str | None
    platform: dict[str, str]


class Timing(NamedTuple):
    """The timing fields of an answer: response time (ms), when the trial appeared (ISO 8601
    UTC or None) and the data-quality measures (``video_plays``, ``hidden_count``,
    ``fullscreen_exits``, ``first_play_ms``, ``hidden_ms``; None where not sent)."""

    rt_ms: float
    shown_at: str | None
    quality: dict[str, Any]


def _is_int(v: Any) -> TypeGuard[int]:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_ms(v: Any) -> TypeGuard[float]:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= MAX_RT_MS


def parse_participant_id(value: Any) -> str:
    """A participant id (from the body or the URL path): 400 unless 1-64 letters, digits,
    '_' or '-' starting with a letter or digit."""
    if not isinstance(value, str) or not PARTICIPANT_ID_PATTERN.fullmatch(value):
        raise ApiError(400, "participant_id must be 1-64 letters, digits, '_' or '-' starting with a letter or digit")
    return value


def _parse_platform(body: dict) -> dict[str, str]:
    raw = body.get("platform", {})
    if not isinstance(raw, dict):
        raise ApiError(400, "platform must be an object {PROLIFIC_PID, STUDY_ID, SESSION_ID}")
    out = {}
    for key, value in raw.items():
        if key not in PLATFORM_FIELDS:
            raise ApiError(400, f"platform has unknown key {key!r:.40}")
        if not isinstance(value, str) or not _PLATFORM_ID.fullmatch(value):
            raise ApiError(400, f"platform.{key} must be 1-64 letters, digits, '_' or '-'")
        out[PLATFORM_FIELDS[key]] = value
    return out


def parse_registration(body: dict) -> Registration:
    """``{"participant_id", "secret"?, "platform"?}`` of a registration or a resume."""
    pid = parse_participant_id(body.get("participant_id"))
    secret = body.get("secret")
    if secret is not None and (not isinstance(secret, str) or len(secret) > 128):
        raise ApiError(400, "secret must be a string")
    return Registration(pid, secret, _parse_platform(body))


def parse_viewport(body: dict) -> tuple[int, int]:
    """``{"width", "height"}``: the viewport's integer CSS pixels (a failed screen check)."""
    w, h = body.get("width"), body.get("height")
    if not _is_int(w) or not _is_int(h) or not (0 <= w <= _MAX_VIEWPORT and 0 <= h <= _MAX_VIEWPORT):
        raise ApiError(422, "width and height must be the viewport's integer CSS pixels")
    return w, h


def parse_consent(body: dict) -> None:
    """``{"consent": true}`` (anything else is refused: a participant who declines stops)."""
    if body.get("consent") is not True:
        raise ApiError(422, "consent must be true (a participant who declines is not registered further)")


def parse_demographics(body: dict) -> tuple[int, str]:
    """``{"age", "gender"}``: age an integer in AGE_RANGE (a string of digits is accepted),
    gender one of GENDERS."""
    age, gender = body.get("age"), body.get("gender")
    if isinstance(age, str) and age.strip().isdigit():
        age = int(age.strip())
    if not _is_int(age) or not AGE_RANGE[0] <= age <= AGE_RANGE[1]:
        raise ApiError(422, f"age must be an integer {AGE_RANGE[0]}..{AGE_RANGE[1]}, got {age!r:.40}")
    if gender not in GENDERS:
        raise ApiError(422, f"gender must be one of {', '.join(GENDERS)}, got {gender!r:.40}")
    return age, gender


def parse_likert(body: dict, item_ids: tuple[str, ...], points: int) -> dict[str, int]:
    """``"answers": {"Q1": 1..points, ...}``: every item of ``item_ids`` rated, no other key."""
    answers = body.get("answers")
    if not isinstance(answers, dict):
        raise ApiError(422, 'answers must be an object {"Q1": 1..6, ...}')
    for q in item_ids:
        if q not in answers:
            raise ApiError(422, f"answers.{q} is missing (all {len(item_ids)} items are required)")
        v = answers[q]
        if not _is_int(v) or not 1 <= v <= points:
            raise ApiError(422, f"answers.{q} must be an integer 1..{points}, got {v!r:.40}")
    extra = sorted(set(answers) - set(item_ids))
    if extra:
        raise ApiError(422, f"answers has unknown item {extra[0]!r:.40}")
    return answers


def parse_slider(body: dict, item_ids: tuple[str, ...]) -> dict[str, int]:
    """``"answers": {"Q1": 0..100, ...}``: every item of ``item_ids`` placed on the slider
    (an integer 0..100, left end 0), no other key."""
    lo, hi = SLIDER_RANGE
    answers = body.get("answers")
    if not isinstance(answers, dict):
        raise ApiError(422, f'answers must be an object {{"{item_ids[0]}": {lo}..{hi}, ...}}')
    for q in item_ids:
        if q not in answers:
            raise ApiError(422, f"answers.{q} is missing (all {len(item_ids)} sliders are required)")
        v = answers[q]
        if not _is_int(v) or not lo <= v <= hi:
            raise ApiError(422, f"answers.{q} must be an integer {lo}..{hi}, got {v!r:.40}")
    extra = sorted(set(answers) - set(item_ids))
    if extra:
        raise ApiError(422, f"answers has unknown item {extra[0]!r:.40}")
    return answers


def parse_choice(body: dict) -> str:
    """``"choice": "left" | "right"``: the video a 2afc answer picks; a 2afc answer carries no
    ``answers``."""
    choice = body.get("choice")
    if choice not in CHOICES:
        raise ApiError(422, f"choice must be 'left' or 'right' (the video chosen), got {choice!r:.40}")
    if body.get("answers") is not None:
        raise ApiError(422, "a 2afc trial's answer is its 'choice'; send no 'answers'")
    return choice


def parse_task_answer(
    body: dict, task: str, item_ids: tuple[str, ...], points: int
) -> tuple[dict[str, int], str | None]:
    """The answer of a ``task`` trial: ({item id: value}, None) for likert and slider,
    ({}, choice) for 2afc."""
    if task == "2afc":
        return {}, parse_choice(body)
    if body.get("choice") is not None:
        raise ApiError(422, f"choice applies to 2afc trials only (this trial's task is {task})")
    if task == "slider":
        return parse_slider(body, item_ids), None
    return parse_likert(body, item_ids, points), None


def parse_practice_task(body: dict, tasks: tuple[str, ...]) -> str:
    """``"task"`` of a practice answer: one of the design's ``tasks`` (default: the first,
    the task of stage 1)."""
    task = body.get("task", tasks[0])
    if task not in tasks:
        raise ApiError(422, f"task must be one of the study's tasks {', '.join(tasks)}, got {task!r:.40}")
    return task


def _parse_time(value: Any, name: str) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or len(value) > 40:
        raise ApiError(422, f"{name} must be an ISO 8601 timestamp string")
    try:
        t = _dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
    except ValueError:
        raise ApiError(422, f"{name} must be an ISO 8601 timestamp, got {value!r}") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.UTC)
    return t.astimezone(_dt.UTC).isoformat(timespec="milliseconds")


def parse_timing(body: dict) -> Timing:
    """``"rt_ms"`` (required), ``"shown_at"`` and the data-quality counts and durations
    (optional) of any trial's answer."""
    rt = body.get("rt_ms")
    if not _is_ms(rt):
        raise ApiError(422, f"rt_ms must be a number of milliseconds 0..{MAX_RT_MS:.0f}, got {rt!r:.40}")
    quality: dict[str, Any] = {}
    for k in _QUALITY_INTS:
        v = body.get(k)
        if v is not None and (not _is_int(v) or not 0 <= v <= 100000):
            raise ApiError(422, f"{k} must be a count 0..100000, got {v!r:.40}")
        quality[k] = v
    for k in _QUALITY_MS:
        v = body.get(k)
        if v is not None and not _is_ms(v):
            raise ApiError(422, f"{k} must be milliseconds 0..{MAX_RT_MS:.0f}, got {v!r:.40}")
        quality[k] = None if v is None else float(v)
    return Timing(float(rt), _parse_time(body.get("shown_at"), "shown_at"), quality)


def parse_trial_ref(body: dict, n_trials: int) -> tuple[int, str]:
    """``"trial_index"`` (0..n_trials-1) and ``"token"`` (the trial's opaque token, well
    formed; whether it is that trial's is the session's check). A ``stimulus_id`` is refused:
    participants never see one."""
    ti = body.get("trial_index")
    if not _is_int(ti) or not 0 <= ti < n_trials:
        raise ApiError(422, f"trial_index must be an integer 0..{n_trials - 1}, got {ti!r:.40}")
    if "stimulus_id" in body:
        raise ApiError(422, "send the trial's token, not a stimulus_id (participants never see stimulus ids)")
    token = body.get("token")
    if not isinstance(token, str) or not TOKEN_PATTERN.fullmatch(token):
        raise ApiError(
            422, f"token must be the trial's {TOKEN_LENGTH}-digit lowercase hex token from the participant's state"
        )
    return ti, token


def parse_check(body: dict, trial_index: int, has_check: bool, points: int, task: str = "likert") -> int | None:
    """``"check"``: the answer to the trial's attention check where it has one (Likert: a
    point 1..points; slider: 0..100; 2afc: ``"left"`` / ``"right"``, returned as 1 / 2, the
    stored code); absent (None) where it has none."""
    check = body.get("check")
    if not has_check:
        if check is not None:
            raise ApiError(422, f"trial {trial_index} has no attention check; send no 'check'")
        return None
    if task == "2afc":
        if check not in CHOICES:
            raise ApiError(422, f"check must be 'left' or 'right', the answer to trial {trial_index}'s extra question")
        return CHOICES.index(check) + 1
    lo, hi = SLIDER_RANGE if task == "slider" else (1, points)
    if not _is_int(check) or not lo <= check <= hi:
        raise ApiError(422, f"check must be the answer {lo}..{hi} to trial {trial_index}'s extra statement")
    return check


def parse_withdrawal(body: dict) -> None:
    """``{"confirm": true}`` of a participant's withdrawal."""
    if body.get("confirm") is not True:
        raise ApiError(422, "confirm must be true")

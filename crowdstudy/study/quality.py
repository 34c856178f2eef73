"""Data-quality controls of the online study and the exclusion rules applied to its export.

Configured in the design's ``[online]`` table (default: the toolkit's ``crowdstudy/study/study.toml``; ``crowdstudy
serve --online FILE`` and ``crowdstudy export --online FILE`` for another), table ``[online]``:

* ``min_width`` / ``min_height``: the smallest browser viewport (CSS pixels) the study runs
  in; a smaller one sees a message before the consent page and, if it cannot enlarge the
  window, is screened out (its platform code: ``codes.screened_out``).
* ``fullscreen``: request fullscreen when the trials start; exits are counted per trial.
* ``attention_checks``: how many trials carry an instructed-response statement, placed on
  trials drawn at random per participant (keyed with the study's secret, so a participant
  cannot predict them), what it asks drawn at random too: on a Likert trial "please choose
  (k) ..." (a point), on a slider trial "move this slider all the way to the left / right
  end" (passed within 10 points of that end), on a 2afc trial "please choose the left / right
  video here" (an extra question beside the comparison).
* ``codes``: the crowdsourcing platform's completion codes for ``completed``,
  ``screened_out`` and ``withdrawn`` participants (empty: none shown).

Exclusion rules, table ``[online.exclude]`` (each optional; a rule that is absent or 0 is
off). A participant is flagged when:

* ``failed_attention_check``: more than ``max_failed_checks`` checks answered wrongly;
* ``too_fast``: the median answer time is below ``min_median_rt_ms`` milliseconds;
* ``straight_lining``: at least ``max_straightline_fraction`` of their Likert and slider
  trials have the same raw answer on every statement (some of which are reversed: a straight
  line there is contradictory; a slider counts when every handle is at the same value);
* ``same_side``: at least ``max_same_side_fraction`` of their 2afc answers chose the same
  side (1.0: always the left, or always the right, video);
* ``tab_switching``: the page was hidden on more than ``max_hidden_trials`` trials;
* ``withdrawn`` / ``screened_out``: always (they have no analysable answers).

``participants.csv`` (:data:`PARTICIPANT_COLUMNS`) lists every participant with ``excluded``
(0/1) and ``exclusion_reason`` (the flagging rules' names joined by ``;``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import random
import statistics
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from crowdstudy.design import read_toml
from crowdstudy.errors import InvalidInputError
from crowdstudy.package_data import resource_path

__all__ = [
    "OnlineConfig",
    "load_online_config",
    "online_config",
    "default_online_path",
    "draw_checks",
    "flag_participants",
    "PARTICIPANT_COLUMNS",
    "RULES",
]

RULES = ("failed_attention_check", "too_fast", "straight_lining", "same_side", "tab_switching")
PARTICIPANT_COLUMNS = (
    "participant",
    "status",
    "excluded",
    "exclusion_reason",
    "started_at",
    "completed_at",
    "screened_out_at",
    "withdrawn_at",
    "completion_code",
    "prolific_pid",
    "prolific_study_id",
    "prolific_session_id",
    "answered",
    "trials",
    "median_rt_ms",
    "straightline_trials",
    "comparison_trials",
    "same_side_fraction",
    "checks_failed",
    "checks_total",
    "hidden_trials",
    "fullscreen_exits",
)
_CODE_KEYS = ("completed", "screened_out", "withdrawn")


@dataclasses.dataclass(frozen=True)
class OnlineConfig:
    """The ``[online]`` table (see the module docstring); sizes in CSS pixels, times in ms."""

    min_width: int = 1280
    min_height: int = 720
    fullscreen: bool = True
    attention_checks: int = 2
    codes: Mapping[str, str] = dataclasses.field(default_factory=dict)
    max_failed_checks: int | None = 0
    min_median_rt_ms: float | None = None
    max_straightline_fraction: float | None = None
    max_same_side_fraction: float | None = None
    max_hidden_trials: int | None = None
    source: str = "<defaults>"

    def code(self, status: str) -> str | None:
        """The platform code for ``status`` (completed / screened_out / withdrawn), or None."""
        return self.codes.get(status) or None


def default_online_path() -> Path:
    """The toolkit's design, ``crowdstudy/study/study.toml``, whose ``[online]`` table holds
    the default controls."""
    return resource_path("crowdstudy.study", "study.toml")


def _num(table: dict, key: str, where: str, *, integer: bool, lo: float, hi: float | None = None):
    if key not in table:
        return None
    v = table[key]
    ok = isinstance(v, int) if integer else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok or v < lo or (hi is not None and v > hi):
        kind = "an integer" if integer else "a number"
        raise InvalidInputError(
            f"{where}: {key} must be {kind} >= {lo}" + (f" and <= {hi}" if hi is not None else "") + f", got {v!r}"
        )
    return v


def load_online_config(path: str | Path | None = None) -> OnlineConfig:
    """Read and validate the ``[online]`` table of ``path`` (default: default_online_path())."""
    path = Path(path) if path is not None else default_online_path()
    top = read_toml(path, f"--online: file {str(path)!r} does not exist").get("online")
    if not isinstance(top, dict):
        raise InvalidInputError(f"{path}: missing the [online] table")
    return online_config(top, str(path))


def online_config(top: dict, source: str) -> OnlineConfig:
    """Validate the ``[online]`` table ``top`` of the file ``source`` (named in errors and
    recorded in the config)."""
    where = f"{source}: [online]"
    if not isinstance(top, dict):
        raise InvalidInputError(f"{where}: expected a table")
    known = {"min_width", "min_height", "fullscreen", "attention_checks", "codes", "exclude"}
    for key in top:
        if key not in known:
            raise InvalidInputError(f"{where}: unknown key {key!r}")
    fullscreen = top.get("fullscreen", True)
    if not isinstance(fullscreen, bool):
        raise InvalidInputError(f"{where}: fullscreen must be true or false")
    codes = top.get("codes", {})
    if (
        not isinstance(codes, dict)
        or any(k not in _CODE_KEYS for k in codes)
        or any(not isinstance(v, str) or len(v) > 128 or not v.isprintable() for v in codes.values())
    ):
        raise InvalidInputError(
            f"{where}: codes must map {', '.join(_CODE_KEYS)} to codes of <= 128 printable characters"
        )
    ex = top.get("exclude", {})
    if not isinstance(ex, dict):
        raise InvalidInputError(f"{where}: exclude must be a table")
    ex_known = {
        "max_failed_checks",
        "min_median_rt_ms",
        "max_straightline_fraction",
        "max_same_side_fraction",
        "max_hidden_trials",
    }
    for key in ex:
        if key not in ex_known:
            raise InvalidInputError(f"{where}.exclude: unknown key {key!r}")
    w = f"{where}.exclude"
    return OnlineConfig(
        min_width=_num(top, "min_width", where, integer=True, lo=0) or 0,
        min_height=_num(top, "min_height", where, integer=True, lo=0) or 0,
        fullscreen=fullscreen,
        attention_checks=_num(top, "attention_checks", where, integer=True, lo=0) or 0,
        codes=dict(codes),
        max_failed_checks=_num(ex, "max_failed_checks", w, integer=True, lo=0),
        min_median_rt_ms=_num(ex, "min_median_rt_ms", w, integer=False, lo=0) or None,
        max_straightline_fraction=_num(ex, "max_straightline_fraction", w, integer=False, lo=0, hi=1) or None,
        max_same_side_fraction=_num(ex, "max_same_side_fraction", w, integer=False, lo=0, hi=1) or None,
        max_hidden_trials=_num(ex, "max_hidden_trials", w, integer=True, lo=0),
        source=source,
    )


def draw_checks(
    secret: str,
    participant_id: str,
    n_trials: int,
    n_checks: int,
    points: int,
    tasks: Sequence[str] | None = None,
) -> dict[int, int]:
    """{trial_index: what the check asks for} of a participant's attention checks:
    ``n_checks`` distinct trials (never the first: it teaches the page), drawn from an HMAC of
    the study's secret (so the same participant always gets the same checks, and nobody
    without the secret can predict them). What is asked depends on the trial's task
    (``tasks[trial_index]``, default likert): a Likert point 1..points, a slider end (0 the
    left, 100 the right), a 2afc side (1 the left video, 2 the right)."""
    digest = hmac.new(
        secret.encode("utf-8"), f"crowdstudy-checks\x00{participant_id}".encode(), hashlib.sha256
    ).digest()
    rng = random.Random(int.from_bytes(digest[:16], "big"))
    chosen = sorted(rng.sample(range(1, n_trials), min(int(n_checks), max(n_trials - 1, 0))))
    out = {}
    for k in chosen:
        task = tasks[k] if tasks is not None else "likert"
        out[k] = rng.choice((0, 100)) if task == "slider" else rng.randint(1, 2 if task == "2afc" else int(points))
    return out


def check_passed(task: str, asked: int, answer: int | None) -> bool:
    """Whether an attention check's answer is what it asked for: the same Likert point or 2afc
    side; a slider within 10 points of the asked end."""
    if answer is None:
        return False
    if task == "slider":
        return abs(int(answer) - int(asked)) <= 10
    return int(answer) == int(asked)


def _summary(rows: Sequence[Mapping], item_ids: Sequence[str]) -> dict:
    """One participant's quality measures over their answer rows (any task)."""
    ratings = [r for r in rows if (r.get("task") or "likert") != "2afc"]
    choices = [r["choice"] for r in rows if (r.get("task") or "likert") == "2afc"]
    rts = [float(r["rt_ms"]) for r in rows]
    checks = [r for r in rows if r.get("check_value") is not None]
    sides = max(choices.count("left"), choices.count("right")) / len(choices) if choices else None
    return {
        "median_rt_ms": statistics.median(rts) if rts else None,
        "straightline_trials": sum(1 for r in ratings if len({r.get(q) for q in item_ids}) == 1),
        "rating_trials": len(ratings),
        "comparison_trials": len(choices),
        "same_side_fraction": sides,
        "checks_failed": sum(
            1
            for r in checks
            if not check_passed(r.get("task") or "likert", int(r["check_value"]), r.get("check_answer"))
        ),
        "checks_total": len(checks),
        "hidden_trials": sum(1 for r in rows if (r.get("hidden_count") or 0) > 0),
        "fullscreen_exits": sum(int(r.get("fullscreen_exits") or 0) for r in rows),
    }


def _reasons(status: str, m: Mapping, config: OnlineConfig) -> list[str]:
    """The exclusion rules that flag a participant with ``status`` and quality measures ``m``."""
    reasons = [status] if status in ("withdrawn", "screened_out") else []
    if config.max_failed_checks is not None and m["checks_total"] and m["checks_failed"] > config.max_failed_checks:
        reasons.append("failed_attention_check")
    if config.min_median_rt_ms and m["median_rt_ms"] is not None and m["median_rt_ms"] < config.min_median_rt_ms:
        reasons.append("too_fast")
    if (
        config.max_straightline_fraction
        and m["rating_trials"]
        and m["straightline_trials"] / m["rating_trials"] >= config.max_straightline_fraction
    ):
        reasons.append("straight_lining")
    if config.max_same_side_fraction and m["same_side_fraction"] is not None:
        if m["same_side_fraction"] >= config.max_same_side_fraction:
            reasons.append("same_side")
    if config.max_hidden_trials is not None and m["hidden_trials"] > config.max_hidden_trials:
        reasons.append("tab_switching")
    return reasons


def flag_participants(
    people: Sequence[Mapping], responses: Iterable[Mapping], config: OnlineConfig, item_ids: Sequence[str]
) -> list[dict]:
    """participants.csv rows: each of ``people`` (rows of roster.list_participants) with the
    per-participant quality summary and the exclusion flags of ``config``'s rules.

    responses: rows of StudyStore.response_rows (every task, with QUALITY_FIELDS and
    check_value); item_ids: the study's items (a straight line is one value on all of them).
    """
    by_pid: dict[str, list[Mapping]] = {}
    for r in responses:
        by_pid.setdefault(r["participant_id"], []).append(r)
    out = []
    for person in people:
        m = _summary(by_pid.get(person["participant"], []), item_ids)
        reasons = _reasons(person["status"], m, config)
        m.pop("rating_trials")
        out.append(
            {
                **{k: person.get(k) for k in PARTICIPANT_COLUMNS if k in person},
                "excluded": int(bool(reasons)),
                "exclusion_reason": ";".join(reasons),
                **m,
            }
        )
    return out

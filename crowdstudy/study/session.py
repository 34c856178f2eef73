"""The participant API's logic (blocking; :mod:`crowdstudy.study.app` runs it in a thread pool).

No per-process state can go stale: every request reads the participant's row (secret hash,
progress, withdrawal) from the database, so a secret replaced or a participant withdrawn
through one server process is refused at once by every other. The only per-process caches
are pure functions of the database's immutable data: a participant's schedule with its
tokens and video URLs (written once at registration), the media names and the study's
secret.

What the browser receives names a trial by ``trial_index``, ``stage``, an opaque
per-participant ``token`` (:mod:`crowdstudy.study.blinding`) and the video's opaque
per-deployment URL (:mod:`crowdstudy.study.media`); never a stimulus id, a condition, an item's
reversal or the composites' pairing (that scoring metadata is admin-only).
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import hmac
import math
import re
import secrets

from crowdstudy.errors import InvalidInputError
from crowdstudy.study.blinding import TOKEN_LENGTH, TOKEN_PATTERN, token_table
from crowdstudy.study.media import PRACTICE_KEY, media_table
from crowdstudy.study.quality import draw_checks
from crowdstudy.study.roster import status_of, withdraw_participant
from crowdstudy.study.schedule import PARTICIPANT_ID_PATTERN, make_schedule
from crowdstudy.study.storage import ITEM_IDS
from crowdstudy.study.webio import ApiError

__all__ = ["StudySession", "hash_secret", "GENDERS", "AGE_RANGE", "PLATFORM_FIELDS"]

GENDERS = ("female", "male", "non-binary", "other", "prefer not to say")
AGE_RANGE = (18, 120)
#: Crowdsourcing-platform ids accepted at registration: {request key: database column}.
PLATFORM_FIELDS = {"PROLIFIC_PID": "prolific_pid", "STUDY_ID": "prolific_study_id", "SESSION_ID": "prolific_session_id"}
_PLATFORM_ID = re.compile(r"[A-Za-z0-9_-]{1,64}")
_MAX_RT_MS = 24 * 3600 * 1000.0
_QUALITY_INTS = ("video_plays", "hidden_count", "fullscreen_exits")
_QUALITY_MS = ("first_play_ms", "hidden_ms")


def hash_secret(secret: str) -> str:
    """SHA-256 hex digest of a participant secret (the database stores only this)."""
    return hashlib.sha256(secret.encode("utf-8")).hexdigest()


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _parse_time(value, name: str) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str) or len(value) > 40:
        raise ApiError(422, f"{name} must be an ISO 8601 timestamp string")
    try:
        t = _dt.datetime.fromisoformat(value.replace("Z", "+00:00"))
    except ValueError:
        raise ApiError(422, f"{name} must be an ISO 8601 timestamp, got {value!r}") from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.timezone.utc)
    return t.astimezone(_dt.timezone.utc).isoformat(timespec="milliseconds")


class StudySession:
    """Request handlers bound to one StudyConfig (``cfg``)."""

    def __init__(self, config):
        self.cfg = config
        self.store = config.store
        self.online = config.online
        self.points = int(config.design.likert_points)
        self.labels = list(config.design.likert_labels)
        self.item_ids = tuple(it.id for it in config.design.items)
        if self.item_ids != ITEM_IDS:
            raise InvalidInputError(f"design {config.design.source}: the server stores items {', '.join(ITEM_IDS)}, "
                                    f"the design lists {', '.join(self.item_ids)}")
        self.by_stage = config.stimuli.by_stage()
        self.n_trials = sum(map(len, self.by_stage.values()))
        self.seed = int(config.design.seed)
        self._secret = config.store.blinding_secret()
        self._schedules: dict[str, list[dict]] = {}
        self.store.sync_stimuli(config.stimuli.rows.values())
        self.media = media_table(self._secret, config.stimuli.files, config.stimuli.practice_file)
        self.media_files = {name: path for name, path in self.media.values()}
        base = (config.media_url or "/media").rstrip("/")
        self.video_url = {sid: f"{base}/{name}" for sid, (name, _) in self.media.items()}
        self.study_info = {
            "name": config.design.name,
            "items": [{"id": it.id, "text": it.text} for it in config.design.items],
            "labels": self.labels, "points": self.points,
            "consent_html": config.consent_html,
            "stages": [{"number": st.number, "scenario": st.scenario, "description": st.description,
                        "n_trials": len(self.by_stage.get(st.number, []))} for st in config.design.stages],
            "genders": list(GENDERS), "age_range": list(AGE_RANGE),
            "screen": {"min_width": self.online.min_width, "min_height": self.online.min_height},
            "fullscreen": bool(self.online.fullscreen),
            "practice_video_url": self.video_url[PRACTICE_KEY],
        }

    # -- participants -----------------------------------------------------------------
    def check_pid(self, pid) -> str:
        if not isinstance(pid, str) or not PARTICIPANT_ID_PATTERN.fullmatch(pid):
            raise ApiError(400, "participant_id must be 1-64 letters, digits, '_' or '-' starting with a letter "
                                "or digit")
        return pid

    def authenticate(self, pid: str, secret: str | None) -> dict:
        """The participant's row, read now from the database; 401 without a secret, 403 for a
        wrong secret or an unknown id alike (the answer never tells whether an id exists),
        410 once withdrawn."""
        self.check_pid(pid)
        if not secret:
            raise ApiError(401, "missing X-Participant-Secret header (the secret returned at registration)")
        row = self.store.participant(pid)
        stored = row["secret_hash"] if row is not None else "0" * 64
        if not hmac.compare_digest(hash_secret(secret), stored) or row is None:
            raise ApiError(403, "wrong participant secret (or no such participant)")
        if row["withdrawn_at"] is not None:
            raise ApiError(410, "you have withdrawn from this study; your answers were deleted")
        return row

    def schedule(self, pid: str) -> list[dict]:
        """The participant's trials with the REAL stimulus id and conditions plus each trial's
        ``token``, ``video_url`` and attention ``check`` (server side and admin only)."""
        sched = self._schedules.get(pid)
        if sched is None:
            sched = self.store.schedule(pid)
            tokens = token_table(self._secret, pid, [row["stimulus_id"] for row in sched])
            for row in sched:
                row["token"] = tokens[row["stimulus_id"]]
                row["video_url"] = self.video_url[row["stimulus_id"]]
            if sched:
                self._schedules[pid] = sched
        return sched

    def _check_of(self, trial: dict) -> dict | None:
        v = trial.get("check_value")
        if v is None:
            return None
        # where the statement goes among the items: from the token (opaque, fixed per trial)
        return {"text": f'To show that you read each statement, please choose ({v}) "{self.labels[v - 1]}" here.',
                "position": int(trial["token"][:4], 16) % (len(self.item_ids) + 1)}

    def public_trials(self, pid: str) -> list[dict]:
        """The participant's trials as the browser sees them: trial_index, stage, token,
        video_url and, on attention-check trials, check {text, position}."""
        out = []
        for t in self.schedule(pid):
            row = {k: t[k] for k in ("trial_index", "stage", "token", "video_url")}
            check = self._check_of(t)
            if check is not None:
                row["check"] = check
            out.append(row)
        return out

    def state(self, pid: str, row: dict | None = None) -> dict:
        row = row if row is not None else self.store.participant(pid)
        sched = self.public_trials(pid)
        done = set(self.store.answered_indices(pid))
        nxt = next((t["trial_index"] for t in sched if t["trial_index"] not in done), len(sched))
        status = status_of(row)
        finished = status in ("completed", "screened_out")
        return {
            "participant_id": pid, "status": status, "consented": row["consented_at"] is not None,
            "demographics": row["demographics_at"] is not None, "practice_done": row["practice_at"] is not None,
            "completed": row["completed_at"] is not None, "screened_out": row["screened_out_at"] is not None,
            "n_trials": len(sched), "n_answered": len(done), "next_trial_index": nxt,
            "trials": sched, "practice": {"video_url": self.video_url[PRACTICE_KEY]},
            "completion_code": row["completion_code"] if finished else None,
            "redirect_url": self.cfg.redirect_url if finished else None,
        }

    def state_of(self, pid: str, row: dict) -> dict:
        """GET /api/participants/<id> (row: the authenticated participant's)."""
        return self.state(pid, row)

    def _platform(self, body: dict) -> dict:
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

    def register(self, body: dict, user_agent: str | None) -> tuple[int, dict]:
        pid = self.check_pid(body.get("participant_id"))
        secret = body.get("secret")
        if secret is not None and (not isinstance(secret, str) or len(secret) > 128):
            raise ApiError(400, "secret must be a string")
        platform = self._platform(body)
        if secret and self.store.participant(pid) is not None:  # resume (a stale secret of a new id: register)
            row = self.authenticate(pid, secret)
            return 200, {"participant_id": pid, "secret": secret, "resumed": True, "state": self.state(pid, row)}
        secret = secrets.token_urlsafe(24)
        sched = make_schedule(self.by_stage, pid, self.seed, secret=self._secret)
        checks = draw_checks(self._secret, pid, len(sched), self.online.attention_checks, self.points)
        if not self.store.register(pid, hash_secret(secret), sched, seed=self.seed, user_agent=user_agent,
                                   platform=platform, checks=checks):
            raise ApiError(409, f"participant {pid!r} is already registered; resume from the browser that "
                                "started the session (it holds the session secret)")
        return 201, {"participant_id": pid, "secret": secret, "resumed": False, "state": self.state(pid)}

    def screen_out(self, pid: str, row: dict, body: dict) -> dict:
        """Record a failed screen check (before consent only); returns the state with its code."""
        w, h = body.get("width"), body.get("height")
        if not _is_int(w) or not _is_int(h) or not (0 <= w <= 100000 and 0 <= h <= 100000):
            raise ApiError(422, "width and height must be the viewport's integer CSS pixels")
        if row["consented_at"] is not None:
            raise ApiError(409, "the screen check comes before consent")
        if w >= self.online.min_width and h >= self.online.min_height:
            raise ApiError(422, f"a {w}x{h} viewport passes the screen check "
                                f"({self.online.min_width}x{self.online.min_height})")
        reason = f"viewport {w}x{h} below {self.online.min_width}x{self.online.min_height}"
        return self.state(pid, self.store.set_screened_out(pid, reason, self.online.code("screened_out")))

    def _require_active(self, row: dict) -> None:
        if row["screened_out_at"] is not None:
            raise ApiError(409, "this session ended at the screen check")

    def consent(self, pid: str, row: dict, body: dict) -> dict:
        self._require_active(row)
        if body.get("consent") is not True:
            raise ApiError(422, "consent must be true (a participant who declines is not registered further)")
        return self.state(pid, self.store.set_consent(pid))

    def demographics(self, pid: str, row: dict, body: dict) -> dict:
        if row["consented_at"] is None:
            raise ApiError(409, "give consent before the demographics")
        age, gender = body.get("age"), body.get("gender")
        if isinstance(age, str) and age.strip().isdigit():
            age = int(age.strip())
        if not _is_int(age) or not AGE_RANGE[0] <= age <= AGE_RANGE[1]:
            raise ApiError(422, f"age must be an integer {AGE_RANGE[0]}..{AGE_RANGE[1]}, got {age!r:.40}")
        if gender not in GENDERS:
            raise ApiError(422, f"gender must be one of {', '.join(GENDERS)}, got {gender!r:.40}")
        new = self.store.set_demographics(pid, age, gender)
        if (new["age"], new["gender"]) != (age, gender):
            raise ApiError(409, "the demographics were already given; the first answer is kept")
        return self.state(pid, new)

    def parse_answers(self, body: dict) -> tuple[dict, float, str | None, dict]:
        answers = body.get("answers")
        if not isinstance(answers, dict):
            raise ApiError(422, "answers must be an object {\"Q1\": 1..6, ...}")
        for q in self.item_ids:
            if q not in answers:
                raise ApiError(422, f"answers.{q} is missing (all {len(self.item_ids)} items are required)")
            v = answers[q]
            if not _is_int(v) or not 1 <= v <= self.points:
                raise ApiError(422, f"answers.{q} must be an integer 1..{self.points}, got {v!r:.40}")
        extra = sorted(set(answers) - set(self.item_ids))
        if extra:
            raise ApiError(422, f"answers has unknown item {extra[0]!r:.40}")
        rt = body.get("rt_ms")
        if isinstance(rt, bool) or not isinstance(rt, (int, float)) or not math.isfinite(rt) or \
                not 0 <= rt <= _MAX_RT_MS:
            raise ApiError(422, f"rt_ms must be a number of milliseconds 0..{_MAX_RT_MS:.0f}, got {rt!r:.40}")
        quality = {}
        for k in _QUALITY_INTS:
            v = body.get(k)
            if v is not None and (not _is_int(v) or not 0 <= v <= 100000):
                raise ApiError(422, f"{k} must be a count 0..100000, got {v!r:.40}")
            quality[k] = v
        for k in _QUALITY_MS:
            v = body.get(k)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                                  or not 0 <= v <= _MAX_RT_MS):
                raise ApiError(422, f"{k} must be milliseconds 0..{_MAX_RT_MS:.0f}, got {v!r:.40}")
            quality[k] = None if v is None else float(v)
        return answers, float(rt), _parse_time(body.get("shown_at"), "shown_at"), quality

    def practice(self, pid: str, row: dict, body: dict) -> tuple[int, dict]:
        if row["demographics_at"] is None:
            raise ApiError(409, "give consent and the demographics before the practice trial")
        answers, rt, shown, quality = self.parse_answers(body)
        status, _ = self.store.record_practice(pid, answers, rt, shown, quality)
        return (201 if status == "created" else 200), {"stored": status == "created", "practice": True}

    def answer(self, pid: str, row: dict, body: dict) -> tuple[int, dict]:
        if row["practice_at"] is None or row["demographics_at"] is None:
            raise ApiError(409, "complete consent, demographics and the practice trial first")
        sched = self.schedule(pid)
        ti = body.get("trial_index")
        if not _is_int(ti) or not 0 <= ti < len(sched):
            raise ApiError(422, f"trial_index must be an integer 0..{len(sched) - 1}, got {ti!r:.40}")
        if "stimulus_id" in body:
            raise ApiError(422, "send the trial's token, not a stimulus_id (participants never see stimulus ids)")
        token = body.get("token")
        if not isinstance(token, str) or not TOKEN_PATTERN.fullmatch(token):
            raise ApiError(422, f"token must be the trial's {TOKEN_LENGTH}-digit lowercase hex token from the "
                                "participant's state")
        trial = sched[ti]
        if trial["token"] != token:
            other = next((t["trial_index"] for t in sched if t["token"] == token), None)
            if other is None:
                raise ApiError(422, f"token {token} is not in this participant's schedule")
            raise ApiError(422, f"token {token} belongs to trial {other}, not to trial_index {ti}")
        answers, rt, shown, quality = self.parse_answers(body)
        check = body.get("check")
        if trial["check_value"] is None:
            if check is not None:
                raise ApiError(422, f"trial {ti} has no attention check; send no 'check'")
        elif not _is_int(check) or not 1 <= check <= self.points:
            raise ApiError(422, f"check must be the answer 1..{self.points} to trial {ti}'s extra statement")
        quality["check_answer"] = check
        status, stored = self.store.record_answer(pid, ti, trial["stimulus_id"], trial["stage"], answers, rt, shown,
                                                  quality=quality)
        if status == "out_of_order":
            raise ApiError(409, f"trial {stored['expected']} is not answered yet; answers arrive in trial order")
        if status == "conflict":
            raise ApiError(409, f"trial {ti} already has a different answer (given in another tab or window?); "
                                "the first one is kept, this one was recorded separately")
        return (201 if status == "created" else 200), {"stored": True, "trial_index": ti,
                                                       "answer": _public_answer(stored, token)}

    def own_responses(self, pid: str, row: dict) -> dict:
        """The participant's stored answers, each naming its trial by token (no conditions)."""
        tokens = {t["trial_index"]: t["token"] for t in self.schedule(pid)}
        return {"participant_id": pid,
                "responses": [{"participant_id": pid, "stage": r["stage"], **_public_answer(r, tokens[r["trial_index"]])}
                              for r in self.store.response_rows(pid)]}

    def complete(self, pid: str, row: dict) -> dict:
        st = self.state(pid, row)
        missing = st["n_trials"] - st["n_answered"]
        if missing:
            raise ApiError(409, f"{missing} trials are not answered yet (next: trial {st['next_trial_index']})")
        code = self.cfg.completion_code or self.online.code("completed")
        return self.state(pid, self.store.set_completed(pid, code))

    def withdraw(self, pid: str, row: dict, body: dict) -> dict:
        """The participant withdraws: answers and demographics deleted, an audit line kept."""
        if body.get("confirm") is not True:
            raise ApiError(422, "confirm must be true")
        code = self.online.code("withdrawn")
        withdraw_participant(self.store, pid, by="participant", completion_code=code)
        self._schedules.pop(pid, None)
        return {"participant_id": pid, "withdrawn": True, "completion_code": code,
                "redirect_url": self.cfg.redirect_url}

    # -- admin ------------------------------------------------------------------------------
    def admin_schedule(self, pid: str) -> dict:
        """Participant ``pid``'s trials with token, stimulus id and conditions, read from the
        database (admin only: the token -> stimulus mapping the participant must not see)."""
        self.check_pid(pid)
        self._schedules.pop(pid, None)
        sched = self.schedule(pid)
        if not sched:
            raise ApiError(404, f"unknown participant {pid!r}")
        return {"participant_id": pid, "trials": [dict(t) for t in sched]}

    def scoring(self) -> dict:
        """The scoring metadata (reversed items, composites): admin only, never the browser's."""
        d = self.cfg.design
        return {"name": d.name, "points": self.points, "labels": self.labels,
                "items": [{"id": it.id, "text": it.text, "reverse": it.reverse} for it in d.items],
                "composites": {k: list(v) for k, v in d.composites.items()}}

    def resume_link(self, pid: str) -> dict:
        """A new secret for ``pid`` (e.g. to continue on another device); the old one stops working."""
        self.check_pid(pid)
        secret = secrets.token_urlsafe(24)
        if not self.store.replace_secret(pid, hash_secret(secret)):
            raise ApiError(404, f"unknown participant {pid!r}")
        return {"participant_id": pid, "url": f"/?participant={pid}&resume={secret}"}


def _public_answer(row: dict, token: str) -> dict:
    """A stored answer as its participant may see it: the trial's token, never the stimulus id."""
    return {"trial_index": row["trial_index"], "token": token,
            **{k: row[k] for k in (*ITEM_IDS, "rt_ms", "shown_at", "answered_at")}}

"""The participant API's logic (blocking; the route handlers of
:mod:`crowdstudy.study.routes_participant` and :mod:`crowdstudy.study.routes_admin` run it
in a thread pool). The request bodies' values are checked by :mod:`crowdstudy.study.bodies`.

No per-process state can go stale: every request reads the participant's row (secret hash,
progress, withdrawal) from the database, so a secret replaced or a participant withdrawn
through one server process is refused at once by every other. The only per-process caches
are pure functions of the database's immutable data: a participant's schedule with its
tokens and video URLs (written once at registration), the media names and the study's
secret.

What the browser receives names a trial by ``trial_index``, ``stage``, its ``task``, an
opaque per-participant ``token`` (:mod:`crowdstudy.study.blinding`) and the opaque
per-deployment URL of its video (:mod:`crowdstudy.study.media`; a 2afc trial: its left and
right videos); never a stimulus id, a method, a condition, an item's reversal or the
composites' pairing (that scoring metadata is admin-only).

Tasks: each stage of the design has one (``likert``, ``slider`` or ``2afc``); a trial's answer
is checked by its task (:func:`crowdstudy.study.bodies.parse_task_answer`), and the trials of a
task need that task's practice answer first (``POST .../practice`` with ``"task"``).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets

from crowdstudy.study import bodies
from crowdstudy.study.blinding import token_table
from crowdstudy.study.media import PRACTICE_KEY, media_table
from crowdstudy.study.quality import draw_checks
from crowdstudy.study.roster import status_of, withdraw_participant
from crowdstudy.study.schedule import make_schedule
from crowdstudy.study.storage import answer_items
from crowdstudy.study.webio import ApiError

__all__ = ["StudySession", "hash_secret"]


def hash_secret(secret: str) -> str:
    """SHA-256 hex digest of a participant secret (the database stores only this)."""
    return hashlib.sha256(secret.encode("utf-8")).hexdigest()


class StudySession:
    """The participant API's logic bound to one StudyConfig (``cfg``): the route handlers
    call its methods with the authenticated participant's id, database row and request body."""

    def __init__(self, config):
        self.cfg = config
        self.store = config.store
        self.online = config.online
        self.points = int(config.design.likert_points)
        self.labels = list(config.design.likert_labels)
        design = config.design
        self.item_ids = tuple(it.id for it in design.items)
        self.tasks = design.tasks()
        self.stage_task = {st.number: st.task for st in design.stages}
        self.by_stage, self.comparisons = _stage_units(design, config.stimuli.rows)
        self.n_trials = sum(map(len, self.by_stage.values())) + sum(
            len(cells) for pairs in self.comparisons.values() for cells in pairs.values()
        )
        self.seed = int(design.seed)
        self._secret = config.store.blinding_secret()
        self._schedules: dict[str, list[dict]] = {}
        self.store.sync_items(self.item_ids, self.tasks)
        self.store.sync_stimuli(config.stimuli.rows.values())
        self.media = media_table(self._secret, config.stimuli.files, config.stimuli.practice_file)
        self.media_files = {name: path for name, path in self.media.values()}
        base = (config.media_url or "/media").rstrip("/")
        self.video_url = {sid: f"{base}/{name}" for sid, (name, _) in self.media.items()}
        self.study_info = {
            "name": config.design.name,
            "items": [{"id": it.id, "text": it.text} for it in config.design.items],
            "labels": self.labels,
            "points": self.points,
            "consent_html": config.consent_html,
            "stages": [
                {
                    "number": st.number,
                    "scenario": st.scenario,
                    "description": st.description,
                    "task": st.task,
                    "n_trials": len(self.by_stage.get(st.number, []))
                    + sum(len(c) for c in self.comparisons.get(st.number, {}).values()),
                }
                for st in design.stages
            ],
            "tasks": list(self.tasks),
            "comparison": design.comparison.text if design.comparison is not None else None,
            "slider": None if design.slider is None else {"left": design.slider.left, "right": design.slider.right},
            "genders": list(bodies.GENDERS),
            "age_range": list(bodies.AGE_RANGE),
            "screen": {"min_width": self.online.min_width, "min_height": self.online.min_height},
            "fullscreen": bool(self.online.fullscreen),
            "practice_video_url": self.video_url[PRACTICE_KEY],
        }

    # -- participants -----------------------------------------------------------------
    def authenticate(self, pid: str, secret: str | None) -> dict:
        """The participant's row, read now from the database; 401 without a secret, 403 for a
        wrong secret or an unknown id alike (the answer never tells whether an id exists),
        410 once withdrawn."""
        bodies.parse_participant_id(pid)
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
            tokens = token_table(self._secret, pid, [_trial_key(row) for row in sched])
            for row in sched:
                row["token"] = tokens[_trial_key(row)]
                row["video_url"] = self.video_url[row["stimulus_id"]]
                if row["stimulus_right"] is not None:
                    row["video_url_right"] = self.video_url[row["stimulus_right"]]
            if sched:
                self._schedules[pid] = sched
        return sched

    def forget_schedule(self, pid: str) -> None:
        """Drop this process's copy of ``pid``'s schedule (the next :meth:`schedule` reads the
        database): after a withdrawal, and before the admin's view of it."""
        self._schedules.pop(pid, None)

    def _check_of(self, trial: dict) -> dict | None:
        v = trial.get("check_value")
        if v is None:
            return None
        # where the statement goes among the items: from the token (opaque, fixed per trial)
        position = int(trial["token"][:4], 16) % (len(self.item_ids) + 1)
        if trial["task"] == "2afc":
            side = ("left", "right")[v - 1]
            return {
                "text": f"To show that you read the instructions, please choose the {side} video here.",
                "position": 0,
            }
        if trial["task"] == "slider":
            sl = self.cfg.design.slider
            end, label = ("left", sl.left) if v == 0 else ("right", sl.right)
            return {
                "text": "To show that you read each statement, please move this slider all the way to the "
                f'{end} end ("{label}").',
                "position": position,
            }
        return {
            "text": f'To show that you read each statement, please choose ({v}) "{self.labels[v - 1]}" here.',
            "position": position,
        }

    def public_trials(self, pid: str) -> list[dict]:
        """The participant's trials as the browser sees them: trial_index, stage, task, token,
        video_url (a 2afc trial: also video_url_right) and, on attention-check trials, check
        {text, position}."""
        out = []
        for t in self.schedule(pid):
            row = {k: t[k] for k in ("trial_index", "stage", "task", "token", "video_url")}
            if "video_url_right" in t:
                row["video_url_right"] = t["video_url_right"]
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
            "participant_id": pid,
            "status": status,
            "consented": row["consented_at"] is not None,
            "demographics": row["demographics_at"] is not None,
            "practice_done": row["practice_at"] is not None,
            "practiced": sorted(self.store.practiced_tasks(pid))
            if len(self.tasks) > 1
            else (list(self.tasks) if row["practice_at"] is not None else []),
            "completed": row["completed_at"] is not None,
            "screened_out": row["screened_out_at"] is not None,
            "n_trials": len(sched),
            "n_answered": len(done),
            "next_trial_index": nxt,
            "trials": sched,
            "practice": {"video_url": self.video_url[PRACTICE_KEY]},
            "completion_code": row["completion_code"] if finished else None,
            "redirect_url": self.cfg.redirect_url if finished else None,
        }

    def state_of(self, pid: str, row: dict) -> dict:
        """GET /api/participants/<id> (row: the authenticated participant's)."""
        return self.state(pid, row)

    def register(self, body: dict, user_agent: str | None) -> tuple[int, dict]:
        """POST /api/participants: a new participant (201, a new secret) or, with the secret of
        a registered one, a resumed session (200)."""
        pid, secret, platform = bodies.parse_registration(body)
        if secret and self.store.participant(pid) is not None:  # resume (a stale secret of a new id: register)
            row = self.authenticate(pid, secret)
            return 200, {"participant_id": pid, "secret": secret, "resumed": True, "state": self.state(pid, row)}
        secret = secrets.token_urlsafe(24)
        sched = make_schedule(self.by_stage, pid, self.seed, secret=self._secret, comparisons=self.comparisons)
        tasks = [self.stage_task[t.stage] for t in sched]
        checks = draw_checks(self._secret, pid, len(sched), self.online.attention_checks, self.points, tasks)
        if not self.store.register(
            pid,
            hash_secret(secret),
            sched,
            seed=self.seed,
            user_agent=user_agent,
            platform=platform,
            checks=checks,
            tasks=self.stage_task,
        ):
            raise ApiError(
                409,
                f"participant {pid!r} is already registered; resume from the browser that "
                "started the session (it holds the session secret)",
            )
        return 201, {"participant_id": pid, "secret": secret, "resumed": False, "state": self.state(pid)}

    def screen_out(self, pid: str, row: dict, body: dict) -> dict:
        """Record a failed screen check (before consent only); returns the state with its code."""
        w, h = bodies.parse_viewport(body)
        if row["consented_at"] is not None:
            raise ApiError(409, "the screen check comes before consent")
        if w >= self.online.min_width and h >= self.online.min_height:
            raise ApiError(
                422, f"a {w}x{h} viewport passes the screen check ({self.online.min_width}x{self.online.min_height})"
            )
        reason = f"viewport {w}x{h} below {self.online.min_width}x{self.online.min_height}"
        return self.state(pid, self.store.set_screened_out(pid, reason, self.online.code("screened_out")))

    def _require_active(self, row: dict) -> None:
        if row["screened_out_at"] is not None:
            raise ApiError(409, "this session ended at the screen check")

    def consent(self, pid: str, row: dict, body: dict) -> dict:
        self._require_active(row)
        bodies.parse_consent(body)
        return self.state(pid, self.store.set_consent(pid))

    def demographics(self, pid: str, row: dict, body: dict) -> dict:
        if row["consented_at"] is None:
            raise ApiError(409, "give consent before the demographics")
        age, gender = bodies.parse_demographics(body)
        new = self.store.set_demographics(pid, age, gender)
        if (new["age"], new["gender"]) != (age, gender):
            raise ApiError(409, "the demographics were already given; the first answer is kept")
        return self.state(pid, new)

    def practice(self, pid: str, row: dict, body: dict) -> tuple[int, dict]:
        if row["demographics_at"] is None:
            raise ApiError(409, "give consent and the demographics before the practice trial")
        task = bodies.parse_practice_task(body, self.tasks)
        answers, choice = bodies.parse_task_answer(body, task, self.item_ids, self.points)
        rt, shown, quality = bodies.parse_timing(body)
        status, _ = self.store.record_practice(pid, answers, rt, shown, quality, task=task, choice=choice)
        return (201 if status == "created" else 200), {"stored": status == "created", "practice": True, "task": task}

    def _trial(self, pid: str, body: dict) -> tuple[int, dict]:
        """(trial_index, scheduled trial) an answer names by ``trial_index`` and ``token`` (422
        unless the token is that trial's)."""
        sched = self.schedule(pid)
        ti, token = bodies.parse_trial_ref(body, len(sched))
        trial = sched[ti]
        if trial["token"] != token:
            other = next((t["trial_index"] for t in sched if t["token"] == token), None)
            if other is None:
                raise ApiError(422, f"token {token} is not in this participant's schedule")
            raise ApiError(422, f"token {token} belongs to trial {other}, not to trial_index {ti}")
        return ti, trial

    def answer(self, pid: str, row: dict, body: dict) -> tuple[int, dict]:
        """POST /api/participants/<id>/responses: one trial's answer, committed in trial order."""
        if row["practice_at"] is None or row["demographics_at"] is None:
            raise ApiError(409, "complete consent, demographics and the practice trial first")
        ti, trial = self._trial(pid, body)
        task = trial["task"]
        if len(self.tasks) > 1 and task not in self.store.practiced_tasks(pid):
            raise ApiError(409, f"answer the practice trial of the {task} task first (POST .../practice with its task)")
        answers, choice = bodies.parse_task_answer(body, task, self.item_ids, self.points)
        rt, shown, quality = bodies.parse_timing(body)
        quality["check_answer"] = bodies.parse_check(body, ti, trial["check_value"] is not None, self.points, task)
        status, stored = self.store.record_answer(
            pid,
            ti,
            trial["stimulus_id"],
            trial["stage"],
            answers,
            rt,
            shown,
            quality=quality,
            task=task,
            choice=choice,
            stimulus_right=trial["stimulus_right"],
        )
        if status == "out_of_order":
            raise ApiError(409, f"trial {stored['expected']} is not answered yet; answers arrive in trial order")
        if status == "conflict":
            raise ApiError(
                409,
                f"trial {ti} already has a different answer (given in another tab or window?); "
                "the first one is kept, this one was recorded separately",
            )
        return (201 if status == "created" else 200), {
            "stored": True,
            "trial_index": ti,
            "answer": _public_answer(stored, trial["token"], self.item_ids),
        }

    def own_responses(self, pid: str, row: dict) -> dict:
        """The participant's stored answers, each naming its trial by token (no conditions)."""
        tokens = {t["trial_index"]: t["token"] for t in self.schedule(pid)}
        return {
            "participant_id": pid,
            "responses": [
                {
                    "participant_id": pid,
                    "stage": r["stage"],
                    **_public_answer(r, tokens[r["trial_index"]], self.item_ids),
                }
                for r in self.store.response_rows(pid)
            ],
        }

    def complete(self, pid: str, row: dict) -> dict:
        st = self.state(pid, row)
        missing = st["n_trials"] - st["n_answered"]
        if missing:
            raise ApiError(409, f"{missing} trials are not answered yet (next: trial {st['next_trial_index']})")
        code = self.cfg.completion_code or self.online.code("completed")
        return self.state(pid, self.store.set_completed(pid, code))

    def withdraw(self, pid: str, row: dict, body: dict) -> dict:
        """The participant withdraws: answers and demographics deleted, an audit line kept."""
        bodies.parse_withdrawal(body)
        code = self.online.code("withdrawn")
        withdraw_participant(self.store, pid, by="participant", completion_code=code)
        self.forget_schedule(pid)
        return {
            "participant_id": pid,
            "withdrawn": True,
            "completion_code": code,
            "redirect_url": self.cfg.redirect_url,
        }

    # -- admin ------------------------------------------------------------------------------
    def admin_schedule(self, pid: str) -> dict:
        """Participant ``pid``'s trials with token, stimulus id and conditions, read from the
        database (admin only: the token -> stimulus mapping the participant must not see)."""
        bodies.parse_participant_id(pid)
        self.forget_schedule(pid)
        sched = self.schedule(pid)
        if not sched:
            raise ApiError(404, f"unknown participant {pid!r}")
        return {"participant_id": pid, "trials": [dict(t) for t in sched]}

    def scoring(self) -> dict:
        """The scoring metadata (reversed items, composites): admin only, never the browser's."""
        d = self.cfg.design
        return {
            "name": d.name,
            "points": self.points,
            "labels": self.labels,
            "items": [{"id": it.id, "text": it.text, "reverse": it.reverse} for it in d.items],
            "composites": {k: list(v) for k, v in d.composites.items()},
            "methods": list(d.methods),
            "stages": [
                {
                    "number": st.number,
                    "task": st.task,
                    "methods": list(st.methods),
                    "pairs": [list(p) for p in st.pairs],
                }
                for st in d.stages
            ],
        }

    def resume_link(self, pid: str) -> dict:
        """A new secret for ``pid`` (e.g. to continue on another device); the old one stops working."""
        bodies.parse_participant_id(pid)
        secret = secrets.token_urlsafe(24)
        if not self.store.replace_secret(pid, hash_secret(secret)):
            raise ApiError(404, f"unknown participant {pid!r}")
        return {"participant_id": pid, "url": f"/?participant={pid}&resume={secret}"}


def _trial_key(row: dict) -> str:
    """The key of a scheduled trial's token: its stimulus id, a 2afc trial's ``LEFT~RIGHT``."""
    right = row.get("stimulus_right")
    return row["stimulus_id"] if right is None else f"{row['stimulus_id']}~{right}"


def _stage_units(design, rows: dict) -> tuple[dict[int, list[str]], dict[int, dict[str, list[tuple[str, str]]]]]:
    """The trials' material per stage: {stage: stimulus ids} of the Likert and slider stages,
    {stage: {"A~B": [(video of A, video of B), one per cell]}} of the 2afc stages
    (:func:`crowdstudy.study.schedule.make_schedule`'s two mappings)."""
    cell = {(r["stage"], r["density_level"], r["viewpoint"], r["method"]): sid for sid, r in rows.items()}
    by_stage: dict[int, list[str]] = {}
    comparisons: dict[int, dict[str, list[tuple[str, str]]]] = {}
    for st in design.stages:
        if st.task != "2afc":
            by_stage[st.number] = [sid for sid, r in rows.items() if r["stage"] == st.number]
            continue
        comparisons[st.number] = {
            f"{a}~{b}": [
                (cell[(st.number, lv, vp, a)], cell[(st.number, lv, vp, b)])
                for lv in design.densities
                for vp in st.viewpoints
            ]
            for a, b in st.pairs
        }
    return by_stage, comparisons


def _public_answer(row: dict, token: str, item_ids: tuple[str, ...]) -> dict:
    """A stored answer as its participant may see it: the trial's token, never the stimulus id."""
    items = answer_items(row)
    out = {"trial_index": row["trial_index"], "token": token}
    if row.get("choice") is not None:
        out["choice"] = row["choice"]
    else:
        out.update({k: items.get(k) for k in item_ids})
    return {**out, **{k: row[k] for k in ("rt_ms", "shown_at", "answered_at")}}

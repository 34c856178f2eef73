"""Simulated participants that take the study through the server's HTTP API.

Each bot registers, consents, gives demographics, answers the practice trial, then every
trial of its schedule in order with answers drawn from
:class:`crowdstudy.stats.synthetic.ResponseModel` (each trial by its task: Likert points,
slider positions 0..100, or a 2afc choice of the left or right video; before the first trial
of a task it answers that task's practice trial), and completes. Bots run concurrently
(asyncio, one keep-alive connection each); every answer's round-trip latency is recorded, so the same code serves
the demo, load tests and end-to-end checks of the server.

Participants are blinded: their API names trials only by opaque tokens and carries no
scoring metadata. A bot needs each trial's condition (density, method, ...) and the items'
reversal for the response model, so it reads its schedule from the admin endpoint
``GET /admin/participants/<id>/schedule`` and the scoring from ``GET /admin/study.json``
with the admin token, routes real participants do not have; it answers through the participant API like a
browser does (``trial_index`` + ``token``).
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import time
import urllib.parse

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["SimulationResult", "simulate_participants", "run_simulation", "resolve_method_effects"]


@dataclasses.dataclass
class SimulationResult:
    """Outcome of a simulation.

    participants: ids that completed; answers: answers stored (HTTP 201 or 200);
    latencies_ms: (n_answers,) float64 round-trip time of each answer POST, milliseconds;
    errors: one message per bot that failed; wall_s: seconds for the whole run.
    """

    participants: list[str]
    answers: int
    latencies_ms: np.ndarray
    errors: list[str]
    wall_s: float

    def percentile(self, q: float) -> float:
        """Answer latency percentile ``q`` (0..100), milliseconds (nan without answers)."""
        return float(np.percentile(self.latencies_ms, q)) if self.latencies_ms.size else float("nan")

    def summary(self) -> dict:
        return {
            "participants": len(self.participants),
            "answers": self.answers,
            "errors": len(self.errors),
            "wall_s": round(self.wall_s, 3),
            "latency_ms_p50": round(self.percentile(50), 2),
            "latency_ms_p95": round(self.percentile(95), 2),
            "latency_ms_p99": round(self.percentile(99), 2),
            "latency_ms_max": round(float(self.latencies_ms.max()), 2) if self.latencies_ms.size else None,
        }


class _Connection:
    """A minimal HTTP/1.1 keep-alive JSON client over one asyncio stream (plain http:// only).

    A load generator must cost far less CPU than the server it measures; a general client
    (httpx) spends far more CPU per request than this one, which does no more than it needs.
    It sends JSON, reads responses with a Content-Length (what the study server sends) and
    reconnects once when the server closed an idle connection.
    """

    def __init__(self, host: str, port: int, timeout: float):
        self.host, self.port, self.timeout = host, port, timeout
        self.reader = self.writer = None

    async def _connect(self) -> asyncio.StreamWriter:
        self.reader, self.writer = await asyncio.wait_for(asyncio.open_connection(self.host, self.port), self.timeout)
        return self.writer

    async def close(self):
        if self.writer is not None:
            self.writer.close()
            try:
                await self.writer.wait_closed()
            except (ConnectionError, OSError):
                pass
            self.writer = None

    async def request(
        self, method: str, path: str, payload: dict | None, secret: str | None, headers: dict | None = None
    ) -> tuple[int, dict]:
        body = b"" if payload is None else json.dumps(payload).encode()
        head = [
            f"{method} {path} HTTP/1.1",
            f"Host: {self.host}:{self.port}",
            f"Content-Length: {len(body)}",
            "Accept: application/json",
        ]
        if payload is not None:
            head.append("Content-Type: application/json")
        if secret:
            head.append(f"X-Participant-Secret: {secret}")
        head += [f"{k}: {v}" for k, v in (headers or {}).items()]
        data = ("\r\n".join(head) + "\r\n\r\n").encode() + body
        for attempt in range(2):
            try:
                writer = self.writer if self.writer is not None else await self._connect()
                writer.write(data)
                return await asyncio.wait_for(self._read(), self.timeout)
            except (ConnectionError, asyncio.IncompleteReadError, OSError):
                await self.close()
                if attempt:
                    raise
        raise ConnectionError("unreachable")  # pragma: no cover

    async def _read(self) -> tuple[int, dict]:
        reader = self.reader
        if reader is None:
            raise ConnectionError("not connected")
        head = await reader.readuntil(b"\r\n\r\n")
        lines = head.decode("latin-1").split("\r\n")
        status = int(lines[0].split(" ", 2)[1])
        headers = {k.strip().lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:] if ln)}
        if "content-length" not in headers:
            raise ConnectionError(f"response without Content-Length (status {status})")
        raw = await reader.readexactly(int(headers["content-length"]))
        if headers.get("connection", "").lower() == "close":
            await self.close()
        return status, (json.loads(raw) if raw else {})


def _bot_rng(seed: int, index: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), int(index)])


def resolve_method_effects(methods: list[str], effects: dict[str, float] | None) -> dict[str, float]:
    """{method: points relative to the reference} the bots answer with: ``effects`` checked
    against the study's ``methods`` (the first is the reference), or by default 1 point for
    "Ours" when the study has it (the paper's bots), else none."""
    reference = methods[0]
    if effects is None:
        return {"Ours": 1.0} if "Ours" in methods[1:] else {}
    for name, value in effects.items():
        if name not in methods or name == reference:
            raise InvalidInputError(
                f"--method-effect {name}={value:g}: {name!r} is not a method of the study other than its "
                f"reference {reference!r} (methods: {', '.join(methods)})"
            )
    return {k: float(v) for k, v in effects.items()}


def _model(study: dict, method_effects: dict[str, float], noise_sd: float, **kwargs):
    """The response model of ``study`` (the admin API's scoring metadata: items with their
    reversal, composites, points, methods; the participants' /api/study carries none of it)."""
    from crowdstudy.stats.synthetic import ResponseModel

    composites = {k: tuple(v) for k, v in study["composites"].items()}
    kwargs.setdefault(
        "composite_effects", {c: e for c, e in ResponseModel().composite_effects.items() if c in composites}
    )
    others = {m: v for m, v in method_effects.items() if m != "Ours"}
    return ResponseModel(
        method_effect=float(method_effects.get("Ours", 0.0)),
        method_effects=others,
        noise_sd=float(noise_sd),
        composites=composites,
        reversed_items=tuple(it["id"] for it in study["items"] if it["reverse"]),
        likert_points=int(study["points"]),
        **kwargs,
    )


async def _post(conn: _Connection, url: str, secret: str | None, payload: dict):
    status, data = await conn.request("POST", url, payload, secret)
    if status >= 400:
        raise RuntimeError(f"POST {url} -> {status} {str(data)[:200]}")
    return data


async def _admin_schedule(conn: _Connection, pid: str, admin_token: str) -> dict[int, dict]:
    """{trial_index: trial with token, stimulus id and conditions} from the admin API."""
    status, data = await conn.request(
        "GET", f"/admin/participants/{pid}/schedule", None, None, headers={"Authorization": f"Bearer {admin_token}"}
    )
    if status != 200:
        raise RuntimeError(f"GET /admin/participants/{pid}/schedule -> {status} {str(data)[:200]}")
    return {int(t["trial_index"]): t for t in data["trials"]}


def _answer(model, trial: dict, offsets: dict, rng: np.random.Generator) -> dict:
    """The answer fields of one trial by its task: ``answers`` (Likert, slider) or ``choice``."""
    if trial["task"] == "2afc":
        return {"choice": model.choose(trial["method"], trial["method_right"], offsets, rng)}
    return {"answers": model.answer(trial, offsets, rng, task=trial["task"])}


async def _practice(client, base: str, secret: str, model, offsets: dict, rng, task: str) -> None:
    """Answer the practice trial of ``task`` (the practice clip: no condition)."""
    stim = {"density": 4.44, "method": "practice", "method_right": "practice", "scenario": "concert", "task": task}
    body = {"task": task, **_answer(model, stim, offsets, rng), "rt_ms": 5000.0}
    if task == "likert":
        body.pop("task")  # the body of earlier versions (a server of the paper's design accepts both)
    await _post(client, base + "/practice", secret, body)


async def _one_bot(
    client: _Connection,
    pid: str,
    model,
    rng: np.random.Generator,
    think_time: float,
    latencies: list,
    admin_token: str,
    max_answers: int | None = None,
) -> int:
    reg = await _post(client, "/api/participants", None, {"participant_id": pid})
    secret, state = reg["secret"], reg["state"]
    conditions = await _admin_schedule(client, pid, admin_token)
    base = f"/api/participants/{pid}"
    if not state["consented"]:
        await _post(client, base + "/consent", secret, {"consent": True})
    if not state["demographics"]:
        await _post(
            client,
            base + "/demographics",
            secret,
            {"age": int(rng.integers(18, 71)), "gender": str(rng.choice(["female", "male"]))},
        )
    offsets = model.draw_participant(rng)
    todo = state["trials"][state["next_trial_index"] :]
    practiced = set(state.get("practiced", []))
    first = state["trials"][0]["task"] if state["trials"] else "likert"
    if not state["practice_done"]:
        await _practice(client, base, secret, model, offsets, rng, first)
        practiced.add(first)
    n = 0
    for trial in todo[:max_answers]:
        if think_time > 0:
            await asyncio.sleep(float(rng.uniform(0.0, 2.0 * think_time)))
        full = conditions.get(trial["trial_index"])
        if full is None or full["token"] != trial["token"]:
            raise RuntimeError(f"trial {trial['trial_index']}: the admin schedule does not match the participant's")
        task = full["task"]
        if task not in practiced:
            await _practice(client, base, secret, model, offsets, rng, task)
            practiced.add(task)
        body = {"trial_index": trial["trial_index"], "token": trial["token"], **_answer(model, full, offsets, rng)}
        body.update(
            {
                "rt_ms": float(np.round(2000.0 + rng.lognormal(np.log(8000.0), 0.4), 1)),
                "video_plays": 1,
                "first_play_ms": 20000.0,
                "hidden_count": 0,
                "hidden_ms": 0.0,
                "fullscreen_exits": 0,
            }
        )
        if full.get("check_value") is not None:  # an attentive participant follows the instruction
            v = int(full["check_value"])
            body["check"] = ("left", "right")[v - 1] if task == "2afc" else v
        t0 = time.perf_counter()
        await _post(client, base + "/responses", secret, body)
        latencies.append((time.perf_counter() - t0) * 1000.0)
        n += 1
    if max_answers is None or max_answers >= len(todo):
        await _post(client, base + "/complete", secret, {})
    return n


async def simulate_participants(
    url: str,
    n: int,
    *,
    admin_token: str,
    method_effects: dict[str, float] | None = None,
    method_effect: float | None = None,
    noise_sd: float = 0.9,
    seed: int = 1,
    concurrency: int = 10,
    think_time: float = 0.0,
    prefix: str = "bot",
    timeout: float = 60.0,
    model_kwargs: dict | None = None,
    max_answers: int | None = None,
) -> SimulationResult:
    """Run ``n`` bots against the server at ``url``, at most ``concurrency`` at once.

    admin_token: the server's admin token (the bots read their trials' conditions from the
    admin API; participants are blinded). method_effects: {method: points relative to the
    study's reference method} (default: Ours 1 point when the study has it; methods not named
    have 0); method_effect: the earlier scalar, Ours' effect (merged into method_effects).
    think_time: mean pause before each answer (s;
    uniform 0..2x), 0 = as fast as possible. max_answers: stop each bot after that many answers
    (without completing; benchmarks), None = the whole session. Participant ids are
    ``{prefix}-{seed}-{index:05d}``; the answers depend only on ``seed``.
    """
    for name, value in (("n", n), ("concurrency", concurrency), ("seed", seed)):
        if not isinstance(value, int) or isinstance(value, bool) or value < (0 if name == "seed" else 1):
            raise InvalidInputError(f"{name} must be a positive integer, got {value!r}")
    parsed = urllib.parse.urlsplit(url)
    if parsed.scheme != "http" or not parsed.hostname or parsed.path not in ("", "/"):
        raise InvalidInputError(f"--url must be a plain http://HOST:PORT base URL, got {url!r}")
    host, port = parsed.hostname, parsed.port or 80
    if not isinstance(admin_token, str) or not admin_token or not admin_token.isprintable():
        raise InvalidInputError(
            "--admin-token (or $CROWDSTUDY_ADMIN_TOKEN) is required: the bots read their trials' "
            "conditions from the admin API (participants are blinded)"
        )
    if think_time < 0:
        raise InvalidInputError(f"think_time must be >= 0 seconds, got {think_time!r}")
    t_start = time.perf_counter()
    probe = _Connection(host, port, timeout)
    try:
        status, study = await probe.request("GET", "/api/study", None, None)
    except (TimeoutError, ConnectionError, OSError) as exc:
        raise InvalidInputError(f"--url {url}: no study server answers there ({exc})") from None
    finally:
        await probe.close()
    if status != 200:
        raise InvalidInputError(f"--url {url}: GET /api/study answered {status}")
    probe = _Connection(host, port, timeout)
    try:
        status, data = await probe.request(
            "GET", "/admin/metrics.json", None, None, headers={"Authorization": f"Bearer {admin_token}"}
        )
        if status == 200:
            status, data = await probe.request(
                "GET", "/admin/study.json", None, None, headers={"Authorization": f"Bearer {admin_token}"}
            )
    finally:
        await probe.close()
    if status != 200:
        raise InvalidInputError(
            f"--admin-token: the server at {url} refused it ({status}: {str(data.get('error', ''))[:100]})"
        )
    methods = data.get("methods") or ["Baseline", "Ours"]
    if method_effect is not None:
        method_effects = {"Ours": float(method_effect), **(method_effects or {})}
    model = _model(data, resolve_method_effects(methods, method_effects), noise_sd, **(model_kwargs or {}))
    gate = asyncio.Semaphore(concurrency)
    latencies: list[float] = []
    done: list[str] = []
    errors: list[str] = []
    counts: list[int] = []

    async def run(i: int):
        pid = f"{prefix}-{seed}-{i:05d}"
        async with gate:
            conn = _Connection(host, port, timeout)
            try:
                counts.append(
                    await _one_bot(conn, pid, model, _bot_rng(seed, i), think_time, latencies, admin_token, max_answers)
                )
                done.append(pid)
            except (TimeoutError, RuntimeError, ConnectionError, OSError, ValueError) as exc:
                errors.append(f"{pid}: {type(exc).__name__}: {exc}")
            finally:
                await conn.close()

    await asyncio.gather(*(run(i) for i in range(n)))
    return SimulationResult(
        participants=sorted(done),
        answers=int(sum(counts)),
        latencies_ms=np.asarray(latencies, dtype=np.float64),
        errors=errors,
        wall_s=time.perf_counter() - t_start,
    )


def run_simulation(url: str, n: int, **kwargs) -> SimulationResult:
    """Blocking wrapper of :func:`simulate_participants`."""
    return asyncio.run(simulate_participants(url, n, **kwargs))

"""Importing and initialising NVIDIA Warp the same way everywhere.

Warp compiles kernels on first use (seconds per module on CPU) and caches the binaries; the
cache lives in the per-user cache folder (``crowdstudy.paths``) unless ``WARP_CACHE_PATH``
says otherwise.
"""

from __future__ import annotations

import functools
import os
import re
import threading
import time
from collections.abc import Callable
from typing import Any, Literal

from crowdstudy.paths import cache_dir

__all__ = ["DeviceKind", "device_kind", "get_warp", "resolve_device", "host_threads", "run_parallel", "run_together"]

#: The kinds of Warp device: the host ("cpu") or a CUDA GPU ("cuda", "cuda:N").
DeviceKind = Literal["cpu", "cuda"]
_DEVICE_NAME = re.compile(r"(cpu|cuda)(:\d+)?")


@functools.lru_cache(maxsize=1)
def get_warp():
    """The initialised ``warp`` module, quiet, with the project's kernel cache."""
    cache = os.environ.get("WARP_CACHE_PATH") or str(cache_dir("warp-cache"))
    os.makedirs(cache, exist_ok=True)
    import warp as wp

    # Warp >= 1.10 replaced ``config.quiet`` with ``config.log_level``: silence the banner and
    # the per-module load lines either way.
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING
    else:  # pragma: no cover - older Warp
        wp.config.quiet = True  # pyright: ignore[reportAttributeAccessIssue]  (older Warp only)
    wp.config.kernel_cache_dir = cache
    wp.init()
    return wp


def device_kind(device: str) -> DeviceKind:
    """The kind of a Warp device name: ``"cpu"``, or ``"cuda"`` for ``"cuda"`` and
    ``"cuda:N"``; any other name is an :class:`~crowdstudy.errors.InvalidInputError`
    naming ``device``."""
    match = _DEVICE_NAME.fullmatch(device) if isinstance(device, str) else None
    if match is None or (match.group(1) == "cpu" and match.group(2)):
        from crowdstudy.errors import InvalidInputError

        raise InvalidInputError(f"device: expected 'cpu', 'cuda' or 'cuda:N' (or 'auto'), got {device!r}")
    return "cpu" if match.group(1) == "cpu" else "cuda"


def resolve_device(device: str | None = None) -> str:
    """``"cuda:0"`` when a CUDA device is present and ``device`` is None or ``"auto"``,
    else ``"cpu"``; an explicit name (``"cpu"``, ``"cuda"``, ``"cuda:N"``,
    :func:`device_kind`) is checked and returned."""
    if device is None or device == "auto":
        wp = get_warp()
        return "cuda:0" if wp.is_cuda_available() else "cpu"
    device_kind(device)
    wp = get_warp()
    try:
        wp.get_device(device)
    except Exception as exc:  # warp raises plain RuntimeError/ValueError for unknown devices
        from crowdstudy.errors import InvalidInputError

        raise InvalidInputError(f"device {device!r} is not available ({exc}); use 'cpu' or 'cuda:0'") from None
    return device


def host_threads() -> int:
    """Host threads that Warp CPU launches may run on at once: ``CROWDSTUDY_THREADS`` when
    set (1 switches the splitting off; 2 forces it on, see :func:`run_parallel`), else
    min(2, the CPUs this process may use).

    Warp runs a CPU launch's threads one after the other in the calling thread, but it
    releases the GIL during the launch, so launches on disjoint data from two Python
    threads use two cores."""
    env = os.environ.get("CROWDSTUDY_THREADS")
    if env:
        try:
            value = int(env)
        except ValueError:
            from crowdstudy.errors import InvalidInputError

            raise InvalidInputError(f"CROWDSTUDY_THREADS: expected a positive integer, got {env!r}") from None
        return max(1, value)
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cpus = os.cpu_count() or 1
    return max(1, min(2, cpus))


class _Worker:
    """One persistent helper thread that runs a callable when asked (cheaper than a pool's
    future per call: two Events)."""

    def __init__(self):
        self._go, self._done = threading.Event(), threading.Event()
        self._fn: Callable[[], Any] | None = None
        self._result: tuple[bool, Any] | None = None
        self._thread = threading.Thread(target=self._loop, name="crowdstudy-warp-cpu", daemon=True)
        self._thread.start()

    def _loop(self):
        while True:
            self._go.wait()
            self._go.clear()
            fn = self._fn
            try:
                if fn is None:
                    raise RuntimeError("the helper thread was woken without a call")
                self._result = (True, fn())
            except BaseException as exc:  # handed back to the caller
                self._result = (False, exc)
            self._done.set()

    def submit(self, fn) -> None:
        self._done.clear()
        self._fn = fn
        self._go.set()

    def result(self) -> Any:
        self._done.wait()
        result, self._fn, self._result = self._result, None, None
        if result is None:
            raise RuntimeError("the helper thread finished without a result")
        ok, value = result
        if not ok:
            raise value
        return value


_local = threading.local()  # one helper thread per calling thread


class _Policy:
    """Whether two threads pay off here and now: on a machine whose other core is busy (a
    shared machine) handing work to a second thread costs more than it saves. In parallel
    mode the gain (CPU seconds of both halves over the wall time) is tracked; when it falls
    under ``MIN_GAIN`` the calls run serially for ``SERIAL_CALLS`` calls, then parallel is
    probed again. The callers split work so that the result is the same either way."""

    MIN_GAIN = 1.1
    SERIAL_CALLS = 400
    PROBE_CALLS = 40

    def __init__(self):
        self.gain = 2.0
        self.serial_left = 0
        self.probe_left = 0

    def parallel(self) -> bool:
        if self.serial_left > 0:
            self.serial_left -= 1
            if self.serial_left == 0:
                self.gain, self.probe_left = 2.0, self.PROBE_CALLS
            return False
        return True

    def record(self, cpu: float, wall: float) -> None:
        if wall <= 0.0:
            return
        self.gain = 0.8 * self.gain + 0.2 * (cpu / wall)
        if self.probe_left > 0:
            self.probe_left -= 1
            if self.probe_left > 0:
                return
        if self.gain < self.MIN_GAIN:
            self.serial_left = self.SERIAL_CALLS


def _thread_seconds(fn) -> float:
    """CPU seconds (``time.thread_time``) this thread spent running ``fn``."""
    c0 = time.thread_time()
    fn()
    return time.thread_time() - c0


def _pays_off() -> bool:
    """Whether two calls may go to two threads now: :func:`host_threads` allows it and the
    second core has paid off lately (``_Policy``; always when ``CROWDSTUDY_THREADS`` is set)."""
    policy = getattr(_local, "policy", None)
    if policy is None:
        policy = _local.policy = _Policy()
    forced = bool(os.environ.get("CROWDSTUDY_THREADS"))  # set: no second-guessing (benchmarks)
    return host_threads() >= 2 and (forced or policy.parallel())


def _on_two_threads(first, second) -> tuple[float, float]:
    """``second`` on this thread's helper while ``first`` runs here; waits for both,
    records the gain for ``_Policy`` and returns the CPU seconds of each."""
    worker = getattr(_local, "worker", None)
    if worker is None:
        worker = _local.worker = _Worker()
    w0 = time.perf_counter()
    worker.submit(lambda: _thread_seconds(second))
    try:
        t_first = _thread_seconds(first)
    finally:
        t_second = worker.result()
    _local.policy.record(t_first + t_second, time.perf_counter() - w0)
    return t_first, t_second


def run_parallel(first, second) -> tuple[float, float]:
    """Run two independent callables, ``second`` on a helper thread when
    :func:`host_threads` allows it and it pays off (see ``_Policy``), and wait for both.
    Returns the CPU seconds each took (``time.thread_time``), for balancing the split."""
    if not _pays_off():
        return _thread_seconds(first), _thread_seconds(second)
    return _on_two_threads(first, second)


def run_together(first, second) -> bool:
    """Run two callables that synchronise with each other (e.g. at a ``threading.Barrier``)
    on two threads at once, ``second`` on the helper thread, and wait for both; returns
    True. Where :func:`run_parallel` would run serially (one host thread, or a second core
    that has not paid off lately), runs nothing and returns False: the caller takes its
    serial path, which must give the same result."""
    if not _pays_off():
        return False
    _on_two_threads(first, second)
    return True

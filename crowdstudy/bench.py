"""``crowdstudy bench NAME``: side-by-side performance scripts in ``benchmarks/``.

Each ``benchmarks/NAME.py`` defines ``main(argv: list[str]) -> int``. Benchmarks report
medians over repeated runs and ratios against a peer measured in the same run (pyrvo for
navigation, MuJoCo for physics ...); they write their table as JSON under
``build/bench/NAME.json`` with the provenance of the run, the command line that ran it,
the machine (CPU model, cores, GPUs, load) and the date. The helpers here keep their output
uniform; ``scripts/results_pages.py`` turns the reports kept in ``docs/results/data/`` into
the documentation's results pages.
"""

from __future__ import annotations

import datetime
import importlib.util
import json
import os
import platform
import shlex
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.paths import check_output_path
from crowdstudy.provenance import provenance, repository_root

__all__ = [
    "measure",
    "write_report",
    "report_path",
    "benchmarks_dir",
    "available",
    "load_benchmark",
    "run_benchmarks",
    "machine",
    "command_line",
]

#: The command line of the benchmark that :func:`run_benchmarks` is running (set per
#: benchmark), which :func:`write_report` records; None outside ``crowdstudy bench``.
_RUNNING: str | None = None


def benchmarks_dir() -> Path:
    return repository_root() / "benchmarks"


def available() -> list[str]:
    folder = benchmarks_dir()
    return sorted(p.stem for p in folder.glob("*.py") if not p.stem.startswith("_")) if folder.is_dir() else []


def measure(fn: Callable[[], object], *, repeat: int = 20, warmup: int = 2) -> dict:
    """Time ``fn`` ``repeat`` times after ``warmup`` calls; seconds: median, min, max, all."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "n": repeat}


def report_path(name: str) -> Path:
    """Where :func:`write_report` saves benchmark ``name`` by default: ``build/bench/NAME.json``
    under the working directory (never inside the installed package)."""
    return Path.cwd() / "build" / "bench" / f"{name}.json"


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _gpus() -> list[str]:
    """Names of the NVIDIA GPUs ``nvidia-smi`` lists (empty without the tool or a GPU)."""
    if shutil.which("nvidia-smi") is None:
        return []
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [line.strip() for line in out.splitlines() if line.strip()]


def machine() -> dict:
    """The machine a benchmark ran on: ``cpu`` (model name), ``cores`` (logical CPUs this
    process may use), ``gpus`` (names; empty for none), ``load_average`` (1, 5 and 15
    minutes, when the report is written: other work on a shared machine slows a timing),
    ``platform`` and ``python``."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 0
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        load = None
    return {
        "cpu": _cpu_model(),
        "cores": int(cores),
        "gpus": _gpus(),
        "load_average": load,
        "platform": platform.platform(),
        "python": platform.python_version(),
    }


def command_line() -> str:
    """The command that is running: ``crowdstudy bench NAME ARGS`` inside :func:`run_benchmarks`,
    else this process' own command line."""
    if _RUNNING is not None:
        return _RUNNING
    argv = list(sys.argv) or ["python"]
    prog = Path(argv[0]).name
    return shlex.join(["crowdstudy" if prog == "crowdstudy" else prog, *argv[1:]])


def write_report(name: str, rows: list[dict], *, out: Path | None = None, seed: int | None = None, **extra) -> Path:
    """Save a benchmark table to ``build/bench/NAME.json`` (or ``out``).

    The report holds ``benchmark`` (the name), ``rows``, ``command`` (the command line,
    :func:`command_line`), ``machine`` (:func:`machine`), ``date`` (UTC, ISO 8601, to the
    second), ``provenance`` (seed, git SHA, package versions) and the ``extra`` keys. A
    benchmark may pass its own ``command`` or ``machine`` in ``extra``.
    """
    out = Path(out) if out else report_path(name)
    out.parent.mkdir(parents=True, exist_ok=True)
    now = datetime.datetime.now(datetime.UTC).replace(microsecond=0)
    report = {
        "benchmark": name,
        "rows": rows,
        "command": command_line(),
        "machine": machine(),
        "date": now.isoformat(),
        "provenance": provenance(seed),
    }
    report.update(extra)
    out.write_text(json.dumps(report, indent=2, default=float))
    return out


def load_benchmark(name: str):
    """``benchmarks/NAME.py`` as a module (the benchmarks are scripts, not a package)."""
    path = benchmarks_dir() / f"{name}.py"
    if not path.is_file():
        raise InvalidInputError(f"unknown benchmark {name!r}; available: {', '.join(available()) or 'none'}")
    spec = importlib.util.spec_from_file_location(f"crowdstudy_benchmarks.{name}", path)
    if spec is None or spec.loader is None:
        raise InvalidInputError(f"benchmark {name!r}: {path} cannot be imported")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_benchmarks(name: str, bench_args: list[str]) -> int:
    """Run benchmark ``name`` (or every one, ``"all"``) with ``bench_args``; the exit status
    is the bitwise or of theirs. Every report path is checked before any benchmark runs."""
    names = available() if name == "all" else [name]
    status = 0
    modules = {name: load_benchmark(name) for name in names}
    for name in names:  # before any benchmark runs: a report that cannot be written fails at once
        check_output_path(report_path(name), f"benchmark {name} report")
    global _RUNNING
    for name in names:
        print(f"== benchmark {name} ==", flush=True)
        _RUNNING = shlex.join(["crowdstudy", "bench", name, *bench_args])
        try:
            status |= int(modules[name].main(list(bench_args)) or 0)
        finally:
            _RUNNING = None
    return status

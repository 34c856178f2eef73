"""``crowdstudy bench NAME``: side-by-side performance scripts in ``benchmarks/``.

Each ``benchmarks/NAME.py`` defines ``main(argv: list[str]) -> int``. Benchmarks report
medians over repeated runs and ratios against a peer measured in the same run (pyrvo for
navigation, MuJoCo for physics ...); they write their table as JSON under
``build/bench/NAME.json`` with the provenance of the run. The helpers here keep their
output uniform.
"""

from __future__ import annotations

import importlib.util
import json
import statistics
import time
from pathlib import Path
from typing import Callable

from crowdstudy.errors import InvalidInputError
from crowdstudy.paths import check_output_path
from crowdstudy.provenance import provenance, repository_root

__all__ = ["measure", "write_report", "report_path", "benchmarks_dir", "available", "load_benchmark",
           "run_benchmarks"]


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


def write_report(name: str, rows: list[dict], *, out: Path | None = None, seed: int | None = None, **extra) -> Path:
    """Save a benchmark table with provenance to ``build/bench/NAME.json`` (or ``out``)."""
    out = Path(out) if out else report_path(name)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": name, "rows": rows, "provenance": provenance(seed), **extra},
                              indent=2, default=float))
    return out


def load_benchmark(name: str):
    """``benchmarks/NAME.py`` as a module (the benchmarks are scripts, not a package)."""
    path = benchmarks_dir() / f"{name}.py"
    if not path.is_file():
        raise InvalidInputError(f"unknown benchmark {name!r}; available: {', '.join(available()) or 'none'}")
    spec = importlib.util.spec_from_file_location(f"crowdstudy_benchmarks.{name}", path)
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
    for name in names:
        print(f"== benchmark {name} ==", flush=True)
        status |= int(modules[name].main(list(bench_args)) or 0)
    return status

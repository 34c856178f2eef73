"""``crowdstudy bench NAME [ARGS...]``: run a benchmark script of ``benchmarks/`` (or ``all``);
the benchmarks themselves and their helpers are :mod:`crowdstudy.bench`."""

from __future__ import annotations

import argparse

__all__ = ["configure", "run"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", help="benchmark to run: one of the scripts in benchmarks/, or 'all'")
    parser.add_argument("bench_args", nargs=argparse.REMAINDER, help="arguments passed to the benchmark")


def run(args: argparse.Namespace) -> int:
    from crowdstudy.bench import run_benchmarks

    return run_benchmarks(args.name, list(args.bench_args))

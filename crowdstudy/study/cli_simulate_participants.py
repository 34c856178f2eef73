"""``crowdstudy simulate-participants``: bots answering through a running server's API."""

from __future__ import annotations

import argparse
import json

__all__ = ["configure", "run", "parse_method_effects"]


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--url", default="http://127.0.0.1:8000", help="server base URL")
    parser.add_argument(
        "--admin-token",
        metavar="TOKEN",
        help="the server's admin token (default: $CROWDSTUDY_ADMIN_TOKEN); the bots read their "
        "trials' conditions from the admin API, participants only see opaque tokens",
    )
    parser.add_argument("-n", type=int, default=10, help="number of simulated participants (default 10)")
    parser.add_argument(
        "--method-effect",
        action="append",
        metavar="NAME=POINTS",
        help="a method's effect relative to the study's reference method (its first), Likert points on the "
        "first composite at the reference density; repeatable, methods not named have 0; a bare POINTS means "
        "Ours (default: Ours=1.0 when the study has Ours)",
    )
    parser.add_argument(
        "--density-slope",
        type=float,
        default=0.15,
        help="relative growth of the effect per character/m^2 below the reference density",
    )
    parser.add_argument("--noise", type=float, default=0.9, help="SD of each item answer's noise, points (default 0.9)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the bots' answers and ids (default 1)")
    parser.add_argument("--concurrency", type=int, default=10, help="bots running at once (default 10)")
    parser.add_argument("--think-time", type=float, default=0.0, help="mean pause before each answer, seconds")
    parser.add_argument("--prefix", default="bot", help="participant id prefix (default 'bot')")
    parser.add_argument("--json", metavar="FILE", help="also write the summary as JSON")


def parse_method_effects(values: list[str] | None) -> dict[str, float] | None:
    """``--method-effect`` values (``NAME=POINTS``, or a bare ``POINTS`` for Ours) as
    {method: points}; None when none was given."""
    import math

    from crowdstudy.errors import InvalidInputError

    if not values:
        return None
    out: dict[str, float] = {}
    for raw in values:
        name, sep, number = raw.rpartition("=")
        name = name.strip() if sep else "Ours"
        try:
            points = float(number)
        except ValueError:
            raise InvalidInputError(f"--method-effect must be NAME=POINTS or POINTS, got {raw!r}") from None
        if not name or not math.isfinite(points):
            raise InvalidInputError(f"--method-effect must be NAME=POINTS with a finite number, got {raw!r}")
        if name in out:
            raise InvalidInputError(f"--method-effect gives {name} twice")
        out[name] = points
    return out


def run(args: argparse.Namespace) -> int:
    import os

    from crowdstudy.errors import InvalidInputError
    from crowdstudy.paths import check_output_path
    from crowdstudy.provenance import provenance
    from crowdstudy.study.bots import run_simulation
    from crowdstudy.study.server import ADMIN_TOKEN_ENV

    if args.noise < 0:
        raise InvalidInputError(f"--noise must be >= 0, got {args.noise}")
    if args.json:
        check_output_path(args.json, "--json")
    admin_token = args.admin_token or os.environ.get(ADMIN_TOKEN_ENV)  # checked by the bots
    effects = parse_method_effects(args.method_effect)
    result = run_simulation(
        args.url,
        args.n,
        admin_token=admin_token,
        method_effects=effects,
        noise_sd=args.noise,
        seed=args.seed,
        concurrency=args.concurrency,
        think_time=args.think_time,
        prefix=args.prefix,
        model_kwargs={"density_slope": args.density_slope},
    )
    s = result.summary()
    print(
        f"crowdstudy simulate-participants: {s['participants']}/{args.n} completed, {s['answers']} answers in "
        f"{s['wall_s']:.1f} s; answer latency p50 {s['latency_ms_p50']} ms, p95 {s['latency_ms_p95']} ms, "
        f"p99 {s['latency_ms_p99']} ms"
    )
    for msg in result.errors[:5]:
        print(f"  error: {msg}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(
                {
                    **s,
                    "provenance": provenance(args.seed, n=args.n, method_effects=effects, noise=args.noise),
                },
                fh,
                indent=2,
            )
    return 0 if not result.errors else 1

"""Side-by-side ORCA benchmark: crowdstudy's Warp ORCA vs pyrvo (RVO2 C++) on one scenario.

``crowdstudy bench navigation [--agents 60,1000,10000 --steps 200 --device cpu]``

Scenario (:mod:`crowdstudy.navigation.room`): N agents (radius 0.2 m, simulated with the
corridor's 3 % safety margin; preferred speeds 1.2 +- 0.1 m/s, max speed 1.5 m/s) in a
closed square room at 1.5 agents/m^2, walking towards random goals; ORCA parameters time
step 1/60 s, neighbour distance 1.5 m, 10 neighbours, time horizons 1.0 s (agents) and
0.5 s (walls), identical for both engines.
Reported per engine: overlapping pair-frames (discs overlapping by more than 1 % of the
radius, checked every 10 steps), the largest overlap, mean speed, and the median time of
one step (pyrvo: ``do_step`` only, not the per-agent Python calls that feed it; crowdstudy:
grid build + velocities + integration), and the time ratio pyrvo / crowdstudy.
Bar: crowdstudy at least as fast as pyrvo from 1,000 agents on, the same collision-freeness,
mean speeds within 10 %.

A second table times the Poisson-disk layout (``crowdstudy.layout.poisson_disk``, exactly n
points at least ``0.75 * sqrt(area / n)`` apart) against SciPy's ``qmc.PoissonDisk`` asked
for the same n at the same radius in the unit square (``--layout-points``, default 10,000;
bar: under 1 s).
"""

from __future__ import annotations

import argparse
import sys

from crowdstudy.bench import write_report
from crowdstudy.errors import InvalidInputError
from crowdstudy.tables import format_table


def _agents(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InvalidInputError(f"--agents: expected comma-separated integers, got {text!r}") from None
    if not values or any(v < 2 for v in values):
        raise InvalidInputError(f"--agents: expected agent counts >= 2, got {text!r}")
    return values


def _layout_rows(n: int, seed: int) -> list[dict]:
    import math
    import time

    import numpy as np
    from scipy.spatial import cKDTree

    from crowdstudy.bench import measure
    from crowdstudy.layout import poisson_disk

    def spacing(points):
        d, _ = cKDTree(points).query(points, k=2)
        return float(d[:, 1].min() * math.sqrt(n))  # in units of sqrt(area / n), area = 1

    ours = measure(lambda: poisson_disk((1.0, 1.0), n, seed=seed), repeat=5, warmup=1)
    pts = poisson_disk((1.0, 1.0), n, seed=seed).points
    rows = [
        {
            "method": "crowdstudy poisson_disk",
            "points_asked": n,
            "points_returned": len(pts),
            "min_dist_/sqrt(A/n)": spacing(pts),
            "ms_median": 1000 * ours["median"],
        }
    ]
    try:
        from scipy.stats import qmc
    except ImportError:
        return rows
    radius = 0.75 / math.sqrt(n)
    t0 = time.perf_counter()
    ref = qmc.PoissonDisk(d=2, radius=radius, seed=seed).random(n)
    elapsed = time.perf_counter() - t0
    rows.append(
        {
            "method": "scipy qmc.PoissonDisk",
            "points_asked": n,
            "points_returned": len(ref),
            "min_dist_/sqrt(A/n)": spacing(np.asarray(ref)),
            "ms_median": 1000 * elapsed,
        }
    )
    rows[0]["speedup_vs_scipy"] = elapsed / ours["median"]
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench navigation", description=__doc__.split("\n\n")[0])
    parser.add_argument("--agents", default="60,1000,10000", help="comma-separated agent counts")
    parser.add_argument("--steps", type=int, default=200, help="time steps per run (default 200 = 3.3 s)")
    parser.add_argument("--density", type=float, default=1.5, help="agents per m^2 (default 1.5)")
    parser.add_argument("--device", default="cpu", help="Warp device for crowdstudy (cpu, cuda:0)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--layout-points", type=int, default=10_000, help="points of the layout timing (0: skip)")
    parser.add_argument(
        "--safety-margin",
        type=float,
        default=1.03,
        help="simulated radius / disc radius for both engines (default 1.03, as the corridor)",
    )
    args = parser.parse_args(argv)
    if args.steps < 1:
        raise InvalidInputError(f"--steps: expected >= 1, got {args.steps}")
    from crowdstudy.navigation.room import RoomScenario, run_room

    rows = []
    for n in _agents(args.agents):
        scenario = RoomScenario(n_agents=n, density=args.density, seed=args.seed, safety_margin=args.safety_margin)
        ours = run_room(scenario, args.steps, engine="crowdstudy", device=args.device)
        ref = run_room(scenario, args.steps, engine="pyrvo")
        speed_diff = (ours.mean_speed - ref.mean_speed) / ref.mean_speed
        rows.append(
            {
                "agents": n,
                "steps": args.steps,
                "overlaps_ours": ours.overlaps,
                "overlaps_pyrvo": ref.overlaps,
                "max_overlap_ours_%r": 100 * ours.max_overlap,
                "max_overlap_pyrvo_%r": 100 * ref.max_overlap,
                "speed_ours": ours.mean_speed,
                "speed_pyrvo": ref.mean_speed,
                "speed_diff_%": 100 * speed_diff,
                "ms_step_ours": ours.ms_per_step,
                "ms_step_pyrvo": ref.ms_per_step,
                "speedup": ref.ms_per_step / ours.ms_per_step,
            }
        )
        print(f"  {n} agents done", file=sys.stderr, flush=True)
    print(format_table(rows))
    big = [r for r in rows if r["agents"] >= 1000]
    faster = all(r["speedup"] >= 1.0 for r in big)
    speeds = all(abs(r["speed_diff_%"]) <= 10.0 for r in rows)
    collisions = all(r["max_overlap_ours_%r"] <= max(1.0, 1.5 * r["max_overlap_pyrvo_%r"]) for r in rows)
    print(
        f"bar: at least as fast as pyrvo from 1,000 agents: {'yes' if faster else 'NO'}; "
        f"mean speeds within 10 %: {'yes' if speeds else 'NO'}; "
        f"overlaps no worse than pyrvo's: {'yes' if collisions else 'NO'}"
    )
    layout_rows = _layout_rows(args.layout_points, args.seed) if args.layout_points > 0 else []
    if layout_rows:
        print()
        print(format_table(layout_rows))
        print(
            f"bar: {args.layout_points} layout points in under 1 s: "
            f"{'yes' if layout_rows[0]['ms_median'] < 1000 else 'NO'}"
        )
    path = write_report(
        "navigation",
        rows,
        seed=args.seed,
        device=args.device,
        density=args.density,
        layout_rows=layout_rows,
        safety_margin=args.safety_margin,
        steps=args.steps,
        bar={"faster_from_1000": faster, "speeds_within_10pct": speeds, "overlaps_no_worse": collisions},
    )
    print(f"report: {path}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main(sys.argv[1:]))

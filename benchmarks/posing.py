"""Posing and skinning a crowd for one frame: forward kinematics + linear blend skinning of
60 bodies of the open model (about 9,000 vertices each).

    crowdstudy bench posing [--characters 60] [--repeat 200] [--device cpu] [--no-naive]

Rows (same bodies, same random pose):

* ``CrowdSkinner``: ``crowdstudy.body.skinning.CrowdSkinner.pose`` (Warp: FK one thread per
  body, skinning one thread per run of vertices sharing a joint set), with 1 and with 2
  CPU threads, and ``copy=True`` (results copied out of the skinner's buffers);
* ``CrowdSkinner schedule=vertices``: one Warp thread per vertex (the CUDA schedule; on the
  CPU this is the layout of the first version);
* ``pose_bodies``: ``crowdstudy.body.model.pose_bodies`` (numpy, batched per template);
* peer ``Body.pose loop``: the straightforward numpy code, one ``Body.pose`` per body;
* peer ``naive loop``: FK plus a Python loop over vertices and their weights, timed on one
  body and multiplied by the number of bodies (marked extrapolated).

The Warp rows are timed round-robin (one call of each per round, ``--repeat`` rounds), so
a change of machine load hits them alike; the numpy rows get fewer repeats. Each row
reports the median, min and 90th percentile; the ratio column is each row's median over the
default CrowdSkinner's. The bar: under 5 ms median per frame for 60 bodies. The machine's
load average is recorded before and after: on a shared machine the min is the best guide to
the unloaded time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from crowdstudy.bench import measure, write_report
from crowdstudy.tables import format_table

SEED = 0
BAR_MS = 5.0


def _naive_pose(body, rot, root):
    from crowdstudy.body.skeleton import forward_kinematics

    glob, pos = forward_kinematics(body.rest_joints, rot, root)
    trans = pos - np.einsum("jab,jb->ja", glob, body.rest_joints)
    out = np.zeros_like(body.rest_vertices)
    idx, val = body.top_weights()
    for v in range(body.n_vertices):
        p = body.rest_vertices[v]
        acc = np.zeros(3)
        for k in range(4):
            j = idx[v, k]
            acc += val[v, k] * (glob[j] @ p + trans[j])
        out[v] = acc
    return out


def _round_robin(fns: dict, repeat: int, warmup: int = 3) -> dict:
    """Time each callable once per round; seconds per name: median, min, p90, mean."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    times = {name: [] for name in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {
        name: {
            "median": statistics.median(ts),
            "min": min(ts),
            "p90": float(np.percentile(ts, 90)),
            "mean": statistics.fmean(ts),
            "n": len(ts),
        }
        for name, ts in times.items()
    }


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench posing", description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=200, help="rounds for the Warp rows")
    parser.add_argument("--device", default="cpu", help="Warp device for CrowdSkinner (cpu, cuda:0, auto)")
    parser.add_argument("--no-naive", action="store_true", help="skip the slow per-vertex Python peer")
    args = parser.parse_args(argv)

    import crowdstudy.body as cb
    from crowdstudy.body.model import pose_bodies
    from crowdstudy.body.skinning import CrowdSkinner

    n = args.characters
    bodies = [cb.load_body(r) for r in cb.sample_bodies(n, seed=SEED)]
    rng = np.random.default_rng(SEED)
    rot = rng.normal(0.0, 0.3, (n, 24, 3))
    root = np.c_[rng.uniform(-1.5, 1.5, (n, 2)), np.full(n, 0.95)]
    default = CrowdSkinner(bodies, device=args.device)
    skinners = {f"CrowdSkinner ({default.device}, default: {default.threads} thread(s))": default}
    if default.device == "cpu":
        for threads in (1, 2):
            if threads != default.threads:
                skinners[f"CrowdSkinner ({default.device}, {threads} thread(s))"] = CrowdSkinner(
                    bodies, device=args.device, threads=threads
                )
    other = "segments" if default.schedule == "vertices" else "vertices"
    skinners[f"CrowdSkinner ({default.device}, schedule={other})"] = CrowdSkinner(
        bodies, device=args.device, schedule=other
    )
    n_vertices = default.n_vertices

    # the fast paths agree with Body.pose before anything is timed
    worst = 0.0
    for s in skinners.values():
        verts = s.pose(rot, root, copy=True)[0]
        for i in (0, n - 1):
            ref = bodies[i].pose(rot[i], root[i])[0]
            worst = max(worst, float(np.abs(verts[s.offsets[i] : s.offsets[i + 1]] - ref).max()))

    load_before = _load()
    fns = {name: (lambda s=s: s.pose(rot, root)) for name, s in skinners.items()}
    fns["CrowdSkinner default, copy=True"] = lambda: default.pose(rot, root, copy=True)
    stats = _round_robin(fns, args.repeat)
    stats["pose_bodies (numpy, batched)"] = measure(
        lambda: pose_bodies(bodies, rot, root), repeat=max(3, args.repeat // 40)
    )
    stats["peer: Body.pose loop (numpy)"] = measure(
        lambda: [b.pose(rot[i], root[i]) for i, b in enumerate(bodies)], repeat=3, warmup=1
    )
    load_after = _load()

    rows = [
        {
            "method": name,
            "median_ms": 1e3 * st["median"],
            "min_ms": 1e3 * st["min"],
            "p90_ms": 1e3 * st["p90"] if "p90" in st else float("nan"),
            "repeats": st["n"],
            "note": "",
        }
        for name, st in stats.items()
    ]
    if not args.no_naive:
        t0 = time.perf_counter()
        _naive_pose(bodies[0], rot[0], root[0])
        one = time.perf_counter() - t0
        rows.append(
            {
                "method": "peer: naive per-vertex loop",
                "median_ms": 1e3 * one * n,
                "min_ms": 1e3 * one * n,
                "p90_ms": float("nan"),
                "repeats": 1,
                "note": f"extrapolated from 1 body x {n}",
            }
        )
    base = rows[0]["median_ms"]
    for r in rows:
        r["ratio_vs_default"] = r["median_ms"] / base
    print(
        f"{n} bodies, {n_vertices} vertices, {default.n_segments} skinning segments, one frame; "
        f"max |CrowdSkinner - Body.pose| = {worst:.2e} m"
    )
    print(format_table(rows, ["method", "median_ms", "min_ms", "p90_ms", "repeats", "ratio_vs_default", "note"]))
    verdict = "meets" if base < BAR_MS else "misses"
    print(
        f"bar: < {BAR_MS:g} ms per frame for {n} bodies -> {verdict} (median {base:.2f} ms, "
        f"min {rows[0]['min_ms']:.2f} ms; load average {load_before:.2f} before, {load_after:.2f} after)"
    )
    path = write_report(
        "posing",
        rows,
        seed=SEED,
        characters=n,
        vertices=n_vertices,
        max_error_m=worst,
        load_average_before=load_before,
        load_average_after=load_after,
        bar_ms=BAR_MS,
        meets_bar=bool(base < BAR_MS),
    )
    print(f"wrote {path}")
    return 0

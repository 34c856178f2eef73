"""Posing and skinning a crowd for one frame: forward kinematics + linear blend skinning of
60 bodies of the open model (about 9,000 vertices each).

    crowdstudy bench posing [--characters 60] [--repeat 20] [--device cpu] [--no-naive]

Rows (same bodies, same random pose, median of ``--repeat`` runs):

* ``CrowdSkinner``: ``crowdstudy.body.skinning.CrowdSkinner.pose`` (Warp kernels: one
  thread per body for FK, one per vertex for skinning; result copied to numpy);
* ``pose_bodies``: ``crowdstudy.body.model.pose_bodies`` (numpy, batched per template);
* peer ``Body.pose loop``: the straightforward numpy code, one ``Body.pose`` per body;
* peer ``naive loop``: FK plus a Python loop over vertices and their weights, timed on one
  body and multiplied by the number of bodies (marked extrapolated).

The ratio column is each row's time over the CrowdSkinner's. The bar: under 5 ms per
frame for 60 bodies.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from crowdstudy.bench import format_table, measure, write_report

SEED = 0


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


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench posing", description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=20)
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
    skinner = CrowdSkinner(bodies, device=args.device)
    skinner.pose(rot, root)  # compiles / loads the kernels
    n_vertices = skinner.n_vertices

    rows = []

    def row(name, stats, note=""):
        rows.append({"method": name, "median_ms": 1e3 * stats["median"], "min_ms": 1e3 * stats["min"],
                     "note": note})

    row(f"CrowdSkinner ({skinner.device})", measure(lambda: skinner.pose(rot, root), repeat=args.repeat))
    row("pose_bodies (numpy, batched)", measure(lambda: pose_bodies(bodies, rot, root), repeat=max(3, args.repeat // 4)))
    row("peer: Body.pose loop (numpy)",
        measure(lambda: [b.pose(rot[i], root[i]) for i, b in enumerate(bodies)], repeat=max(3, args.repeat // 4)))
    if not args.no_naive:
        t0 = time.perf_counter()
        _naive_pose(bodies[0], rot[0], root[0])
        one = time.perf_counter() - t0
        rows.append({"method": "peer: naive per-vertex loop", "median_ms": 1e3 * one * n,
                     "min_ms": 1e3 * one * n, "note": f"extrapolated from 1 body x {n}"})
    base = rows[0]["median_ms"]
    for r in rows:
        r["ratio_vs_skinner"] = r["median_ms"] / base
    print(f"{n} bodies, {n_vertices} vertices, one frame")
    print(format_table(rows, ["method", "median_ms", "min_ms", "ratio_vs_skinner", "note"]))
    verdict = "meets" if base < 5.0 else "misses"
    print(f"bar: < 5 ms per frame for {n} bodies -> {verdict} ({base:.2f} ms)")
    try:
        import os

        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    path = write_report("posing", rows, seed=SEED, characters=n, vertices=n_vertices, load_average=load,
                        bar_ms=5.0)
    print(f"wrote {path} (load average {load:.2f})")
    return 0

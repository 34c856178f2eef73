"""Overlap-volume benchmark: the column method against point sampling with Warp.

    crowdstudy bench metrics [--characters 60] [--resolution 0.02] [--repeat 8] [--no-peer]

Scene: the study's densest stationary cell (D5, 60 characters) from
``crowdstudy.motion.build_baseline`` when available, else 60 body-model characters on a
jittered grid over 9 m^2 with random joint rotations. Measured per frame (one call over
``--repeat`` frames against a 1-frame call, median of two: the per-frame cost and the
per-call set-up, i.e. body loading, rest volumes, skinning tables, reported apart):

* ``columns/mesh``: :func:`crowdstudy.metrics.overlap_volume` on the posed body meshes
  (exact z-intervals along vertical columns, ``resolution`` apart), with the crossing
  and skinning kernels in Warp (default) and in pure numpy (``device="numpy"``, posing
  with ``crowdstudy.body.pose_bodies``);
* ``columns/capsule``: the same on the bone capsules;
* ``warp-winding/mesh`` (the peer): the textbook alternative, sample cell centres of a 3D
  grid in every character's AABB intersected with its neighbours' and test each against
  the meshes with Warp's BVH winding-number query
  (``wp.mesh_query_point_sign_winding_number``); one frame at ``--peer-resolution``
  (4 cm: at 2 cm it takes minutes on a CPU), side by side with the column method at the
  same spacing.

Reports ms/frame, the mean overlap (litres per character), and the ratios time(peer) /
time(columns) and volume(columns) / volume(peer).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from crowdstudy.bench import write_report
from crowdstudy.tables import format_table


def _scene(n: int, seed: int = 0):
    """A stationary crowd: build_baseline's D5 cell when ``n`` is its size, else a jittered grid."""
    from crowdstudy.design import load_design
    from crowdstudy.motion import build_baseline

    design = load_design()
    if n == design.n_characters("D5"):
        return build_baseline(design, "stationary", "D5", duration=1.0), "build_baseline stationary D5"
    from crowdstudy.body import load_body
    from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
    from crowdstudy.scene import CrowdAnimation

    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n)))
    grid = (
        np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n] * (3.0 / side) - 1.5 + 1.5 / side
    )
    records = [
        {"model": "open", "sex": ("female", "male")[i % 2], "height": float(rng.uniform(1.55, 1.9))} for i in range(n)
    ]
    t = 30
    roots = np.zeros((t, n, 3))
    roots[:, :, :2] = grid + rng.normal(0, 0.03, grid.shape)
    roots[:, :, 2] = [load_body(r).pelvis_height for r in records]
    rot = rng.normal(0, 0.15, (t, n, 24, 3))
    rot[:, :, 0] = 0.0
    rot[:, :, 0, 2] = rng.uniform(-0.5, 0.5, (t, n))
    rot[:, :, 16, 1] = -1.2
    rot[:, :, 17, 1] = 1.2
    anim = CrowdAnimation(JOINT_NAMES, PARENTS, roots, rot, 30.0, records, [{}] * n, {})
    return anim, f"synthetic: {n} characters, jittered grid on 9 m^2, random poses"


def _warp_peer(anim, frame: int, h: float) -> tuple[float, np.ndarray]:
    """Overlap volumes (N,) m^3 at one frame by 3D point sampling with Warp winding numbers."""
    from crowdstudy.metrics.overlap import resolve_bodies
    from crowdstudy.warp_runtime import get_warp

    wp = get_warp()

    @wp.kernel
    def inside_others(
        meshes: wp.array(dtype=wp.uint64),
        points: wp.array(dtype=wp.vec3),
        owner: wp.array(dtype=wp.int32),
        first: wp.array(dtype=wp.int32),
        partners: wp.array(dtype=wp.int32),
        out: wp.array(dtype=wp.float32),
    ):
        t = wp.tid()
        p = points[t]
        i = owner[t]
        hit = float(0.0)
        q = wp.mesh_query_point_sign_winding_number(meshes[i], p, 1.0e3, 2.0, 0.5)
        if q.result and q.sign < 0.0:
            for k in range(first[i], first[i + 1]):
                if hit == 0.0:
                    q2 = wp.mesh_query_point_sign_winding_number(meshes[partners[k]], p, 1.0e3, 2.0, 0.5)
                    if q2.result and q2.sign < 0.0:
                        hit = 1.0
        out[t] = hit

    bodies = resolve_bodies(anim)
    verts = [
        np.asarray(b.pose(anim.joint_rotations[frame, i], anim.root_translation[frame, i])[0])
        for i, b in enumerate(bodies)
    ]
    t0 = time.perf_counter()
    meshes = [
        wp.Mesh(
            points=wp.array(v, dtype=wp.vec3),
            indices=wp.array(np.asarray(b.faces, np.int32).ravel(), dtype=wp.int32),
            support_winding_number=True,
        )
        for v, b in zip(verts, bodies, strict=True)
    ]
    lo = np.array([v.min(0) for v in verts])
    hi = np.array([v.max(0) for v in verts])
    meet = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
    np.fill_diagonal(meet, False)
    points, owner, first, partners = [], [], [0], []
    for i in range(len(verts)):
        js = np.flatnonzero(meet[i])
        partners.extend(js.tolist())
        first.append(len(partners))
        if len(js) == 0:
            continue
        b_lo = np.maximum(lo[i], lo[js]).min(0)
        b_hi = np.minimum(hi[i], hi[js]).max(0)
        axes = [
            (np.arange(np.ceil(a / h - 0.5), np.floor(b / h - 0.5) + 1) + 0.5) * h
            for a, b in zip(b_lo, b_hi, strict=True)
        ]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        points.append(grid)
        owner.append(np.full(len(grid), i, np.int32))
    pts = np.concatenate(points)
    out = wp.zeros(len(pts), dtype=wp.float32)
    wp.launch(
        inside_others,
        dim=len(pts),
        inputs=[
            wp.array([m.id for m in meshes], dtype=wp.uint64),
            wp.array(pts, dtype=wp.vec3),
            wp.array(np.concatenate(owner), dtype=wp.int32),
            wp.array(np.array(first, np.int32), dtype=wp.int32),
            wp.array(np.array(partners or [0], np.int32), dtype=wp.int32),
            out,
        ],
    )
    wp.synchronize()
    vol = np.bincount(np.concatenate(owner), weights=out.numpy(), minlength=len(verts)) * h**3
    return time.perf_counter() - t0, vol


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench metrics", description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, default=60)
    parser.add_argument("--resolution", type=float, default=0.02)
    parser.add_argument("--repeat", type=int, default=8, help="frames timed for the column method (>= 2)")
    parser.add_argument(
        "--peer-resolution",
        type=float,
        default=0.04,
        help="grid spacing for the side-by-side with the Warp peer (0.04)",
    )
    parser.add_argument("--no-peer", action="store_true", help="skip the (slow) Warp point-sampling peer")
    args = parser.parse_args(argv)
    from crowdstudy.metrics import overlap_volume

    if args.repeat < 2:
        parser.error("--repeat must be at least 2")
    anim, label = _scene(args.characters)
    print(f"scene: {label}; resolution {100 * args.resolution:g} cm", flush=True)
    frames = np.linspace(0, anim.n_frames - 1, args.repeat).astype(int)
    rows = []
    results = {}
    for geometry, device in (("mesh", None), ("mesh", "numpy"), ("capsule", None)):
        overlap_volume(anim, resolution=args.resolution, geometry=geometry, frames=[0], device=device)  # warm-up
        per_frame, setup = [], []
        for _ in range(2):  # a 1-frame call and a `repeat`-frame call: per-frame cost and set-up
            t0 = time.perf_counter()
            overlap_volume(anim, resolution=args.resolution, geometry=geometry, frames=frames[:1], device=device)
            t1 = time.perf_counter()
            res = overlap_volume(anim, resolution=args.resolution, geometry=geometry, frames=frames, device=device)
            t2 = time.perf_counter()
            per_frame.append(((t2 - t1) - (t1 - t0)) / (len(frames) - 1))
            setup.append((t1 - t0) - per_frame[-1])
        times = per_frame
        name = f"columns/{geometry}" + (
            "" if geometry == "capsule" else " (numpy)" if device == "numpy" else " (warp kernel)"
        )
        results[name] = float(np.median(times))
        rows.append(
            {
                "method": name,
                "characters": anim.n_characters,
                "frames": len(frames),
                "ms_per_frame": 1000 * results[name],
                "setup_ms": 1000 * float(np.median(setup)),
                "overlap_litres": res.mean_litres,
            }
        )
    rows[1]["speedup_vs_peer"] = results[rows[1]["method"]] / results[rows[0]["method"]]
    rows[1]["note"] = "speedup = numpy / warp kernel"
    if not args.no_peer:
        # The peer costs far more; compare on one frame at --peer-resolution (frame 0 is
        # also the first of the column method's frames, whose volume is compared).
        f0 = int(frames[0])
        hp = args.peer_resolution
        _warp_peer(anim, f0, hp)  # kernel compile on a cold cache, BVH code paths warm
        peer_s, peer_vol = _warp_peer(anim, f0, hp)
        t0 = time.perf_counter()
        ours = overlap_volume(anim, resolution=hp, geometry="mesh", frames=frames).per_character[0]
        ours_s = (time.perf_counter() - t0) / len(frames)
        rows.append(
            {
                "method": f"columns/mesh @ {100 * hp:g} cm",
                "characters": anim.n_characters,
                "frames": len(frames),
                "ms_per_frame": 1000 * ours_s,
                "overlap_litres": 1000 * float(ours.mean()),
                "speedup_vs_peer": peer_s / ours_s,
                "volume_vs_peer": float(ours.sum() / max(peer_vol.sum(), 1e-12)),
            }
        )
        rows.append(
            {
                "method": f"warp-winding/mesh @ {100 * hp:g} cm (peer)",
                "characters": anim.n_characters,
                "frames": 1,
                "ms_per_frame": 1000 * peer_s,
                "overlap_litres": 1000 * float(peer_vol.mean()),
            }
        )
    print(
        format_table(
            rows,
            [
                "method",
                "characters",
                "frames",
                "ms_per_frame",
                "setup_ms",
                "overlap_litres",
                "speedup_vs_peer",
                "volume_vs_peer",
                "note",
            ],
        )
    )
    path = write_report("metrics", rows, scene=label, resolution=args.resolution)
    print(f"wrote {path}")
    return 0

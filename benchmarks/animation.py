"""Baseline animation benchmark: a 20 s, 60-character crowd, vectorised vs a per-frame loop.

    crowdstudy bench animation [--characters 60] [--duration 20] [--fps 30] [--repeat 5] [--no-peer]

Scenes: the stationary concert crowd (Poisson-disk layout of the study's D5 cell, or a
jittered grid when the layout stage is missing) and the walking corridor crowd (the D5
ORCA trajectories when the navigation stage is there, else synthetic walkers with speed
changes). The trajectories, the bodies and the clips are prepared once (not timed);
the timed call is :func:`crowdstudy.motion.animate_stationary` /
:func:`crowdstudy.motion.animate_walking`: clip choice, sampling, blending, placement, the
per-body leg IK and foot locking, and building the validated ``CrowdAnimation``.

Peer: the obvious implementation, a Python loop over frames and characters that samples
each character's clip(s) at one time (``MotionClip.sample_quaternions`` on a scalar),
blends and places it (no leg IK, so it does strictly less work). Reported: median seconds,
and the ratio peer / ours.
"""

from __future__ import annotations

import argparse

import numpy as np

from crowdstudy.bench import measure, write_report
from crowdstudy.tables import format_table


def _stationary_crowd(n: int, seed: int):
    from crowdstudy.design import load_design
    from crowdstudy.layout import concert_layout
    from crowdstudy.scene import Crowd

    design = load_design()
    level = next((lv for lv in design.densities if design.n_characters(lv) == n), None)
    if level is not None:
        return concert_layout(design, level, seed)
    rng = np.random.default_rng(seed)
    side = int(np.ceil(np.sqrt(n)))
    grid = np.stack(np.meshgrid(np.linspace(-1.3, 1.3, side), np.linspace(-1.3, 1.3, side)), -1).reshape(-1, 2)[:n]
    return Crowd(positions=(grid + rng.normal(0, 0.03, grid.shape))[None], radius=0.2)


def _walking_crowd(n: int, duration: float, fps: float, seed: int):
    from crowdstudy.design import load_design
    from crowdstudy.navigation import corridor_crowd
    from crowdstudy.scene import Crowd

    design = load_design()
    level = next((lv for lv in design.densities if design.n_characters(lv) == n), None)
    if level is not None:
        return corridor_crowd(design, level, seed, duration=duration, fps=fps)
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration * fps))) / fps
    speed = rng.uniform(0.8, 1.5, n) + 0.2 * np.sin(t[:, None] + rng.uniform(0, 6, n))
    pos = np.stack([np.cumsum(speed / fps, axis=0), np.broadcast_to(rng.uniform(-1, 1, n), speed.shape)], -1)
    return Crowd(positions=pos, radius=0.2, fps=fps)


def _naive_stationary(crowd, duration, fps, seed, bodies):
    """Per-frame, per-character loop (the peer)."""
    from crowdstudy.body.rotations import quat_about_z, quat_multiply, quaternion_to_axis_angle
    from crowdstudy.motion import list_clips
    from crowdstudy.motion.baseline import DEFAULT_TEMPO, body_scales
    from crowdstudy.motion.mocap_library import dance_loop

    names = list_clips("dance", default_only=True)
    loops = {name: dance_loop(name, DEFAULT_TEMPO, fps, duration) for name in names}  # the same loops as ours
    rng = np.random.default_rng(seed)
    n = crowd.n_agents
    choice = rng.integers(len(names), size=n)
    phase = rng.uniform(0, 5, n)
    yaw = rng.normal(0, 0.14, n)
    scale = body_scales(bodies)
    n_frames = int(round(duration * fps))
    rot = np.empty((n_frames, n, 24, 3))
    root = np.empty((n_frames, n, 3))
    for f in range(n_frames):
        for i in range(n):
            clip = loops[names[choice[i]]]
            q, r = clip.sample_quaternions(np.array(f / fps + phase[i]))
            q = q.copy()
            q[0] = quat_multiply(quat_about_z(np.array(yaw[i])), q[0])
            rot[f, i] = quaternion_to_axis_angle(q)
            c, s = np.cos(yaw[i]), np.sin(yaw[i])
            root[f, i] = [
                crowd.positions[0, i, 0] + scale[i] * (c * r[0] - s * r[1]),
                crowd.positions[0, i, 1] + scale[i] * (s * r[0] + c * r[1]),
                scale[i] * r[2],
            ]
    return rot, root


def _naive_walking(crowd, bodies):
    from crowdstudy.body.rotations import quat_about_z, quat_blend, quat_multiply, quaternion_to_axis_angle
    from crowdstudy.motion.baseline import body_scales, gait_blend
    from crowdstudy.motion.library import walk_clips

    walks = walk_clips()
    speeds = np.array([c.speed for c in walks])
    strides = np.array([c.meta["stride_length"] for c in walks])
    scale = body_scales(bodies)
    pos = crowd.positions
    n_frames, n = pos.shape[:2]
    rot = np.empty((n_frames, n, 24, 3))
    root = np.empty((n_frames, n, 3))
    phase = np.zeros(n)
    for f in range(n_frames):
        for i in range(n):
            a, b = pos[max(f - 1, 0), i], pos[min(f + 1, n_frames - 1), i]
            v = np.linalg.norm(b - a) * crowd.fps / max(min(f + 1, n_frames - 1) - max(f - 1, 0), 1)
            w = gait_blend(v / scale[i], speeds)
            if f:
                phase[i] += np.linalg.norm(pos[f, i] - pos[f - 1, i]) / (scale[i] * (w @ strides))
            k = int(np.argmax(w > 0))
            k = min(k, len(walks) - 2)
            q0, r0 = walks[k].sample_quaternions(np.array(phase[i] * walks[k].duration))
            q1, r1 = walks[k + 1].sample_quaternions(np.array(phase[i] * walks[k + 1].duration))
            q = quat_blend(q0, q1, np.full(24, w[k + 1]))
            r = (1 - w[k + 1]) * r0 + w[k + 1] * r1
            heading = np.arctan2(b[1] - a[1], b[0] - a[0]) - np.pi / 2
            q[0] = quat_multiply(quat_about_z(np.array(heading)), q[0])
            rot[f, i] = quaternion_to_axis_angle(q)
            c, s = np.cos(heading), np.sin(heading)
            root[f, i] = [
                pos[f, i, 0] + scale[i] * (c * r[0] - s * r[1]),
                pos[f, i, 1] + scale[i] * (s * r[0] + c * r[1]),
                scale[i] * r[2],
            ]
    return rot, root


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench animation", description=__doc__.splitlines()[0])
    parser.add_argument("--characters", type=int, default=60)
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-peer", action="store_true", help="skip the per-frame loop")
    args = parser.parse_args(argv)

    from crowdstudy.body import load_body, sample_bodies
    from crowdstudy.motion import animate_stationary, animate_walking, list_clips, load_clip

    n, dur, fps = args.characters, args.duration, args.fps
    bodies = sample_bodies(n, args.seed)
    for b in bodies:
        load_body(b)
    for name in list_clips():
        load_clip(name)
    stationary = _stationary_crowd(n, args.seed)
    walking = _walking_crowd(n, dur, fps, args.seed)
    rows = []
    cases = [
        (
            "stationary",
            lambda: animate_stationary(stationary, duration=dur, fps=fps, seed=args.seed, bodies=bodies),
            lambda: _naive_stationary(stationary, dur, fps, args.seed, bodies),
        ),
        (
            "walking",
            lambda: animate_walking(walking, fps=fps, seed=args.seed, bodies=bodies),
            lambda: _naive_walking(walking, bodies),
        ),
    ]
    for scene, ours, peer in cases:
        t_ours = measure(ours, repeat=args.repeat, warmup=1)["median"]
        row = {"scene": scene, "characters": n, "frames": int(round(dur * fps)), "ours_s": t_ours}
        if not args.no_peer:
            t_peer = measure(peer, repeat=1, warmup=0)["median"]
            row.update({"per_frame_loop_s": t_peer, "ratio_loop_over_ours": t_peer / t_ours})
        rows.append(row)
    print(format_table(rows))
    target = max(r["ours_s"] for r in rows)
    print(f"slowest build: {target:.3f} s for {dur:g} s x {n} characters (target < 2 s)")
    write_report("animation", rows, seed=args.seed, duration=dur, fps=fps)
    return 0

"""``crowdstudy bench physics``: cost per step of the collision-correction physics.

* median ms per step (split detection / assembly / solve) over ``--steps`` steps for 20
  characters (D1), 60 (D5) and 200 (the D5 scene tiled on a larger floor);
* the CG implementations on the same assembled 60-character system (fused single-launch
  PCG with the per-character tree preconditioner or 6x6 block Jacobi, scipy CG on a BSR
  matrix, warp.optim.linear.cg on a warp.sparse BSR matrix);
* side by side, the same capsule characters as a MuJoCo model (free root + ball joints,
  capsule geoms, soft weld constraints to mocap bodies following the animation) on the same
  scene: ms per step and per simulated 1/60 s, residual capsule overlap, tracking error.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from crowdstudy.bench import format_table, write_report


def _scene(level: str, duration: float, seed: int | None = None):
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary", level, duration=duration, seed=seed)


def _tile(anim, n: int, spacing: float = 3.2):
    """n characters: the scene repeated on a grid of floors ``spacing`` m apart."""
    reps = int(np.ceil(n / anim.n_characters))
    side = int(np.ceil(np.sqrt(reps)))
    roots, rots, bodies, clips = [], [], [], []
    for r in range(reps):
        off = np.array([spacing * (r % side), spacing * (r // side), 0.0])
        roots.append(anim.root_translation + off)
        rots.append(anim.joint_rotations)
        bodies += list(anim.bodies)
        clips += list(anim.clips)
    root = np.concatenate(roots, 1)[:, :n]
    rot = np.concatenate(rots, 1)[:, :n]
    return anim.replace(root_translation=root, joint_rotations=rot, bodies=tuple(bodies[:n]), clips=tuple(clips[:n]),
                        meta={"scenario": "tiled"})


def _corrector(anim, **kw):  # kw: CrowdCorrector options (device, config, ...)
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies

    corr = CrowdCorrector(load_bodies(anim.bodies), fps=anim.fps, n_frames=anim.n_frames, **kw)
    corr.control.set_frames(anim.joint_rotations, anim.root_translation)
    corr.reset_to_frame(0)
    return corr


def time_steps(anim, steps: int, device: str = "cpu") -> dict:
    """Median ms per phase over ``steps`` steps.

    Warp's CPU kernels run synchronously in the calling thread, so both the wall clock and
    the thread's CPU time are recorded: on a shared machine the wall clock also counts the
    time slices other processes take (preemption), the CPU time only this process's work.
    """
    corr = _corrector(anim, device=device)
    sub = corr.substeps
    names = ("detection", "assembly", "solve", "update")
    wp = corr.solver.wp

    def mark():
        if device != "cpu":
            wp.synchronize_device(device)
        return time.perf_counter(), time.thread_time()

    wall = {k: [] for k in (*names, "total")}
    cpu = {k: [] for k in (*names, "total")}
    cg, contacts = [], []
    s = 0
    while s < steps + 4:
        f = 1 + (s // sub) % (anim.n_frames - 1)
        corr.control.advance(f - 1, f, ((s % sub) + 1) / sub)
        marks = [mark()]
        corr.pipeline.collide(corr.states[0], corr.contacts)
        marks.append(mark())
        corr.solver.assemble(corr.states[0], corr.control, corr.contacts, corr.dt)
        marks.append(mark())
        corr.solver.solve(corr.contacts)
        marks.append(mark())
        corr.solver.update(corr.states[0], corr.states[1], corr.dt)
        marks.append(mark())
        corr.states.reverse()
        if s >= 4:
            for i, k in enumerate(names):
                wall[k].append(1000 * (marks[i + 1][0] - marks[i][0]))
                cpu[k].append(1000 * (marks[i + 1][1] - marks[i][1]))
            wall["total"].append(1000 * (marks[-1][0] - marks[0][0]))
            cpu["total"].append(1000 * (marks[-1][1] - marks[0][1]))
            cg.append(corr.solver.last_cg[0])
            contacts.append(corr.contacts.n_active())
        s += 1
    out = {"device": device}
    out.update({f"{k}_cpu_ms": statistics.median(v) for k, v in cpu.items()})
    out.update({f"{k}_wall_ms": statistics.median(v) for k, v in wall.items() if k != "total"})
    out["total_wall_ms"] = statistics.median(wall["total"])
    out["total_wall_min_ms"] = min(wall["total"])
    out.update(cg_iterations=float(np.mean(cg)), contacts=float(np.mean(contacts)))
    return out


def compare_cg(anim, repeat: int = 10) -> list[dict]:
    """The CG implementations on the same assembled CPU system (after 10 steps)."""
    corr = _corrector(anim, device="cpu")
    for s in range(10):     # get into a contact-rich state
        f = 1 + s // 2
        corr.control.advance(f - 1, f, (s % 2 + 1) / 2)
        corr.pipeline.collide(corr.states[0], corr.contacts)
        corr.solver.step(corr.states[0], corr.states[1], corr.control, corr.contacts, corr.dt)
        corr.states.reverse()
    corr.pipeline.collide(corr.states[0], corr.contacts)
    corr.solver.assemble(corr.states[0], corr.control, corr.contacts, corr.dt)
    rows = []
    for name, solver, precond in (("fused PCG, tree precond", "fused", "character"),
                                  ("fused PCG, 6x6 block Jacobi", "fused", "body"),
                                  ("scipy CG on BSR, 6x6 block Jacobi", "scipy", "body"),
                                  ("warp.optim.linear.cg on BSR, tree precond", "warp", "character"),
                                  ("warp.optim.linear.cg on BSR, 6x6 block Jacobi", "warp", "body")):
        corr.solver.linear_solver, corr.solver.preconditioner = solver, precond
        corr.solver.solve(corr.contacts)     # warm-up (compiles)
        times, cpu = [], []
        for _ in range(repeat):
            t0, c0 = time.perf_counter(), time.thread_time()
            corr.solver.solve(corr.contacts)
            times.append(1000 * (time.perf_counter() - t0))
            cpu.append(1000 * (time.thread_time() - c0))
        rows.append({"cg": name, "cpu_ms": statistics.median(cpu), "wall_ms": statistics.median(times),
                     "iterations": corr.solver.last_cg[0], "rel_residual": corr.solver.last_cg[1]})
    best = rows[0]["cpu_ms"]
    for r in rows:
        r["x_fused_tree"] = r["cpu_ms"] / best
    return rows


def mujoco_peer(anim, frames: int, substeps: int = 2):
    """The same capsule characters in MuJoCo: a free root and ball joints per character,
    capsule geoms (density 1000), each bone welded softly (solref 0.05 s) to a mocap body that
    follows the animation (interpolated like ours), ``substeps`` steps per frame.

    Returns ``(anim, timing)``: the simulated CrowdAnimation and cpu/wall ms per mj_step.
    """
    import mujoco

    from scipy.spatial.transform import Rotation

    from crowdstudy.body.rotations import matrix_to_axis_angle, matrix_to_quaternion
    from crowdstudy.body.skeleton import PARENTS, forward_kinematics
    from crowdstudy.physics.corrector import load_bodies

    bodies = load_bodies(anim.bodies)
    n, nj = anim.n_characters, len(PARENTS)
    parts = ['<mujoco><option timestep="%g" gravity="0 0 -9.81" integrator="implicitfast"/>' % (1 / (anim.fps * substeps)),
             '<default><geom density="1000" condim="1" solref="0.01 1"/></default><worldbody>',
             '<geom type="plane" size="50 50 0.1"/>']

    def body_xml(i, j, rest, caps):
        p = PARENTS[j]
        pos = anim.root_translation[0, i] if p < 0 else rest[j] - rest[p]
        s, e = caps.start[j] - rest[j], caps.end[j] - rest[j]
        if np.linalg.norm(e - s) < 1e-4:
            e = s + np.array([0, 0, 1e-3])
        joint = '<freejoint/>' if p < 0 else '<joint type="ball" damping="1" armature="0.01"/>'
        kids = "".join(body_xml(i, c, rest, caps) for c in range(nj) if PARENTS[c] == j)
        return (f'<body name="c{i}b{j}" pos="{pos[0]:.5f} {pos[1]:.5f} {pos[2]:.5f}">{joint}'
                f'<geom type="capsule" fromto="{s[0]:.5f} {s[1]:.5f} {s[2]:.5f} {e[0]:.5f} {e[1]:.5f} {e[2]:.5f}" '
                f'size="{caps.radius[j]:.4f}"/>{kids}</body>')

    for i, b in enumerate(bodies):
        parts.append(body_xml(i, 0, np.asarray(b.rest_joints), b.capsules))
    for i in range(n):
        for j in range(nj):
            parts.append(f'<body name="m{i}b{j}" mocap="true"/>')
    parts.append('</worldbody><equality>')
    for i in range(n):
        for j in range(nj):
            parts.append(f'<weld body1="m{i}b{j}" body2="c{i}b{j}" relpose="0 0 0 1 0 0 0" solref="0.05 1"/>')
    parts.append('</equality></mujoco>')
    model = mujoco.MjModel.from_xml_string("".join(parts))
    data = mujoco.MjData(model)
    bid = np.array([[model.body(f"c{i}b{j}").id for j in range(nj)] for i in range(n)])
    mocap = np.array([[model.body(f"m{i}b{j}").mocapid[0] for j in range(nj)] for i in range(n)])
    rests = np.stack([np.asarray(b.rest_joints) for b in bodies])

    def targets(f0, f1, a):
        root = (1 - a) * anim.root_translation[f0] + a * anim.root_translation[f1]
        rot = anim.joint_rotations[f1] if a > 0.5 else anim.joint_rotations[f0]
        glob, pos = forward_kinematics(rests, rot, root)
        return pos, glob

    pos, glob = targets(0, 0, 0.0)
    data.mocap_pos[mocap.ravel()] = pos.reshape(-1, 3)
    q = matrix_to_quaternion(glob).reshape(-1, 4)
    data.mocap_quat[mocap.ravel()] = q[:, [3, 0, 1, 2]]
    mujoco.mj_forward(model, data)
    out_rot = np.zeros((frames, n, nj, 3))
    out_root = np.zeros((frames, n, 3))
    step_times = []

    def read(f):
        xq = data.xquat[bid.ravel()][:, [1, 2, 3, 0]]
        G = Rotation.from_quat(xq).as_matrix().reshape(n, nj, 3, 3)
        loc = G.copy()
        loc[:, 1:] = np.einsum("nkji,nkjl->nkil", G[:, PARENTS[1:]], G[:, 1:])
        out_rot[f] = matrix_to_axis_angle(loc)
        out_root[f] = data.xpos[bid[:, 0]]

    read(0)
    for f in range(1, frames):
        for s in range(substeps):
            pos, glob = targets(f - 1, f, (s + 1) / substeps)
            data.mocap_pos[mocap.ravel()] = pos.reshape(-1, 3)
            data.mocap_quat[mocap.ravel()] = matrix_to_quaternion(glob).reshape(-1, 4)[:, [3, 0, 1, 2]]
            t0, c0 = time.perf_counter(), time.thread_time()
            mujoco.mj_step(model, data)
            step_times.append((1000 * (time.perf_counter() - t0), 1000 * (time.thread_time() - c0)))
        read(f)
    wall = statistics.median(t[0] for t in step_times)
    cpu = statistics.median(t[1] for t in step_times)
    res = anim.frames(0, frames).replace(root_translation=out_root, joint_rotations=out_rot, meta={"method": "MuJoCo"})
    return res, {"cpu_ms_per_step": cpu, "wall_ms_per_step": wall, "steps_per_60th": substeps * anim.fps / 60.0}


def foot_metrics(anim, reference) -> dict:
    """Feet: mean |height - the animation's| (cm) of the foot joints, and foot skate: mean
    horizontal foot speed (cm/s) over the frames where the animation's foot is planted
    (height < 10 cm and speed < 10 cm/s), for ``anim`` and ``reference``."""
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.physics.corrector import load_bodies

    rest = np.stack([np.asarray(b.rest_joints) for b in load_bodies(anim.bodies)])
    feet = [7, 8, 10, 11]
    _, pa = forward_kinematics(rest[None], anim.joint_rotations, anim.root_translation)
    _, pr = forward_kinematics(rest[None], reference.joint_rotations, reference.root_translation)
    pa, pr = pa[:, :, feet], pr[:, :, feet]
    height = 100 * np.abs(pa[..., 2] - pr[..., 2]).mean()
    va = np.linalg.norm(np.diff(pa[..., :2], axis=0), axis=-1) * anim.fps
    vr = np.linalg.norm(np.diff(pr[..., :2], axis=0), axis=-1) * anim.fps
    planted = (pr[1:, ..., 2] < pr[..., 2].min() + 0.1) & (vr < 0.1)
    return {"foot_height_err_cm": float(height), "foot_skate_cm_s": float(100 * va[planted].mean()),
            "foot_skate_reference_cm_s": float(100 * vr[planted].mean())}


def measure_bars(duration: float, frame_stride: int = 10) -> list[dict]:
    """Overlap (mesh and capsule, m^3 per character) and tracking error (cm) of Baseline vs
    Ours on every (stage, density) cell of the study, ``duration`` seconds each."""
    from crowdstudy.design import load_design
    from crowdstudy.metrics.overlap import overlap_volume
    from crowdstudy.metrics.tracking import tracking_error
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.corrector import correct

    design = load_design()
    rows = []
    for stage in ("stationary", "walking"):
        for level in design.densities:
            base = build_baseline(design, stage, level, duration=duration)
            t0 = time.perf_counter()
            ours = correct(base, progress=False)
            wall = time.perf_counter() - t0
            frames = np.arange(0, base.n_frames, frame_stride)
            row = {"stage": stage, "level": level, "characters": base.n_characters, "frames": base.n_frames}
            for geom in ("mesh", "capsule"):
                ob = overlap_volume(base, geometry=geom, frames=frames).mean
                oo = overlap_volume(ours, geometry=geom, frames=frames).mean
                row[f"{geom}_baseline_m3"] = ob
                row[f"{geom}_ours_m3"] = oo
                row[f"{geom}_ratio"] = oo / max(ob, 1e-12)
            row["tracking_cm"] = tracking_error(ours, base)
            row.update(foot_metrics(ours, base))
            row["correct_wall_s"] = wall
            row["ms_per_step_wall"] = ours.meta["physics"]["ms_per_step"]
            rows.append(row)
            print(format_table([row]), flush=True)
    return rows


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench physics")
    parser.add_argument("--steps", type=int, default=200, help="steps timed per scene")
    parser.add_argument("--peer-frames", type=int, default=60, help="frames simulated for the MuJoCo comparison")
    parser.add_argument("--sizes", default="20,60,200")
    parser.add_argument("--no-peer", action="store_true")
    parser.add_argument("--cpu-only", action="store_true", help="skip the CUDA rows even when a GPU is present")
    parser.add_argument("--peer-substeps", type=int, default=2, help="MuJoCo steps per 30 fps frame (2: 1/60 s)")
    parser.add_argument("--bars", type=float, default=0.0, metavar="SECONDS",
                        help="also measure overlap/tracking on every study cell for SECONDS (20 = the full clips)")
    parser.add_argument("--bars-only", action="store_true", help="only the --bars measurement")
    args = parser.parse_args(argv)
    if args.bars_only:
        bars = measure_bars(args.bars or 20.0)
        path = write_report("physics_bars", bars, seed=None)
        print(f"wrote {path}", file=sys.stderr)
        return 0
    duration = max(args.steps / 60.0 + 0.5, args.peer_frames / 30.0 + 0.2)
    d1, d5 = _scene("D1", duration), _scene("D5", duration)
    from crowdstudy.warp_runtime import get_warp

    cuda = get_warp().is_cuda_available() and not args.cpu_only
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        anim = d1 if n == d1.n_characters else d5 if n == d5.n_characters else _tile(d5, n)
        r = time_steps(anim, args.steps)
        rows.append({"characters": n, **r, "cpu_ms_per_character": r["total_cpu_ms"] / n})
        print(format_table([rows[-1]]), flush=True)
        if cuda:
            r = time_steps(anim, args.steps, device="cuda:0")
            rows.append({"characters": n, **r, "cpu_ms_per_character": r["total_cpu_ms"] / n})
            print(format_table([rows[-1]]), flush=True)
    cg_rows = compare_cg(d5)
    print(format_table(cg_rows), flush=True)
    peer_rows = []
    if not args.no_peer:
        from crowdstudy.metrics.overlap import overlap_volume
        from crowdstudy.metrics.tracking import tracking_error
        from crowdstudy.physics.corrector import correct

        base = d5.frames(0, args.peer_frames)
        ours = correct(base, progress=False, device="cpu")
        ours_t = time_steps(base, min(args.steps, 2 * (args.peer_frames - 1)))
        mj, mj_t = mujoco_peer(base, args.peer_frames, substeps=args.peer_substeps)
        sel = np.arange(args.peer_frames // 2, args.peer_frames, 5)
        ov_base = overlap_volume(base, geometry="capsule", frames=sel).mean
        timing = {"Ours": {"cpu_ms_per_step": ours_t["total_cpu_ms"], "wall_ms_per_step": ours_t["total_wall_ms"],
                           "steps_per_60th": 1.0}, "MuJoCo": mj_t}
        for name, a in (("Ours", ours), ("MuJoCo", mj)):
            ov = overlap_volume(a, geometry="capsule", frames=sel).mean
            t = timing[name]
            peer_rows.append({"method": name, "cpu_ms_per_step": t["cpu_ms_per_step"],
                              "wall_ms_per_step": t["wall_ms_per_step"],
                              "cpu_ms_per_sim_1_60s": t["cpu_ms_per_step"] * t["steps_per_60th"],
                              "overlap_capsule_m3": ov, "overlap_vs_baseline": ov / max(ov_base, 1e-12),
                              "tracking_cm": tracking_error(a, base)})
        for r in peer_rows:
            r["x_ours_cpu_per_sim_time"] = r["cpu_ms_per_sim_1_60s"] / max(peer_rows[0]["cpu_ms_per_sim_1_60s"], 1e-12)
        peer_rows.append({"method": "Baseline", "overlap_capsule_m3": ov_base, "overlap_vs_baseline": 1.0,
                          "tracking_cm": 0.0})
        print(format_table(peer_rows[:2]), flush=True)
        print(f"Baseline capsule overlap: {ov_base:.4g} m^3 per character", flush=True)
    bars = measure_bars(args.bars) if args.bars > 0 else []
    path = write_report("physics", rows, seed=None, cg=cg_rows, peer=peer_rows, bars=bars)
    print(f"wrote {path}", file=sys.stderr)
    return 0

"""``crowdstudy bench physics``: cost per step of the collision-correction physics.

* the device rows (cpu; cuda:N when present, else "cuda: not present");
* median ms per step (split detection / assembly / solve) over ``--steps`` steps for 20
  characters (D1), 60 (D5) and 200 (the D5 scene tiled on a larger floor);
* ``--curve-only --sizes 20,60,200,1000,5000``: the cost curve (ms per simulated 1/60 s,
  CPU and wall, memory per character) and its log-log figure
  ``build/bench/physics_runtime.png``;
* ``--stadium 1000,5000``: ``correct()`` on stadium crowds (``--stadium-level``,
  ``--stadium-seconds``): time, peak memory per character, NaN/stability and the bars;
* ``--bars-only --bars 20 [--cells ...] [--seeds study,1,2]``: the bars of every study cell
  (or of some), on the study's own crowds or on other seeds of the same cells; with more
  than one seed, the spread per cell (:func:`seed_spread`) and its figure
  ``build/bench/physics_bars_seeds.png``;
* the CG implementations on the same assembled 60-character system (fused single-launch
  PCG with the per-character tree preconditioner or 6x6 block Jacobi, scipy CG on a BSR
  matrix, warp.optim.linear.cg on a warp.sparse BSR matrix);
* side by side (``--mujoco`` alone), the same characters as a MuJoCo model (free root +
  ball joints; the same capsules plus mesh skin and contact margin for inter-body and wall
  contacts, the same self pairs, ground and walls; the same settle and interpolated targets,
  through soft welds to mocap bodies) on concert D5 and corridor D5: ms per step and per
  simulated 1/60 s (CPU and wall), mesh and capsule overlap as a fraction of the Baseline's,
  tracking error and jerk, for each MuJoCo tuning in ``MUJOCO_SETTINGS``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

from crowdstudy.bench import format_table, report_path, write_report
from crowdstudy.physics.config_file import add_config_option, config_from_cli
from crowdstudy.physics.crowding import crowd_config


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
    """A CrowdCorrector on ``anim``'s whole clip, placed at frame 0, its configuration
    resolved for the crowd as ``correct()`` resolves it (``PhysicsConfig.for_density``)."""
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies

    kw["config"] = crowd_config(anim, kw.get("config"))[0]
    corr = CrowdCorrector(load_bodies(anim.bodies), fps=anim.fps, n_frames=anim.n_frames, **kw)
    corr.control.set_frames(anim.joint_rotations, anim.root_translation)
    corr.reset_to_frame(0)
    return corr


def time_steps(anim, steps: int, device: str = "cpu", config=None) -> dict:
    """Median ms per phase over ``steps`` steps (``config``: a PhysicsConfig, default the defaults).

    Warp's CPU kernels run synchronously in the calling thread, so both the wall clock and
    the thread's CPU time are recorded: on a shared machine the wall clock also counts the
    time slices other processes take (preemption), the CPU time only this process's work.
    """
    corr = _corrector(anim, device=device, config=config)
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
        corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
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
    out["warp_mib"] = _warp_mib(corr)
    return out


def _warp_mib(corr) -> float:
    """MiB of all Warp arrays a corrector holds (model, states, control frames, contacts,
    collision and solver buffers): the simulation's own memory, on its device."""
    wp = corr.solver.wp
    seen, total = set(), 0
    holders = [corr, corr.pipeline, corr.solver, corr.control, corr.contacts, *corr.states, corr.model.wp]
    if getattr(corr.pipeline, "_scratch", None) is not None:
        holders.append(corr.pipeline._scratch)
    for h in holders:
        values = h.values() if isinstance(h, dict) else vars(h).values()
        flat = []
        for v in values:
            flat.extend(v if isinstance(v, (list, tuple)) else [v])
        for v in flat:
            if isinstance(v, wp.array) and id(v) not in seen:
                seen.add(id(v))
                total += int(v.capacity)
    return total / 2**20


def _rss_mib(field: str = "VmRSS") -> float:
    """Resident (``VmRSS``) or peak resident (``VmHWM``) memory of this process, MiB (Linux;
    NaN elsewhere)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def device_rows(cpu_only: bool = False) -> list[dict]:
    """One row per Warp device the benchmark can run on: ``cpu`` always, ``cuda:0`` with
    its name when a CUDA device is present, else the row ``cuda: not present``."""
    from crowdstudy.warp_runtime import get_warp, host_threads

    wp = get_warp()
    cpu = wp.get_device("cpu")
    rows = [{"device": "cpu", "present": True, "name": getattr(cpu, "name", "cpu"),
             "host_threads": host_threads()}]
    if cpu_only:
        rows.append({"device": "cuda", "present": False, "name": "skipped (--cpu-only)"})
    elif wp.is_cuda_available():
        for dev in wp.get_cuda_devices():
            rows.append({"device": str(dev), "present": True, "name": dev.name, "host_threads": None})
    else:
        rows.append({"device": "cuda", "present": False, "name": "cuda: not present"})
    for r in rows:
        print(f"device {r['device']}: {r['name'] if r['present'] else r['name']}", flush=True)
    return rows


def cost_curve(sizes, steps: int, device: str = "cpu", base=None, config=None) -> list[dict]:
    """ms per step (= per simulated 1/60 s at the study's 1/60 s step) against characters:
    the D5 concert tiled on a grid of floors (:func:`_tile`) for each size; CPU (main
    thread) and wall medians over ``steps`` steps, the phases, and memory: the Warp arrays
    of the corrector (MiB, and KiB per character) and the resident growth of the process
    (MiB; the allocator reuses what earlier sizes freed, so it undercounts after the first)."""
    import gc

    base = base if base is not None else _scene("D5", max(steps, 8) / 60.0 + 0.5)
    rows = []
    for n in sizes:
        anim = base if n == base.n_characters else _tile(base, n)
        gc.collect()
        rss0 = _rss_mib()
        r = time_steps(anim, steps, device=device, config=config)
        grown = _rss_mib() - rss0
        row = {"characters": n, "device": device, "steps": steps, "load": os.getloadavg()[0],
               "cpu_ms_per_60th": r["total_cpu_ms"], "wall_ms_per_60th": r["total_wall_ms"],
               "wall_min_ms": r["total_wall_min_ms"],
               **{k: r[k] for k in r if k.endswith("_cpu_ms") and k != "total_cpu_ms"},
               "cg_iterations": r["cg_iterations"], "contacts": r["contacts"],
               "warp_mib": r["warp_mib"], "warp_kib_per_character": 1024.0 * r["warp_mib"] / n,
               "rss_growth_mib": grown,
               "peak_rss_mib": _rss_mib("VmHWM")}
        rows.append(row)
        print(format_table([row]), flush=True)
        del anim
    return rows


def runtime_figure(rows: list[dict], path=None):
    """ms per simulated 1/60 s against characters, log-log (PNG): CPU and wall time per
    device, with the 40 ms bar at 1,000 characters and a linear-cost guide."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = report_path("physics_runtime").with_suffix(".png") if path is None else path
    fig, ax = plt.subplots(figsize=(6.0, 4.2), dpi=120)
    for dev in sorted({r["device"] for r in rows}):
        sel = sorted((r for r in rows if r["device"] == dev), key=lambda r: r["characters"])
        n = [r["characters"] for r in sel]
        ax.loglog(n, [r["cpu_ms_per_60th"] for r in sel], "o-", label=f"{dev}: CPU time (main thread)")
        ax.loglog(n, [r["wall_ms_per_60th"] for r in sel], "s--", label=f"{dev}: wall time")
    ns = np.array(sorted({r["characters"] for r in rows}), float)
    if len(ns):
        ref = min(rows, key=lambda r: r["characters"])
        ax.loglog(ns, ref["cpu_ms_per_60th"] * ns / ref["characters"], ":", color="grey", label="linear in N")
    ax.plot([1000], [40.0], "r*", ms=12, label="bar: 40 ms at 1,000")
    ax.set_xlabel("characters")
    ax.set_ylabel("ms per simulated 1/60 s")
    ax.set_title("crowdstudy physics step (Warp CPU)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def stadium_crowd(n: int, level: str, duration: float, seed: int = 1):
    """The Baseline of a stadium concert: ``n`` characters at ``level``'s density
    (:func:`~crowdstudy.layout.concert_layout` with ``n_characters``), animated as
    ``crowdstudy animate layout.npz`` does."""
    from crowdstudy.design import load_design
    from crowdstudy.layout import concert_layout
    from crowdstudy.motion.baseline import animate_stationary

    design = load_design()
    crowd = concert_layout(design, level, seed, n_characters=n)
    meta = {k: crowd.meta[k] for k in ("density_level", "density", "n_characters")}
    return animate_stationary(crowd, duration=duration, fps=design.fps, seed=seed,
                              meta={**meta, "seed": seed, "stage": "stationary"})


def _central_subset(anim, k: int):
    """The ``k`` characters nearest the floor's centre (frame 0), in index order."""
    d = np.linalg.norm(anim.root_translation[0, :, :2], axis=1)
    idx = np.sort(np.argsort(d, kind="stable")[:k])
    return idx


def _select(anim, idx):
    return anim.replace(root_translation=anim.root_translation[:, idx], joint_rotations=anim.joint_rotations[:, idx],
                        bodies=tuple(anim.bodies[i] for i in idx), clips=tuple(anim.clips[i] for i in idx))


class _BodyProxy:
    """What the physics and the joint metrics read of a body: rest joints, capsules, and (for
    the capsules' mesh skin, ``capsule_skin``) the rest vertices with a one-hot of each
    vertex's dominant bone instead of the float skinning weights and the faces. The same
    skin as the full body; about 0.7 MB instead of several MB per MakeHuman character."""

    def __init__(self, body):
        self.rest_joints = np.asarray(body.rest_joints, np.float64)
        self.capsules = body.capsules
        self.rest_vertices = np.asarray(body.rest_vertices, np.float64)
        weights = np.asarray(body.weights)
        dominant = weights.argmax(1)
        self.weights = np.zeros(weights.shape, np.uint8)
        self.weights[np.arange(len(dominant)), dominant] = 1


def tile_ratios(xy: np.ndarray, baseline: np.ndarray, ours: np.ndarray, tile: tuple[float, float],
                min_characters: int) -> np.ndarray:
    """The overlap ratio of each neighbourhood of a large crowd: the characters binned by
    their floor position ``xy`` (N, 2) m into ``tile`` = (width, depth) m rectangles (a study
    cell's floor), and per tile the sum of Ours' per-character overlap over the Baseline's
    (``ours``, ``baseline``: (N,) m^3). Tiles with fewer than ``min_characters`` characters
    (the crowd's ragged edge) or no Baseline overlap are left out. Returns the ratios, in
    tile order (row-major from the smallest x and y)."""
    xy = np.asarray(xy, float)
    if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) != len(baseline) or len(xy) != len(ours):
        raise ValueError(f"xy (N, 2), baseline (N,) and ours (N,): got {xy.shape}, {np.shape(baseline)}, "
                         f"{np.shape(ours)}")
    if len(xy) == 0:
        return np.zeros(0)
    cell = np.floor((xy - xy.min(axis=0)) / np.asarray(tile, float)).astype(int)
    _, tile_of = np.unique(cell[:, 1] * (cell[:, 0].max() + 1) + cell[:, 0], return_inverse=True)
    count = np.bincount(tile_of)
    b = np.bincount(tile_of, weights=np.asarray(baseline, float))
    o = np.bincount(tile_of, weights=np.asarray(ours, float))
    keep = (count >= min_characters) & (b > 0)
    return o[keep] / b[keep]


def _profile_columns(ours) -> dict:
    """How crowded ``correct()`` found the crowd and the skins and hold it used
    (``PhysicsConfig.for_density``)."""
    phys = ours.meta["physics"]
    return {"crowd_density": phys["crowd_density"], "profile_weight": phys["profile_weight"],
            "mesh_skin_max": phys["config"]["skin"]["max"], "output_hold": phys["config"]["output"]["hold"]}


def _smoothness_columns(base, ours, bodies=None) -> dict:
    """The smoothness columns of a bars row (:func:`crowdstudy.metrics.smoothness`): each
    measure's ``NAME_baseline`` and ``NAME_ours``, ``jerk_ratio`` and
    ``foot_slide_over_5cm_s_ours``."""
    from crowdstudy.metrics import smoothness

    sb, so = smoothness(base, base, bodies=bodies).as_dict(), smoothness(ours, base, bodies=bodies).as_dict()
    cols = {}
    for key, name in (("jerk_m_s3", "jerk"), ("hf_share", "hf_share"), ("max_joint_speed_m_s", "max_joint_speed"),
                      ("pelvis_accel_p99_m_s2", "pelvis_p99"), ("foot_slide_p99_m_s", "foot_slide_p99"),
                      ("seam_ratio", "seam_ratio")):
        cols[f"{name}_baseline"], cols[f"{name}_ours"] = sb[key], so[key]
    cols["jerk_ratio"] = so["jerk_m_s3"] / sb["jerk_m_s3"]
    cols["foot_slide_over_5cm_s_ours"] = so["foot_slide_fraction_over_5cm_s"]
    return cols


def stadium_run(n: int, level: str = "D3", duration: float = 20.0, frame_stride: int = 10,
                overlap_characters: int = 300, light_bodies: bool = False, config=None) -> dict:
    """``correct()`` on a stadium crowd (:func:`stadium_crowd`): wall time, ms per step, peak
    memory, NaN/stability, and the bars (:func:`bar_checks`) of Ours against its Baseline.

    The mesh overlap is measured on every ``frame_stride``-th frame and on the
    ``overlap_characters`` characters nearest the floor's centre (the overlap among them;
    the full crowd's mesh overlap costs minutes per frame at 5,000); the smoothness and
    tracking on every character and frame. The overlap is also given neighbourhood by
    neighbourhood (:func:`tile_ratios` on study-cell-sized tiles: ``tiles``,
    ``mesh_ratio_tile_min/median/max``, ``tiles_over_overlap_bar``), the spread a study cell
    of the same density shows from crowd to crowd. ``light_bodies`` hands ``correct()`` and the
    joint metrics :class:`_BodyProxy` objects (at 5,000 MakeHuman characters the full body
    models alone would not fit in 24 GiB: ``correct()`` keeps every body for the run)."""
    from crowdstudy.body import load_body
    from crowdstudy.design import load_design
    from crowdstudy.metrics import overlap_volume, tracking_error
    from crowdstudy.physics.corrector import correct

    design = load_design()
    levels = list(design.densities)
    rss0 = _rss_mib()
    t0 = time.perf_counter()
    base = stadium_crowd(n, level, duration)
    t_anim = time.perf_counter() - t0
    rss_base = _rss_mib()
    timings: dict = {}
    c0 = time.process_time()
    t0 = time.perf_counter()
    bodies = [_BodyProxy(load_body(rec)) for rec in base.bodies] if light_bodies else None
    ours = correct(base, config, progress=False, device="cpu", timings=timings, bodies=bodies)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    peak = _rss_mib("VmHWM")
    finite = bool(np.all(np.isfinite(ours.root_translation)) and np.all(np.isfinite(ours.joint_rotations)))
    # stable: no body ran away from its animation (the largest root deviation, m)
    max_dev = float(np.max(np.linalg.norm(ours.root_translation - base.root_translation, axis=-1)))
    row = {"stage": "stationary", "level": level, "characters": n, "frames": base.n_frames, "seconds": duration,
           "animate_s": t_anim, "correct_wall_s": wall, "correct_cpu_s": cpu,
           "setup_s": timings.get("setup_seconds"), "simulate_s": timings.get("simulate_seconds"),
           "output_s": timings.get("output_seconds"), "ms_per_step_wall": timings.get("ms_per_step"),
           "steps": timings.get("steps"), "finite": finite, "max_root_deviation_m": max_dev,
           "baseline_rss_mib": rss_base - rss0, "peak_rss_mib": peak,
           "peak_kib_per_character": 1024.0 * (peak - rss0) / n,
           "bodies": "proxies (rest joints, capsules, vertices)" if light_bodies else "full body models",
           "loop": loop_mode(base), **_profile_columns(ours)}
    sub = _central_subset(base, min(overlap_characters, n))
    frames = np.arange(0, base.n_frames, frame_stride)
    for geom in ("mesh", "capsule"):
        rb = overlap_volume(_select(base, sub), geometry=geom, frames=frames)
        ro = overlap_volume(_select(ours, sub), geometry=geom, frames=frames)
        ob, oo = rb.mean, ro.mean
        row[f"{geom}_baseline_m3"], row[f"{geom}_ours_m3"], row[f"{geom}_ratio"] = ob, oo, oo / max(ob, 1e-12)
        if geom == "mesh":      # per character, for the neighbourhoods below
            mesh_per_character = (rb.per_character.mean(axis=0), ro.per_character.mean(axis=0))
    row["overlap_subset"] = f"{len(sub)} central characters, every {frame_stride}th frame"
    # the same overlap neighbourhood by neighbourhood: study-cell-sized tiles of the floor
    tile = (float(design.floor_width), float(design.floor_depth))
    ratios = tile_ratios(base.root_translation[0, sub, :2], *mesh_per_character, tile,
                         min_characters=max(1, design.n_characters(level) // 2))
    row["tile_m"] = f"{tile[0]:g} x {tile[1]:g}"
    row["tiles"] = len(ratios)
    if len(ratios):
        row["mesh_ratio_tile_min"], row["mesh_ratio_tile_median"], row["mesh_ratio_tile_max"] = (
            float(ratios.min()), float(np.median(ratios)), float(ratios.max()))
        row["tiles_over_overlap_bar"] = f"{int(np.sum(ratios > 0.05))}/{len(ratios)}"
    row["tracking_cm"] = tracking_error(ours, base, bodies=bodies)
    row.update(_smoothness_columns(base, ours, bodies))
    checks = bar_checks(row, levels.index(level), len(levels))
    row["bars_failed"] = ",".join(k for k, ok in checks.items() if not ok) or "-"
    print(format_table([row]), flush=True)
    return row


def compare_cg(anim, repeat: int = 10) -> list[dict]:
    """The CG implementations on the same assembled CPU system (after 10 steps)."""
    corr = _corrector(anim, device="cpu")
    for s in range(10):     # get into a contact-rich state
        f = 1 + s // 2
        corr.control.advance(f - 1, f, (s % 2 + 1) / 2)
        corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
        corr.solver.step(corr.states[0], corr.states[1], corr.control, corr.contacts, corr.dt)
        corr.states.reverse()
    corr.pipeline.collide(corr.states[0], corr.contacts, corr.control)
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


# --- MuJoCo peer ----------------------------------------------------------------------------
#
# The same characters as a MuJoCo model, built from the SAME crowdstudy Model as Ours
# (ModelBuilder + PhysicsConfig.mesh_skin):
#
# * per bone two capsules on the same segment: a "core" of the bare radius (density ->
#   the same masses and inertias; ground contacts and self contacts, like ours) and a
#   "hull" of radius + mesh skin with geom margin = contact_margin (inter-body and wall
#   contacts, like ours). A MuJoCo contact of two geoms is active below
#   max(margin1, margin2) = contact_margin, the distance the constraint holds: exactly our
#   depth r_a + skin_a + r_b + skin_b + margin - distance (the margin counted once per pair;
#   inflating both radii by the margin would count it twice, and walls once).
# * contype/conaffinity: hull 1/1, core 2/0, ground plane 0/2 (cores only), walls 0/1
#   (hulls only); every body pair of one character is <exclude>d from the dynamic pairs, and
#   the self contacts are explicit <pair>s of core geoms, exactly Model.intra_pairs (not
#   parent-child, not touching in the T-pose).
# * targets: each bone is welded (soft equality) to a mocap body placed at every MuJoCo step
#   at the same interpolated target as ours (nlerp of the joint rotations and lerp of the
#   root between two frames, then forward kinematics: targets_kernel).
# * settle: config.solver.settle_time simulated on frame 0, targets frozen, before frame 0 is read.
# * walls: crowdstudy.scene_meta.static_walls_from_meta, as boxes WALL_DEPTH deep behind
#   the wall's face (ours: one-sided planes facing the characters' roots); in periodic
#   scenes (the corridor) the walls are stretched over the whole run and every character has
#   two kinematic images at +-L (mocap bodies with its hulls, moved to the simulated pose
#   every step): MuJoCo has no periodic boundary, the images stand in for our minimum image.
# * output: the joint rotations R_parent^T R_child (root global) and the pelvis joint
#   position, by :func:`rigid_to_animation`, the numpy twin of project_kernel.

#: m, how deep MuJoCo's wall boxes reach behind the wall's face (away from the crowd)
WALL_DEPTH = 0.5

MUJOCO_SETTINGS = {
    # name: MuJoCo steps per 30 fps frame, weld solref (timeconst, dampratio), contact solref,
    # solimp (welds and contacts), joint damping (N m s/rad)
    "weld0.05": dict(substeps=2, weld_solref=(0.05, 1.0), contact_solref=(0.0334, 1.0),
                     solimp=(0.9, 0.95, 0.001), joint_damping=1.0),
    "weld0.1-stiffcontact": dict(substeps=2, weld_solref=(0.1, 1.0), contact_solref=(0.0334, 1.0),
                                 solimp=(0.95, 0.99, 0.001), joint_damping=1.0),
    "weld0.05-dt1/120": dict(substeps=4, weld_solref=(0.05, 1.0), contact_solref=(0.0167, 1.0),
                             solimp=(0.95, 0.99, 0.001), joint_damping=1.0),
    # stiffer welds (MuJoCo clamps a timeconst below 2 steps, so this needs the 1/120 s step)
    "weld0.025-dt1/120": dict(substeps=4, weld_solref=(0.025, 1.0), contact_solref=(0.0167, 1.0),
                              solimp=(0.95, 0.99, 0.001), joint_damping=1.0),
}


def check_timeconsts(setting: dict, dt: float) -> None:
    """Raise ValueError where a weld's or contact's solref time constant is under 2 steps:
    MuJoCo silently clamps it to 2 * dt, so two such tunings would run the same model."""
    for key in ("weld_solref", "contact_solref"):
        timeconst = float(setting[key][0])
        if timeconst < 2.0 * dt - 1e-9:
            raise ValueError(f"MuJoCo setting {key}: time constant {timeconst:g} s is under 2 steps "
                             f"({2.0 * dt:.4g} s at a {dt:.4g} s step), which MuJoCo clamps to 2 steps")


def _quat_mul(a, b):
    """Hamilton product of scalar-last quaternions (..., 4)."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], -1)


def _quat_rotate(q, v):
    vq = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], -1)
    conj = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return _quat_mul(_quat_mul(q, vq), conj)[..., :3]


def interpolated_targets(anim_q, anim_root, rests, f0: int, f1: int, alpha: float):
    """The target pose of ``targets_kernel`` in numpy (float64).

    anim_q (F, N, J, 4) joint rotations (scalar-last; root global), anim_root (F, N, 3) m,
    rests (N, J, 3) m. Local rotations nlerp (short arc) and the root lerps between frames
    f0 and f1 at ``alpha``; returns ``(global rotations (N, J, 4), joint positions (N, J, 3))``.
    """
    from crowdstudy.body.skeleton import PARENTS

    a, b = anim_q[f0], anim_q[f1]
    s = np.where(np.sum(a * b, -1, keepdims=True) < 0.0, -1.0, 1.0)
    local = (1.0 - alpha) * a + s * alpha * b
    local /= np.linalg.norm(local, axis=-1, keepdims=True)
    glob = np.empty_like(local)
    pos = np.empty(local.shape[:-1] + (3,))
    glob[:, 0] = local[:, 0]
    pos[:, 0] = (1.0 - alpha) * anim_root[f0] + alpha * anim_root[f1]
    for j in range(1, len(PARENTS)):
        p = PARENTS[j]
        glob[:, j] = _quat_mul(glob[:, p], local[:, j])
        pos[:, j] = pos[:, p] + _quat_rotate(glob[:, p], rests[:, j] - rests[:, p])
    return glob, pos


def rigid_to_animation(glob_q, root_pos):
    """Bone world rotations (..., J, 4) scalar-last and pelvis joint positions (..., 3) ->
    ``(joint_rotations (..., J, 3) axis-angle, root (..., 3))``: root global, the others
    R_parent^T R_child, as ``project_kernel`` writes Ours."""
    from crowdstudy.body.rotations import quaternion_to_axis_angle
    from crowdstudy.body.skeleton import PARENTS

    q = np.asarray(glob_q, np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    local = q.copy()
    conj = q[..., PARENTS[1:], :] * np.array([-1.0, -1.0, -1.0, 1.0])
    local[..., 1:, :] = _quat_mul(conj, q[..., 1:, :])
    return quaternion_to_axis_angle(local), np.asarray(root_pos, np.float64).copy()


class MujocoScene:
    """The MuJoCo model of a crowd (see the notes above) and the bookkeeping to drive it.

    Attributes: ``model``/``data`` (MjModel/MjData), ``cs_model`` (crowdstudy Model used for
    the geometry), ``body_id`` (N, J) simulated bodies, ``mocap_id`` (N, J) target mocap
    slots, ``ghost_mocap`` (K, N, J) image mocap slots, ``ghost_shift`` (K,) m along x,
    ``hull_geom``/``core_geom`` (N, J) geom ids, ``dt`` s, ``substeps`` per frame.
    """

    def __init__(self, anim, config=None, setting: str | dict = "weld0.05"):
        import mujoco

        from crowdstudy.body.skeleton import PARENTS
        from crowdstudy.scene_meta import static_walls_from_meta
        from crowdstudy.physics.corrector import load_bodies
        from crowdstudy.physics.model import ModelBuilder

        self.mujoco = mujoco
        self.anim = anim
        # the geometry and hold correct() would use on this crowd
        self.config = config = crowd_config(anim, config)[0]
        self.setting = st = dict(MUJOCO_SETTINGS[setting] if isinstance(setting, str) else setting)
        bodies = load_bodies(anim.bodies)
        builder = ModelBuilder()
        for b in bodies:
            builder.add_character(b.rest_joints, b.capsules, config.mesh_skin(b))
        cm = self.cs_model = builder.finalize(density=config.body.density, device="cpu")
        n, nj = cm.n_characters, cm.n_joints
        self.n, self.nj = n, nj
        self.rests = np.asarray(cm.rest_joints, np.float64)
        self.substeps = int(st["substeps"])
        self.dt = 1.0 / (anim.fps * self.substeps)
        check_timeconsts(st, self.dt)
        from crowdstudy.body.rotations import axis_angle_to_quaternion

        self.anim_q = axis_angle_to_quaternion(anim.joint_rotations)
        self.anim_root = np.asarray(anim.root_translation, np.float64)
        period = anim.periodic_length
        self.ghost_shift = np.array([-period, period]) if period else np.zeros(0)
        margin = float(config.contacts.margin)
        p0 = (cm.cap_p0 + cm.body_com_rest).reshape(n, nj, 3)    # capsule ends in the rest frame
        p1 = (cm.cap_p1 + cm.body_com_rest).reshape(n, nj, 3)
        rad = cm.cap_radius.reshape(n, nj)
        hull = (cm.cap_radius + cm.cap_skin).reshape(n, nj)
        sr = lambda v: f'{v[0]:g} {v[1]:g}'                     # noqa: E731
        si = " ".join(f"{v:g}" for v in st["solimp"])
        g = -float(config.body.gravity)
        parts = [f'<mujoco><option timestep="{self.dt:.10g}" gravity="0 0 {g:g}" integrator="implicitfast"/>',
                 '<size memory="1G"/>',
                 f'<default><geom condim="1" solref="{sr(st["contact_solref"])}" solimp="{si}"/>'
                 f'<default class="core"><geom contype="2" conaffinity="0" density="{config.body.density:g}" group="1"/>'
                 '</default>'
                 f'<default class="hull"><geom contype="1" conaffinity="1" density="0" margin="{margin:g}" '
                 'group="2"/></default></default><worldbody>',
                 '<geom name="ground" type="plane" size="0 0 0.1" contype="0" conaffinity="2"/>']
        walls = np.asarray(static_walls_from_meta(anim.meta), np.float64).reshape(-1, 2, 2)
        x_lo = float(self.anim_root[..., 0].min()) - 3.0
        x_hi = float(self.anim_root[..., 0].max()) + 3.0
        for w, ((x0, y0), (x1, y1)) in enumerate(walls):
            if period and abs(y1 - y0) < 1e-9:          # periodic: cover the whole (unwrapped) run
                x0, x1 = min(x0, x1, x_lo), max(x0, x1, x_hi)
            c = 0.5 * np.array([x0 + x1, y0 + y1])
            half = 0.5 * float(np.hypot(x1 - x0, y1 - y0))
            ang = float(np.arctan2(y1 - y0, x1 - x0))
            # ours are one-sided planes facing the crowd (wall_kernel): a box WALL_DEPTH deep
            # behind the wall's face, away from the characters' roots, so that a limb through
            # the face is pushed back as ours is, not through a thin sheet
            normal = np.array([-np.sin(ang), np.cos(ang)])
            if np.mean((self.anim_root[0, :, :2] - c) @ normal) < 0:
                normal = -normal
            c = c - 0.5 * WALL_DEPTH * normal
            parts.append(f'<geom name="wall{w}" type="box" pos="{c[0]:.5f} {c[1]:.5f} 1.1" euler="0 0 {ang:.6f}" '
                         f'size="{half:.5f} {0.5 * WALL_DEPTH:.5f} 1.1" contype="0" conaffinity="1"/>')

        def seg(i, j):
            s, e = p0[i, j] - self.rests[i, j], p1[i, j] - self.rests[i, j]
            if np.linalg.norm(e - s) < 1e-4:
                e = s + np.array([0.0, 0.0, 1e-4])
            return f'fromto="{s[0]:.6f} {s[1]:.6f} {s[2]:.6f} {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}"'

        jd = float(st["joint_damping"])

        def body_xml(i, j):
            p = PARENTS[j]
            pos = self.anim_root[0, i] if p < 0 else self.rests[i, j] - self.rests[i, p]
            joint = '<freejoint/>' if p < 0 else f'<joint type="ball" damping="{jd:g}" armature="0.01"/>'
            kids = "".join(body_xml(i, c) for c in range(nj) if PARENTS[c] == j)
            return (f'<body name="c{i}b{j}" pos="{pos[0]:.6f} {pos[1]:.6f} {pos[2]:.6f}">{joint}'
                    f'<geom name="core{i}_{j}" class="core" type="capsule" {seg(i, j)} size="{rad[i, j]:.9g}"/>'
                    f'<geom name="hull{i}_{j}" class="hull" type="capsule" {seg(i, j)} size="{hull[i, j]:.9g}"/>'
                    f'{kids}</body>')

        for i in range(n):
            parts.append(body_xml(i, 0))
        for i in range(n):
            for j in range(nj):
                parts.append(f'<body name="m{i}b{j}" mocap="true"/>')
        for k in range(len(self.ghost_shift)):
            for i in range(n):
                for j in range(nj):
                    parts.append(f'<body name="g{k}c{i}b{j}" mocap="true"><geom class="hull" contype="0" conaffinity="1" type="capsule" '
                                 f'{seg(i, j)} size="{hull[i, j]:.9g}"/></body>')
        parts.append('</worldbody><contact>')
        for a, b in cm.intra_pairs:
            ia, ja, ib, jb = a // nj, a % nj, b // nj, b % nj
            parts.append(f'<pair geom1="core{ia}_{ja}" geom2="core{ib}_{jb}" condim="1" '
                         f'solref="{sr(st["contact_solref"])}" solimp="{si}"/>')
        for i in range(n):
            for a in range(nj):
                for b in range(a + 1, nj):
                    parts.append(f'<exclude body1="c{i}b{a}" body2="c{i}b{b}"/>')
        parts.append('</contact><equality>')
        for i in range(n):
            for j in range(nj):
                parts.append(f'<weld body1="m{i}b{j}" body2="c{i}b{j}" relpose="0 0 0 1 0 0 0" '
                             f'solref="{sr(st["weld_solref"])}" solimp="{si}"/>')
        parts.append('</equality></mujoco>')
        self.xml = "".join(parts)
        self.model = model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(model)
        name = lambda kind, s: mujoco.mj_name2id(model, kind, s)  # noqa: E731
        B, G = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_GEOM
        self.body_id = np.array([[name(B, f"c{i}b{j}") for j in range(nj)] for i in range(n)])
        self.mocap_id = np.array([[model.body_mocapid[name(B, f"m{i}b{j}")] for j in range(nj)] for i in range(n)])
        self.ghost_mocap = np.array([[[model.body_mocapid[name(B, f"g{k}c{i}b{j}")] for j in range(nj)]
                                      for i in range(n)] for k in range(len(self.ghost_shift))], dtype=np.int64)
        self.hull_geom = np.array([[name(G, f"hull{i}_{j}") for j in range(nj)] for i in range(n)])
        self.core_geom = np.array([[name(G, f"core{i}_{j}") for j in range(nj)] for i in range(n)])
        self.place(0)

    # -- driving ---------------------------------------------------------------------------
    def set_targets(self, f0: int, f1: int, alpha: float) -> None:
        glob, pos = interpolated_targets(self.anim_q, self.anim_root, self.rests, f0, f1, alpha)
        self.target_glob, self.target_pos = glob, pos
        self.data.mocap_pos[self.mocap_id.ravel()] = pos.reshape(-1, 3)
        self.data.mocap_quat[self.mocap_id.ravel()] = glob.reshape(-1, 4)[:, [3, 0, 1, 2]]

    def place(self, frame: int) -> None:
        """Every body at the animation's frame ``frame``, at rest (like ``reset_to_frame``)."""
        m, d = self.model, self.data
        self.mujoco.mj_resetData(m, d)
        self.set_targets(frame, frame, 0.0)
        local = self.anim_q[frame]
        for i in range(self.n):
            for j in range(self.nj):
                jid = m.body_jntadr[self.body_id[i, j]]
                adr = m.jnt_qposadr[jid]
                if j == 0:
                    d.qpos[adr:adr + 3] = self.anim_root[frame, i]
                    d.qpos[adr + 3:adr + 7] = local[i, 0][[3, 0, 1, 2]]
                else:
                    d.qpos[adr:adr + 4] = local[i, j][[3, 0, 1, 2]]
        self.mujoco.mj_forward(m, d)
        self._move_ghosts()

    def _move_ghosts(self) -> None:
        if not len(self.ghost_shift):
            return
        d = self.data
        xpos = d.xpos[self.body_id.ravel()]
        xquat = d.xquat[self.body_id.ravel()]
        for k, shift in enumerate(self.ghost_shift):
            d.mocap_pos[self.ghost_mocap[k].ravel()] = xpos + np.array([shift, 0.0, 0.0])
            d.mocap_quat[self.ghost_mocap[k].ravel()] = xquat

    def step(self) -> tuple[float, float]:
        """One mj_step (images moved first); returns its (wall ms, thread CPU ms)."""
        self._move_ghosts()
        t0, c0 = time.perf_counter(), time.thread_time()
        self.mujoco.mj_step(self.model, self.data)
        return 1000 * (time.perf_counter() - t0), 1000 * (time.thread_time() - c0)

    def read(self):
        """The current pose as ``(joint_rotations (N, J, 3), root (N, 3))``."""
        xq = self.data.xquat[self.body_id.ravel()][:, [1, 2, 3, 0]].reshape(self.n, self.nj, 4)
        return rigid_to_animation(xq, self.data.xpos[self.body_id[:, 0]])

    # -- what the test compares with ours --------------------------------------------------
    def inter_body_radius(self) -> np.ndarray:
        """(N, J) m: hull radius + margin, the distance inter-body contacts hold per capsule
        side (ours: cap_radius + cap_skin, + contact_margin once per pair)."""
        return self.model.geom_size[self.hull_geom, 0] + self.model.geom_margin[self.hull_geom]

    def self_pairs(self) -> np.ndarray:
        """(P, 2) global body indices (i * J + j) of the same-character pairs that can touch."""
        m, nj = self.model, self.nj
        body_index = {int(b): k for k, b in enumerate(self.body_id.ravel())}
        pairs = set()
        for g1, g2 in zip(m.pair_geom1, m.pair_geom2):
            a, b = body_index[int(m.geom_bodyid[g1])], body_index[int(m.geom_bodyid[g2])]
            if a // nj == b // nj:
                pairs.add((min(a, b), max(a, b)))
        excluded = {(int(s) >> 16, int(s) & 0xFFFF) for s in m.exclude_signature}
        for i in range(self.n):           # dynamic (contype/conaffinity) pairs not excluded
            ids = self.body_id[i]
            for a in range(nj):
                for b in range(a + 1, nj):
                    ba, bb = int(ids[a]), int(ids[b])
                    key = (min(ba, bb), max(ba, bb))
                    parent_child = m.body_parentid[ba] == bb or m.body_parentid[bb] == ba
                    if key in excluded or parent_child:
                        continue
                    if _geoms_filter(m, ba, bb):
                        pairs.add((i * nj + a, i * nj + b))
        return np.array(sorted(pairs), np.int64).reshape(-1, 2)


def _geoms_filter(m, ba: int, bb: int) -> bool:
    """Whether any geoms of bodies ba and bb pass MuJoCo's contype/conaffinity filter."""
    ga = range(m.body_geomadr[ba], m.body_geomadr[ba] + m.body_geomnum[ba])
    gb = range(m.body_geomadr[bb], m.body_geomadr[bb] + m.body_geomnum[bb])
    return any((m.geom_contype[x] & m.geom_conaffinity[y]) or (m.geom_contype[y] & m.geom_conaffinity[x])
               for x in ga for y in gb)


def mujoco_peer(anim, config=None, setting: str | dict = "weld0.05", *, settle: bool = True):
    """Simulate ``anim``'s targets in MuJoCo (:class:`MujocoScene`): settle on frame 0, then
    ``substeps`` steps per frame at the interpolated targets.

    Returns ``(anim, timing)``: the simulated CrowdAnimation (meta method "MuJoCo") and
    median cpu/wall ms per mj_step, the step (s) and steps per simulated 1/60 s.
    """
    scene = MujocoScene(anim, config, setting)
    t_frames = anim.n_frames
    out_rot = np.zeros(anim.joint_rotations.shape)
    out_root = np.zeros(anim.root_translation.shape)
    if settle:
        for _ in range(int(round(scene.config.solver.settle_time / scene.dt))):
            scene.set_targets(0, 0, 0.0)
            scene.step()
    out_rot[0], out_root[0] = scene.read()
    times = []
    unstable = False
    for f in range(1, t_frames):
        for s in range(1, scene.substeps + 1):
            scene.set_targets(f - 1, f, s / scene.substeps)
            times.append(scene.step())
        out_rot[f], out_root[f] = scene.read()
        if not np.all(np.isfinite(out_root[f])):
            unstable = True
            out_rot[f:], out_root[f:] = anim.joint_rotations[f:], anim.root_translation[f:]
            break
    res = anim.replace(root_translation=out_root, joint_rotations=out_rot, meta={"method": "MuJoCo"})
    timing = {"cpu_ms_per_step": statistics.median(t[1] for t in times),
              "wall_ms_per_step": statistics.median(t[0] for t in times),
              "dt": scene.dt, "steps_per_60th": scene.substeps * anim.fps / 60.0, "unstable": unstable,
              "nbody": int(scene.model.nbody), "ngeom": int(scene.model.ngeom),
              "contacts": float(scene.data.ncon)}
    return res, timing


def _mujoco_scene(kind: str, duration: float):
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary" if kind == "concert" else "walking", "D5", duration=duration)


def compare_mujoco(duration: float = 4.0, scenes=("concert", "corridor"), settings=None,
                   frame_stride: int = 10, steps: int = 200) -> list[dict]:
    """Ours and MuJoCo (each setting) side by side on the D5 scenes, ``duration`` s each:
    cost per step and per simulated 1/60 s, mesh/capsule overlap as a fraction of the
    Baseline's (every ``frame_stride``-th frame), tracking error (cm), jerk ratio."""
    from crowdstudy.metrics import mean_jerk, overlap_volume, tracking_error
    from crowdstudy.physics.corrector import correct

    settings = list(settings or MUJOCO_SETTINGS)
    rows = []
    for kind in scenes:
        base = _mujoco_scene(kind, duration)
        frames = np.arange(0, base.n_frames, frame_stride)
        ov_base = {g: overlap_volume(base, geometry=g, frames=frames).mean for g in ("mesh", "capsule")}
        jerk_base = mean_jerk(base)
        ours = correct(base, progress=False, device="cpu")
        t = time_steps(base, min(steps, 2 * (base.n_frames - 1)))
        runs = [("Ours", "crowdstudy (Warp CPU)", ours,
                 {"cpu_ms_per_step": t["total_cpu_ms"], "wall_ms_per_step": t["total_wall_ms"],
                  "dt": 1.0 / 60.0, "steps_per_60th": 1.0})]
        for name in settings:
            mj, mj_t = mujoco_peer(base, setting=name)
            runs.append(("MuJoCo", name, mj, mj_t))
        for method, setting, a, tm in runs:
            row = {"scene": f"{kind} D5", "method": method, "setting": setting,
                   "characters": base.n_characters, "frames": base.n_frames,
                   "dt_ms": 1000 * tm["dt"],
                   "cpu_ms_per_step": tm["cpu_ms_per_step"], "wall_ms_per_step": tm["wall_ms_per_step"],
                   "cpu_ms_per_60th": tm["cpu_ms_per_step"] * tm["steps_per_60th"],
                   "wall_ms_per_60th": tm["wall_ms_per_step"] * tm["steps_per_60th"]}
            for g in ("mesh", "capsule"):
                row[f"{g}_overlap_vs_baseline"] = overlap_volume(a, geometry=g, frames=frames).mean / max(ov_base[g], 1e-12)
            row["tracking_cm"] = tracking_error(a, base)
            row["jerk_vs_baseline"] = mean_jerk(a) / max(jerk_base, 1e-12)
            if tm.get("unstable"):
                row["setting"] += " (UNSTABLE)"
            rows.append(row)
            print(format_table([row]), flush=True)
        _mark_best(rows[-len(runs):])
        rows.append({"scene": f"{kind} D5", "method": "Baseline", "setting": "input",
                     "characters": base.n_characters, "frames": base.n_frames,
                     "mesh_overlap_vs_baseline": 1.0, "capsule_overlap_vs_baseline": 1.0,
                     "tracking_cm": 0.0, "jerk_vs_baseline": 1.0,
                     "mesh_baseline_m3": ov_base["mesh"], "capsule_baseline_m3": ov_base["capsule"]})
    return rows


def _mark_best(rows: list[dict], tracking_slack: float = 1.25) -> None:
    """Cost ratios to Ours (rows[0]) and ``best`` = "*" on the MuJoCo setting with the least
    mesh overlap among those tracking comparably (within ``tracking_slack`` x Ours' error)."""
    ref = rows[0]
    for r in rows:
        r["x_ours_cpu_per_60th"] = r["cpu_ms_per_60th"] / max(ref["cpu_ms_per_60th"], 1e-12)
        r["best"] = ""
    ok = [r for r in rows[1:] if r["tracking_cm"] <= tracking_slack * ref["tracking_cm"]
          and "UNSTABLE" not in r["setting"]]
    if ok:
        min(ok, key=lambda r: r["mesh_overlap_vs_baseline"])["best"] = "*"


MUJOCO_COLUMNS = ["scene", "method", "setting", "dt_ms", "cpu_ms_per_step", "wall_ms_per_step", "cpu_ms_per_60th",
                  "wall_ms_per_60th", "x_ours_cpu_per_60th", "mesh_overlap_vs_baseline",
                  "capsule_overlap_vs_baseline", "tracking_cm", "jerk_vs_baseline", "best"]


#: the smoothness bars of a corrected stimulus (Ours against its Baseline, same cell)
BAR_TEXT = {"jerk": "mean jerk <= 1.3x", "hf": "HF share <= 1.5x", "speed": "max joint speed <= +0.5 m/s",
            "pelvis": "pelvis accel p99 <= 2x + 0.5 m/s^2", "slide": "planted-foot slide p99 <= 5 cm/s",
            "overlap": "mesh overlap <= 5 %", "tracking": "tracking <= 1.5 cm at D1, <= 5 cm at D5",
            "seam": "seam <= 1.5x median step (a looped concert)"}


def tracking_bar_cm(level_index: int, n_levels: int) -> float | None:
    """The tracking bar of a level, cm: 1.5 at the sparsest (D1), 5 at the densest (D5),
    None between (the bar is stated for D1 and D5 only)."""
    return 1.5 if level_index == 0 else 5.0 if level_index == n_levels - 1 else None


def bar_checks(row: dict, level_index: int, n_levels: int) -> dict:
    """Pass/fail of each bar for one measured cell (``row`` from :func:`measure_bars`)."""
    checks = {"jerk": row["jerk_ratio"] <= 1.3,
              "hf": row["hf_share_ours"] <= 1.5 * row["hf_share_baseline"],
              "speed": row["max_joint_speed_ours"] <= row["max_joint_speed_baseline"] + 0.5,
              "pelvis": row["pelvis_p99_ours"] <= 2.0 * row["pelvis_p99_baseline"] + 0.5,
              "slide": row["foot_slide_p99_ours"] <= 0.05,
              "overlap": row["mesh_ratio"] <= 0.05}
    bar = tracking_bar_cm(level_index, n_levels)
    if bar is not None:
        checks["tracking"] = row["tracking_cm"] <= bar
    if row["loop"] == "periodic":                 # a looped concert (a clip too short to loop has no seam)
        checks["seam"] = max(row["seam_ratio_baseline"], row["seam_ratio_ours"]) <= 1.5
    return checks


def loop_mode(anim) -> str:
    """How the animation's video loops: ``meta["loop"]["mode"]`` ("periodic", "dissolve" or
    "none")."""
    return str((anim.meta.get("loop") or {}).get("mode", "none"))


def parse_cells(text: str, levels) -> list[tuple[str, str]] | None:
    """``"concert:D1,corridor:D5"`` -> [("stationary", "D1"), ("walking", "D5")]; "" -> None
    (every cell). Scenes are ``concert``/``stationary`` and ``corridor``/``walking``."""
    if not text.strip():
        return None
    stages = {"concert": "stationary", "stationary": "stationary", "corridor": "walking", "walking": "walking"}
    cells = []
    for item in text.split(","):
        scene, _, level = item.strip().partition(":")
        if scene not in stages or level not in levels:
            raise SystemExit(f"--cells: expected SCENE:LEVEL with SCENE in concert, corridor and LEVEL in "
                             f"{', '.join(levels)}, got {item.strip()!r}")
        cells.append((stages[scene], level))
    return cells


def parse_seeds(text: str) -> list[int | None]:
    """``"study,1,2"`` -> [None, 1, 2] (``study``: the design's seed of each cell)."""
    seeds: list[int | None] = []
    for item in text.split(","):
        item = item.strip()
        if item == "study":
            seeds.append(None)
            continue
        try:
            value = int(item)
        except ValueError:
            value = -1
        if value < 0:
            raise SystemExit(f"--seeds: expected 'study' or non-negative integers, comma-separated, got {item!r}")
        seeds.append(value)
    if len(set(seeds)) != len(seeds):
        raise SystemExit(f"--seeds: a seed is given twice in {text!r}")
    return seeds


SPREAD_COLUMNS = ["stage", "level", "seeds", "mesh_ratio_study", "mesh_ratio_mean", "mesh_ratio_sd",
                  "mesh_ratio_min", "mesh_ratio_max", "baseline_cm3_mean", "ours_cm3_mean", "ours_cm3_max",
                  "overlap_met", "tracking_cm_mean", "tracking_cm_max",
                  "tracking_met", "all_bars_met"]


def seed_spread(rows: list[dict]) -> list[dict]:
    """Per cell, how the bars vary from crowd to crowd (rows of :func:`measure_bars` with
    several seeds): the mesh overlap ratio's mean, sample standard deviation, range and the
    study seed's value (NaN where the study's own crowd was not measured), the overlap itself
    in cm^3 per character (the Baseline's mean, Ours' mean and largest: a sparse cell's ratio
    is a ratio of small volumes), the tracking
    error's mean and largest value, and how many crowds meet the overlap bar, the tracking
    bar (D1 and D5 only; "" elsewhere) and every bar, as "k/n"."""
    cells: dict = {}
    for r in rows:
        cells.setdefault((r["stage"], r["level"]), []).append(r)
    out = []
    for (stage, level), rs in cells.items():
        ratio = np.array([r["mesh_ratio"] for r in rs], float)
        track = np.array([r["tracking_cm"] for r in rs], float)
        failed = [set(filter(None, r["bars_failed"].replace("-", "").split(","))) for r in rs]
        study = [r["mesh_ratio"] for r in rs if r.get("study_seed")]
        n = len(rs)
        out.append({"stage": stage, "level": level, "seeds": n,
                    "mesh_ratio_study": float(study[0]) if study else float("nan"),
                    "mesh_ratio_mean": float(ratio.mean()),
                    "mesh_ratio_sd": float(ratio.std(ddof=1)) if n > 1 else 0.0,
                    "mesh_ratio_min": float(ratio.min()), "mesh_ratio_max": float(ratio.max()),
                    "baseline_cm3_mean": 1e6 * float(np.mean([r["mesh_baseline_m3"] for r in rs])),
                    "ours_cm3_mean": 1e6 * float(np.mean([r["mesh_ours_m3"] for r in rs])),
                    "ours_cm3_max": 1e6 * float(np.max([r["mesh_ours_m3"] for r in rs])),
                    "overlap_met": f"{sum('overlap' not in f for f in failed)}/{n}",
                    "tracking_cm_mean": float(track.mean()), "tracking_cm_max": float(track.max()),
                    "tracking_met": (f"{sum('tracking' not in f for f in failed)}/{n}"
                                     if rs[0].get("tracking_bar_cm") is not None else ""),
                    "all_bars_met": f"{sum(not f for f in failed)}/{n}"})
    return out


def seed_figure(rows: list[dict], path=None):
    """The bars crowd by crowd (PNG): mesh overlap (% of the Baseline's) and tracking error
    (cm) per cell, one dot per seed, the study's own crowd ringed, the bars as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = report_path("physics_bars_seeds").with_suffix(".png") if path is None else path
    cells = list(dict.fromkeys((r["stage"], r["level"]) for r in rows))
    names = [f"{'concert' if st == 'stationary' else 'corridor'}\n{lv}" for st, lv in cells]
    fig, axes = plt.subplots(2, 1, figsize=(max(6.0, 0.8 * len(cells) + 2), 6.4), dpi=120, sharex=True)
    for ax, key, scale, label in ((axes[0], "mesh_ratio", 100.0, "mesh overlap, % of the Baseline's"),
                                  (axes[1], "tracking_cm", 1.0, "tracking error, cm")):
        for i, cell in enumerate(cells):
            sel = [r for r in rows if (r["stage"], r["level"]) == cell]
            ys = np.array([r[key] * scale for r in sel])
            xs = i + np.linspace(-0.15, 0.15, len(ys)) if len(ys) > 1 else np.full(1, float(i))
            ax.plot(xs, ys, "o", color="tab:blue", ms=5, alpha=0.8)
            for x, r, y in zip(xs, sel, ys):
                if r.get("study_seed"):
                    ax.plot([x], [y], "o", mfc="none", mec="k", ms=10, mew=1.5)
            ax.plot([i - 0.25, i + 0.25], [ys.mean()] * 2, "-", color="tab:blue", lw=2)
        ax.set_ylabel(label)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].axhline(5.0, color="r", ls="--", lw=1, label="bar: 5 %")
    for i, cell in enumerate(cells):
        bar = next(r.get("tracking_bar_cm") for r in rows if (r["stage"], r["level"]) == cell)
        if bar is not None:
            axes[1].plot([i - 0.3, i + 0.3], [bar, bar], "r--", lw=1)
    axes[0].plot([], [], "o", mfc="none", mec="k", ms=10, label="the study's own crowd")
    axes[0].plot([], [], "-", color="tab:blue", lw=2, label="mean over seeds")
    axes[0].legend(fontsize=7, loc="upper right", framealpha=0.9)
    axes[1].set_xticks(range(len(cells)), names, fontsize=8)
    axes[0].set_title("The bars crowd by crowd: one dot per seed of each study cell")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def measure_bars(duration: float, frame_stride: int = 10, config=None, cells=None,
                 seeds=(None,)) -> list[dict]:
    """Every (stage, density) cell of the study, ``duration`` seconds each: overlap (mesh and
    capsule, m^3 per character, every ``frame_stride``-th frame), tracking error (cm; with its
    placement and motion parts, :func:`crowdstudy.metrics.tracking_parts`) and the
    smoothness of Ours against its Baseline (:func:`crowdstudy.metrics.smoothness`), with the
    bars (:data:`BAR_TEXT`) checked per cell (``bars_failed`` lists the failed ones), and how
    far the skin reaches through the scene's walls (``wall_p99_cm_*``, ``wall_max_cm_*``:
    :func:`crowdstudy.metrics.wall_penetration`, the same frames as the overlap).
    ``config``: the :class:`~crowdstudy.physics.config.PhysicsConfig` of Ours (None: the
    defaults); ``cells``: (stage, level) pairs to measure (None: all ten); ``seeds``: the
    cells' seeds, each one a crowd of its own (layout, bodies, clips; None: the design's
    seed of the cell, the study's stimulus). Each row records its ``seed`` and whether it
    is the study's (``study_seed``)."""
    from crowdstudy.design import load_design

    design = load_design()
    levels = list(design.densities)
    rows = []
    for stage in ("stationary", "walking"):
        for li, level in enumerate(levels):
            if cells is not None and (stage, level) not in cells:
                continue
            for seed in seeds:
                rows.append(_bars_of_cell(design, stage, li, level, seed, duration, frame_stride, config))
                print(format_table([rows[-1]]), flush=True)
    return rows


def _bars_of_cell(design, stage: str, li: int, level: str, seed, duration: float, frame_stride: int,
                  config) -> dict:
    """One row of :func:`measure_bars`: one crowd of one cell, corrected and measured."""
    from crowdstudy.metrics import overlap_volume, tracking_parts, wall_penetration
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.corrector import correct

    levels = list(design.densities)
    base = build_baseline(design, stage, level, duration=duration, seed=seed)
    t0 = time.perf_counter()
    run_timings: dict = {}
    ours = correct(base, config, progress=False, timings=run_timings)
    wall = time.perf_counter() - t0
    frames = np.arange(0, base.n_frames, frame_stride)
    study_seed = design.cell_seed(design.stage(stage), level)
    row = {"stage": stage, "level": level, "seed": int(base.meta["seed"]),
           "study_seed": int(base.meta["seed"]) == study_seed, "characters": base.n_characters,
           "frames": base.n_frames, "loop": loop_mode(base), "tracking_bar_cm": tracking_bar_cm(li, len(levels)),
           **_profile_columns(ours)}
    for geom in ("mesh", "capsule"):
        ob = overlap_volume(base, geometry=geom, frames=frames).mean
        oo = overlap_volume(ours, geometry=geom, frames=frames).mean
        row[f"{geom}_baseline_m3"] = ob
        row[f"{geom}_ours_m3"] = oo
        row[f"{geom}_ratio"] = oo / max(ob, 1e-12)
    for name, a in (("baseline", base), ("ours", ours)):     # skin through the walls (not a bar)
        walls = wall_penetration(a, frames=frames)
        row[f"wall_p99_cm_{name}"], row[f"wall_max_cm_{name}"] = walls.p99_cm, walls.max_cm
    parts = tracking_parts(ours, base)
    row["tracking_cm"] = parts.total_cm
    # placement, motion and each body part's mean (where the tracking goes; not bars)
    row.update({key: value for key, value in parts.as_dict().items() if key != "tracking_error_cm"})
    row.update(_smoothness_columns(base, ours))
    checks = bar_checks(row, li, len(levels))
    row["bars_failed"] = ",".join(k for k, ok in checks.items() if not ok) or "-"
    limited = (ours.meta.get("physics") or {}).get("speed_limit") or {}
    row["speed_limited_characters"] = len(limited.get("characters", ()))   # re-timed by the speed limit
    row["correct_wall_s"] = wall
    row["ms_per_step_wall"] = run_timings["ms_per_step"]     # the clip's steps only
    return row


def _run_mujoco(args) -> list[dict]:
    unknown = set(args.mujoco_settings.split(",")) - set(MUJOCO_SETTINGS)
    if unknown:
        raise SystemExit(f"--mujoco-settings: unknown {sorted(unknown)}; expected some of {list(MUJOCO_SETTINGS)}")
    rows = compare_mujoco(args.mujoco_duration, scenes=tuple(args.mujoco_scenes.split(",")),
                          settings=args.mujoco_settings.split(","), steps=args.steps)
    print(format_table(rows, MUJOCO_COLUMNS), flush=True)
    return rows


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench physics")
    parser.add_argument("--steps", type=int, default=200, help="steps timed per scene")
    parser.add_argument("--sizes", default="20,60,200")
    parser.add_argument("--no-peer", action="store_true")
    parser.add_argument("--cpu-only", action="store_true", help="skip the CUDA rows even when a GPU is present")
    parser.add_argument("--mujoco", action="store_true",
                        help="only the side-by-side comparison with MuJoCo (concert D5 and corridor D5)")
    parser.add_argument("--mujoco-duration", type=float, default=4.0, metavar="SECONDS",
                        help="seconds of each scene simulated for the MuJoCo comparison (20 = the full clips)")
    parser.add_argument("--mujoco-settings", default=",".join(MUJOCO_SETTINGS),
                        help=f"MuJoCo tunings to run, comma-separated among {', '.join(MUJOCO_SETTINGS)}")
    parser.add_argument("--mujoco-scenes", default="concert,corridor", help="D5 scenes: concert, corridor")
    parser.add_argument("--bars", type=float, default=0.0, metavar="SECONDS",
                        help="also measure overlap/tracking on every study cell for SECONDS (20 = the full clips)")
    parser.add_argument("--bars-only", action="store_true", help="only the --bars measurement")
    parser.add_argument("--cells", default="", metavar="SCENE:LEVEL,...",
                        help="--bars on these cells only (e.g. concert:D1,corridor:D5; default all ten)")
    parser.add_argument("--seeds", default="study", metavar="SEED,...",
                        help="--bars-only on these seeds of each cell ('study': the stimulus's own crowd; "
                             "e.g. study,1,2,3): with more than one, the spread per cell and its figure")
    add_config_option(parser, "the physics of the timed steps, --bars and --stadium (e.g. cg_tolerance=1e-4); "
                              "the report (physics_*_trial) records them")
    parser.add_argument("--curve-only", action="store_true",
                        help="only the cost curve over --sizes (and its figure), no CG comparison or peers")
    parser.add_argument("--stadium", default="", metavar="N,N",
                        help="only correct() on stadium crowds of these sizes (e.g. 1000,5000): time, memory, bars")
    parser.add_argument("--stadium-level", default="D3", help="density level of the stadium crowds (default D3)")
    parser.add_argument("--stadium-seconds", default="20", metavar="S[,S]",
                        help="seconds simulated per stadium size (one value, or one per size)")
    parser.add_argument("--light-bodies", action="store_true",
                        help="stadium runs hand correct() body proxies without the meshes (needed at 5,000 "
                             "MakeHuman characters in 24 GiB)")
    args = parser.parse_args(argv)
    config = config_from_cli(args.config)                  # the defaults without --config
    trial = "_trial" if args.config else ""                 # reports of changed settings keep their own names
    try:
        sizes = [int(v) for v in args.sizes.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"--sizes: expected comma-separated character counts, got {args.sizes!r}") from None
    if not sizes or min(sizes) < 1:
        raise SystemExit(f"--sizes: expected positive character counts, got {args.sizes!r}")
    if args.stadium:
        try:
            counts = [int(v) for v in args.stadium.split(",")]
            secs = [float(v) for v in args.stadium_seconds.split(",")]
        except ValueError:
            raise SystemExit("--stadium/--stadium-seconds: expected comma-separated numbers") from None
        if len(secs) == 1:
            secs = secs * len(counts)
        if len(secs) != len(counts) or min(counts) < 1 or min(secs) <= 0:
            raise SystemExit("--stadium-seconds: one positive value, or one per --stadium size")
        devices = device_rows()      # the stadium runs are CPU runs; the rows say what else is there
        rows = [stadium_run(n, args.stadium_level, s, light_bodies=args.light_bodies, config=config)
                for n, s in zip(counts, secs)]
        print("bars: " + "; ".join(BAR_TEXT.values()), flush=True)
        path = write_report("physics_stadium" + trial, rows, seed=None, devices=devices, bar_text=BAR_TEXT,
                            config_changes=list(args.config))
        print(f"wrote {path}", file=sys.stderr)
        return 0
    if args.bars_only:
        from crowdstudy.design import load_design
        cells = parse_cells(args.cells, list(load_design().densities))
        seeds = parse_seeds(args.seeds)
        bars = measure_bars(args.bars or 20.0, config=config, cells=cells, seeds=seeds)
        print("bars: " + "; ".join(BAR_TEXT.values()), flush=True)
        extra: dict = {}
        if len(seeds) > 1:
            extra["spread"] = seed_spread(bars)
            print(format_table(extra["spread"], SPREAD_COLUMNS), flush=True)
            extra["figure"] = str(seed_figure(bars, path=report_path(f"physics_bars_seeds{trial}").with_suffix(".png")))
            print(f"figure: {extra['figure']}", flush=True)
            name = f"physics_bars_seeds{trial}"
        else:
            name = "physics_bars_trial" if trial or cells is not None or seeds != [None] else "physics_bars"
        path = write_report(name, bars, seed=None, bar_text=BAR_TEXT, config_changes=list(args.config),
                            seeds=["study" if v is None else v for v in seeds], **extra)
        print(f"wrote {path}", file=sys.stderr)
        return 0
    if args.mujoco:
        peer_rows = _run_mujoco(args)
        path = write_report("physics_mujoco", peer_rows, seed=None)
        print(f"wrote {path}", file=sys.stderr)
        return 0
    duration = args.steps / 60.0 + 0.5
    devices = device_rows(cpu_only=args.cpu_only)
    cuda = any(r["present"] and r["device"].startswith("cuda") for r in devices)
    if args.curve_only:
        d5 = _scene("D5", duration)
        rows = cost_curve(sizes, args.steps, base=d5, config=config)
        if cuda:
            rows += cost_curve(sizes, args.steps, device="cuda:0", base=d5, config=config)
        figure = runtime_figure(rows, path=report_path(f"physics_runtime{trial}").with_suffix(".png"))
        print(f"figure: {figure}", flush=True)
        path = write_report(f"physics_curve{trial}", rows, seed=None, devices=devices, figure=str(figure),
                            config_changes=list(args.config))
        print(f"wrote {path}", file=sys.stderr)
        return 0
    d1, d5 = _scene("D1", duration), _scene("D5", duration)
    rows = []
    for n in sizes:
        anim = d1 if n == d1.n_characters else d5 if n == d5.n_characters else _tile(d5, n)
        r = time_steps(anim, args.steps, config=config)
        rows.append({"characters": n, **r, "cpu_ms_per_character": r["total_cpu_ms"] / n})
        print(format_table([rows[-1]]), flush=True)
        if cuda:
            r = time_steps(anim, args.steps, device="cuda:0", config=config)
            rows.append({"characters": n, **r, "cpu_ms_per_character": r["total_cpu_ms"] / n})
            print(format_table([rows[-1]]), flush=True)
    cg_rows = compare_cg(d5)
    print(format_table(cg_rows), flush=True)
    peer_rows = [] if args.no_peer else _run_mujoco(args)
    bars = measure_bars(args.bars, config=config) if args.bars > 0 else []
    path = write_report(f"physics{trial}", rows, seed=None, cg=cg_rows, peer=peer_rows,
                        bars=bars, bar_text=BAR_TEXT, config_changes=list(args.config),
                        devices=devices)
    print(f"wrote {path}", file=sys.stderr)
    return 0

"""What one step of the correction costs: per phase (detection, assembly, solve, update),
CPU and wall time, CG iterations, contacts and memory, on any crowd.

``crowdstudy bench physics`` builds its cost tables and curves on these; the MuJoCo
comparison (:mod:`crowdstudy.evaluation.mujoco_compare`) times Ours with them. The crowd of a
given size is the study's scene repeated on a grid of floors (:func:`tile_crowd`).
"""

from __future__ import annotations

import statistics
import time
from typing import Any, Literal

import numpy as np

from crowdstudy.physics.crowding import crowd_config

__all__ = ["tile_crowd", "timed_corrector", "time_steps", "warp_mib", "rss_mib"]


def tile_crowd(anim, n: int, spacing: float = 3.2):
    """``n`` characters: the scene ``anim`` repeated on a grid of floors ``spacing`` m apart
    (meta ``scenario`` "tiled")."""
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
    return anim.replace(
        root_translation=root,
        joint_rotations=rot,
        bodies=tuple(bodies[:n]),
        clips=tuple(clips[:n]),
        meta={"scenario": "tiled"},
    )


def timed_corrector(anim, **kw):
    """A CrowdCorrector on ``anim``'s whole clip, placed at frame 0, its configuration
    resolved for the crowd as ``correct()`` resolves it (``PhysicsConfig.for_density``);
    ``kw``: CrowdCorrector options (device, config, ...)."""
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies

    kw["config"] = crowd_config(anim, kw.get("config"))[0]
    corr = CrowdCorrector(load_bodies(anim.bodies), fps=anim.fps, n_frames=anim.n_frames, **kw)
    corr.control.set_frames(anim.joint_rotations, anim.root_translation)
    corr.reset_to_frame(0)
    return corr


def time_steps(anim, steps: int, device: str = "cpu", config=None) -> dict:
    """Median ms per phase over ``steps`` steps (after 4 untimed ones) of ``anim``'s
    correction (``config``: a PhysicsConfig, default the defaults).

    Warp's CPU kernels run synchronously in the calling thread, so both the wall clock and
    the thread's CPU time are recorded: on a shared machine the wall clock also counts the
    time slices other processes take (preemption), the CPU time only this process's work.
    Keys: ``{phase}_cpu_ms``, ``{phase}_wall_ms`` (phases detection, assembly, solve,
    update), ``total_cpu_ms``, ``total_wall_ms``, ``total_wall_min_ms``, ``cg_iterations``,
    ``contacts`` (means), ``warp_mib`` (:func:`warp_mib`) and ``device``.
    """
    corr = timed_corrector(anim, device=device, config=config)
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
    out: dict[str, Any] = {"device": device}
    out.update({f"{k}_cpu_ms": statistics.median(v) for k, v in cpu.items()})
    out.update({f"{k}_wall_ms": statistics.median(v) for k, v in wall.items() if k != "total"})
    out["total_wall_ms"] = statistics.median(wall["total"])
    out["total_wall_min_ms"] = min(wall["total"])
    out.update(cg_iterations=float(np.mean(cg)), contacts=float(np.mean(contacts)))
    out["warp_mib"] = warp_mib(corr)
    return out


def warp_mib(corr) -> float:
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


def rss_mib(field: Literal["VmRSS", "VmHWM"] = "VmRSS") -> float:
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

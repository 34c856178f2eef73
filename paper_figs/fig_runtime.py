"""Runtime of the correction: ms per physics step (1/60 s) against the number of characters,
on this machine's CPU (and its GPU when one is present), beside the paper's reported
5 ms (20 characters) and 20 ms (60 characters) on a GTX 1080 Ti.

The timings come from :mod:`crowdstudy.physics.step_timing` (the code ``crowdstudy bench
physics`` times with): the D1 scene for 20 characters, the D5 concert for 60, and the D5
scene tiled on a larger floor beyond that. Medians over the timed steps; CPU time of the stepping thread
(wall-clock time is noisier on a shared machine and is drawn dotted).

    .venv/bin/python paper_figs/fig_runtime.py [--quick] [--refresh]
"""

from __future__ import annotations

import json
import sys

from figstyle import apply_style, cache_path, figure_args, out_path, save_figure

PAPER = {20: 5.0, 60: 20.0}  # ms per step reported by the paper (GTX 1080 Ti)


def _measure(sizes: list[int], steps: int) -> list[dict]:
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline
    from crowdstudy.physics.step_timing import tile_crowd, time_steps
    from crowdstudy.warp_runtime import get_warp

    duration = steps / 60.0 + 0.5
    d1, d5 = (build_baseline(load_design(), "stationary", level, duration=duration) for level in ("D1", "D5"))
    devices = ["cpu"] + (["cuda:0"] if get_warp().is_cuda_available() else [])
    rows = []
    for n in sizes:
        anim = d1 if n == d1.n_characters else d5 if n == d5.n_characters else tile_crowd(d5, n)
        for device in devices:
            r = time_steps(anim, steps, device=device)
            rows.append(
                {
                    "characters": n,
                    "device": device,
                    "cpu_ms": r["total_cpu_ms"],
                    "wall_ms": r["total_wall_ms"],
                    "contacts": r["contacts"],
                }
            )
            print(f"{n:4d} characters on {device}: {r['total_cpu_ms']:.2f} ms/step (CPU time)", flush=True)
    return rows


def main(argv=None) -> int:
    args = figure_args(__doc__.splitlines()[0], argv)
    sizes = [20, 60] if args.quick else [20, 40, 60, 100, 150, 200]
    steps = 20 if args.quick else 200
    cache = cache_path(f"fig_runtime_{'-'.join(map(str, sizes))}_{steps}.json")
    if args.refresh or not cache.is_file():
        cache.write_text(json.dumps(_measure(sizes, steps), indent=1))
    rows = json.loads(cache.read_text())

    apply_style()
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.6, 3.6))
    for device, colour in (("cpu", "#00798c"), ("cuda:0", "#edae49")):
        pts = [r for r in rows if r["device"] == device]
        if not pts:
            continue
        label = "crowdstudy, this CPU (2 cores)" if device == "cpu" else "crowdstudy, CUDA"
        ax.plot([r["characters"] for r in pts], [r["cpu_ms"] for r in pts], "o-", color=colour, label=label)
        ax.plot(
            [r["characters"] for r in pts],
            [r["wall_ms"] for r in pts],
            ":",
            color=colour,
            lw=1,
            label=f"{label}, wall clock",
        )
    ax.plot(list(PAPER), list(PAPER.values()), "s--", color="#d1495b", label="paper (GTX 1080 Ti)")
    ax.axhline(1000 / 60, color="#888888", lw=0.8)
    ax.annotate(
        "real time at 1/60 s steps",
        (max(r["characters"] for r in rows), 1000 / 60),
        ha="right",
        va="bottom",
        fontsize=7,
        color="#666666",
    )
    ax.set_xlabel("characters (24 bones each)")
    ax.set_ylabel("ms per physics step")
    ax.set_title("Cost of one correction step")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7.5)
    save_figure(fig, out_path("fig_runtime", args), rows=rows, steps=steps)
    return 0


if __name__ == "__main__":
    sys.exit(main())

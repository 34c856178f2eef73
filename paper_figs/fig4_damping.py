"""Paper Fig. 4, the damping study: a character held back by a collision until t = 3.5 s,
then released; its global (pelvis) position against time for several damping values d of
the PD control (Eq. 4), with the animation's target. d = 0 oscillates, the paper's
d = 0.006 returns quickly without overshoot, a large d lags.

    .venv/bin/python paper_figs/fig4_damping.py [--quick] [--dampings 0,0.006,0.06]
"""

from __future__ import annotations

import json
import sys

import numpy as np
from figstyle import apply_style, cache_path, figure_args, out_path, save_figure


def _compute(dampings: tuple[float, ...], duration: float) -> dict:
    from crowdstudy.physics.damping import damping_study

    data = damping_study(dampings=dampings, duration=duration)
    return {
        "time": np.asarray(data["time"]).tolist(),
        "target": np.asarray(data["target"]).tolist(),
        "release_time": float(data["release_time"]),
        "push": float(data["push"]),
        "position": {repr(float(d)): np.asarray(p).tolist() for d, p in data["position"].items()},
        "metrics": {repr(float(d)): {k: float(v) for k, v in m.items()} for d, m in data["metrics"].items()},
    }


def main(argv=None) -> int:
    args = figure_args(
        __doc__.splitlines()[0], argv, dampings=dict(default="0,0.006,0.06", help="comma-separated damping values d")
    )
    dampings = tuple(float(v) for v in args.dampings.split(","))
    duration = 5.0 if args.quick else 6.0
    cache = cache_path(f"fig4_damping_{'_'.join(f'{d:g}' for d in dampings)}_{duration:g}s.json")
    if args.refresh or not cache.is_file():
        cache.write_text(json.dumps(_compute(dampings, duration)))
    data = json.loads(cache.read_text())

    apply_style()
    import matplotlib.pyplot as plt

    t = np.asarray(data["time"])
    target = np.asarray(data["target"])
    target = np.broadcast_to(target, t.shape) if target.ndim == 0 else target
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    ax.plot(t, target, color="black", ls="--", lw=1.2, label="target (animation)")
    colours = plt.cm.viridis(np.linspace(0.1, 0.85, len(data["position"])))
    for colour, (d, pos) in zip(colours, data["position"].items(), strict=True):
        m = data["metrics"][d]
        ret = "never" if not np.isfinite(m["return_time"]) else f"{m['return_time']:.2f} s"
        ax.plot(
            t,
            pos,
            color=colour,
            label=f"d = {float(d):g}  (back within 2 cm: {ret}, overshoot {100 * m['overshoot']:.1f} cm)",
        )
    ax.axvline(data["release_time"], color="#888888", lw=0.8)
    ax.annotate(
        "released",
        (data["release_time"], ax.get_ylim()[1]),
        xytext=(4, -12),
        textcoords="offset points",
        fontsize=8,
        color="#555555",
    )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("pelvis position along y (m)")
    ax.set_title("Damping of the PD control: recovery after a collision")
    ax.legend(loc="upper left", fontsize=7.5)
    save_figure(
        fig,
        out_path("fig4_damping", args),
        metrics=data["metrics"],
        dampings=dampings,
        series={
            "time": data["time"],
            "target": target.tolist(),
            "release_time": data["release_time"],
            "position": data["position"],
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Paper Fig. 5: rendered frames per density, Baseline vs Ours, overlapping volumes in red.

For each density level, the stationary (concert) Baseline of the study design's cell and
its physics-corrected version are rendered at the same frame and viewpoint in the overlap
view (``crowdstudy.render.overlap_view``: body surfaces lying inside another character are
painted red, seen through the two bodies involved). Each panel gives the red fraction of
the crowd's pixels. Animations are cached in ``paper_figs/cache/``.

    .venv/bin/python paper_figs/fig5_frames.py            # D1..D5, 960x540, 1 s clips
    .venv/bin/python paper_figs/fig5_frames.py --quick    # D1, D3, D5, 480x270, 0.4 s clips
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from figstyle import METHOD_COLOURS, apply_style, cache_path, figure_args, out_path, save_figure  # noqa: E402


def cell_animations(design, level: str, duration: float, refresh: bool):
    """(Baseline, Ours) of the stationary cell ``level``, cached."""
    from crowdstudy.motion import build_baseline
    from crowdstudy.physics import correct
    from crowdstudy.scene import CrowdAnimation

    st = design.stage("stationary")
    tag = f"fig5_S{st.number}-{level}-{duration:g}s"
    paths = {m: cache_path(f"{tag}-{m}.npz") for m in ("Baseline", "Ours")}
    if not refresh and all(p.is_file() for p in paths.values()):
        try:
            return tuple(CrowdAnimation.load(paths[m]) for m in ("Baseline", "Ours"))
        except ValueError:
            pass
    base = build_baseline(design, st.key, level, duration=duration)
    ours = correct(base, progress=True)
    base.save(paths["Baseline"])
    ours.save(paths["Ours"])
    return base, ours


def main(argv=None) -> int:
    args = figure_args(__doc__.splitlines()[0], argv, view={"default": "V2", "help": "viewpoint"})
    import matplotlib.pyplot as plt

    from crowdstudy.design import load_design
    from crowdstudy.render.renderer import CrowdRenderer

    apply_style()
    design = load_design()
    levels = ["D1", "D3", "D5"] if args.quick else list(design.densities)
    width, height = (480, 270) if args.quick else (960, 540)
    duration = 0.4 if args.quick else 1.0
    fig, axes = plt.subplots(len(levels), 2, figsize=(7.2, 2.05 * len(levels)), squeeze=False)
    info = {"view": args.view, "width": width, "height": height, "duration": duration, "panels": []}
    for row, level in enumerate(levels):
        anims = cell_animations(design, level, duration, args.refresh)
        colours = anims[0].root_translation[0, :, :2]  # both methods wear the Baseline's colours
        for col, (method, anim) in enumerate(zip(("Baseline", "Ours"), anims, strict=True)):
            frame = anim.n_frames - 1
            with CrowdRenderer(anim, design=design, width=width, height=height, color_positions=colours) as r:
                r.set_view(args.view)
                res = r.overlap(frame)
            ax = axes[row, col]
            ax.imshow(res.image)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.grid(False)
            for spine in ax.spines.values():
                spine.set_visible(True)
                spine.set_color(METHOD_COLOURS[method])
                spine.set_linewidth(1.5)
            ax.set_title(
                f"{level} ({anim.n_characters} characters), {method}: "
                f"{100 * res.crowd_fraction:.1f}% of crowd pixels overlap",
                fontsize=8,
            )
            info["panels"].append(
                {
                    "level": level,
                    "method": method,
                    "frame": frame,
                    "characters": anim.n_characters,
                    "red_fraction": res.red_fraction,
                    "crowd_fraction": res.crowd_fraction,
                }
            )
    fig.suptitle("Overlapping body volumes (red), Baseline vs Ours, per density", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out_path("fig5_frames", args), seed=design.seed, **info)
    for p in info["panels"]:
        print(
            f"  {p['level']} {p['method']:8s} red {100 * p['red_fraction']:.2f}% of image, "
            f"{100 * p['crowd_fraction']:.2f}% of crowd"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Paper Fig. 8: samples of the stimuli, densities x viewpoints x scenarios.

One row per (scenario, viewpoint) the study design shows (stage 1, the concert: V1..V4;
stage 2, the corridor: V3, V4), one column per density level; each panel is a frame of
that cell's stimulus, rendered directly from the cell's animation (``--method``: Ours,
the corrected stimulus, by default) at the viewpoint the videos use. The sidecar lists
every panel (stage, scenario, viewpoint, level, characters, frame, the image's mean and
spread). Animations are cached in ``paper_figs/cache/``.

    .venv/bin/python paper_figs/fig8_samples.py            # 6 rows x D1..D5, 480x270, 1 s clips
    .venv/bin/python paper_figs/fig8_samples.py --quick    # concert V1, V4 and corridor V3 x D1, D5, 320x180, 0.4 s
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from figstyle import METHOD_COLOURS, apply_style, cache_path, figure_args, out_path, save_figure  # noqa: E402


def cell(design, stage, level: str, duration: float, method: str, refresh: bool):
    """The ``method`` animation of the cell (stage, level), ``duration`` s, cached."""
    from crowdstudy.motion import build_baseline
    from crowdstudy.physics import correct
    from crowdstudy.scene import CrowdAnimation

    tag = f"fig8_S{stage.number}-{level}-{duration:g}s"
    path = cache_path(f"{tag}-{method}.npz")
    if not refresh and path.is_file():
        try:
            return CrowdAnimation.load(path)
        except ValueError:
            pass
    anim = build_baseline(design, stage.key, level, duration=duration)
    if method == "Ours":
        anim = correct(anim, progress=False)
    anim.save(path)
    return anim


def grid(design, quick: bool) -> tuple[list[tuple[object, str]], list[str]]:
    """The rows ((stage, viewpoint) pairs) and the columns (density levels) of the figure."""
    rows = [(st, v) for st in design.stages for v in st.viewpoints]
    levels = list(design.densities)
    if quick:
        concert = [r for r in rows if r[0].key == "stationary"]
        corridor = [r for r in rows if r[0].key == "walking"]
        rows = [concert[0], concert[-1], corridor[0]]
        levels = [levels[0], levels[-1]]
    return rows, levels


def _panel(ax, image, method: str, level: str | None, row) -> None:
    ax.imshow(image)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.grid(False)
    for spine in ax.spines.values():
        spine.set_visible(True)
        spine.set_color(METHOD_COLOURS[method])
    if level is not None:
        ax.set_title(level, fontsize=8)
    if row is not None:
        st, view = row
        ax.set_ylabel(f"{st.scenario}\n{view}", fontsize=8)


def main(argv=None) -> int:
    args = figure_args(
        __doc__.splitlines()[0], argv, method={"default": "Ours", "choices": ["Baseline", "Ours"], "help": "method"}
    )
    import matplotlib.pyplot as plt

    from crowdstudy.design import load_design
    from crowdstudy.render.renderer import CrowdRenderer

    apply_style()
    design = load_design()
    rows, levels = grid(design, args.quick)
    width, height = (320, 180) if args.quick else (480, 270)
    duration = 0.4 if args.quick else 1.0
    fig, axes = plt.subplots(len(rows), len(levels), figsize=(1.9 * len(levels), 1.2 * len(rows)), squeeze=False)
    info = {"method": args.method, "width": width, "height": height, "duration": duration, "panels": []}
    stages = list(dict.fromkeys(st.key for st, _ in rows))
    for c, level in enumerate(levels):
        for key in stages:
            st = design.stage(key)
            anim = cell(design, st, level, duration, args.method, args.refresh)
            frame = min(anim.n_frames - 1, int(round(duration * anim.fps)) - 1)
            with CrowdRenderer(anim, design=design, width=width, height=height) as rend:
                for r, (row_stage, view) in enumerate(rows):
                    if row_stage.key != key:
                        continue
                    rend.set_view(view)
                    image = rend.render(frame)
                    _panel(axes[r, c], image, args.method, level if r == 0 else None, (st, view) if c == 0 else None)
                    info["panels"].append(
                        {
                            "stage": key,
                            "scenario": anim.meta.get("scenario"),
                            "viewpoint": view,
                            "level": level,
                            "characters": anim.n_characters,
                            "frame": frame,
                            "row": r,
                            "column": c,
                            "image_mean": float(np.mean(image)),
                            "image_std": float(np.std(image)),
                        }
                    )
    fig.suptitle(f"Samples of the stimuli ({args.method}): densities x viewpoints x scenarios", fontsize=10)
    fig.tight_layout()
    save_figure(fig, out_path("fig8_samples", args), seed=design.seed, **info)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Paper Fig. 6: the live walker through the concert crowd, Baseline above Ours.

A CMU walk crosses the dancing D5 concert crowd (60 dancers, the study's cell and seed;
:func:`crowdstudy.motion.walker.live_scene`) and the scene is corrected one frame at a time,
as a game loop would (:func:`crowdstudy.physics.live.run_live`: no look-ahead, no output
stage). Three moments (the walker entering the crowd, in its middle, leaving it) are
rendered in the overlap view (surfaces inside another character in red) from behind the
crowd; the walker is ringed in yellow. The sidecar holds, per panel, the walker's position
and its mesh overlap (litres) at that frame, and the live loop's ms per frame.

    .venv/bin/python paper_figs/fig6_live.py            # a 4.8 m walk, 960x540 panels
    .venv/bin/python paper_figs/fig6_live.py --quick    # a 3.2 m walk, 480x270 panels
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from figstyle import METHOD_COLOURS, apply_style, cache_path, figure_args, out_path, save_figure  # noqa: E402

#: where the walker's pelvis is at the three moments (x, m): entering, middle, leaving
MOMENTS = {"entering": -1.1, "middle": 0.0, "leaving": 1.1}
#: the camera: behind the crowd (the stage is at +y), raised
EYE, TARGET = (0.4, -4.6, 3.4), (0.0, -0.2, 0.7)


def live_animations(quick: bool, refresh: bool):
    """(Baseline, Ours, per-frame stats of the live loop), cached."""
    from crowdstudy.motion.walker import WalkerPath, live_scene
    from crowdstudy.physics.live import frame_stats, run_live
    from crowdstudy.scene import CrowdAnimation

    path = WalkerPath(start=(-1.7, -0.3), distance=3.4) if quick else WalkerPath()
    tag = f"fig6_live-{path.start[0]:g}-{path.distance:g}"
    paths = {m: cache_path(f"{tag}-{m}.npz") for m in ("Baseline", "Ours")}
    if not refresh and all(p.is_file() for p in paths.values()):
        try:
            return (*(CrowdAnimation.load(paths[m]) for m in ("Baseline", "Ours")), None)
        except ValueError:
            pass
    base = live_scene(None, "D5", path)
    run = run_live(base)
    base.save(paths["Baseline"])
    run.ours.save(paths["Ours"])
    stats = {"wall": frame_stats(run.wall_seconds, base.fps), "cpu": frame_stats(run.cpu_seconds, base.fps)}
    return base, run.ours, stats


def moment_frames(base, walker: int) -> dict[str, int]:
    """The frame at which the walker's pelvis is nearest each of :data:`MOMENTS`' x."""
    x = base.root_translation[:, walker, 0]
    return {name: int(np.argmin(np.abs(x - target))) for name, target in MOMENTS.items()}


def _walker_overlap(anim, walker: int, frames: list[int]) -> list[float]:
    from crowdstudy.metrics.overlap import overlap_volume

    res = overlap_volume(anim, resolution=0.02, geometry="mesh", frames=np.asarray(frames))
    return [1000.0 * float(v) for v in res.per_character[:, walker]]


def _panel(ax, image, method: str, title: str, ring) -> None:
    from matplotlib.patches import Ellipse

    ax.imshow(image)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.grid(False)
    for spine in ax.spines.values():
        spine.set_visible(True)
        spine.set_color(METHOD_COLOURS[method])
        spine.set_linewidth(1.5)
    (cx, cy), w, h = ring
    ax.add_patch(Ellipse((cx, cy), w, h, fill=False, edgecolor="#ffd400", linewidth=1.6))
    ax.set_title(title, fontsize=8)


def _ring(camera, anim, walker: int, frame: int, width: int, height: int):
    """The walker's pelvis-to-head extent on screen: ((cx, cy), w, h) pixels."""
    root = anim.root_translation[frame, walker]
    pts = np.array([root + (0, 0, -0.9), root + (0, 0, 0.75)])
    px, _ = camera.project(pts, width, height)
    h = abs(px[1, 1] - px[0, 1]) * 1.15
    return ((px[:, 0].mean(), px[:, 1].mean()), 0.55 * h, h)


def main(argv=None) -> int:
    args = figure_args(__doc__.splitlines()[0], argv)
    import matplotlib.pyplot as plt

    from crowdstudy.motion.walker import walker_index
    from crowdstudy.render.camera import free_camera
    from crowdstudy.render.renderer import CrowdRenderer

    apply_style()
    width, height = (480, 270) if args.quick else (960, 540)
    base, ours, stats = live_animations(args.quick, args.refresh)
    walker = walker_index(base)
    moments = moment_frames(base, walker)
    frames = list(moments.values())
    colours = base.root_translation[0, :, :2]  # both methods wear the Baseline's colours
    fig, axes = plt.subplots(2, 3, figsize=(10.5, 4.0), squeeze=False)
    info = {"width": width, "height": height, "walker": base.meta["live_walker"], "live_ms": stats, "panels": []}
    for row, (method, anim) in enumerate(zip(("Baseline", "Ours"), (base, ours), strict=True)):
        litres = _walker_overlap(anim, walker, frames)
        with CrowdRenderer(anim, width=width, height=height, color_positions=colours) as r:
            camera = r.set_view(free_camera(EYE, TARGET, fov=40.0))
            for col, (name, frame) in enumerate(moments.items()):
                res = r.overlap(frame)
                ring = _ring(camera, anim, walker, frame, width, height)
                title = f"{method}, {name} (t = {frame / anim.fps:.1f} s): walker overlap {litres[col]:.2f} L"
                _panel(axes[row, col], res.image, method, title, ring)
                info["panels"].append(
                    {
                        "method": method,
                        "moment": name,
                        "frame": frame,
                        "walker_xy": [float(v) for v in anim.root_translation[frame, walker, :2]],
                        "walker_overlap_l": litres[col],
                        "red_fraction": res.red_fraction,
                        "crowd_fraction": res.crowd_fraction,
                        "ring_px": [float(ring[0][0]), float(ring[0][1])],
                    }
                )
    fig.suptitle(
        "A captured walker through the D5 concert crowd, corrected frame by frame (top Baseline, bottom Ours)",
        fontsize=10,
    )
    fig.tight_layout()
    save_figure(fig, out_path("fig6_live", args), seed=base.meta.get("seed"), **info)
    for p in info["panels"]:
        print(f"  {p['method']:8s} {p['moment']:8s} frame {p['frame']:3d} walker overlap {p['walker_overlap_l']:.2f} L")
    return 0


if __name__ == "__main__":
    sys.exit(main())

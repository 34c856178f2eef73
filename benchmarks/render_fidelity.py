"""The SSIM check of ``crowdstudy bench render``: stimulus frames against their supersampled
references (:mod:`crowdstudy.render.fidelity`), with the time per frame of each setting.

Frames checked (:data:`FRAMES`): the D3 concert from V1 (the wide view the bar was set
on), the D5 corridor from V3, the D5 concert from V4 and the D1 corridor from V2, each at
frame 10 of its Baseline. Each is rendered with the stimulus settings and with the
previous default (4x MSAA, no post-process filter, the same levels of detail), and
compared with the frame at twice the width and height, 4x MSAA, the finest meshes, box
filtered down. CPU seconds per frame are medians over ``frames`` frames drawn by one
renderer (its set-up and static layers drawn beforehand).
"""

from __future__ import annotations

import functools
import time

import numpy as np

__all__ = ["FRAMES", "fidelity_rows"]

#: (stage key, density level, viewpoint, frame) of the frames checked
FRAMES = (
    ("stationary", "D3", "V1", 10),
    ("walking", "D5", "V3", 10),
    ("stationary", "D5", "V4", 10),
    ("walking", "D1", "V2", 10),
)


def fidelity_rows(design, configs: dict, *, width: int, height: int, frames: int = 4, progress=print) -> list[dict]:
    """One row per checked frame and configuration (name -> renderer options, or a preset's
    settings): stage, level, view, config, ssim, cpu_s (median per frame), wall_s."""
    from crowdstudy.motion import build_baseline
    from crowdstudy.render.fidelity import SSIM_BAR, frame_ssim, reference_frame
    from crowdstudy.render.renderer import CrowdRenderer
    from crowdstudy.render.stimuli import renderer_options

    rows = []
    for stage, level, view, frame in FRAMES:
        anim = build_baseline(design, stage, level, duration=max(1.0, (frame + frames + 2) / design.fps))
        factory = functools.partial(CrowdRenderer, anim, design=design)
        ref = reference_frame(factory, view, frame, width=width, height=height)
        for name, options in configs.items():
            with factory(**{**renderer_options(options), "width": width, "height": height}) as r:
                r.set_view(view)
                r.draw_layers()
                image = r.render(frame)
                cpu, wall = [], []
                for f in range(frame + 1, frame + 1 + frames):
                    c0, t0 = time.process_time(), time.perf_counter()
                    r.render_raw(f)
                    cpu.append(time.process_time() - c0)
                    wall.append(time.perf_counter() - t0)
            ssim = frame_ssim(image, ref)
            rows.append(
                {
                    "stage": stage,
                    "level": level,
                    "view": view,
                    "config": name,
                    "ssim": ssim,
                    "meets_bar": bool(ssim >= SSIM_BAR),
                    "cpu_s": float(np.median(cpu)),
                    "wall_s": float(np.median(wall)),
                }
            )
            progress(f"  SSIM {stage} {level} {view} {name}: {ssim:.4f}, {np.median(cpu):.3f} CPU-s per frame")
    return rows

"""How faithful a rendered frame is: its SSIM against a supersampled reference.

The reference of a frame is the same frame rendered at ``scale`` times the width and height
with 4x MSAA and the detail (textures, meshes, levels of detail) of the frame's own size,
then averaged down over ``scale`` x ``scale`` pixel blocks (a box filter): what an ideal
anti-aliasing of the same content would give. :func:`frame_ssim` compares two frames the
way scikit-image's ``structural_similarity`` does on their luma (Rec. 601 weights,
7x7 uniform window, data range 255): 1 means identical structure.

The stimulus renderer's settings are held to :data:`SSIM_BAR` on the study's frames
(:func:`check_frames`; ``crowdstudy bench render --ssim`` and ``--set``): the D3 concert
from V1 (the wide view the bar was set on), the D5 corridor from V3, the D5 concert from
V4 and the D1 corridor from V2, each at frame 10 of its Baseline.
"""

from __future__ import annotations

import functools
import time

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["SSIM_BAR", "FRAMES", "box_downsample", "luma", "frame_ssim", "reference_frame", "check_frames"]

#: the lowest SSIM a stimulus frame may have against its supersampled reference: 4x MSAA
#: at the frame's size scores just above it on the concert's wide view
SSIM_BAR = 0.988


def box_downsample(image: np.ndarray, scale: int) -> np.ndarray:
    """(H*scale, W*scale, C) uint8 -> (H, W, C) uint8, the mean of each block, rounded."""
    if scale < 1 or image.shape[0] % scale or image.shape[1] % scale:
        raise InvalidInputError(f"scale: expected a divisor of the image size {image.shape[:2]}, got {scale!r}")
    h, w = image.shape[0] // scale, image.shape[1] // scale
    blocks = image.reshape(h, scale, w, scale, -1).astype(np.float64)
    return np.clip(np.rint(blocks.mean(axis=(1, 3))), 0, 255).astype(np.uint8)


def luma(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 -> (H, W) float64 luma in 0..255 (Rec. 601: 0.299 R + 0.587 G + 0.114 B)."""
    return np.asarray(image[..., :3], dtype=np.float64) @ np.array([0.299, 0.587, 0.114])


def frame_ssim(image: np.ndarray, reference: np.ndarray) -> float:
    """The mean SSIM of two (H, W, 3) uint8 frames' luma (scikit-image's defaults: 7x7
    uniform window, K1 0.01, K2 0.03, data range 255)."""
    from skimage.metrics import structural_similarity

    if image.shape != reference.shape:
        raise InvalidInputError(f"image: expected the reference's shape {reference.shape}, got {image.shape}")
    return float(structural_similarity(luma(image), luma(reference), data_range=255.0))


def reference_frame(renderer_factory, view, frame: int, *, width: int, height: int, scale: int = 2) -> np.ndarray:
    """The supersampled reference of one frame: ``renderer_factory(**options)`` makes a
    :class:`~crowdstudy.render.renderer.CrowdRenderer` (the animation and everything else
    bound), called here with ``width``/``height`` times ``scale``, 4x MSAA, no post-process
    filter and ``detail_height=height`` (the same meshes and textures); the frame rendered
    from ``view`` and box-filtered down to ``width`` x ``height``. (H, W, 3) uint8, first row at the top."""
    if isinstance(scale, bool) or not isinstance(scale, int) or not 1 <= scale <= 4:
        raise InvalidInputError(f"scale: expected an integer in 1..4, got {scale!r}")
    with renderer_factory(
        width=width * scale, height=height * scale, msaa=4, post_aa="none", detail_height=height
    ) as r:
        r.set_view(view)
        return box_downsample(r.render(frame), scale)


#: (stage key, density level, viewpoint, frame) of the frames checked
FRAMES = (
    ("stationary", "D3", "V1", 10),
    ("walking", "D5", "V3", 10),
    ("stationary", "D5", "V4", 10),
    ("walking", "D1", "V2", 10),
)


def check_frames(design, configs: dict, *, width: int, height: int, frames: int = 4, progress=None) -> list[dict]:
    """The SSIM check: each of :data:`FRAMES` (its Baseline, built here) rendered with each
    of ``configs`` (name -> renderer options, or a stimulus preset's settings) against its
    :func:`reference_frame`. One row per frame and configuration: stage, level, view,
    config, ssim, meets_bar (:data:`SSIM_BAR`), cpu_s and wall_s (medians per frame over
    ``frames`` frames drawn after it by the same renderer, its set-up done)."""
    from crowdstudy.motion import build_baseline
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
            if progress is not None:
                progress(f"  SSIM {stage} {level} {view} {name}: {ssim:.4f}, {np.median(cpu):.3f} CPU-s per frame")
    return rows

"""How faithful a rendered frame is: its SSIM against a supersampled reference.

The reference of a frame is the same frame rendered at ``scale`` times the width and height
with 4x MSAA and the detail (textures, meshes, levels of detail) of the frame's own size,
then averaged down over ``scale`` x ``scale`` pixel blocks (a box filter): what an ideal
anti-aliasing of the same content would give. :func:`frame_ssim` compares two frames the
way scikit-image's ``structural_similarity`` does on their luma (Rec. 601 weights,
7x7 uniform window, data range 255): 1 means identical structure.

The stimulus renderer's settings are held to :data:`SSIM_BAR` on the study's frames
(``crowdstudy bench render --ssim``).
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["SSIM_BAR", "box_downsample", "luma", "frame_ssim", "reference_frame"]

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

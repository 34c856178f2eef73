"""How visible a looping video's seam is, in pixels.

A video loops while the participant answers, so its last frame is followed by its first.
:func:`seam_change` compares that step with the ordinary ones: the mean absolute pixel
change (0..255, averaged over pixels and channels) between consecutive frames, the change
at the seam (last frame -> first frame) and their ratio against the median consecutive
change. A seam that reads as continuous motion has a ratio near 1; a jump (the whole crowd
moving 1.5 m between two frames) gives several times the median.

:func:`decode_video` reads a video back (ffmpeg, raw RGB, optionally scaled down) for it.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.render.video import find_ffmpeg, probe_video

__all__ = ["decode_video", "seam_change", "measure_seam"]


def decode_video(path: str | Path, *, width: int | None = None, height: int | None = None) -> np.ndarray:
    """(F, H, W, 3) uint8 frames of a video, top row first; scaled to ``width`` x ``height``
    when given (area filter; give both, or one and -2 is used for the other)."""
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"path: video {str(path)!r} does not exist")
    info = probe_video(path)
    w, h = info["width"], info["height"]
    vf = []
    if width or height:
        w_out, h_out = int(width or -2), int(height or -2)
        if w_out == -2:
            w_out = int(round(w * h_out / h / 2)) * 2
        if h_out == -2:
            h_out = int(round(h * w_out / w / 2)) * 2
        vf = ["-vf", f"scale={w_out}:{h_out}:flags=area"]
        w, h = w_out, h_out
    raw = subprocess.run(
        [
            find_ffmpeg(),
            "-hide_banner",
            "-loglevel",
            "error",
            "-i",
            str(path),
            *vf,
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "pipe:1",
        ],
        capture_output=True,
        check=True,
    ).stdout
    return np.frombuffer(raw, np.uint8).reshape(-1, h, w, 3)


def seam_change(frames) -> dict:
    """Pixel change at the loop seam of ``frames`` (F, H, W, C) (uint8 or float, F >= 3).

    Returns a dict: ``steps`` (list, F-1 mean absolute changes frame k -> k+1), ``median``,
    ``max`` (of the steps), ``seam`` (frame F-1 -> frame 0), ``ratio`` (seam / median),
    ``max_ratio`` (largest step / median, for comparison: how jumpy the clip is anyway).
    """
    f = np.asarray(frames)
    if f.ndim not in (3, 4) or f.shape[0] < 3:
        raise InvalidInputError(f"frames: expected (F >= 3, H, W[, C]) frames, got shape {f.shape}")
    steps = np.array(
        [np.abs(f[k + 1].astype(np.float32) - f[k].astype(np.float32)).mean() for k in range(f.shape[0] - 1)],
        dtype=np.float64,
    )
    seam = float(np.abs(f[0].astype(np.float32) - f[-1].astype(np.float32)).mean())
    median = float(np.median(steps))
    scale = median if median > 0 else np.inf
    return {
        "steps": steps.tolist(),
        "median": median,
        "max": float(steps.max()),
        "seam": seam,
        "ratio": seam / scale if np.isfinite(scale) else (0.0 if seam == 0 else np.inf),
        "max_ratio": float(steps.max()) / scale if np.isfinite(scale) else 0.0,
    }


def measure_seam(video, *, width: int | None = 480, height: int | None = 270) -> dict:
    """:func:`seam_change` of a video file (decoded at ``width`` x ``height``; None = as
    stored) or of already decoded frames; adds ``frames`` and ``size``."""
    frames = decode_video(video, width=width, height=height) if isinstance(video, (str, Path)) else np.asarray(video)
    out = seam_change(frames)
    out["frames"] = int(frames.shape[0])
    out["size"] = [int(frames.shape[2]), int(frames.shape[1])]
    return out

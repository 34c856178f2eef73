"""One dictionary of metrics for an animation (the CLI, the stimulus manifest, the demo)."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from crowdstudy.metrics.overlap import GEOMETRIES, overlap_volume, resolve_bodies
from crowdstudy.metrics.tracking import intra_penetration, mean_jerk, tracking_error

__all__ = ["summarize"]


def summarize(anim, reference=None, *, resolution: float = 0.02, frames: Any = "auto",
              geometries: Sequence[str] = GEOMETRIES, bodies: Sequence | None = None,
              device: str | None = None, progress: bool = False) -> dict:
    """Overlap, smoothness, self-penetration and (with a reference) tracking of ``anim``.

    Args:
        anim: the :class:`~crowdstudy.scene.CrowdAnimation` to measure.
        reference: its input animation (e.g. the Baseline of an "Ours"), or None.
        resolution: overlap grid spacing, metres.
        frames: frames for the overlap and self-penetration measurements (see
            :func:`~crowdstudy.metrics.overlap.frame_indices`; ``"auto"`` = every 10th frame
            of clips longer than 100 frames). Jerk and tracking use every frame.
        geometries: overlap geometries to measure, from ``("mesh", "capsule")``.
        bodies: optional body objects overriding ``load_body`` (shared with the reference).
        device: where mesh crossings run (see :func:`~crowdstudy.metrics.overlap_volume`).

    Returns:
        A JSON-serialisable dict: ``characters``, ``frames``, ``fps``, ``method``,
        ``resolution_m``, ``frames_measured``, ``overlap_<geometry>_m3`` and ``_litres``
        (mean per character), ``overlap_<geometry>_seconds``, ``jerk_m_s3``,
        ``intra_penetration_cm``, ``intra_penetration_fraction``; with a reference also
        ``tracking_error_cm``, ``reference_overlap_<geometry>_m3`` and
        ``overlap_<geometry>_ratio`` (anim / reference).
    """
    body_objs = resolve_bodies(anim, bodies)
    out: dict = {"characters": anim.n_characters, "frames": anim.n_frames, "fps": anim.fps,
                 "method": anim.meta.get("method"), "resolution_m": float(resolution)}
    for geometry in geometries:
        res = overlap_volume(anim, resolution=resolution, geometry=geometry, frames=frames, bodies=body_objs,
                             device=device, progress=progress)
        out["frames_measured"] = int(len(res.frames))
        steps = np.unique(np.diff(res.frames))
        # None when the measured frames are not evenly spaced (an explicit list)
        out["frame_step"] = int(steps[0]) if len(steps) == 1 else (1 if len(res.frames) == 1 else None)
        out[f"overlap_{geometry}_m3"] = res.mean
        out[f"overlap_{geometry}_litres"] = res.mean_litres
        out[f"overlap_{geometry}_seconds"] = res.seconds
        if res.fraction is not None:
            out[f"overlap_{geometry}_fraction"] = res.fraction
        if reference is not None:
            ref = overlap_volume(reference, resolution=resolution, geometry=geometry, frames=frames,
                                 bodies=body_objs, device=device, progress=progress)
            out[f"reference_overlap_{geometry}_m3"] = ref.mean
            out[f"reference_overlap_{geometry}_litres"] = ref.mean_litres
            out[f"overlap_{geometry}_ratio"] = res.mean / ref.mean if ref.mean > 0 else None
    if anim.n_frames >= 4:
        out["jerk_m_s3"] = mean_jerk(anim, bodies=body_objs)
        if reference is not None:
            out["reference_jerk_m_s3"] = mean_jerk(reference, bodies=body_objs)
    intra = intra_penetration(anim, frames=frames, bodies=body_objs)
    out["intra_penetration_cm"] = 100.0 * intra.mean_depth
    out["intra_penetration_fraction"] = intra.fraction
    if reference is not None:
        out["tracking_error_cm"] = tracking_error(anim, reference, bodies=body_objs)
    return out

"""One dictionary of metrics for an animation (the CLI, the stimulus manifest, the demo)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdstudy.metrics.overlap import GEOMETRIES, overlap_volume, resolve_bodies
from crowdstudy.metrics.smoothness import _joint_positions, smoothness_from_positions, smoothness_ratios
from crowdstudy.metrics.tracking import intra_penetration, tracking_parts
from crowdstudy.metrics.walls import wall_penetration

__all__ = ["summarize"]


def summarize(
    anim,
    reference=None,
    *,
    resolution: float = 0.02,
    frames: Any = "auto",
    geometries: Sequence[str] = GEOMETRIES,
    bodies: Sequence | None = None,
    device: str | None = None,
    progress: bool = False,
    per_character: bool = False,
) -> dict:
    """Overlap, smoothness, self-penetration and (with a reference) tracking of ``anim``.

    Args:
        anim: the :class:`~crowdstudy.scene.CrowdAnimation` to measure.
        reference: its input animation (e.g. the Baseline of an "Ours"), or None.
        resolution: overlap grid spacing, metres.
        frames: frames for the overlap and self-penetration measurements (see
            :func:`~crowdstudy.metrics.overlap.frame_indices`; ``"auto"`` = every 10th frame
            of clips longer than 100 frames). Smoothness and tracking use every frame.
        geometries: overlap geometries to measure, from ``("mesh", "capsule")``.
        bodies: optional body objects overriding ``load_body`` (shared with the reference).
        device: where mesh crossings run (see :func:`~crowdstudy.metrics.overlap_volume`).
        per_character: also add the per-character smoothness lists (``smoothness_per_character``
            and, with a reference, ``reference_smoothness_per_character`` and
            ``tracking_per_character``: tracking, placement and each body part's, cm).

    Returns:
        A JSON-serialisable dict: ``characters``, ``frames``, ``fps``, ``method``,
        ``resolution_m``, ``frames_measured``, ``overlap_<geometry>_m3`` and ``_litres``
        (mean per character), ``overlap_<geometry>_seconds``, ``intra_penetration_cm``,
        ``intra_penetration_fraction``, ``wall_penetration_p99_cm`` / ``_max_cm`` (skin
        through the scene's walls, :func:`~crowdstudy.metrics.wall_penetration`; 0 without
        walls), and (clips of at least 4 frames) the smoothness keys
        of :meth:`~crowdstudy.metrics.smoothness.SmoothnessResult.as_dict` (``jerk_m_s3``,
        ``hf_share``, ``max_joint_speed_m_s``, ``pelvis_accel_p99_m_s2``,
        ``foot_slide_p99_m_s`` ..., ``seam_ratio``; the planted feet of ``anim`` are taken from
        the reference when given). With a reference also ``tracking_error_cm``,
        ``tracking_placement_cm``, ``tracking_motion_cm`` and ``tracking_legs_cm`` /
        ``_trunk_cm`` / ``_arms_cm`` (:class:`~crowdstudy.metrics.tracking.TrackingParts`),
        ``reference_overlap_<geometry>_m3``, ``overlap_<geometry>_ratio`` (anim / reference),
        ``reference_wall_penetration_p99_cm`` / ``_max_cm``,
        the reference's smoothness keys prefixed ``reference_`` and the keys of
        :func:`~crowdstudy.metrics.smoothness.smoothness_ratios` (``jerk_ratio`` ...).
    """
    body_objs = resolve_bodies(anim, bodies)
    out: dict = {
        "characters": anim.n_characters,
        "frames": anim.n_frames,
        "fps": anim.fps,
        "method": anim.meta.get("method"),
        "resolution_m": float(resolution),
    }
    for geometry in geometries:
        res = overlap_volume(
            anim,
            resolution=resolution,
            geometry=geometry,
            frames=frames,
            bodies=body_objs,
            device=device,
            progress=progress,
        )
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
            ref = overlap_volume(
                reference,
                resolution=resolution,
                geometry=geometry,
                frames=frames,
                bodies=body_objs,
                device=device,
                progress=progress,
            )
            out[f"reference_overlap_{geometry}_m3"] = ref.mean
            out[f"reference_overlap_{geometry}_litres"] = ref.mean_litres
            out[f"overlap_{geometry}_ratio"] = res.mean / ref.mean if ref.mean > 0 else None
    if anim.n_frames >= 4:
        ref_pos = None if reference is None else _joint_positions(reference, body_objs)
        smooth = smoothness_from_positions(
            _joint_positions(anim, body_objs),
            anim.root_translation,
            anim.fps,
            reference_pos=ref_pos,
            periodic_length=anim.periodic_length,
        )
        values = smooth.as_dict(per_character=per_character)
        if per_character:
            out["smoothness_per_character"] = values.pop("per_character")
        out.update(values)
        if reference is not None:
            # the Baseline's own feet decide where it is planted
            ref_smooth = smoothness_from_positions(
                ref_pos, reference.root_translation, reference.fps, periodic_length=reference.periodic_length
            )
            ref_values = ref_smooth.as_dict(per_character=per_character)
            if per_character:
                out["reference_smoothness_per_character"] = ref_values.pop("per_character")
            out.update({f"reference_{key}": value for key, value in ref_values.items()})
            out.update(smoothness_ratios(smooth, ref_smooth))
    intra = intra_penetration(anim, frames=frames, bodies=body_objs)
    out["intra_penetration_cm"] = 100.0 * intra.mean_depth
    out["intra_penetration_fraction"] = intra.fraction
    for prefix, a in (("", anim), ("reference_", reference)):
        if a is not None:
            walls = wall_penetration(a, frames=frames, bodies=body_objs)
            out[f"{prefix}wall_penetration_p99_cm"] = walls.p99_cm
            out[f"{prefix}wall_penetration_max_cm"] = walls.max_cm
    if reference is not None:
        out.update(tracking_parts(anim, reference, bodies=body_objs).as_dict(per_character=per_character))
    return out

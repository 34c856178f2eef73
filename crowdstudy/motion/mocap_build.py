"""Building the shipped motion-capture library (``crowdstudy motion build-library``).

:func:`build_library` reads the BVH takes of
:data:`~crowdstudy.motion.mocap_library.TAKES` from a folder (``shared/data/mocap``),
cleans them (:mod:`crowdstudy.motion.mocap`: facing, drift, planted feet), times the dances'
bounce (:mod:`crowdstudy.motion.beat`), makes the walks' gait loops
(:mod:`crowdstudy.motion.mocap_walks`) and writes ``takes.npz`` and ``library.json`` (the
format is described in :mod:`crowdstudy.motion.mocap_library`). Same input, same bytes.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from crowdstudy.body.rotations import axis_angle_to_quaternion
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.beat import beat_curve, low_points
from crowdstudy.motion.bvh import load_bvh
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.mocap import clean_take
from crowdstudy.motion.mocap_library import CREDIT, LICENCE, TAKES, TakeSpec
from crowdstudy.motion.mocap_walks import build_walk_loops

__all__ = ["build_library", "default_output"]


def default_output() -> Path:
    """The library folder inside the package source (``crowdstudy/motion/mocap``)."""
    return Path(__file__).resolve().parent / "mocap"


def _pack(clip: MotionClip, spec: TakeSpec) -> tuple[dict[str, np.ndarray], dict]:
    quat = axis_angle_to_quaternion(clip.joint_rotations)
    quat = quat * np.where(quat[..., 3:] < 0.0, -1.0, 1.0)  # w >= 0: no sign flips to store
    arrays = {
        f"{spec.name}.quat": quat.astype(np.float16),
        f"{spec.name}.root": clip.root_translation.astype(np.float32),
    }
    meta = {k: v for k, v in clip.meta.items() if k != "source"}
    info = {
        "kind": spec.kind,
        "fps": clip.fps,
        "loop": clip.loop,
        "speed": clip.speed,
        "file": spec.file,
        "trial": f"CMU {spec.trial}",
        "description": spec.description,
        "default": spec.default,
        "licence": LICENCE,
        "meta": json.loads(json.dumps(meta, default=float)),
    }
    return arrays, info


def build_library(
    source: str | Path, out: str | Path, *, names: list[str] | None = None, progress: bool = False
) -> Path:
    """Convert the takes of :data:`TAKES` (all, or ``names``) from the BVH folder ``source``
    into ``out/takes.npz`` and ``out/library.json``; returns ``out``."""
    source, out = Path(source), Path(out)
    specs = [t for t in TAKES if names is None or t.name in names]
    for t in specs:
        if not (source / t.file).is_file():
            raise InvalidInputError(f"source: {str(source / t.file)!r} is missing (take {t.name!r})")
    arrays: dict[str, np.ndarray] = {}
    library: dict[str, dict] = {}
    walk_specs = [t for t in specs if t.kind == "walk"]
    if walk_specs:
        loops = {c.meta["source"].split("/")[-1]: c for c in build_walk_loops(source)}
        for t in walk_specs:
            clip = loops[t.file]
            a, info = _pack(dataclasses.replace(clip, name=t.name), t)
            arrays.update(a)
            library[t.name] = info
    for t in specs:
        if t.kind == "walk":
            continue
        if progress:
            print(f"[mocap] {t.name} <- {t.file}", flush=True)
        clip = clean_take(load_bvh(source / t.file), trim_start=t.trim[0], trim_end=t.trim[1], name=t.name)
        if t.kind == "dance":
            bc = beat_curve(clip.root_translation[:, 2], clip.fps, period=t.bounce_period)
            lows = [round(float(x), 6) for x in low_points(clip.root_translation[:, 2], clip.fps)]
            clip = dataclasses.replace(
                clip,
                meta={
                    **clip.meta,
                    "bounce_period": bc.period,
                    "bounce_lows": lows,
                    "bounce_method": bc.method,
                    "bounce_strength": bc.strength,
                    "bounce_beats": t.bounce_beats,
                },
            )
        a, info = _pack(clip, t)
        arrays.update(a)
        library[t.name] = info
    out.mkdir(parents=True, exist_ok=True)
    # numpy's stub reads a ** of arrays as possibly its allow_pickle flag
    np.savez_compressed(out / "takes.npz", **arrays)  # pyright: ignore[reportArgumentType]
    (out / "library.json").write_text(json.dumps({"credit": CREDIT, "takes": library}, indent=1, sort_keys=True) + "\n")
    return out

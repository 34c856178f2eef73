"""Correct a glTF or USD crowd file to a file of its format (``crowdstudy correct IN.glb
OUT.glb``, ``IN.usda OUT.usda``).

Import (:func:`crowdstudy.interchange.gltf_crowd.read_crowd`), correct
(:func:`~crowdstudy.physics.corrector.correct`, with the characters' own bodies), measure
the mesh overlap before and after (:func:`crowdstudy.metrics.overlap_volume`, every
``overlap_every`` seconds), write the corrected motion into the same scene
(:mod:`crowdstudy.interchange.gltf_write`, or
:mod:`crowdstudy.interchange.usd_write`). Nothing is written until everything has
worked: the output, its overlap report (``OUT_STEM.overlap.json``) and the timings
sidecar go to temporary files renamed at the end.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.errors import InvalidInputError

if TYPE_CHECKING:
    from crowdstudy.interchange.gltf_crowd import ImportedCrowd
    from crowdstudy.scene import CrowdAnimation

__all__ = [
    "GLTF_SUFFIXES",
    "SCENE_SUFFIXES",
    "GltfCorrection",
    "correct_gltf",
    "overlap_report_path",
    "check_gltf_paths",
]

GLTF_SUFFIXES = (".glb", ".gltf")
#: Scene formats corrected file to file: glTF and USD (:mod:`crowdstudy.interchange.usd_write`).
SCENE_SUFFIXES = (*GLTF_SUFFIXES, ".usd", ".usda", ".usdc")


def overlap_report_path(output: str | Path) -> Path:
    """``OUT_STEM.overlap.json`` beside ``output``."""
    output = Path(output)
    return output.with_name(output.stem + ".overlap.json")


def check_gltf_paths(inp: str | Path, out: str | Path) -> None:
    """The output must be in the input's format (.glb -> .glb, .gltf -> .gltf, .usda -> .usda...)."""
    a, b = Path(inp).suffix.lower(), Path(out).suffix.lower()
    if a in SCENE_SUFFIXES and b != a:
        raise InvalidInputError(f"output: {str(out)!r} must be a {a} file like the input {str(inp)!r}")
    if a not in SCENE_SUFFIXES and b in SCENE_SUFFIXES:
        what = "glTF" if b in GLTF_SUFFIXES else "USD"
        raise InvalidInputError(
            f"output: {str(out)!r} is {what} but the input {str(inp)!r} is not (use export-{what.lower()})"
        )


@dataclasses.dataclass
class GltfCorrection:
    """What :func:`correct_gltf` did: the imported crowd, the corrected animation, the
    output's bytes, the overlap report (a JSON-ready dict) and the timings (s)."""

    crowd: ImportedCrowd
    corrected: CrowdAnimation
    data: bytes
    overlap: dict
    timings: dict


def _overlap(anim, bodies, every: float, device: str | None) -> tuple[np.ndarray, object]:
    from crowdstudy.metrics.overlap import overlap_volume

    step = max(1, int(round(every * anim.fps)))
    frames = np.arange(0, anim.n_frames, step)
    res = overlap_volume(anim, geometry="mesh", frames=frames, bodies=bodies, device=device)
    return frames, res


def correct_gltf(
    inp: str | Path,
    out: str | Path,
    config=None,
    *,
    fps: float | None = None,
    animations: list[str] | None = None,
    overrides: dict | None = None,
    frames: int | None = None,
    device: str | None = None,
    linear_solver=None,
    progress: bool = False,
    overlap_every: float = 1.0,
) -> GltfCorrection:
    """Import, correct, measure and rewrite a glTF crowd; returns the output's bytes and
    reports without writing anything (:func:`write_outputs` writes them)."""
    from crowdstudy.interchange.gltf_crowd import read_crowd
    from crowdstudy.interchange.gltf_write import corrected_gltf_bytes
    from crowdstudy.physics.corrector import correct
    from crowdstudy.provenance import provenance

    check_gltf_paths(inp, out)
    t0 = time.perf_counter()
    crowd = read_crowd(inp, fps=fps, animations=animations, overrides=overrides)
    anim = crowd.anim
    if frames is not None:
        if not 2 <= frames <= anim.n_frames:
            raise InvalidInputError(f"--frames: expected 2 .. {anim.n_frames}, got {frames}")
        anim = anim.frames(0, frames)
    t1 = time.perf_counter()
    timings: dict = {}
    ours = correct(
        anim,
        config,
        device=device,
        progress=progress,
        bodies=crowd.bodies,
        linear_solver=linear_solver,
        timings=timings,
    )
    ours = _as_the_rigs_show_it(ours, crowd)
    t2 = time.perf_counter()
    measured, before = _overlap(anim, crowd.bodies, overlap_every, device)
    _, after = _overlap(ours, crowd.bodies, overlap_every, device)
    t3 = time.perf_counter()
    prov = provenance(stage="correct", source=str(inp), sha256=anim.meta["imported"]["sha256"])
    if crowd.usd is not None:
        from crowdstudy.interchange.usd_write import corrected_usd_bytes

        data = corrected_usd_bytes(crowd, ours, out, prov)
    else:
        data = corrected_gltf_bytes(crowd, ours, out, prov)
    t4 = time.perf_counter()
    report = _overlap_report(crowd, ours, measured, before, after, prov)
    timings.update(import_seconds=t1 - t0, correct_seconds=t2 - t1, overlap_seconds=t3 - t2, write_seconds=t4 - t3)
    return GltfCorrection(crowd, ours, data, report, timings)


def _as_the_rigs_show_it(ours, crowd):
    """The corrected motion with the turns of the joints each rig lacks passed to their
    children (:func:`~crowdstudy.interchange.retarget.fold_missing`): what the written
    file shows, so the overlap measured after is the file's."""
    from crowdstudy.interchange.retarget import fold_missing

    rot = np.array(ours.joint_rotations)
    for i, c in enumerate(crowd.characters):
        rot[:, i] = fold_missing(rot[:, i], c.character.rig_map.missing)
    return ours.replace(joint_rotations=rot)


def _overlap_report(crowd, ours, measured, before, after, prov) -> dict:
    doc = crowd.gltf.doc
    per = []
    for i, c in enumerate(crowd.characters):
        b, a = float(before.per_character[:, i].mean()), float(after.per_character[:, i].mean())
        per.append(
            {
                "character": i,
                "node": c.spec.root,
                "name": doc["nodes"][c.spec.root].get("name", "")
                if crowd.usd is None
                else crowd.usd.skins[c.spec.skins[0]].skel_root,
                "before_litres": 1000.0 * b,
                "after_litres": 1000.0 * a,
                "ratio": None if b <= 0 else a / b,
            }
        )
    mb, ma = before.mean, after.mean
    return {
        "input": str(crowd.gltf.path),
        "frames": int(ours.n_frames),
        "fps": float(ours.fps),
        "frames_measured": [int(f) for f in measured],
        "geometry": "mesh",
        "resolution_m": before.resolution,
        "overall": {"before_litres": 1000.0 * mb, "after_litres": 1000.0 * ma, "ratio": None if mb <= 0 else ma / mb},
        "characters": per,
        "provenance": prov,
    }


def format_overlap(report: dict) -> str:
    """The overlap report as a small table (litres per character, mean over measured frames)."""
    lines = [f"{'character':>9s} {'node':>6s} {'before (l)':>11s} {'after (l)':>10s} {'ratio':>6s}  name"]
    for row in report["characters"]:
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}"
        lines.append(
            f"{row['character']:9d} {row['node']:6d} {row['before_litres']:11.3f} {row['after_litres']:10.3f} "
            f"{ratio:>6s}  {row['name']}"
        )
    o = report["overall"]
    ratio = "-" if o["ratio"] is None else f"{o['ratio']:.3f}"
    lines.append(f"{'overall':>9s} {'':6s} {o['before_litres']:11.3f} {o['after_litres']:10.3f} {ratio:>6s}")
    return "\n".join(lines)


def write_outputs(files: dict[Path, bytes]) -> None:
    """Write every file through a temporary beside it, renaming them only once all are
    written (nothing is left half-done when one fails)."""
    tmps = []
    try:
        for path, data in files.items():
            tmp = path.with_name(path.name + ".tmp")
            tmp.write_bytes(data)
            tmps.append((tmp, path))
        for tmp, path in tmps:
            tmp.replace(path)
    except BaseException:
        for tmp, _ in tmps:
            tmp.unlink(missing_ok=True)
        raise


def report_bytes(report: dict) -> bytes:
    return (json.dumps(report, indent=2, sort_keys=True) + "\n").encode("utf-8")

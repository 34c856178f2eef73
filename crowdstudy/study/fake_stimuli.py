"""A tiny stand-in stimulus folder (manifest + a few short H.264 clips) for tests and demos.

The real stimuli come from ``crowdstudy stimuli``; this writes the same manifest layout
(the manifest format of :mod:`crowdstudy.render.stimuli`) with every stimulus of a design pointing at one of a
few test-pattern clips, so the questionnaire can run without rendering anything.
"""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

from crowdstudy.design import StudyDesign, load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.provenance import provenance

__all__ = ["write_fake_stimuli"]

_PATTERNS = ("testsrc", "testsrc2", "smptebars", "rgbtestsrc")


def _encode(path: Path, pattern: str, width: int, height: int, seconds: float, fps: int) -> None:
    from crowdstudy.render.video import BT709_SCALE, BT709_TAGS, find_ffmpeg

    cmd = [
        find_ffmpeg(),
        "-loglevel",
        "error",
        "-y",
        "-f",
        "lavfi",
        "-i",
        f"{pattern}=size={width}x{height}:rate={fps}:duration={seconds}",
        "-vf",
        BT709_SCALE,
        "-c:v",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        *BT709_TAGS,
        "-preset",
        "veryfast",
        "-movflags",
        "+faststart",
        "-bitexact",
        "-map_metadata",
        "-1",
        str(path),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=60)


def write_fake_stimuli(
    out_dir: str | Path,
    design: StudyDesign | str | Path | None = None,
    *,
    n_files: int = 3,
    seconds: float = 1.0,
    width: int = 160,
    height: int = 90,
    fps: int = 30,
) -> Path:
    """Write ``out_dir/manifest.json``, ``manifest.csv``, ``videos/clip*.mp4`` and
    ``practice.mp4``; stimuli share the ``n_files`` clips round-robin. Returns ``out_dir``.

    seconds: clip length (s); width, height: pixels (even); fps: frames per second.
    """
    if design is None or isinstance(design, (str, Path)):
        design = load_design(design)
    if not isinstance(n_files, int) or n_files < 1:
        raise InvalidInputError(f"n_files must be an integer >= 1, got {n_files!r}")
    if width % 2 or height % 2 or width < 16 or height < 16:
        raise InvalidInputError(f"width and height must be even and >= 16, got {width}x{height}")
    if not seconds > 0:
        raise InvalidInputError(f"seconds must be > 0, got {seconds!r}")
    from crowdstudy.render.stimuli import MANIFEST_COLUMNS
    from crowdstudy.render.video import sha256_file

    out = Path(out_dir)
    (out / "videos").mkdir(parents=True, exist_ok=True)
    clips = []
    for k in range(n_files):
        rel = f"videos/clip{k}.mp4"
        _encode(out / rel, _PATTERNS[k % len(_PATTERNS)], width, height, seconds, fps)
        clips.append((rel, sha256_file(out / rel)))
    _encode(out / "practice.mp4", "testsrc2", width, height, seconds, fps)
    rows = []
    for i, stim in enumerate(design.stimuli()):
        rel, digest = clips[i % n_files]
        rows.append(
            {
                "stimulus_id": stim.stimulus_id,
                "stage": stim.stage,
                "scenario": stim.scenario,
                "density_level": stim.density_level,
                "density": stim.density,
                "viewpoint": stim.viewpoint,
                "method": stim.method,
                "characters": stim.n_characters,
                "seed": stim.seed,
                "file": rel,
                "sha256": digest,
                "duration": float(seconds),
                "fps": fps,
                "width": width,
                "height": height,
                "overlap_mesh": None,
                "overlap_capsule": None,
                "red_pixel_fraction": None,
                "software_version": "fake-stimuli",
                "digest": None,
            }
        )
    manifest = {
        "design": str(design.source),
        "preset": "fake",
        "provenance": provenance(design.seed, fake=True),
        "practice": {"file": "practice.mp4"},
        "stimuli": rows,
    }
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    with open(out / "manifest.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=MANIFEST_COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return out

"""The study's stimulus set: every video of a design, its manifest, resumable, in parallel.

Steps (``build_stimuli``):

1. **Cell animations** — for each (stage, density) cell: ONE Baseline animation
   (``crowdstudy.motion.build_baseline`` with ``design.cell_seed``) shared by all the
   cell's viewpoints, and its corrected version (``crowdstudy.physics.correct``) for
   "Ours". Cached in ``DIR/animations/S{stage}-{level}-{method}.npz`` with their overlap
   metrics (``crowdstudy.metrics.overlap_volume``, mesh and capsule, on every 10th frame)
   in ``...-{method}.metrics.json``; a cached file is reused when it loads and matches the
   preset's duration, frame rate and the cell's seed.
2. **Videos** — ``DIR/videos/{stimulus_id}.mp4`` per stimulus, plus the mean red-pixel
   fraction of the overlap view on a few frames.
3. **Manifest** — ``DIR/manifest.json`` and ``DIR/manifest.csv`` (columns of
   :data:`MANIFEST_COLUMNS`), rewritten after every finished video, so an interrupted run
   resumes: a video whose file exists and whose SHA-256 and settings match its manifest
   row is skipped.

Work runs in local worker processes (``workers``, spawned, each with its own EGL context)
or on a Dask distributed cluster (``scheduler="tcp://HOST:PORT"``). Dask tasks are
self-contained (the animation travels as bytes, the video comes back as bytes), so the
workers need no shared file system.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from pathlib import Path

from crowdstudy.errors import InvalidInputError

__all__ = ["build_stimuli", "PRESETS", "MANIFEST_COLUMNS", "load_manifest", "animation_job", "video_job"]

MANIFEST_COLUMNS = ("stimulus_id", "stage", "scenario", "density_level", "density", "viewpoint", "method",
                    "characters", "seed", "file", "sha256", "duration", "fps", "width", "height", "overlap_mesh",
                    "overlap_capsule", "red_pixel_fraction", "software_version")

#: Render settings per preset; None = the design's value. "quick" keeps the design's
#: character counts and only shrinks resolution and duration. x264 "faster" at crf 18
#: (measured on 1080p D5 concert frames: PSNR 45.9 dB, SSIM 0.993 against the raw frames,
#: vs 46.2 dB / 0.993 for "medium") needs about 30% less encoder CPU than "medium".
PRESETS = {
    "full": {"width": None, "height": None, "duration": None, "msaa": 4, "crf": 18, "x264_preset": "faster",
             "red_frames": 10, "metric_frames": "every:10"},
    "quick": {"width": 320, "height": 180, "duration": 2.0, "msaa": 4, "crf": 23, "x264_preset": "veryfast",
              "red_frames": 3, "metric_frames": "every:10"},
}


def _settings(design, preset: str) -> dict:
    if preset not in PRESETS:
        raise InvalidInputError(f"preset: expected one of {', '.join(PRESETS)}, got {preset!r}")
    p = dict(PRESETS[preset])
    p["width"] = p["width"] or design.video_width
    p["height"] = p["height"] or design.video_height
    p["duration"] = float(p["duration"] or design.duration)
    p["fps"] = float(design.fps)
    return p


def _software_version() -> str:
    from crowdstudy import __version__
    from crowdstudy.provenance import git_sha
    return f"crowdstudy {__version__} ({git_sha()})"


# -- jobs (run in worker processes or on Dask workers) --------------------------------------

def _limit_threads(workers: int) -> None:
    cpus = os.cpu_count() or 1
    os.environ.setdefault("LP_NUM_THREADS", str(max(1, cpus // max(1, workers))))


def animation_job(job: dict) -> dict:
    """Build one cell's Baseline and Ours animations and their overlap metrics.

    ``job``: design, stage (key), level, seed, duration, fps, metric_frames, and either
    ``out_dir`` (write the files there) or ``return_bytes`` (return them, for Dask).
    Returns {"files": {name: path or bytes}, "metrics": {method: {...}}, "timings": {"Ours": {...}}};
    the files include ``<cell>-Ours.timings.json`` (see :func:`crowdstudy.physics.correct`).
    """
    from crowdstudy.motion import build_baseline
    from crowdstudy.physics import correct

    design = job["design"]
    base = build_baseline(design, job["stage"], job["level"], duration=job["duration"], fps=job["fps"],
                          seed=job["seed"])
    timings: dict = {}
    ours = correct(base, progress=False, timings=timings)
    out: dict = {"files": {}, "metrics": {}, "timings": {"Ours": timings}}
    for method, anim in (("Baseline", base), ("Ours", ours)):
        out["metrics"][method] = _overlap_metrics(anim, job["metric_frames"])
        name = f"{job['cell']}-{method}.npz"
        if job.get("return_bytes"):
            with tempfile.TemporaryDirectory() as tmp:
                out["files"][name] = Path(anim.save(Path(tmp) / name)).read_bytes()
        else:
            out["files"][name] = str(anim.save(Path(job["out_dir"]) / name))
    # the physics timings: a sidecar beside the Ours file (run-dependent, so never inside it)
    from crowdstudy.paths import timings_path

    name = timings_path(f"{job['cell']}-Ours.npz").name
    text = json.dumps({"device": ours.meta["physics"]["device"], **timings}, indent=2, sort_keys=True) + "\n"
    if job.get("return_bytes"):
        out["files"][name] = text.encode()
    else:
        (Path(job["out_dir"]) / name).write_text(text)
        out["files"][name] = str(Path(job["out_dir"]) / name)
    return out


def _overlap_metrics(anim, frames) -> dict:
    from crowdstudy.metrics import overlap_volume
    res = {}
    for geometry in ("mesh", "capsule"):
        r = overlap_volume(anim, geometry=geometry, frames=frames)
        res[f"overlap_{geometry}"] = float(r.mean)
    return res


def video_job(job: dict) -> dict:
    """Render one stimulus video. ``job``: stimulus_id, viewpoint, design, settings, and
    ``animation`` (a path) or ``animation_bytes``; ``out`` (a path) unless
    ``return_bytes``. Returns render_video's dict (+ ``video_bytes`` for Dask)."""
    from crowdstudy.render.video import render_video
    from crowdstudy.scene import CrowdAnimation

    s = job["settings"]
    with tempfile.TemporaryDirectory() as tmp:
        src = job.get("animation")
        if src is None:
            src = Path(tmp) / "anim.npz"
            src.write_bytes(job["animation_bytes"])
        anim = CrowdAnimation.load(src)
        out = Path(tmp) / f"{job['stimulus_id']}.mp4" if job.get("return_bytes") else Path(job["out"])
        res = render_video(anim, job["viewpoint"], out, width=s["width"], height=s["height"], duration=s["duration"],
                           fps=s["fps"], msaa=s["msaa"], design=job["design"], progress=job.get("progress", False),
                           body_loader=job.get("body_loader"), crf=s["crf"], preset=s["x264_preset"],
                           red_sample_frames=s["red_frames"], color_positions=job.get("color_positions"))
        if job.get("return_bytes"):
            res["video_bytes"] = out.read_bytes()
    res["stimulus_id"] = job["stimulus_id"]
    return res


# -- execution backends ------------------------------------------------------------------

class _Runner:
    """Runs jobs in-process (workers=0), in spawned local processes, or on Dask."""

    def __init__(self, scheduler: str | None, workers: int):
        self.scheduler, self.workers = scheduler, workers
        self.client = self.pool = None
        if scheduler:
            try:
                from distributed import Client
            except ImportError as exc:
                from crowdstudy.errors import MissingDependencyError
                raise MissingDependencyError(f"--scheduler needs dask.distributed ({exc}); "
                                             "`pip install 'crowdstudy[cluster]'`") from None
            try:
                self.client = Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise InvalidInputError(f"scheduler: cannot connect to the Dask scheduler at {scheduler!r} ({exc}); "
                                        "start one with `dask scheduler` and `dask worker ADDRESS`") from None
        elif workers > 0:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor
            self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=_limit_threads, initargs=(workers,))

    @property
    def portable(self) -> bool:
        return self.client is not None

    def run(self, fn, jobs: list[dict]):
        """Yield (job, result) as jobs finish; a failure raises naming the job."""
        if self.client is not None:
            from distributed import as_completed
            futures = {self.client.submit(fn, job, pure=False): job for job in jobs}
            for fut in as_completed(futures):
                yield futures[fut], _result(fut.result, futures[fut])
        elif self.pool is not None:
            from concurrent.futures import as_completed
            futures = {self.pool.submit(fn, job): job for job in jobs}
            for fut in as_completed(futures):
                yield futures[fut], _result(fut.result, futures[fut])
        else:
            for job in jobs:
                yield job, _result(lambda: fn(job), job)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)
        if self.client is not None:
            self.client.close()


def _result(get, job):
    try:
        return get()
    except InvalidInputError:
        raise
    except Exception as exc:
        label = job.get("stimulus_id") or job.get("cell")
        raise RuntimeError(f"{label}: {type(exc).__name__}: {exc}") from exc


# -- manifest ------------------------------------------------------------------------------

def load_manifest(out_dir: str | Path) -> dict | None:
    """The manifest.json of a stimulus folder, or None when absent or unreadable."""
    path = Path(out_dir) / "manifest.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("stimuli"), list) else None


def _write_manifest(out_dir: Path, design, preset: str, rows: dict, order: list[str]) -> dict:
    from crowdstudy.provenance import provenance

    listed = [rows[sid] for sid in order if sid in rows]
    manifest = {"design": str(design.source), "preset": preset,
                "provenance": provenance(design.seed, design_name=design.name), "stimuli": listed}
    tmp = out_dir / "manifest.json.tmp"
    tmp.write_text(json.dumps(manifest, indent=2), encoding="utf-8")
    tmp.replace(out_dir / "manifest.json")
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(MANIFEST_COLUMNS), lineterminator="\n")
    writer.writeheader()
    for row in listed:
        writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in MANIFEST_COLUMNS})
    tmp = out_dir / "manifest.csv.tmp"
    tmp.write_text(buf.getvalue(), encoding="utf-8")
    tmp.replace(out_dir / "manifest.csv")
    return manifest


def _video_done(out_dir: Path, row: dict | None, settings: dict) -> bool:
    from crowdstudy.render.video import sha256_file
    if not row:
        return False
    path = out_dir / str(row.get("file", ""))
    same = (row.get("width") == settings["width"] and row.get("height") == settings["height"]
            and abs(float(row.get("duration") or 0) - settings["duration"]) < 1e-6
            and abs(float(row.get("fps") or 0) - settings["fps"]) < 1e-6)
    return same and path.is_file() and sha256_file(path) == row.get("sha256")


def _cached_animation(path: Path, seed: int, n_frames: int, fps: float) -> bool:
    from crowdstudy.scene import CrowdAnimation
    if not path.is_file():
        return False
    try:
        anim = CrowdAnimation.load(path)
    except (ValueError, OSError):
        return False
    from crowdstudy.render.video import video_frame_count
    # a "dissolve" loop (the corridor) holds its seam's extra frames past the video's n_frames
    return video_frame_count(anim) == n_frames and abs(anim.fps - fps) < 1e-9 \
        and int(anim.meta.get("seed", -1)) == seed


# -- the builder -------------------------------------------------------------------------

def build_stimuli(design, out_dir, *, preset: str = "full", scheduler: str | None = None, workers: int | None = None,
                  progress: bool = True, body_loader=None) -> dict:
    """Build (or finish) the stimulus set of a study design.

    Args:
        design: a StudyDesign or the path of its TOML file.
        out_dir: output folder (created): ``animations/``, ``videos/``, manifest files.
        preset: "full" (the design's 1920x1080, 20 s) or "quick" (320x180, 2 s, same
            character counts).
        scheduler: "tcp://HOST:PORT" of a Dask distributed scheduler; None = local.
        workers: local worker processes (default: one per 4 CPUs, at least 1; 0 = run in
            this process).
        body_loader: record -> Body override (tests); default ``crowdstudy.body.load_body``.
    Returns:
        The manifest dict (also written to ``out_dir/manifest.json`` and ``.csv``).
    """
    from crowdstudy.design import StudyDesign, load_design
    from crowdstudy.paths import check_output_path

    if not isinstance(design, StudyDesign):
        design = load_design(design)
    settings = _settings(design, preset)
    out_dir = Path(out_dir)
    check_output_path(out_dir / "manifest.json", "out")
    (out_dir / "animations").mkdir(exist_ok=True)
    (out_dir / "videos").mkdir(exist_ok=True)
    if workers is None:
        workers = max(1, (os.cpu_count() or 1) // 4)
    if not isinstance(workers, int) or workers < 0:
        raise InvalidInputError(f"workers: expected an integer >= 0, got {workers!r}")
    stimuli = design.stimuli()
    order = [s.stimulus_id for s in stimuli]
    old = load_manifest(out_dir)
    rows = {r["stimulus_id"]: r for r in old["stimuli"]} if old and old.get("preset") == preset else {}
    todo = [s for s in stimuli if not _video_done(out_dir, rows.get(s.stimulus_id), settings)]
    rows = {sid: r for sid, r in rows.items() if sid in order and sid not in {s.stimulus_id for s in todo}}
    if progress:
        print(f"stimuli: {len(stimuli)} videos in the design, {len(stimuli) - len(todo)} already done, "
              f"{len(todo)} to render ({preset}: {settings['width']}x{settings['height']}, "
              f"{settings['duration']:g} s at {settings['fps']:g} fps)", flush=True)
    runner = _Runner(scheduler, workers)
    try:
        metrics = _build_animations(design, out_dir, settings, todo, runner, progress)
        _render_videos(design, out_dir, preset, settings, todo, rows, order, metrics, runner, progress, body_loader)
    finally:
        runner.close()
    return _write_manifest(out_dir, design, preset, rows, order)


def _cell_name(stim) -> str:
    return f"S{stim.stage}-{stim.density_level}"


def _build_animations(design, out_dir: Path, settings, todo, runner: _Runner, progress: bool) -> dict:
    from tqdm import tqdm

    n_frames = max(1, int(round(settings["duration"] * settings["fps"])))
    cells = {}
    for s in todo:
        cells.setdefault(_cell_name(s), s)
    jobs = []
    for cell, s in cells.items():
        ready = all(_cached_animation(out_dir / "animations" / f"{cell}-{m}.npz", s.seed, n_frames, settings["fps"])
                    and (out_dir / "animations" / f"{cell}-{m}.metrics.json").is_file() for m in ("Baseline", "Ours"))
        if not ready:
            jobs.append({"cell": cell, "design": design, "stage": s.stage_key, "level": s.density_level,
                         "seed": s.seed, "duration": settings["duration"], "fps": settings["fps"],
                         "metric_frames": settings["metric_frames"], "out_dir": str(out_dir / "animations"),
                         "return_bytes": runner.portable})
    bar = tqdm(total=len(jobs), desc="cell animations", unit="cell", disable=not progress or not jobs)
    for job, res in runner.run(animation_job, jobs):
        for name, content in res["files"].items():
            if isinstance(content, (bytes, bytearray)):
                (out_dir / "animations" / name).write_bytes(content)
        for method, values in res["metrics"].items():
            (out_dir / "animations" / f"{job['cell']}-{method}.metrics.json").write_text(json.dumps(values, indent=2))
        bar.update(1)
    bar.close()
    metrics = {}
    for cell in cells:
        for m in ("Baseline", "Ours"):
            metrics[(cell, m)] = json.loads((out_dir / "animations" / f"{cell}-{m}.metrics.json").read_text())
    return metrics


def _render_videos(design, out_dir: Path, preset: str, settings, todo, rows: dict, order, metrics, runner: _Runner,
                   progress: bool, body_loader) -> None:
    from tqdm import tqdm

    from crowdstudy.render.video import sha256_file

    from crowdstudy.render.renderer import baseline_color_positions

    version = _software_version()
    jobs = []
    colour_refs: dict[str, list] = {}
    for s in todo:
        anim_path = out_dir / "animations" / f"{_cell_name(s)}-{s.method}.npz"
        if _cell_name(s) not in colour_refs:  # both methods of a cell wear the Baseline's colours
            colour_refs[_cell_name(s)] = baseline_color_positions(
                out_dir / "animations" / f"{_cell_name(s)}-Baseline.npz").tolist()
        job = {"stimulus_id": s.stimulus_id, "viewpoint": s.viewpoint, "design": design, "settings": settings,
               "body_loader": body_loader, "progress": progress and runner.workers <= 1 and not runner.portable,
               "return_bytes": runner.portable, "stimulus": s.as_dict(),
               "color_positions": colour_refs[_cell_name(s)]}
        if runner.portable:
            job["animation_bytes"] = anim_path.read_bytes()
        else:
            job["animation"] = str(anim_path)
            job["out"] = str(out_dir / "videos" / f"{s.stimulus_id}.mp4")
        jobs.append(job)
    bar = tqdm(total=len(jobs), desc="stimulus videos", unit="video", disable=not progress or not jobs)
    for job, res in runner.run(video_job, jobs):
        s = job["stimulus"]
        rel = f"videos/{s['stimulus_id']}.mp4"
        if "video_bytes" in res:
            part = out_dir / (rel + ".part")
            part.write_bytes(res["video_bytes"])
            part.replace(out_dir / rel)
        digest = sha256_file(out_dir / rel)
        if digest != res["sha256"]:
            raise RuntimeError(f"{s['stimulus_id']}: the video arrived corrupted (SHA-256 mismatch)")
        m = metrics[(f"S{s['stage']}-{s['density_level']}", s["method"])]
        rows[s["stimulus_id"]] = {
            "stimulus_id": s["stimulus_id"], "stage": s["stage"], "scenario": s["scenario"],
            "density_level": s["density_level"], "density": s["density"], "viewpoint": s["viewpoint"],
            "method": s["method"], "characters": s["n_characters"], "seed": s["seed"], "file": rel,
            "sha256": digest, "duration": settings["duration"], "fps": settings["fps"], "width": settings["width"],
            "height": settings["height"], "overlap_mesh": m.get("overlap_mesh"),
            "overlap_capsule": m.get("overlap_capsule"), "red_pixel_fraction": res["mean_red_fraction"],
            "software_version": version}
        _write_manifest(out_dir, design, preset, rows, order)
        bar.update(1)
    bar.close()

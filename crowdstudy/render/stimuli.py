"""The study's stimulus set: every video of a design, its manifest, resumable, in parallel.

Steps (``build_stimuli``):

1. **Cell animations** — for each (stage, density) cell: ONE Baseline animation
   (``crowdstudy.motion.build_baseline`` with ``design.cell_seed``) shared by all the
   cell's viewpoints and methods, then one animation per method of the design the cell's
   videos show (:func:`crowdstudy.recipes.make_method_animation`: the method's recipe run
   on the Baseline), one job each. Cached in ``DIR/animations/S{stage}-{level}-{method}.npz``
   with their overlap metrics (``crowdstudy.metrics.overlap_volume``, mesh and capsule, on
   every 10th frame) in ``...-{method}.metrics.json``, which also records the animation's
   digest (:func:`~crowdstudy.render.stimuli_digests.animation_digest`) and the SHA-256 of
   the ``.npz``; a cached animation is reused only when both match. What a recipe needs
   from outside the package (a ``files`` method's files, ``mujoco``) is checked before any
   work.
2. **Videos** — ``DIR/videos/{stimulus_id}.mp4`` per stimulus, plus the mean red-pixel
   fraction of the overlap view on a few frames.
3. **Manifest** — ``DIR/manifest.json`` and ``DIR/manifest.csv`` (columns of
   :data:`MANIFEST_COLUMNS`), rewritten after every finished video, so an interrupted run
   resumes: a video is skipped only when its file exists, its SHA-256 matches its manifest
   row and the row's ``digest``
   (:func:`~crowdstudy.render.stimuli_digests.video_digest`) matches the current one.

Digests (:mod:`crowdstudy.render.stimuli_digests`) say what each animation and video
depends on: a change of one method re-makes that method's animations and videos only, a
change of one viewpoint that viewpoint's videos, a change of render settings every video
but no animation.

Manifest format: ``manifest.json`` is an object with ``design`` (the design file),
``preset``, ``provenance`` (:func:`crowdstudy.provenance.provenance`), ``methods`` (each
method's name and recipe, in the design's order), ``stages`` (each stage's number, key,
scenario, task, methods and pairs), ``stimuli`` (one row per video, in the design's order)
and optionally ``practice: {"file": ...}`` (a practice clip, relative to the folder). Each
row holds :data:`MANIFEST_COLUMNS`: the stimulus' metadata (``stimulus_id``, ``stage``
number, ``scenario``, ``density_level``, ``density`` in characters per m^2,
``viewpoint``, ``method``, ``characters``, the cell's ``seed``), the video (``file``,
relative to the folder, ``sha256``, ``duration`` s, ``fps``, ``width``, ``height``), the
cell animation's mean overlap volume (``overlap_mesh``, ``overlap_capsule``, m^3 per
character), the overlap view's ``red_pixel_fraction``, ``software_version`` and the
``digest`` above (null in stand-in sets). ``manifest.csv`` holds the same rows.

Work runs in local worker processes (``workers``, spawned, each with its own EGL context)
or on a Dask distributed cluster (``scheduler="tcp://HOST:PORT"``). Dask tasks are
self-contained (the animation travels as bytes, the video comes back as bytes), so the
workers need no shared file system.
"""

from __future__ import annotations

import csv
import functools
import io
import json
import os
import tempfile
from pathlib import Path

from crowdstudy.errors import InvalidInputError
from crowdstudy.render.stimuli_digests import animation_digest, design_dir, physics_config_of, video_digest

__all__ = [
    "build_stimuli",
    "check_stimuli_inputs",
    "default_workers",
    "PRESETS",
    "MANIFEST_COLUMNS",
    "load_manifest",
    "animation_job",
    "video_job",
    "animation_record",
    "preset_settings",
    "renderer_options",
]

MANIFEST_COLUMNS = (
    "stimulus_id",
    "stage",
    "scenario",
    "density_level",
    "density",
    "viewpoint",
    "method",
    "characters",
    "seed",
    "file",
    "sha256",
    "duration",
    "fps",
    "width",
    "height",
    "overlap_mesh",
    "overlap_capsule",
    "red_pixel_fraction",
    "software_version",
    "digest",
)

#: Render settings per preset; None = the design's value. "quick" keeps the design's
#: character counts and only shrinks resolution and duration. "full" anti-aliases with
#: the FXAA pass instead of 4x MSAA: on a CPU rasteriser MSAA multiplies the characters'
#: fragment work, and the filtered frames stay within the SSIM bar of their supersampled
#: references (:data:`crowdstudy.render.fidelity.SSIM_BAR`); x264 "superfast" at crf 18
#: costs about half the encoder time of "faster" at a similar PSNR against the lossless
#: encode. `crowdstudy bench render --set` measures both again (docs: the rendering guide).
PRESETS = {
    "full": {
        "width": None,
        "height": None,
        "duration": None,
        "msaa": 0,
        "post_aa": "fxaa",
        "crf": 18,
        "x264_preset": "superfast",
        "red_frames": 10,
        "metric_frames": "every:10",
    },
    "quick": {
        "width": 320,
        "height": 180,
        "duration": 2.0,
        "msaa": 4,
        "crf": 23,
        "x264_preset": "veryfast",
        "red_frames": 3,
        "metric_frames": "every:10",
    },
}


def preset_settings(design, preset: str, *, duration: float | None = None) -> dict:
    """The render settings of ``preset`` for ``design`` (:data:`PRESETS`, None filled in);
    ``duration`` (s), when given, replaces the preset's clip length."""
    if preset not in PRESETS:
        raise InvalidInputError(f"preset: expected one of {', '.join(PRESETS)}, got {preset!r}")
    if duration is not None and (
        isinstance(duration, bool) or not isinstance(duration, (int, float)) or not 0 < duration <= design.duration
    ):
        raise InvalidInputError(
            f"duration: expected seconds in (0, {design.duration:g}] (the design's clip length), got {duration!r}"
        )
    p = dict(PRESETS[preset])
    p["width"] = p["width"] or design.video_width
    p["height"] = p["height"] or design.video_height
    p["duration"] = float(duration if duration is not None else p["duration"] or design.duration)
    p["fps"] = float(design.fps)
    return p


def renderer_options(settings: dict) -> dict:
    """The :class:`~crowdstudy.render.renderer.CrowdRenderer` options among a preset's
    settings (:func:`preset_settings`): image size, anti-aliasing, levels of detail and
    shadow map, those present."""
    keys = ("width", "height", "msaa", "post_aa", "lod_scale", "shadow_size")
    return {k: settings[k] for k in keys if k in settings}


def _software_version() -> str:
    from crowdstudy import __version__
    from crowdstudy.provenance import git_sha

    return f"crowdstudy {__version__} ({git_sha()})"


def animation_record(path: str | Path, digest: str, metrics: dict) -> dict:
    """The ``.metrics.json`` record of the cached animation ``path``: its overlap metrics,
    its digest and the SHA-256 of the file (what a resumed build checks)."""
    from crowdstudy.render.video import sha256_file

    return {**metrics, "animation_digest": digest, "animation_sha256": sha256_file(path)}


# -- jobs (run in worker processes or on Dask workers) --------------------------------------


def default_workers() -> int:
    """Local worker processes of ``build_stimuli`` by default: one per 2 CPUs, and one per
    CPU up to 2. A software rasteriser runs a frame's vertex stage and the Python side on
    one thread, so two single-threaded workers keep two cores busier than one worker with
    two rendering threads (each worker gets ``LP_NUM_THREADS`` = CPUs / workers)."""
    cpus = os.cpu_count() or 1
    return max(min(2, cpus), cpus // 2)


def _limit_threads(workers: int) -> None:
    cpus = os.cpu_count() or 1
    os.environ.setdefault("LP_NUM_THREADS", str(max(1, cpus // max(1, workers))))


def animation_job(job: dict) -> dict:
    """Build one cell's animations of some methods and their overlap metrics.

    ``job``: design, cell (``S{stage}-{level}``), stage (key), level, seed, duration, fps,
    metric_frames, ``methods`` (the names to build; "Baseline" is the uncorrected
    animation every method starts from; without it, the cached Baseline comes as
    ``baseline`` (a path) or ``baseline_bytes``), ``recipes`` ({name:
    :class:`~crowdstudy.design.Method`}), ``physics`` (the starting ``PhysicsConfig`` of the
    ``physics`` methods, or None), ``files_bytes`` ({name: bytes of a ``files`` method's
    animation}, for Dask) and either ``out_dir`` (write the files there) or ``return_bytes``
    (return them, for Dask).
    Returns {"files": {name: path or bytes}, "metrics": {method: {...}}, "timings":
    {method: {...}}}; the files include ``<cell>-<method>.timings.json`` for every method
    that ran a simulation (see :func:`crowdstudy.physics.correct`).
    """
    from crowdstudy.design import DEFAULT_METHODS
    from crowdstudy.motion import build_baseline
    from crowdstudy.recipes import make_method_animation

    design = job["design"]
    methods = tuple(job.get("methods") or ("Baseline",))
    if "Baseline" in methods:
        base = build_baseline(
            design, job["stage"], job["level"], duration=job["duration"], fps=job["fps"], seed=job["seed"]
        )
        base = make_method_animation(DEFAULT_METHODS["Baseline"], base, cell=job["cell"])
    else:
        base = _job_animation(job.get("baseline"), job.get("baseline_bytes"))
    built = [("Baseline", base)] if "Baseline" in methods else []
    timings: dict = {}
    for name in methods:
        if name == "Baseline":
            continue
        timings[name] = {}
        built.append((name, _method_animation(job, job["recipes"][name], base, timings[name])))
    out: dict = {"files": {}, "metrics": {}, "timings": {m: t for m, t in timings.items() if t}}
    for method, anim in built:
        out["metrics"][method] = _overlap_metrics(anim, job["metric_frames"])
        name = f"{job['cell']}-{method}.npz"
        if job.get("return_bytes"):
            with tempfile.TemporaryDirectory() as tmp:
                out["files"][name] = Path(anim.save(Path(tmp) / name)).read_bytes()
        else:
            out["files"][name] = str(anim.save(Path(job["out_dir"]) / name))
    for method, anim in built:
        if out["timings"].get(method) and "physics" in anim.meta:
            _timings_sidecar(job, method, anim, out)
    return out


def _method_animation(job: dict, recipe, base, timings: dict):
    """One method's animation of the job's cell (a ``files`` method's file from the job's
    bytes on a Dask worker, which may not share the file system)."""
    import dataclasses as dc

    from crowdstudy.recipes import make_method_animation

    data = (job.get("files_bytes") or {}).get(recipe.name)
    if data is None:
        return make_method_animation(
            recipe,
            base,
            cell=job["cell"],
            design_dir=job.get("design_dir"),
            timings=timings,
            physics=job.get("physics"),
        )
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / f"{job['cell']}.npz").write_bytes(data)
        anim = make_method_animation(dc.replace(recipe, path=tmp), base, cell=job["cell"])
    return anim.replace(meta={"recipe": recipe.recipe()})


def _timings_sidecar(job: dict, method: str, anim, out: dict) -> None:
    """The physics timings: a sidecar beside the method's file (run-dependent, so never
    inside it)."""
    from crowdstudy.paths import timings_path

    name = timings_path(f"{job['cell']}-{method}.npz").name
    text = json.dumps({"device": anim.meta["physics"]["device"], **out["timings"][method]}, indent=2, sort_keys=True)
    if job.get("return_bytes"):
        out["files"][name] = (text + "\n").encode()
    else:
        (Path(job["out_dir"]) / name).write_text(text + "\n")
        out["files"][name] = str(Path(job["out_dir"]) / name)


def _job_animation(path, data: bytes | None):
    """The CrowdAnimation a job names: the file ``path``, or (for Dask workers, which may not
    share the file system) the bytes ``data`` of one."""
    from crowdstudy.scene import CrowdAnimation

    if path is not None:
        return CrowdAnimation.load(path)
    if data is None:
        raise InvalidInputError("job: names neither an animation file nor its bytes")
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "anim.npz"
        src.write_bytes(data)
        return CrowdAnimation.load(src)


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

    s = job["settings"]
    anim = _job_animation(job.get("animation"), job.get("animation_bytes"))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"{job['stimulus_id']}.mp4" if job.get("return_bytes") else Path(job["out"])
        res = render_video(
            anim,
            job["viewpoint"],
            out,
            duration=s["duration"],
            fps=s["fps"],
            design=job["design"],
            progress=job.get("progress", False),
            body_loader=job.get("body_loader"),
            crf=s["crf"],
            preset=s["x264_preset"],
            red_sample_frames=s["red_frames"],
            color_positions=job.get("color_positions"),
            **renderer_options(s),  # size, anti-aliasing, levels of detail, shadow map
        )
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

                raise MissingDependencyError(
                    f"--scheduler needs dask.distributed ({exc}); `pip install 'crowdstudy[cluster]'`"
                ) from None
            try:
                self.client = Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise InvalidInputError(
                    f"scheduler: cannot connect to the Dask scheduler at {scheduler!r} ({exc}); "
                    "start one with `dask scheduler` and `dask worker ADDRESS`"
                ) from None
        elif workers > 0:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self.pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_limit_threads,
                initargs=(workers,),
            )

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
                yield job, _result(functools.partial(fn, job), job)

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
    manifest = {
        "design": str(design.source),
        "preset": preset,
        "provenance": provenance(design.seed, design_name=design.name),
        "methods": {name: design.method(name).recipe() for name in design.methods},
        "stages": [
            {
                "number": st.number,
                "key": st.key,
                "scenario": st.scenario,
                "task": st.task,
                "methods": list(st.methods),
                "pairs": [list(p) for p in st.pairs],
            }
            for st in design.stages
        ],
        "stimuli": listed,
    }
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


def _video_done(out_dir: Path, row: dict | None, digest: str) -> bool:
    """A manifest row is reused only when its digest is the current one and its file is intact."""
    from crowdstudy.render.video import sha256_file

    if not row or row.get("digest") != digest:
        return False
    path = out_dir / str(row.get("file", ""))
    return path.is_file() and sha256_file(path) == row.get("sha256")


def _cached_animation(folder: Path, cell: str, method: str, digest: str) -> bool:
    """The cached animation of (cell, method) is current: its record holds ``digest`` and
    the SHA-256 of the ``.npz`` beside it."""
    from crowdstudy.render.video import sha256_file

    path, record = folder / f"{cell}-{method}.npz", folder / f"{cell}-{method}.metrics.json"
    try:
        data = json.loads(record.read_text())
    except (OSError, json.JSONDecodeError):
        return False
    return (
        isinstance(data, dict)
        and data.get("animation_digest") == digest
        and path.is_file()
        and sha256_file(path) == data.get("animation_sha256")
    )


# -- the builder -------------------------------------------------------------------------


def build_stimuli(
    design,
    out_dir,
    *,
    preset: str = "full",
    duration: float | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    body_loader=None,
    physics=None,
    methods=None,
) -> dict:
    """Build (or finish) the stimulus set of a study design.

    Args:
        design: a StudyDesign or the path of its TOML file.
        out_dir: output folder (created): ``animations/``, ``videos/``, manifest files.
        preset: "full" (the design's 1920x1080, 20 s) or "quick" (320x180, 2 s, same
            character counts).
        duration: seconds per video instead of the preset's (a short pilot set); at most the
            design's duration.
        scheduler: "tcp://HOST:PORT" of a Dask distributed scheduler; None = local.
        workers: local worker processes (default :func:`default_workers`: one per 2 CPUs,
            at least 2 with 2 CPUs; 0 = run in this process).
        body_loader: record -> Body override (tests); default ``crowdstudy.body.load_body``.
        physics: the :class:`~crowdstudy.physics.PhysicsConfig` (or a dict of its fields,
            :meth:`~crowdstudy.physics.PhysicsConfig.from_overrides`) every ``physics``
            method starts from before its own ``config`` overrides; None = the defaults.
        methods: build only these of the design's methods (``--method``); None = all. The
            manifest lists the videos built so far, of every method.
    Returns:
        The manifest dict (also written to ``out_dir/manifest.json`` and ``.csv``).
    """
    from crowdstudy.design import StudyDesign, load_design
    from crowdstudy.paths import check_output_path

    if not isinstance(design, StudyDesign):
        design = load_design(design)
    settings = preset_settings(design, preset, duration=duration)
    physics = None if physics is None else physics_config_of(physics)
    if workers is None:
        workers = default_workers()
    if not isinstance(workers, int) or workers < 0:
        raise InvalidInputError(f"workers: expected an integer >= 0, got {workers!r}")
    chosen = check_stimuli_inputs(design, methods)
    stimuli = design.stimuli()
    order = [s.stimulus_id for s in stimuli]
    out_dir = Path(out_dir)
    check_output_path(out_dir / "manifest.json", "out")
    (out_dir / "animations").mkdir(exist_ok=True)
    (out_dir / "videos").mkdir(exist_ok=True)
    old = load_manifest(out_dir)
    rows = {r["stimulus_id"]: r for r in old["stimuli"]} if old and old.get("preset") == preset else {}
    digests = {
        s.stimulus_id: video_digest(design, s, settings, physics=physics, body_loader=body_loader)
        for s in stimuli
        if s.method in chosen
    }
    todo = [
        s
        for s in stimuli
        if s.method in chosen and not _video_done(out_dir, rows.get(s.stimulus_id), digests[s.stimulus_id])
    ]
    rows = {sid: r for sid, r in rows.items() if sid in order and sid not in {s.stimulus_id for s in todo}}
    if progress:
        print(
            f"stimuli: {len(stimuli)} videos in the design, {len(stimuli) - len(todo)} already done, "
            f"{len(todo)} to render ({preset}: {settings['width']}x{settings['height']}, "
            f"{settings['duration']:g} s at {settings['fps']:g} fps)",
            flush=True,
        )
    runner = _Runner(scheduler, workers)
    try:
        metrics = _build_animations(design, out_dir, settings, todo, runner, progress, physics)
        _render_videos(
            design, out_dir, preset, settings, todo, rows, order, metrics, runner, progress, body_loader, digests
        )
    finally:
        runner.close()
    return _write_manifest(out_dir, design, preset, rows, order)


def _cell_name(stim) -> str:
    return f"S{stim.stage}-{stim.density_level}"


def _chosen_methods(design, methods) -> tuple[str, ...]:
    """The design's methods to build: all, or those ``methods`` names (``--method``)."""
    if methods is None:
        return tuple(design.methods)
    if isinstance(methods, str):
        methods = (methods,)
    for m in methods:
        if m not in design.methods:
            raise InvalidInputError(
                f"--method: the design {design.source} has no method {m!r}; its methods are {', '.join(design.methods)}"
            )
    return tuple(m for m in design.methods if m in methods)


def check_stimuli_inputs(design, methods=None) -> tuple[str, ...]:
    """What building ``methods`` (None: all) of ``design`` needs from outside the package,
    checked before any work (:func:`build_stimuli` runs it first; ``crowdstudy stimuli``
    before it makes the output folder): the method names, and each method's inputs
    (:func:`crowdstudy.recipes.check_method_inputs`: a ``files`` method's folder and every
    cell's file, ``mujoco``) for the cells whose videos it builds, the reference method's
    too (every video wears its colours). Returns the methods to build, in the design's
    order."""
    from crowdstudy.recipes import check_method_inputs

    chosen = _chosen_methods(design, methods)
    per_method: dict[str, set[str]] = {}
    for s in design.stimuli():
        if s.method in chosen:
            for m in (s.method, design.reference_method):
                per_method.setdefault(m, set()).add(_cell_name(s))
    for m, cells in per_method.items():
        check_method_inputs(design, [m], sorted(cells))
    return chosen


def _build_animations(design, out_dir: Path, settings, todo, runner: _Runner, progress: bool, physics) -> dict:
    """The cell animations the videos ``todo`` need, made where their cached file is stale:
    first each cell's Baseline (one job per cell), then one job per (cell, method)."""
    from crowdstudy.progress import progress_bar

    folder = out_dir / "animations"
    cells: dict[str, tuple] = {}  # cell -> (a stimulus of it, methods its videos need)
    for s in todo:
        stim, need = cells.setdefault(_cell_name(s), (s, set()))
        need.update({"Baseline", design.reference_method, s.method})  # colours follow the reference
    keys = {
        (cell, m): animation_digest(design, s, settings, physics=physics, method=m)
        for cell, (s, need) in cells.items()
        for m in need
    }
    stale = {
        cell: sorted(m for m in need if not _cached_animation(folder, cell, m, keys[(cell, m)]))
        for cell, (s, need) in cells.items()
    }
    for cell, (_, need) in cells.items():
        if "Baseline" in stale[cell]:  # a new Baseline makes a new everything
            stale[cell] = sorted(need)
    first = [
        _animation_job(design, cells[cell][0], ["Baseline"], settings, physics, folder, runner)
        for cell, methods in stale.items()
        if "Baseline" in methods
    ]
    total = sum(len(v) for v in stale.values())
    bar = progress_bar(total=total, desc="cell animations", unit="animation", enabled=progress and bool(total))
    _run_animation_jobs(first, keys, folder, runner, bar)
    second = [
        _animation_job(design, cells[cell][0], [m], settings, physics, folder, runner)
        for cell, methods in stale.items()
        for m in methods
        if m != "Baseline"
    ]
    _run_animation_jobs(second, keys, folder, runner, bar)
    bar.close()
    return {
        (cell, m): json.loads((folder / f"{cell}-{m}.metrics.json").read_text())
        for cell, (s, need) in cells.items()
        for m in need
    }


def _animation_job(design, s, methods: list[str], settings, physics, folder: Path, runner: _Runner) -> dict:
    """The job of ``methods``' animations of the cell of stimulus ``s`` (:func:`animation_job`)."""
    from crowdstudy.recipes import method_file

    cell = _cell_name(s)
    recipes = {m: design.method(m) for m in methods if m != "Baseline"}
    job = {
        "cell": cell,
        "design": design,
        "design_dir": design_dir(design),
        "stage": s.stage_key,
        "level": s.density_level,
        "seed": s.seed,
        "duration": settings["duration"],
        "fps": settings["fps"],
        "physics": physics,
        "recipes": recipes,
        "metric_frames": settings["metric_frames"],
        "out_dir": str(folder),
        "methods": list(methods),
        "return_bytes": runner.portable,
    }
    if "Baseline" not in methods:
        if runner.portable:
            job["baseline_bytes"] = (folder / f"{cell}-Baseline.npz").read_bytes()
            job["files_bytes"] = {
                m: method_file(r, cell, design_dir(design)).read_bytes()
                for m, r in recipes.items()
                if r.correction == "files"
            }
        else:
            job["baseline"] = str(folder / f"{cell}-Baseline.npz")
    return job


def _run_animation_jobs(jobs: list[dict], keys: dict, folder: Path, runner: _Runner, bar) -> None:
    """Run animation jobs; write their files (Dask sends them back as bytes) and records."""
    for job, res in runner.run(animation_job, jobs):
        for name, content in res["files"].items():
            if isinstance(content, (bytes, bytearray)):
                (folder / name).write_bytes(content)
        for method, values in res["metrics"].items():
            record = animation_record(folder / f"{job['cell']}-{method}.npz", keys[(job["cell"], method)], values)
            (folder / f"{job['cell']}-{method}.metrics.json").write_text(json.dumps(record, indent=2))
            bar.update(1)


def _render_videos(
    design,
    out_dir: Path,
    preset: str,
    settings,
    todo,
    rows: dict,
    order,
    metrics,
    runner: _Runner,
    progress: bool,
    body_loader,
    digests: dict,
) -> None:
    from crowdstudy.progress import progress_bar
    from crowdstudy.render.renderer import baseline_color_positions
    from crowdstudy.render.video import sha256_file

    version = _software_version()
    jobs = []
    colour_refs: dict[str, list] = {}
    for s in todo:
        anim_path = out_dir / "animations" / f"{_cell_name(s)}-{s.method}.npz"
        if _cell_name(s) not in colour_refs:  # every method of a cell wears the reference's colours
            colour_refs[_cell_name(s)] = baseline_color_positions(
                out_dir / "animations" / f"{_cell_name(s)}-{design.reference_method}.npz"
            ).tolist()
        job = {
            "stimulus_id": s.stimulus_id,
            "viewpoint": s.viewpoint,
            "design": design,
            "settings": settings,
            "body_loader": body_loader,
            "progress": progress and runner.workers <= 1 and not runner.portable,
            "return_bytes": runner.portable,
            "stimulus": s.as_dict(),
            "color_positions": colour_refs[_cell_name(s)],
        }
        if runner.portable:
            job["animation_bytes"] = anim_path.read_bytes()
        else:
            job["animation"] = str(anim_path)
            job["out"] = str(out_dir / "videos" / f"{s.stimulus_id}.mp4")
        jobs.append(job)
    bar = progress_bar(total=len(jobs), desc="stimulus videos", unit="video", enabled=progress and bool(jobs))
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
            "stimulus_id": s["stimulus_id"],
            "stage": s["stage"],
            "scenario": s["scenario"],
            "density_level": s["density_level"],
            "density": s["density"],
            "viewpoint": s["viewpoint"],
            "method": s["method"],
            "characters": s["n_characters"],
            "seed": s["seed"],
            "file": rel,
            "sha256": digest,
            "duration": settings["duration"],
            "fps": settings["fps"],
            "width": settings["width"],
            "height": settings["height"],
            "overlap_mesh": m.get("overlap_mesh"),
            "overlap_capsule": m.get("overlap_capsule"),
            "red_pixel_fraction": res["mean_red_fraction"],
            "software_version": version,
            "digest": digests[s["stimulus_id"]],
        }
        _write_manifest(out_dir, design, preset, rows, order)
        bar.update(1)
    bar.close()

"""``crowdstudy bench render``: seconds per 1920x1080 frame of the D5 concert scene.

Measured in one run, on the same animation (the D5 stationary Baseline, 60 characters):

* ``ours``: the stimulus settings: 4x MSAA, 2048^2 shadow map, bodies at the renderer's
  levels of detail (3000 faces, half for characters under 600 px tall), frame read back;
* peers: the same without shadows and MSAA (``plain``), with the full-resolution
  body meshes (``full-mesh``), and the same crowd as the previous default characters
  (``mannequin``: the generated open-model bodies, region colours, per-vertex lighting):
  ``vs_mannequin`` is the cost of the MakeHuman characters (textured, per-pixel lit,
  dressed), the bar is 1.5 in wall and CPU time;
* ``ours+encode``: render and stream to ffmpeg/x264 with the "full" stimulus preset's
  settings (x264 preset superfast, crf 18), per frame, and the encoder's own CPU time per
  frame and PSNR against the lossless encode for x264 presets medium, faster, veryfast,
  superfast (4 frames repeated: the PSNR of ``--set``, on 12 consecutive frames, is the
  representative one);
* a per-pass breakdown (shadow, cull, static layer copy, characters, environment, MSAA
  resolve, read-back), the static layers drawn beforehand as a video's set-up does;
* the characters' pass taken apart, for ``ours`` and ``plain``: its vertex stage and set-up
  (the pass under a 1x1 scissor), its fragments, and of those the shading (against the
  same pass with a constant-colour fragment shader);
* the projected time of the whole 60-video set (60 x 600 frames) on this machine, from
  the wall time of ``ours+encode`` and, load-independent, from the CPU time of rendering
  plus encoding spread over the machine's CPUs.

``--set``: the whole 60-video stimulus set. Every video of the design (or an evenly spaced
``--videos K`` of them) is rendered ``--frames N`` frames long through the stimulus path
(``stimuli.video_job`` in the worker pool, x264 through ffmpeg, the overlap view's red-pixel
samples), and projected to its full length: set-up, first frame (shader compilation) and
red samples once per video, the other frames scaled, a loop's cross-dissolve counted as that
many more frames. CPU time counts the workers and their ffmpeg children. Also printed: the
passes of a D5 frame at every view, the x264 presets' CPU time and PSNR against the lossless
encode. ``--set --full`` builds the whole set for real (``stimuli.build_stimuli``, hours
here). The report is ``build/bench/render_set.json``.

Both wall-clock and process CPU seconds are reported: on a shared machine the CPU time
(all llvmpipe threads together) is the steadier number; when other processes hold a core,
wall time approaches CPU time.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import tempfile
import time

import numpy as np

from crowdstudy.bench import write_report
from crowdstudy.tables import format_table

__all__ = ["main"]


def _scene(duration: float):
    from crowdstudy.design import load_design
    from crowdstudy.motion import build_baseline

    design = load_design()
    return design, build_baseline(design, "stationary", "D5", duration=duration)


def _time_frames(renderer, frames: list[int]) -> dict:
    renderer.render_raw(frames[0])  # warm-up: shader variants, first uploads
    wall, cpu = [], []
    for f in frames:
        t0, c0 = time.perf_counter(), time.process_time()
        renderer.render_raw(f)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return {"wall_s": float(np.median(wall)), "cpu_s": float(np.median(cpu))}


def _bind_frame_target(renderer, vp: np.ndarray):
    """Bind the frame's target (the MSAA buffer if any) with the shadow map and the camera,
    as the colour pass (``passes.ColorPass.run``) does before the characters; the framebuffer."""
    fbo = renderer.targets.draw
    fbo.use()
    renderer.ctx.viewport = (0, 0, renderer.width, renderer.height)
    renderer.shadow_map.texture.use(3)
    for prog in renderer.programs.lit:
        if "u_view_proj" in prog:
            prog["u_view_proj"].write(np.ascontiguousarray(vp.T, dtype=np.float32).tobytes())
    return fbo


def _draw_characters(renderer, prog, vp: np.ndarray) -> None:
    """The characters' part of the colour pass: back faces culled, ``prog`` (or its per-kind variants)."""
    from crowdstudy.render.passes import cull_back_faces

    cull_back_faces(renderer.ctx, True)
    renderer.characters.draw(prog, vp)
    cull_back_faces(renderer.ctx, False)


def _passes(renderer, frame: int) -> dict:
    """Wall seconds of each pass of one frame (the GPU/llvmpipe finished after each), as
    ``CrowdRenderer`` runs them; the static layer is drawn beforehand."""
    from crowdstudy.render.passes import ENV_PARTS

    ctx = renderer.ctx
    out = {}

    def timed(name, fn):
        ctx.finish()
        t0 = time.perf_counter()
        fn()
        ctx.finish()
        out[name] = out.get(name, 0.0) + time.perf_counter() - t0

    renderer.render_raw(frame)  # the frame's static layer drawn, its programs compiled
    timed("bones upload", lambda: renderer.load_frame(frame))
    timed("shadow pass", lambda: renderer.draw_shadows(frame))
    vp = None

    def prepare():
        nonlocal vp
        vp = renderer.prepare(frame, upload=False)

    timed("cull+instances", prepare)
    fbo = renderer.targets.draw
    beat = renderer.environment.beat(frame)
    parts = renderer.layers.parts

    def start():
        _bind_frame_target(renderer, vp)
        if parts:
            layer = renderer.layers.get(beat)
            fbo.use()
            ctx.copy_framebuffer(fbo, layer)
        else:
            fbo.clear(0.5, 0.5, 0.5, 1.0, depth=1.0)

    timed("static layer copy" if parts else "clear", start)
    timed("characters", lambda: _draw_characters(renderer, renderer.programs.character, vp))
    timed("environment", lambda: renderer.environment.draw(ENV_PARTS - parts))
    if renderer.targets.fbo_msaa is not None or renderer.targets.post_aa != "none":
        name = "msaa resolve" if renderer.targets.post_aa == "none" else f"{renderer.targets.post_aa} pass"
        timed(name, renderer.targets.resolve)
    timed("read-back", renderer.targets.read)
    return out


_FLAT_FRAGMENT = "#version 330 core\nout vec4 f_color;\nvoid main() { f_color = vec4(0.6, 0.5, 0.4, 1.0); }\n"


def _constant_colour_program(ctx):
    """The characters' vertex stage with a fragment shader that writes one colour."""
    from crowdstudy.render.gpu import set_uniform, shader_source

    flat = ctx.program(
        vertex_shader="#version 330 core\n" + shader_source("character.vert"), fragment_shader=_FLAT_FRAGMENT
    )
    # the textures the vertex stage pulls the bones and rest shapes from, on the units
    # CharacterPass.draw binds them to
    set_uniform(flat, "u_bones", 0)
    set_uniform(flat, "u_rest", 1)
    return flat


def _character_parts(renderer, frame: int, reps: int = 4) -> dict:
    """Where the characters' pass goes (median wall s over ``reps`` draws of one frame, the
    pass alone as :func:`_passes` times it): ``full``, with the renderer's shaders;
    ``vertex+setup``, the same under a 1x1 scissor (skinning, clipping, binning: every
    fragment culled); ``constant-colour fragments``, the same vertex stage with a fragment
    shader that writes one colour. So ``fragments`` = full - vertex+setup, of which
    ``shading`` = full - constant-colour is the cost of the characters' fragment shader
    (texture, lighting) and the rest rasterisation, depth test and colour writes."""
    from crowdstudy.render.gpu import group_vertex_array

    ctx = renderer.ctx
    flat = _constant_colour_program(ctx)
    added = []
    for gl in renderer.character_resources.groups:
        gl.vaos[flat] = vao = group_vertex_array(ctx, flat, gl.vbo, gl.inst, gl.ibo)
        added.append((gl, vao))

    def draw(prog, scissor):
        times = []
        for _ in range(reps):
            renderer.render_raw(frame)
            renderer.load_frame(frame)
            renderer.draw_shadows(frame)
            vp = renderer.prepare(frame, upload=False)
            _bind_frame_target(renderer, vp).clear(0.5, 0.5, 0.5, 1.0, depth=1.0)
            ctx.finish()
            ctx.scissor = scissor
            t0 = time.perf_counter()
            _draw_characters(renderer, prog, vp)
            ctx.finish()
            times.append(time.perf_counter() - t0)
            ctx.scissor = None
        return float(np.median(times))

    try:
        full = draw(renderer.programs.character, None)
        vertex = draw(renderer.programs.character, (0, 0, 1, 1))
        constant = draw(flat, None)
    finally:
        for gl, vao in added:
            del gl.vaos[flat]
            vao.release()
        flat.release()
    return {
        "full": full,
        "vertex+setup": vertex,
        "constant-colour fragments": constant,
        "fragments": full - vertex,
        "shading": full - constant,
    }


def _psnr(path: str, reference: str) -> float:
    """Mean PSNR (dB, Y'CbCr 4:2:0 planes weighted 4:1:1) of a video against a reference video."""
    import re
    import subprocess

    from crowdstudy.render.video import find_ffmpeg

    res = subprocess.run(
        [find_ffmpeg(), "-hide_banner", "-i", path, "-i", reference, "-lavfi", "psnr", "-f", "null", "-"],
        capture_output=True,
        text=True,
        check=True,
    )
    match = re.findall(r"PSNR y:[\d.inf]+ u:[\d.inf]+ v:[\d.inf]+ average:([\d.inf]+)", res.stderr)
    if not match:
        raise RuntimeError(f"ffmpeg's psnr filter printed no result: {res.stderr[-400:]}")
    return float(match[-1])


def _encoders(raw: list, width: int, height: int, presets, crf: int) -> list[dict]:
    """Per x264 preset at ``crf``: ffmpeg's CPU and wall seconds per frame, size, and PSNR
    against the lossless encode (x264 qp 0, the same 4:2:0 frames) of the same frames."""
    from crowdstudy.render.video import VideoWriter

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        ref = os.path.join(tmp, "lossless.mp4")
        writer = VideoWriter(ref, width, height, 30.0, preset="ultrafast", crf=0)
        for frame in raw:
            writer.write(frame)
        writer.close()
        for preset in presets:
            path = os.path.join(tmp, f"{preset}.mp4")
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            writer = VideoWriter(path, width, height, 30.0, preset=preset, crf=crf)
            for frame in raw:
                writer.write(frame)
            writer.close()
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            rows.append(
                {
                    "x264 preset": preset,
                    "crf": crf,
                    "wall_s": (time.perf_counter() - t0) / len(raw),
                    "ffmpeg_cpu_s": (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime) / len(raw),
                    "kB_per_frame": os.path.getsize(path) / 1024 / len(raw),
                    "psnr_db": _psnr(path, ref),
                }
            )
    return rows


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _set_main(args) -> int:
    """``--set``: the whole stimulus set, sampled (or ``--full``: built for real)."""
    import json

    from crowdstudy.design import load_design
    from crowdstudy.motion import build_baseline
    from crowdstudy.motion.baseline import LOOP_DISSOLVE_SECONDS
    from crowdstudy.render.context import context_info
    from crowdstudy.render.renderer import CrowdRenderer, baseline_color_positions
    from crowdstudy.render.stimuli import (
        _Runner,
        build_stimuli,
        default_workers,
        preset_settings,
        renderer_options,
        video_job,
    )

    design = load_design()
    full = preset_settings(design, "full")
    stimuli = design.stimuli()
    workers = default_workers() if args.workers is None else args.workers
    n_video = int(round(full["duration"] * full["fps"]))
    info = context_info()
    print(
        f"renderer: {info['renderer']} | {_cpus()} CPUs | load {os.getloadavg()[0]:.2f} | {len(stimuli)} videos "
        f"of {n_video} frames, {full['width']}x{full['height']}, {_aa_label(full)}, x264 "
        f"{full['x264_preset']} crf {full['crf']} | {workers} worker process(es)",
        flush=True,
    )

    # where the time of a frame goes, per view (one D5 renderer), and the encoder's quality
    d5 = build_baseline(design, "stationary", "D5", duration=1.0)
    per_view, raw = {}, []
    with CrowdRenderer(d5, design=design, **renderer_options(full)) as r:
        for view in sorted({s.viewpoint for s in stimuli}):
            r.set_view(view)
            for f in range(r.layers.phases()):  # every static layer of the view drawn
                r.render_raw(f)
            per_view[view] = _passes(r, 20)
            per_view[view]["frame (all passes)"] = _time_frames(r, [18, 21, 24, 27])["wall_s"]
            if view == "V1":
                raw = [r.render_raw(f) for f in range(min(d5.n_frames, 12))]
    presets = sorted({full["x264_preset"], "faster", "veryfast", "superfast"}, key=_X264_ORDER.index)
    encoders = _encoders(raw, full["width"], full["height"], presets, full["crf"])
    used = next(e for e in encoders if e["x264 preset"] == full["x264_preset"])
    print("where a frame's time goes (wall s, D5 concert, per view):")
    print(format_table([{"pass": k, **{v: per_view[v][k] for v in per_view}} for k in per_view[next(iter(per_view))]]))
    print("encoder (per 1080p frame, 12 frames of V1; PSNR against the lossless encode):")
    print(format_table(encoders))

    c0, k0, t0 = time.process_time(), _children_cpu(), time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        if args.full:
            out = args.out or os.path.join(tmp, "set")
            build_stimuli(design, out, preset="full", workers=workers, progress=True)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0 + _children_cpu() - k0
            proj = {"wall_h": wall / 3600, "cpu_h": cpu / 3600}
            videos = []
            frames = n_video
        else:
            frames = args.frames
            if frames < 2:
                raise SystemExit("--frames: expected at least 2 frames per video")
            pick = (
                stimuli
                if args.videos is None
                else [stimuli[i] for i in np.unique(np.linspace(0, len(stimuli) - 1, args.videos).round().astype(int))]
            )
            settings = {**full, "duration": frames / full["fps"], "red_frames": min(full["red_frames"], frames)}
            anims, dissolve = {}, {}
            for s in pick:  # the cells' Baselines, `frames` long (the Ours videos render them too)
                cell = f"S{s.stage}-{s.density_level}"
                if cell not in anims:
                    path = os.path.join(tmp, f"{cell}.npz")
                    anim = build_baseline(
                        design,
                        s.stage_key,
                        s.density_level,
                        duration=settings["duration"],
                        fps=full["fps"],
                        seed=s.seed,
                    )
                    # a loop's cross-dissolve (the corridor: its last 0.5 s rendered twice and
                    # blended) would be most of a short sample: left out, and counted below
                    # as that many more frames of the video
                    loop = anim.meta.get("loop") if isinstance(anim.meta, dict) else None
                    dissolve[cell] = 0
                    if isinstance(loop, dict) and loop.get("mode") == "dissolve":
                        dissolve[cell] = min(int(round(LOOP_DISSOLVE_SECONDS * full["fps"])), n_video // 2)
                        meta = {k: v for k, v in anim.meta.items() if k != "loop"}
                        anim = dataclasses.replace(anim, meta=meta)
                    anim.save(path)
                    anims[cell] = (path, baseline_color_positions(path).tolist())
            t_anim = time.perf_counter() - t0
            jobs = [
                {
                    "stimulus_id": s.stimulus_id,
                    "viewpoint": s.viewpoint,
                    "design": design,
                    "settings": settings,
                    "animation": anims[f"S{s.stage}-{s.density_level}"][0],
                    "color_positions": anims[f"S{s.stage}-{s.density_level}"][1],
                    "out": os.path.join(tmp, f"{s.stimulus_id}.mp4"),
                    "cell": f"S{s.stage}-{s.density_level}",
                }
                for s in pick
            ]
            t1, c1, k1 = time.perf_counter(), time.process_time(), _children_cpu()
            runner = _Runner(None, workers)
            videos = []
            try:
                for job, res in runner.run(video_job, jobs):
                    videos.append(
                        {
                            "stimulus_id": job["stimulus_id"],
                            "cell": job["cell"],
                            "frames": res["frames"],
                            "dissolve_frames": dissolve[job["cell"]],
                            **res["timings"],
                        }
                    )
                    print(
                        f"  {job['stimulus_id']}: " + ", ".join(f"{k} {v:.1f}" for k, v in res["timings"].items()),
                        flush=True,
                    )
            finally:
                runner.close()
            wall = time.perf_counter() - t1
            cpu = time.process_time() - c1 + _children_cpu() - k1
            warm = _warm_setups(design, full, {c: anims[c] for c in {j["cell"] for j in jobs}}, pick)
            # projection: per video, its set-up once, its frames scaled to the video's length,
            # its overlap-view samples scaled to the preset's count; walls measured while
            # `workers` videos ran at once, so the set's wall is their sum over the workers
            red_scale = full["red_frames"] / settings["red_frames"]
            scale = len(stimuli) / len(pick)
            # a worker process sets up a cell's bodies (dressed, simplified, painted) once
            # and reuses them for the cell's other videos: of a cell's k videos, about
            # min(workers, k) pay the cold set-up measured in the pool, the others the warm
            # one measured here
            per_cell = len(stimuli) / len({(s.stage, s.density_level) for s in stimuli})
            cold_share = min(max(1, workers), per_cell) / per_cell
            for v in videos:
                w = warm[v["cell"]]
                for kind in ("wall", "cpu"):
                    v[f"setup_cold_{kind}_s"] = v[f"setup_{kind}_s"]
                    v[f"setup_warm_{kind}_s"] = w[kind]
                    v[f"setup_{kind}_s"] = cold_share * v[f"setup_{kind}_s"] + (1 - cold_share) * w[kind]
            proj = {}
            for kind in ("wall", "cpu"):
                per = [
                    v[f"setup_{kind}_s"]
                    + v.get(f"first_frame_{kind}_s", 0.0)
                    + v[f"frames_{kind}_s"] * _rest(v, n_video)
                    + v[f"red_{kind}_s"] * red_scale
                    for v in videos
                ]
                proj[f"{kind}_h"] = sum(per) * scale / (max(1, workers) if kind == "wall" else 1) / 3600
            proj["setup_cold_share"] = cold_share
            keys = sorted({k for v in videos for k in v if k.endswith("_s")})
            stage_totals = {k: sum(v.get(k, 0.0) for v in videos) for k in keys}
            proj["parts_h_cpu"] = {
                st: sum(
                    v.get(f"{st}_cpu_s", 0.0)
                    * (_rest(v, n_video) if st == "frames" else red_scale if st == "red" else 1.0)
                    for v in videos
                )
                * scale
                / 3600
                for st in ("setup", "first_frame", "frames", "red")
            }
            proj["measured"] = {
                "videos": len(pick),
                "frames_per_video": frames,
                "wall_s": wall,
                "cpu_s": cpu,
                "animations_wall_s": t_anim,
                "stage_totals": stage_totals,
            }
    proj["cpu_h_over_cores"] = proj["cpu_h"] / _cpus()
    from crowdstudy.render.fidelity import SSIM_BAR, check_frames

    print("SSIM against the supersampled frames (the set's settings, and 4x MSAA before):", flush=True)
    ssim = check_frames(design, {"set": full, "4x MSAA": {"msaa": 4}}, width=full["width"], height=full["height"])
    ssim_min = min(r["ssim"] for r in ssim if r["config"] == "set")
    print(format_table(ssim))
    label = "full set, built" if args.full else f"sample of {proj['measured']['videos']} videos x {frames} frames"
    print(
        f"whole set ({len(stimuli)} videos x {n_video} frames), {label}: "
        f"{proj['wall_h']:.2f} h wall, {proj['cpu_h']:.2f} CPU-h ({proj['cpu_h_over_cores']:.2f} h over "
        f"{_cpus()} cores); x264 {full['x264_preset']} crf {full['crf']}: PSNR {used['psnr_db']:.2f} dB "
        f"against the lossless encode (target: 1 h)"
    )
    verdict = "met" if proj["wall_h"] <= 1.0 and ssim_min >= SSIM_BAR else "NOT met"
    print(
        f"bar {verdict}: projected {proj['wall_h']:.2f} h wall (target 1 h), lowest SSIM {ssim_min:.4f} "
        f"(bar {SSIM_BAR})"
    )
    if "parts_h_cpu" in proj:
        print("  CPU-h by stage: " + ", ".join(f"{k} {v:.2f}" for k, v in proj["parts_h_cpu"].items()))
    path = write_report(
        "render_set",
        videos,
        projection=proj,
        per_view_passes=per_view,
        encoders=encoders,
        encoder={"x264_preset": full["x264_preset"], "crf": full["crf"], "psnr_db": used["psnr_db"]},
        workers=workers,
        lp_num_threads=os.environ.get("LP_NUM_THREADS"),
        cpus=_cpus(),
        gl=info,
        load=os.getloadavg()[0],
        full=bool(args.full),
        frames_per_video=frames,
        settings={k: full[k] for k in ("msaa", "post_aa", "crf", "x264_preset", "red_frames") if k in full},
        summary=[
            {
                "wall_h": proj["wall_h"],
                "cpu_h": proj["cpu_h"],
                "cpu_h_over_cores": proj["cpu_h_over_cores"],
                **{f"{k}_cpu_h": v for k, v in proj.get("parts_h_cpu", {}).items()},
                "workers": workers,
                "ssim_min": ssim_min,
                "meets_bar": bool(proj["wall_h"] <= 1.0 and ssim_min >= SSIM_BAR),
            }
        ],
        ssim=ssim,
        ssim_min=ssim_min,
        ssim_bar=SSIM_BAR,
        meets_bar=bool(proj["wall_h"] <= 1.0 and ssim_min >= SSIM_BAR),
    )
    print(f"report: {path}")
    print(json.dumps({k: v for k, v in proj.items() if k != "measured"}, default=float))
    return 0


#: the steps the SSIM check compares (renderer options), the stimulus settings among them
SSIM_STEPS = {
    "4x MSAA (before)": {"msaa": 4},
    "no anti-aliasing": {"msaa": 0},
    "FXAA (the set)": {"msaa": 0, "post_aa": "fxaa"},
    "FXAA, 1024 shadow map": {"msaa": 0, "post_aa": "fxaa", "shadow_size": 1024},
    "FXAA, coarser levels of detail (x1.5)": {"msaa": 0, "post_aa": "fxaa", "lod_scale": 1.5},
}


def _ssim_main(args) -> int:
    """``--ssim``: each step's SSIM and CPU time per frame on the checked frames."""
    from crowdstudy.design import load_design
    from crowdstudy.render.context import context_info
    from crowdstudy.render.fidelity import SSIM_BAR, check_frames

    design = load_design()
    info = context_info()
    print(f"renderer: {info['renderer']} | {_cpus()} CPUs | load {os.getloadavg()[0]:.2f}", flush=True)
    rows = check_frames(design, SSIM_STEPS, width=args.width, height=args.height, frames=args.frames, progress=print)
    summary = []
    for name in SSIM_STEPS:
        mine = [r for r in rows if r["config"] == name]
        summary.append(
            {
                "config": name,
                "ssim_min": min(r["ssim"] for r in mine),
                "ssim_mean": float(np.mean([r["ssim"] for r in mine])),
                "cpu_s": float(np.mean([r["cpu_s"] for r in mine])),
                "meets_bar": all(r["meets_bar"] for r in mine),
            }
        )
    before = summary[0]["cpu_s"]
    for row in summary:
        row["cpu_vs_before"] = row["cpu_s"] / before
    print(format_table(rows))
    print(f"per step (SSIM bar {SSIM_BAR}; CPU s per frame, mean over the frames):")
    print(format_table(summary))
    path = write_report(
        "render_ssim", rows, steps=summary, ssim_bar=SSIM_BAR, gl=info, cpus=_cpus(), load=os.getloadavg()[0]
    )
    print(f"report: {path}")
    return 0


def _aa_label(settings: dict) -> str:
    """The anti-aliasing of render settings in words: "4x MSAA", "FXAA", "4x MSAA + FXAA", "no AA"."""
    parts = [f"{settings['msaa']}x MSAA"] if settings.get("msaa", 0) > 1 else []
    if settings.get("post_aa", "none") != "none":
        parts.append(settings["post_aa"].upper())
    return " + ".join(parts) or "no AA"


def _warm_setups(design, full: dict, anims: dict, pick) -> dict:
    """Per sampled cell, the set-up of a video (renderer made, view set, static layers
    drawn) in a process that has set up the cell before: ``{cell: {"wall": s, "cpu": s}}``
    (the second of two set-ups in this process; the first warms the caches)."""
    from crowdstudy.render.renderer import CrowdRenderer
    from crowdstudy.render.stimuli import renderer_options
    from crowdstudy.scene import CrowdAnimation

    views = {f"S{s.stage}-{s.density_level}": s.viewpoint for s in pick}
    out = {}
    for cell, (path, colours) in anims.items():
        anim = CrowdAnimation.load(path)
        for _ in range(2):
            t0, c0 = time.perf_counter(), time.process_time()
            with CrowdRenderer(anim, design=design, color_positions=colours, **renderer_options(full)) as r:
                r.set_view(views[cell])
                r.draw_layers()
            out[cell] = {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0}
    return out


def _rest(video: dict, n_video: int) -> float:
    """The factor from a sampled video's frames after its first to a full video's (with its
    loop's cross-dissolve: that many frames rendered once more)."""
    first = 1 if "first_frame_cpu_s" in video else 0
    return (n_video + video.get("dissolve_frames", 0) - first) / max(1, video["frames"] - first)


_X264_ORDER = [
    "placebo",
    "veryslow",
    "slower",
    "slow",
    "medium",
    "fast",
    "faster",
    "veryfast",
    "superfast",
    "ultrafast",
]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench render")
    parser.add_argument("--frames", type=int, default=8, help="frames timed per configuration")
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--view", default="V3")
    parser.add_argument(
        "--set",
        action="store_true",
        help="the whole stimulus set: every video of the design rendered --frames frames long "
        "through the stimulus path (worker pool, encoder), projected to its full length",
    )
    parser.add_argument("--videos", type=int, default=None, help="--set: an evenly spaced sample of this many videos")
    parser.add_argument("--workers", type=int, default=None, help="--set: worker processes (default: stimuli's)")
    parser.add_argument("--full", action="store_true", help="--set: build the whole set for real (hours)")
    parser.add_argument("--out", default=None, help="--set --full: keep the set in this folder")
    parser.add_argument(
        "--ssim",
        action="store_true",
        help="the SSIM check alone: four study frames against their supersampled references, per "
        "anti-aliasing and detail setting, with the CPU time per frame",
    )
    args = parser.parse_args(argv)
    if args.set:
        return _set_main(args)
    if args.ssim:
        return _ssim_main(args)

    from crowdstudy.render.context import context_info
    from crowdstudy.render.renderer import CrowdRenderer
    from crowdstudy.render.stimuli import PRESETS
    from crowdstudy.render.video import VideoWriter

    x264, crf = PRESETS["full"]["x264_preset"], PRESETS["full"]["crf"]

    design, anim = _scene(duration=max(1.0, (args.frames + 2) / 30.0))
    frames = [int(f) for f in np.linspace(1, anim.n_frames - 1, args.frames).round()]
    info = context_info()
    gl = f"{info['vendor']} {info['renderer']}".lower()
    devices = [
        {"device": "egl", "present": True, "name": f"{info['vendor']} / {info['renderer']}"},
        {
            "device": "nvidia egl",
            "present": "nvidia" in gl,
            "name": info["renderer"] if "nvidia" in gl else "nvidia egl: not present",
        },
    ]
    for d in devices:
        print(f"device {d['device']}: {d['name']}", flush=True)
    print(
        f"renderer: {info['renderer']} | OpenGL {info['version']} | {os.cpu_count()} CPUs | "
        f"load {os.getloadavg()[0]:.2f} | {anim.n_characters} characters, {args.width}x{args.height}",
        flush=True,
    )
    import dataclasses

    mannequins = dataclasses.replace(
        anim, bodies=tuple({"model": "open", "sex": b["sex"], "height": b["height"]} for b in anim.bodies)
    )
    configs = [
        ("ours", dict(msaa=4, shadows=True)),
        ("plain (no MSAA, no shadows)", dict(msaa=0, shadows=False)),
        ("full-mesh (4x MSAA, shadows)", dict(msaa=4, shadows=True, max_faces=None)),
        ("mannequin (open model, 4x MSAA, shadows)", dict(msaa=4, shadows=True)),
    ]
    rows, breakdown, encoders, parts = [], {}, [], {}
    for name, kw in configs:
        scene = mannequins if name.startswith("mannequin") else anim
        t_init = time.perf_counter()
        with CrowdRenderer(scene, design=design, width=args.width, height=args.height, **kw) as r:
            init_s = time.perf_counter() - t_init
            r.set_view(args.view)
            r.draw_layers()  # a video's set-up draws them (render_video); not a per-frame cost
            res = _time_frames(r, frames)
            if name in ("ours", "plain (no MSAA, no shadows)"):
                parts[name] = _character_parts(r, frames[-1])
            if name == "ours":
                breakdown = _passes(r, frames[-1])
                with tempfile.TemporaryDirectory() as tmp:
                    writer = VideoWriter(
                        os.path.join(tmp, "b.mp4"), args.width, args.height, 30.0, preset=x264, crf=crf
                    )
                    t0, c0 = time.perf_counter(), time.process_time()
                    for f in frames:
                        writer.write(r.render_raw(f))
                    writer.close()
                    enc = {
                        "wall_s": (time.perf_counter() - t0) / len(frames),
                        "cpu_s": (time.process_time() - c0) / len(frames),
                    }
                    # the encoder alone (ffmpeg's own CPU time and PSNR), per x264 preset
                    raw = [r.render_raw(f) for f in frames[:4]]
                    raw = [raw[k % len(raw)] for k in range(len(frames))]
                    encoders = _encoders(
                        raw,
                        args.width,
                        args.height,
                        sorted({"medium", x264, "faster", "veryfast", "superfast"}, key=_X264_ORDER.index),
                        crf,
                    )
        rows.append({"config": name, **res, "init_s": init_s})
        if name == "ours":
            rows.append({"config": f"ours+encode (x264 {x264})", **enc, "init_s": init_s})
    base = rows[0]["wall_s"]
    mannequin = next(r for r in rows if r["config"].startswith("mannequin"))
    for row in rows:
        row["vs_ours"] = row["wall_s"] / base
        row["fps"] = 1.0 / row["wall_s"]
    vs_mannequin = {"wall": rows[0]["wall_s"] / mannequin["wall_s"], "cpu": rows[0]["cpu_s"] / mannequin["cpu_s"]}
    n_set = 60 * int(round(design.duration * design.fps))
    projected_h = rows[1]["wall_s"] * n_set / 3600.0
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    enc_cpu = next((e["ffmpeg_cpu_s"] for e in encoders if e["x264 preset"] == x264), 0.0)
    cpu_per_frame = rows[0]["cpu_s"] + enc_cpu
    projected_cpu_h = cpu_per_frame / cpus * n_set / 3600.0
    print(format_table(rows, ["config", "wall_s", "cpu_s", "init_s", "fps", "vs_ours"]))
    print(
        f"MakeHuman characters vs the mannequins, same run: {vs_mannequin['wall']:.2f}x wall, "
        f"{vs_mannequin['cpu']:.2f}x CPU per frame (bar 1.5x)"
    )
    print("where the time goes (one 'ours' frame, seconds):")
    for k, v in breakdown.items():
        print(f"  {k:14s} {v:.4f}")
    print("the characters' pass, taken apart (wall s; 'plain' has no MSAA and no shadows):")
    print(format_table([{"part": k, **{cfg: parts[cfg][k] for cfg in parts}} for k in next(iter(parts.values()))]))
    if len(parts) == 2:
        ours_p, plain_p = parts["ours"], parts["plain (no MSAA, no shadows)"]
        print(
            f"  4x MSAA: fragments {ours_p['fragments'] / max(plain_p['fragments'], 1e-9):.2f}x, shading "
            f"{ours_p['shading'] / max(plain_p['shading'], 1e-9):.2f}x the plain pass's"
        )
    print("encoder alone (per 1080p frame; ffmpeg's CPU time, not in cpu_s above):")
    print(format_table(encoders))
    print(
        f"projected whole set ({n_set} frames, render+encode): {projected_h:.2f} h at the measured wall time; "
        f"{projected_cpu_h:.2f} h from CPU time ({cpu_per_frame:.3f} CPU-s per frame over {cpus} idle CPUs) "
        f"(target 0.15 s/frame -> {0.15 * n_set / 3600:.2f} h)"
    )
    path = write_report(
        "render",
        rows,
        vs_mannequin=vs_mannequin,
        breakdown=breakdown,
        character_pass=parts,
        encoders=encoders,
        projected_set_hours=projected_h,
        projected_set_hours_cpu=projected_cpu_h,
        cpu_s_per_frame_render_encode=cpu_per_frame,
        gl=info,
        load=os.getloadavg()[0],
        frames=args.frames,
        width=args.width,
        height=args.height,
        devices=devices,
    )
    print(f"report: {path}")
    return 0

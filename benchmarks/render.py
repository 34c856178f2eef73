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
  settings (x264 preset faster, crf 18), per frame, and the encoder's own CPU time per
  frame for x264 presets medium, faster, veryfast;
* a per-pass breakdown (shadow, characters, floor, MSAA resolve, read-back);
* the projected time of the whole 60-video set (60 x 600 frames) on this machine, from
  the wall time of ``ours+encode`` and, load-independent, from the CPU time of rendering
  plus encoding spread over the machine's CPUs.

Both wall-clock and process CPU seconds are reported: on a shared machine the CPU time
(all llvmpipe threads together) is the steadier number; when other processes hold a core,
wall time approaches CPU time.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time

import numpy as np

from crowdstudy.bench import format_table, write_report

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


def _passes(renderer, frame: int) -> dict:
    ctx = renderer.ctx
    out = {}

    def timed(name, fn):
        ctx.finish()
        t0 = time.perf_counter()
        fn()
        ctx.finish()
        out[name] = out.get(name, 0.0) + time.perf_counter() - t0

    timed("upload+cull", lambda: renderer._load_frame(frame))
    timed("shadow pass", renderer._shadow_pass)
    timed("upload+cull", lambda: renderer._prepare(frame, upload=False))
    fbo = renderer.fbo_msaa or renderer.fbo_out
    vp = renderer.camera.view_projection(renderer.width / renderer.height)

    def colour_static_setup():
        fbo.use()
        ctx.viewport = (0, 0, renderer.width, renderer.height)
        fbo.clear(0.5, 0.5, 0.5, 1.0, depth=1.0)
        renderer.tex_shadow.use(3)
        for prog in renderer._lit_programs:
            prog["u_view_proj"].write(np.ascontiguousarray(vp.T, dtype=np.float32).tobytes())

    timed("characters", lambda: (colour_static_setup(), renderer._cull_back_faces(True),
                                 renderer._draw_characters(renderer.prog_char, vp), renderer._cull_back_faces(False)))
    timed("floor", renderer._draw_floor)
    if renderer.fbo_msaa is not None:
        timed("msaa resolve", lambda: ctx.copy_framebuffer(renderer.fbo_out, renderer.fbo_msaa))
    timed("read-back", lambda: renderer.fbo_out.read(components=3, alignment=1))
    return out


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="crowdstudy bench render")
    parser.add_argument("--frames", type=int, default=8, help="frames timed per configuration")
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--view", default="V3")
    args = parser.parse_args(argv)

    from crowdstudy.render.context import context_info
    from crowdstudy.render.renderer import CrowdRenderer
    from crowdstudy.render.stimuli import PRESETS
    from crowdstudy.render.video import VideoWriter

    x264, crf = PRESETS["full"]["x264_preset"], PRESETS["full"]["crf"]

    design, anim = _scene(duration=max(1.0, (args.frames + 2) / 30.0))
    frames = [int(f) for f in np.linspace(1, anim.n_frames - 1, args.frames).round()]
    info = context_info()
    print(f"renderer: {info['renderer']} | OpenGL {info['version']} | {os.cpu_count()} CPUs | "
          f"load {os.getloadavg()[0]:.2f} | {anim.n_characters} characters, {args.width}x{args.height}", flush=True)
    import dataclasses

    mannequins = dataclasses.replace(anim, bodies=tuple({"model": "open", "sex": b["sex"], "height": b["height"]}
                                                        for b in anim.bodies))
    configs = [("ours", dict(msaa=4, shadows=True)), ("plain (no MSAA, no shadows)", dict(msaa=0, shadows=False)),
               ("full-mesh (4x MSAA, shadows)", dict(msaa=4, shadows=True, max_faces=None)),
               ("mannequin (open model, 4x MSAA, shadows)", dict(msaa=4, shadows=True))]
    rows, breakdown, encoders = [], {}, []
    for name, kw in configs:
        scene = mannequins if name.startswith("mannequin") else anim
        t_init = time.perf_counter()
        with CrowdRenderer(scene, design=design, width=args.width, height=args.height, **kw) as r:
            init_s = time.perf_counter() - t_init
            r.set_view(args.view)
            res = _time_frames(r, frames)
            if name == "ours":
                breakdown = _passes(r, frames[-1])
                with tempfile.TemporaryDirectory() as tmp:
                    writer = VideoWriter(os.path.join(tmp, "b.mp4"), args.width, args.height, 30.0, preset=x264,
                                         crf=crf)
                    t0, c0 = time.perf_counter(), time.process_time()
                    for f in frames:
                        writer.write(r.render_raw(f))
                    writer.close()
                    enc = {"wall_s": (time.perf_counter() - t0) / len(frames),
                           "cpu_s": (time.process_time() - c0) / len(frames)}
                    # the encoder alone (ffmpeg's own CPU time), per x264 preset
                    raw = [r.render_raw(f) for f in frames[:4]]
                    for preset in ("medium", "faster", "veryfast"):
                        before = resource.getrusage(resource.RUSAGE_CHILDREN)
                        t0 = time.perf_counter()
                        writer = VideoWriter(os.path.join(tmp, f"{preset}.mp4"), args.width, args.height, 30.0,
                                             preset=preset, crf=crf)
                        for k in range(len(frames)):
                            writer.write(raw[k % len(raw)])
                        writer.close()
                        after = resource.getrusage(resource.RUSAGE_CHILDREN)
                        encoders.append({"x264 preset": preset,
                                         "wall_s": (time.perf_counter() - t0) / len(frames),
                                         "ffmpeg_cpu_s": (after.ru_utime + after.ru_stime - before.ru_utime
                                                          - before.ru_stime) / len(frames),
                                         "kB_per_frame": os.path.getsize(os.path.join(tmp, f"{preset}.mp4"))
                                         / 1024 / len(frames)})
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
    print(f"MakeHuman characters vs the mannequins, same run: {vs_mannequin['wall']:.2f}x wall, "
          f"{vs_mannequin['cpu']:.2f}x CPU per frame (bar 1.5x)")
    print("where the time goes (one 'ours' frame, seconds):")
    for k, v in breakdown.items():
        print(f"  {k:14s} {v:.4f}")
    print("encoder alone (per 1080p frame; ffmpeg's CPU time, not in cpu_s above):")
    print(format_table(encoders))
    print(f"projected whole set ({n_set} frames, render+encode): {projected_h:.2f} h at the measured wall time; "
          f"{projected_cpu_h:.2f} h from CPU time ({cpu_per_frame:.3f} CPU-s per frame over {cpus} idle CPUs) "
          f"(target 0.15 s/frame -> {0.15 * n_set / 3600:.2f} h)")
    path = write_report("render", rows, vs_mannequin=vs_mannequin, breakdown=breakdown, encoders=encoders, projected_set_hours=projected_h,
                        projected_set_hours_cpu=projected_cpu_h, cpu_s_per_frame_render_encode=cpu_per_frame, gl=info,
                        load=os.getloadavg()[0], frames=args.frames, width=args.width, height=args.height)
    print(f"report: {path}")
    return 0

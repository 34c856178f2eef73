"""MP4 videos: frames streamed from the renderer to ffmpeg (H.264, yuv420p BT.709 tagged, +faststart).

Frames never accumulate in memory: each raw RGB frame is read back through two alternating
pixel-pack buffers (asynchronous on GPUs: frame k is copied while frame k+1 renders) and
handed to a writer thread that feeds ffmpeg's stdin while the next frame renders (bounded
queue of two frames). OpenGL rows come bottom-up; ffmpeg's ``vflip`` filter turns them over, so
Python never copies a frame. The video is written to ``NAME.part.mp4`` and renamed when
ffmpeg succeeds, so an interrupted run never leaves a truncated file under the final name.

Loops: an animation with ``meta["loop"] = {"mode": "dissolve", "frames": D, "video_frames":
T}`` (the corridor) is longer than its video. The video has T frames; its first D frames are
cross-dissolves of frame i (weight (i + 1) / (D + 1)) with frame T + i (the rest), blended in
linear light (:func:`blend_frames`) before encoding, so the loop seam T-1 -> 0 continues the
motion T-1 -> T and fades into the clip by frame D. Those D later frames are rendered first
and held in memory (15 frames at 0.5 s, 30 fps). "periodic" or no loop renders as is.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import queue
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np

from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.paths import check_output_path
from crowdstudy.scene_meta import loop_mode

__all__ = [
    "find_ffmpeg",
    "VideoWriter",
    "render_video",
    "sha256_file",
    "probe_video",
    "FramePlan",
    "blend_frames",
    "video_frame_count",
    "BT709_SCALE",
    "BT709_TAGS",
]


#: ffmpeg filter converting rgb24 to yuv420p with the BT.709 matrix, limited range
BT709_SCALE = "scale=out_color_matrix=bt709:out_range=tv,format=yuv420p"
#: ffmpeg output options tagging the stream as BT.709 (matrix, primaries, transfer), limited range
BT709_TAGS = ("-colorspace", "bt709", "-color_primaries", "bt709", "-color_trc", "bt709", "-color_range", "tv")


def find_ffmpeg() -> str:
    """The system ``ffmpeg``, else imageio-ffmpeg's bundled binary."""
    exe = shutil.which("ffmpeg")
    if exe:
        return exe
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except Exception:  # not installed, or its binary is missing for this platform
        raise MissingDependencyError(
            "no ffmpeg found: install it with `sudo apt-get install ffmpeg` or `pip install imageio-ffmpeg`"
        ) from None


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class VideoWriter:
    """Streams raw RGB frames (bottom row first) into an H.264 MP4.

    Args:
        path: the .mp4 to write.
        width, height: frame size in pixels (even numbers, for yuv420p).
        fps: frames per second.
        crf: x264 constant rate factor (lower = better quality; 18 is visually lossless).
        preset: x264 speed preset.
    """

    def __init__(
        self,
        path: str | Path,
        width: int,
        height: int,
        fps: float,
        *,
        crf: int = 18,
        preset: str = "medium",
        bottom_up: bool = True,
    ):
        if width % 2 or height % 2:
            raise InvalidInputError(f"width/height: H.264 yuv420p needs even sizes, got {width}x{height}")
        self.path = check_output_path(path)
        self.part = self.path.with_name(self.path.stem + ".part.mp4")
        self.frame_bytes = width * height * 3
        self.frames = 0
        # RGB -> Y'CbCr with the BT.709 matrix in limited ("tv") range, and the stream tagged
        # so (BT.709 primaries, transfer, matrix): players and browsers assume BT.709 for HD
        # and decode these colours back; ffmpeg's default (BT.601, untagged) shifts them
        vf = ",".join((["vflip"] if bottom_up else []) + [BT709_SCALE])
        cmd = [
            find_ffmpeg(),
            "-hide_banner",
            "-loglevel",
            "error",
            "-y",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "-s",
            f"{width}x{height}",
            "-framerate",
            f"{fps:g}",
            "-i",
            "pipe:0",
            "-vf",
            vf,
            "-c:v",
            "libx264",
            "-preset",
            preset,
            "-crf",
            str(int(crf)),
            "-pix_fmt",
            "yuv420p",
            *BT709_TAGS,
            "-movflags",
            "+faststart",
            "-threads",
            "2",
            "-fflags",
            "+bitexact",
            "-flags:v",
            "+bitexact",
            "-an",
            str(self.part),
        ]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
        if self.proc.stdin is None or self.proc.stderr is None:  # both are pipes
            raise RuntimeError("ffmpeg started without its pipes")
        self._stdin, self._stderr = self.proc.stdin, self.proc.stderr
        self._queue: queue.Queue = queue.Queue(maxsize=2)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                self._stdin.write(item)
            except (BrokenPipeError, OSError) as exc:
                self._error = exc
                return

    def write(self, frame) -> None:
        """Queue one frame: raw RGB bytes (bottom row first) or an (H, W, 3) uint8 array
        (top row first when the writer was created with ``bottom_up=False``)."""
        data = frame.tobytes() if isinstance(frame, np.ndarray) else bytes(frame)
        if len(data) != self.frame_bytes:
            raise InvalidInputError(f"frame: expected {self.frame_bytes} bytes, got {len(data)}")
        if self._error is not None:
            self._fail()
        self._queue.put(data)
        self.frames += 1

    def _fail(self):
        try:
            self.proc.kill()
        except OSError:
            pass
        err = self.proc.stderr.read().decode(errors="replace").strip() if self.proc.stderr else ""
        self.part.unlink(missing_ok=True)
        raise RuntimeError(f"ffmpeg failed writing {str(self.path)!r}: {err or self._error}")

    def close(self) -> Path:
        """Finish the file (waits for ffmpeg) and move it to its final name."""
        self._queue.put(None)
        self._thread.join()
        if self._error is not None:
            self._fail()
        self._stdin.close()
        err = self._stderr.read().decode(errors="replace").strip()
        if self.proc.wait() != 0:
            self.part.unlink(missing_ok=True)
            raise RuntimeError(f"ffmpeg failed writing {str(self.path)!r}: {err}")
        os.replace(self.part, self.path)
        return self.path

    def abort(self) -> None:
        self._queue.put(None)
        self._thread.join(timeout=5)
        try:
            self.proc.kill()
            self.proc.wait(timeout=5)
        except OSError:
            pass
        self.part.unlink(missing_ok=True)


def probe_video(path: str | Path) -> dict:
    """ffprobe of the first video stream: codec, pix_fmt, width, height, frames (decoded
    count), rate, and the colour tags color_space, color_primaries, color_transfer,
    color_range (ffprobe's names, e.g. "bt709" and "tv"; "unknown" or None when untagged)."""
    exe = shutil.which("ffprobe")
    if not exe:
        raise MissingDependencyError("ffprobe not found: `sudo apt-get install ffmpeg`")
    out = subprocess.run(
        [
            exe,
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-count_frames",
            "-show_entries",
            "stream=codec_name,pix_fmt,width,height,nb_read_frames,r_frame_rate,"
            "color_space,color_primaries,color_transfer,color_range",
            "-of",
            "default=noprint_wrappers=1",
            str(path),
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    info = dict(line.split("=", 1) for line in out.strip().splitlines() if "=" in line)
    return {
        "codec": info.get("codec_name"),
        "pix_fmt": info.get("pix_fmt"),
        "width": int(info["width"]),
        "height": int(info["height"]),
        "frames": int(info["nb_read_frames"]),
        "rate": info.get("r_frame_rate"),
        "color_space": info.get("color_space"),
        "color_primaries": info.get("color_primaries"),
        "color_transfer": info.get("color_transfer"),
        "color_range": info.get("color_range"),
    }


@dataclasses.dataclass(frozen=True)
class FramePlan:
    """What each video frame shows: animation frame ``source[i]``, blended (when
    ``partner[i] >= 0``) with animation frame ``partner[i]``: ``weight[i] * source +
    (1 - weight[i]) * partner`` in linear light."""

    source: np.ndarray  # (F,) int
    partner: np.ndarray  # (F,) int, -1 = no blend
    weight: np.ndarray  # (F,) float, weight of source (1 without a blend)

    def __len__(self) -> int:
        return len(self.source)

    @property
    def n_blended(self) -> int:
        return int(np.count_nonzero(self.partner >= 0))


def video_frame_count(anim) -> int:
    """Frames of the animation its video shows: ``meta["loop"]["video_frames"]`` for a
    "dissolve" loop (the frames after it feed the seam's cross-dissolve), else all."""
    if loop_mode(anim.meta) == "dissolve":
        return int(anim.meta["loop"]["video_frames"])
    return anim.n_frames


def _frame_plan(anim, duration: float | None, fps: float) -> FramePlan:
    video_frames = video_frame_count(anim)
    if duration is None:
        duration = float(video_frames / anim.fps)
    if not np.isfinite(duration) or duration <= 0:
        raise InvalidInputError(f"duration: expected a positive number of seconds, got {duration!r}")
    if duration > anim.duration + 0.5 / anim.fps:
        raise InvalidInputError(
            f"duration: {duration:g} s is longer than the animation ({anim.duration:g} s, "
            f"{anim.n_frames} frames at {anim.fps:g} fps)"
        )
    n = max(1, int(round(duration * fps)))
    source = np.minimum(np.round(np.arange(n) * anim.fps / fps).astype(int), anim.n_frames - 1)
    partner = np.full(n, -1, dtype=int)
    weight = np.ones(n)
    loop = anim.meta.get("loop", {})
    if loop_mode(anim.meta) == "dissolve" and int(loop.get("frames", 0)) > 0:
        # the video spans `span` animation frames: its seam continues into frame `span`,
        # and frames span + i dissolve into the video's first frames
        span = int(round(n * anim.fps / fps))
        d = min(int(round(int(loop["frames"]) * fps / anim.fps)), n // 2)
        d = min(d, int(np.count_nonzero(source[:d] + span < anim.n_frames)))
        i = np.arange(d)
        partner[:d] = source[:d] + span
        weight[:d] = (i + 1) / (d + 1)
    return FramePlan(source=source, partner=partner, weight=weight)


#: the renderer's display encoding (display.glsl: sqrt of the tone-mapped colour): code
#: value v in 0..255 <-> linear light (v / 255) ** 2
_TO_LINEAR = (np.arange(256, dtype=np.float32) / 255.0) ** 2


def blend_frames(a, b, weight: float | np.floating | np.ndarray):
    """``weight * a + (1 - weight) * b`` of two RGB frames (uint8 arrays of any shape, or raw
    bytes) in linear light, rounded once to uint8; returns the type of ``a``."""
    as_bytes = not isinstance(a, np.ndarray)
    x = np.frombuffer(a, np.uint8) if as_bytes else np.asarray(a, np.uint8)
    y = np.frombuffer(b, np.uint8) if not isinstance(b, np.ndarray) else np.asarray(b, np.uint8)
    if x.shape != y.shape:
        raise InvalidInputError(f"blend_frames: frames differ in size ({x.shape} vs {y.shape})")
    w = float(weight)
    lin = _TO_LINEAR[x] * np.float32(w) + _TO_LINEAR[y] * np.float32(1.0 - w)
    out = np.clip(np.sqrt(lin) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return out.tobytes() if as_bytes else out.reshape(np.shape(a))


def render_video(
    anim,
    viewpoint,
    out_path,
    *,
    width: int | None = None,
    height: int | None = None,
    duration: float | None = None,
    fps: float | None = None,
    msaa: int = 4,
    overlap_view: bool = False,
    design=None,
    progress: bool = True,
    body_loader=None,
    crf: int = 18,
    preset: str = "medium",
    shadows: bool = True,
    red_sample_frames: int = 0,
    color_positions=None,
    post_aa: str = "none",
    lod_scale: float = 1.0,
    shadow_size: int = 2048,
) -> dict:
    """Render an animation to an MP4.

    Args:
        anim: CrowdAnimation.
        viewpoint: "V1".."V4", a design Viewpoint, or a :class:`~crowdstudy.render.camera.Camera`.
        out_path: the .mp4 to write (folders are created).
        width, height, fps: default the design's video settings (1920x1080, 30 fps).
        duration: seconds (default the whole animation, or its ``video_frames`` for a
            "dissolve" loop, see the module doc); frames are resampled from the
            animation's rate to ``fps`` (nearest frame).
        overlap_view: paint interpenetrations red (paper Fig. 5); the red fraction of every
            frame is returned.
        red_sample_frames: with ``overlap_view`` False, also measure the overlap view's red
            fraction on this many evenly spaced frames (rendered separately, not in the video).
        color_positions: (N, 2) positions deciding the clothing colours (see
            :class:`~crowdstudy.render.renderer.CrowdRenderer`); give the Baseline's frame 0
            when rendering its corrected version.
        msaa, post_aa, lod_scale, shadow_size: the renderer's anti-aliasing, levels of
            detail and shadow map (see :class:`~crowdstudy.render.renderer.CrowdRenderer`).
            The overlap view's samples are measured at ``lod_scale`` 1 whatever the video's,
            so the red fraction does not depend on the speed settings.
    Returns:
        dict: path, frames, width, height, fps, duration, sha256, seconds, seconds_per_frame,
        red_fraction (list, per measured frame), mean_red_fraction (or None),
        dissolve_frames (video frames blended at the loop seam, 0 unless a "dissolve" loop),
        timings (wall and CPU seconds, ffmpeg's included, of the stages "setup" (characters
        painted, dressed, simplified; camera; static layers drawn), "first_frame" (without
        a dissolve: the first frame rendered, shaders compiled), "frames" (the rest rendered,
        everything encoded) and "red" (the overlap view's samples): ``{stage}_wall_s``,
        ``{stage}_cpu_s``).
    """
    from crowdstudy.progress import progress_bar
    from crowdstudy.render.renderer import CrowdRenderer

    if design is None:
        from crowdstudy.design import load_design

        design = load_design()
    width = int(width or design.video_width)
    height = int(height or design.video_height)
    fps = float(fps or design.fps)
    if fps <= 0 or not np.isfinite(fps):
        raise InvalidInputError(f"fps: expected a positive frame rate, got {fps!r}")
    plan = _frame_plan(anim, duration, fps)
    out_path = check_output_path(out_path)
    t0 = time.perf_counter()
    clock = _Clock()
    red: list[float] = []
    with CrowdRenderer(
        anim,
        design=design,
        width=width,
        height=height,
        msaa=msaa,
        shadows=shadows,
        shadow_size=shadow_size,
        body_loader=body_loader,
        color_positions=color_positions,
        post_aa=post_aa,
        lod_scale=lod_scale,
    ) as renderer:
        renderer.set_view(viewpoint)
        renderer.draw_layers()
        clock.lap("setup")
        writer = VideoWriter(out_path, width, height, fps, crf=crf, preset=preset, bottom_up=not overlap_view)
        try:
            bar = progress_bar(range(len(plan)), desc=out_path.name, unit="frame", enabled=progress, leave=False)
            if overlap_view:
                red += _write_overlap_frames(renderer, plan, writer, bar)
            else:
                _write_frames(renderer, plan, writer, bar, clock)
            writer.close()
        except BaseException:
            writer.abort()
            raise
        clock.lap("frames")
        if not overlap_view and red_sample_frames > 0:
            renderer.characters.lod_scale = 1.0  # the red fraction on the standard levels of detail
            for src in plan.source[
                np.linspace(0, len(plan) - 1, min(red_sample_frames, len(plan))).round().astype(int)
            ]:
                red.append(renderer.overlap(int(src), image=False).red_fraction)
        clock.lap("red")
    seconds = time.perf_counter() - t0
    return {
        "path": str(out_path),
        "frames": int(len(plan)),
        "width": width,
        "height": height,
        "fps": fps,
        "duration": len(plan) / fps,
        "sha256": sha256_file(out_path),
        "seconds": seconds,
        "seconds_per_frame": seconds / len(plan),
        "red_fraction": red,
        "mean_red_fraction": float(np.mean(red)) if red else None,
        "dissolve_frames": plan.n_blended,
        "timings": clock.laps,
    }


def _write_overlap_frames(renderer, plan: FramePlan, writer: VideoWriter, frames) -> list[float]:
    """Write the overlap view of each video frame in ``frames`` (indices into ``plan``, a
    progress bar); the red fraction of each. The seam's dissolve partners (frames past the
    video) are rendered first and held in memory."""
    red = []
    later = {int(k): renderer.overlap(int(k)).image for k in plan.partner[plan.partner >= 0]}
    for i in frames:
        frame = renderer.overlap(int(plan.source[i]))
        red.append(frame.red_fraction)
        image = (
            frame.image
            if plan.partner[i] < 0
            else blend_frames(frame.image, later[int(plan.partner[i])], plan.weight[i])
        )
        writer.write(image)
    return red


def _write_frames(renderer, plan: FramePlan, writer: VideoWriter, frames, clock: _Clock) -> None:
    """Write each video frame in ``frames`` (indices into ``plan``, a progress bar) through
    two pixel-pack buffers: frame k is read back while frame k+1 renders. The seam's
    dissolve partners are rendered first and held in memory; a dissolve frame is rendered
    synchronously. ``clock`` laps "first_frame" after the first."""
    later = {int(k): renderer.render_raw(int(k)) for k in plan.partner[plan.partner >= 0]}
    pbos = [renderer.ctx.buffer(reserve=renderer.width * renderer.height * 3) for _ in range(2)]
    try:
        pending = None
        for i in frames:
            src = int(plan.source[i])
            if plan.partner[i] >= 0:  # a dissolve frame: rendered synchronously
                if pending is not None:
                    writer.write(pbos[pending].read())
                    pending = None
                writer.write(blend_frames(renderer.render_raw(src), later[int(plan.partner[i])], plan.weight[i]))
                continue
            renderer.render_into(src, pbos[i % 2])
            if i == 0:
                clock.lap("first_frame")  # and the programs' first use (llvmpipe compiles them)
            if pending is not None:
                writer.write(pbos[pending].read())
            pending = i % 2
        if pending is not None:
            writer.write(pbos[pending].read())
    finally:
        for pbo in pbos:
            pbo.release()


class _Clock:
    """Wall and CPU seconds of consecutive stages of a video: this process (every thread,
    llvmpipe's included) plus its finished child processes (ffmpeg, counted when it exits)."""

    def __init__(self):
        self.laps: dict = {}
        self._last = self._now()

    @staticmethod
    def _now() -> tuple[float, float]:
        try:
            import resource
        except ImportError:  # not on Windows: the children's CPU time is not counted there
            return time.perf_counter(), time.process_time()
        child = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.perf_counter(), time.process_time() + child.ru_utime + child.ru_stime

    def lap(self, name: str) -> None:
        now = self._now()
        self.laps[f"{name}_wall_s"] = now[0] - self._last[0]
        self.laps[f"{name}_cpu_s"] = now[1] - self._last[1]
        self._last = now

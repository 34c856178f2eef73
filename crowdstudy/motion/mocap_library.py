"""The shipped motion-capture library: 21 CMU takes, cleaned, in ``crowdstudy/motion/mocap/``.

Source: ``shared/data/mocap`` (CMU Graphics Lab Motion Capture Database, B. Hahne's
Daz-friendly BVH, cMonkeys' FBX bake; origin, trims and licence of each file in its
``SOURCES.md`` and in :data:`TAKES`). :func:`crowdstudy.motion.mocap_build.build_library`
(``crowdstudy motion build-library``) converts them once:

* dances and idles: :func:`~crowdstudy.motion.bvh.load_bvh` (retargeted to the 24-joint
  skeleton), then :func:`~crowdstudy.motion.mocap.clean_take` (trimmed, 60 fps, facing +y
  on its spot, planted feet locked); the bounce (:func:`~crowdstudy.motion.beat.beat_curve`)
  gives each dance its period and phase;
* walks: :func:`~crowdstudy.motion.mocap_walks.build_walk_loops` (in place, whole gait
  cycles, phase 0 at the left heel strike, feet locked).

Storage (``takes.npz`` + ``library.json``, a few MB): rotations as float16 unit
quaternions (about 0.02 degrees), pelvis positions as float32, metadata in JSON. The build
is deterministic; a test rebuilds takes and compares them with the shipped arrays.

At run time :func:`dance_loop` makes the loop a crowd plays: the take time-warped to the
design's tempo (:func:`~crowdstudy.motion.beat.warp_to_tempo`), a loop of whole bars that
divides the stimulus, starting on a beat, chosen by pose-and-velocity matching
(:func:`~crowdstudy.motion.loops.find_loop`, on positions relative to the dancer's spot, so
planted feet match too), its seam blended over one beat and its planted feet held across
the seam (:func:`~crowdstudy.motion.mocap.lock_loop_feet`).
"""

from __future__ import annotations

import dataclasses
import functools
import json
from importlib import resources

import numpy as np

from crowdstudy.body.rotations import quaternion_to_axis_angle
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.beat import beat_offset, beats_per_bounce, low_points, warp_to_tempo
from crowdstudy.motion.clip import MotionClip
from crowdstudy.motion.loops import find_loop, make_loop
from crowdstudy.motion.mocap import lock_loop_feet

__all__ = [
    "TakeSpec",
    "TAKES",
    "CREDIT",
    "LICENCE",
    "mocap_names",
    "load_mocap",
    "dance_loop",
    "idle_loop",
    "MAX_TEMPO_RATIO",
    "LOOP_ACCEPT",
]

#: Acknowledgement the data's providers ask for (README, ASSETS.md).
CREDIT = (
    "Motion capture data from the CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu), "
    "created with funding from NSF EIA-0196217; BVH conversion by Bruce Hahne; FBX conversion by "
    "Ward Dewaele (cMonkeys)."
)
LICENCE = (
    "CMU: free for use in research and commercial projects (may be included in a product, not resold "
    "as data); B. Hahne and cMonkeys add no restrictions"
)
#: Largest speed change (either way) a dance may take to reach the tempo; beyond it the
#: dance is left out of a crowd at that tempo (:func:`dance_loop` raises).
MAX_TEMPO_RATIO = 1.45
_DATA = "mocap"
#: Loop-match score (m^2, mean squared joint distance over the matched windows) below which
#: a longer loop is preferred to a better-matching shorter one (less repetition).
LOOP_ACCEPT = 0.02


@dataclasses.dataclass(frozen=True)
class TakeSpec:
    """One take of the library.

    name: clip name; file: BVH file in the source folder; kind: "dance", "idle" or "walk";
    trial: CMU trial; trim: (start, end) seconds kept (None = to the end); bounce_period:
    seconds, set by hand when the pelvis bounce does not show the dance's beat;
    bounce_beats: beats per bounce, set by hand (default: the closest to the tempo);
    default: in the default concert crowd; description: what it shows.
    """

    name: str
    file: str
    kind: str
    trial: str
    description: str
    trim: tuple[float, float | None] = (0.0, None)
    bounce_period: float | None = None
    bounce_beats: float | None = None
    default: bool = True


TAKES: tuple[TakeSpec, ...] = (
    # cross-steps with the knees together: on our bodies the knee capsules overlap by 11-14 cm
    # in 80-97 % of the frames (the legs pass through each other): not in the default concert
    TakeSpec(
        "groove_steps",
        "cmu_111_05_dance_steps.bvh.gz",
        "dance",
        "111_05",
        "free-style dance: side steps, arm swings at waist height",
        default=False,
    ),
    # turns around on its spot (heading range -156 to +111 degrees): not in a crowd facing the stage
    TakeSpec(
        "groove_knees",
        "cmu_113_04_dance_groove.bvh.gz",
        "dance",
        "113_04",
        "free-style dance: small steps and knee lifts, arm swings, hip sway, turning around",
        default=False,
    ),
    TakeSpec(
        "twist",
        "cmu_141_12_dance_twist.bvh.gz",
        "dance",
        "141_12",
        "the Twist: arms up, knees bent, hips and torso twisting",
    ),
    TakeSpec(
        "macarena",
        "cmu_143_35_macarena_dance.bvh.gz",
        "dance",
        "143_35",
        "Macarena arm routine with a light knee bounce",
    ),
    # the chicken dance's bounce (a squat-wiggle every 1.4 s) is slower than its beat:
    # two routines (beak, wings, wiggle, claps) in the take, 8 beats each
    TakeSpec(
        "chicken_claps",
        "cmu_20_01_chicken_dance_clap.bvh.gz",
        "dance",
        "20_01",
        "chicken dance: beak, wing flaps, squat-wiggle and hand claps",
        bounce_period=0.625,
        bounce_beats=1.0,
    ),
    TakeSpec(
        "jumping_jacks",
        "cmu_22_16_jumping_jacks_arms_up.bvh.gz",
        "dance",
        "22_16",
        "jumping jacks with both arms swinging overhead",
        bounce_beats=1.0,
    ),
    TakeSpec(
        "jump",
        "cmu_49_02_jump_in_place.bvh.gz",
        "dance",
        "49_02",
        "two-footed counter-movement jumps in place",
        bounce_beats=2.0,
        default=False,
    ),
    # the lambada's knees flex at about 1.6 Hz (SOURCES.md), too weakly to time it; the
    # pelvis's clearer 1.23 s cycle spans two of those flexes
    TakeSpec(
        "lambada_arm_up",
        "cmu_55_02_lambada_sway_arm_up.bvh.gz",
        "dance",
        "55_02",
        "lambada hip sway, left arm held overhead",
        bounce_period=1.233,
        bounce_beats=2.0,
    ),
    TakeSpec(
        "cheer",
        "cmu_79_69_cheer_very_happy.bvh.gz",
        "dance",
        "79_69",
        "cheering: arms thrown wide, fist pumps overhead",
    ),
    TakeSpec(
        "wave_overhead",
        "cmu_13_26_wave_arms_overhead.bvh.gz",
        "dance",
        "13_26",
        "both arms waving overhead, one-arm signals",
    ),
    # the performer's hands pat against her chest: on wider bodies they sink 9 cm into the
    # chest (6 cm after clear_hands) and the forearms cross: left out of the default concert
    TakeSpec(
        "happy_claps",
        "cmu_80_43_happy_hands_clasped_bounce.bvh.gz",
        "dance",
        "80_43",
        "hands together in front of the chest, small rapid pats, light bounce",
        bounce_beats=1.0,
        default=False,
    ),
    TakeSpec(
        "idle_still",
        "cmu_113_21_idle_standing_still.bvh.gz",
        "idle",
        "113_21",
        "standing still with natural sway",
        default=False,
    ),
    TakeSpec(
        "idle_shift",
        "cmu_139_02_idle_shift_weight.bvh.gz",
        "idle",
        "139_02",
        "standing, shifting weight between the feet",
        default=False,
    ),
    TakeSpec(
        "idle_wait",
        "cmu_137_28_idle_wait.bvh.gz",
        "idle",
        "137_28",
        "standing and waiting: weight shifts, hands on hips",
        default=False,
    ),
    TakeSpec(
        "gait_short_steps",
        "cmu_142_07_walk_slow_short_steps.bvh.gz",
        "walk",
        "142_07",
        "slow short-step shuffle, slight stoop",
    ),
    TakeSpec("gait_slow", "cmu_139_28_walk_slow.bvh.gz", "walk", "139_28", "natural slow walk"),
    TakeSpec("gait_neutral", "cmu_104_02_walk_neutral.bvh.gz", "walk", "104_02", "neutral walk"),
    TakeSpec("gait_normal", "cmu_81_02_walk_normal.bvh.gz", "walk", "81_02", "walk forward"),
    TakeSpec("gait_brisk", "cmu_82_13_walk_brisk.bvh.gz", "walk", "82_13", "brisk walk"),
    TakeSpec("gait_fast", "cmu_132_20_walk_fast.bvh.gz", "walk", "132_20", "fast walk"),
)
_BY_NAME = {t.name: t for t in TAKES}


# ------------------------------------------------------------------------------ loading
@functools.lru_cache(maxsize=1)
def _store() -> tuple[dict, dict]:
    root = resources.files("crowdstudy.motion") / _DATA
    with (root / "library.json").open("r", encoding="utf-8") as fh:
        lib = json.load(fh)["takes"]
    with (root / "takes.npz").open("rb") as fh:
        with np.load(fh) as z:
            arrays = {k: z[k] for k in z.files}
    return lib, arrays


def mocap_names(kind: str | None = None, *, default_only: bool = False) -> list[str]:
    """Names of the shipped takes of ``kind`` ("dance", "idle", "walk" or None for all), in
    :data:`TAKES` order; ``default_only`` keeps those of the default crowds."""
    if kind not in (None, "dance", "idle", "walk"):
        raise InvalidInputError(f"kind: expected 'dance', 'idle', 'walk' or None, got {kind!r}")
    lib, _ = _store()
    return [
        t.name for t in TAKES if t.name in lib and (kind is None or t.kind == kind) and (not default_only or t.default)
    ]


@functools.cache
def load_mocap(name: str) -> MotionClip:
    """The shipped take ``name`` as a MotionClip (kind "dance"/"walk"; idles have kind "dance"
    and ``meta["idle"] = True``): dances and idles are non-looping takes at 60 fps, walks
    in-place loops."""
    lib, arrays = _store()
    if name not in lib:
        raise InvalidInputError(f"clip name: unknown motion-capture take {name!r}; expected one of {', '.join(lib)}")
    info = lib[name]
    quat = arrays[f"{name}.quat"].astype(np.float64)
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    meta = {
        **info["meta"],
        "source": info["file"],
        "trial": info["trial"],
        "licence": info["licence"],
        "description": info["description"],
        "mocap": True,
        "idle": info["kind"] == "idle",
    }
    return MotionClip(
        name=name,
        kind="walk" if info["kind"] == "walk" else "dance",
        fps=info["fps"],
        joint_rotations=quaternion_to_axis_angle(quat),
        root_translation=arrays[f"{name}.root"].astype(np.float64),
        speed=info["speed"],
        loop=bool(info["loop"]),
        meta=meta,
    )


def _loop_lengths(total_bars: float, bar_frames: int, max_frames: int) -> list[int]:
    """Loop lengths (frames) of whole bars that divide ``total_bars`` (when whole) and fit."""
    if abs(total_bars - round(total_bars)) < 1e-6 and round(total_bars) >= 1:
        n = int(round(total_bars))
        bars = [k for k in range(1, n + 1) if n % k == 0]
    else:
        bars = [1, 2, 4]
    return [k * bar_frames for k in bars if k * bar_frames <= max_frames]


@functools.cache
def dance_loop(name: str, bpm: float, fps: float, duration: float) -> MotionClip:
    """The looping clip a crowd dancing to ``bpm`` plays for a ``duration`` s stimulus at ``fps``.

    The take is time-warped so its bounce falls on the beats, then a loop of whole bars
    (4 beats) that divides the stimulus (when it holds whole bars) is cut on a beat, its seam
    blended over one beat. Meta: ``bpm``, ``tempo_ratio``, ``beats`` (beats in the loop),
    ``beat_frames``, ``loop_source``, ``loop_score`` (m^2).
    """
    take = load_mocap(name)
    if take.loop or "bounce_period" not in take.meta:
        raise InvalidInputError(f"dance_loop: {name!r} is not a dance take")
    bpb = take.meta.get("bounce_beats") or beats_per_bounce(take.meta["bounce_period"], bpm)
    natural = 60.0 / take.meta["bounce_period"] * bpb
    ratio = bpm / natural
    if not 1.0 / MAX_TEMPO_RATIO <= ratio <= MAX_TEMPO_RATIO:
        raise InvalidInputError(
            f"dance_loop: take {name!r} dances at {natural:.0f} bpm; {bpm:g} bpm would change its "
            f"speed by {ratio:.2f}x (limit {MAX_TEMPO_RATIO}x)"
        )
    t = np.arange(take.n_frames) / take.fps
    beat_period = take.meta["bounce_period"] / bpb
    beats = t / beat_period + beat_offset(np.asarray(take.meta["bounce_lows"]), beat_period)
    warped = warp_to_tempo(take, beats, bpm, fps)
    # the loop is cut below; pass 2 re-centres the beat grid on the low points inside it
    beat_frames = fps * 60.0 / bpm
    if abs(beat_frames - round(beat_frames)) > 1e-6:
        raise InvalidInputError(
            f"dance_loop: a beat at {bpm:g} bpm is {beat_frames:.3f} frames at {fps:g} fps; "
            "choose a tempo whose beat is a whole number of frames"
        )
    bf = int(round(beat_frames))
    for blend, window in ((bf, max(2, bf // 2)), (max(2, bf // 2), max(2, bf // 4))):  # short takes: less
        lengths = _loop_lengths(duration * bpm / 240.0, 4 * bf, warped.n_frames - blend - 2 * window - 1)
        if lengths:
            break
    else:
        raise InvalidInputError(
            f"dance_loop: take {name!r} ({warped.duration:.1f} s at {bpm:g} bpm) is shorter than "
            "one bar plus its seam blend"
        )
    # matched on positions relative to the dancer's spot (not in place): planted feet must match too
    choice = find_loop(
        warped.joint_positions(),
        lengths,
        window=window,
        min_start=blend,
        start_step=bf,
        tolerance=1.5,
        accept=LOOP_ACCEPT,
    )
    lows = low_points(warped.root_translation[:, 2], fps)
    lows = lows[(lows >= choice.start / fps) & (lows < (choice.start + choice.length) / fps)]
    if lows.size:
        shift = beat_offset(lows, 60.0 / bpm)  # beats that put these lows on the beat
        warped = warp_to_tempo(take, beats + shift, bpm, fps)
        if warped.n_frames < choice.start + choice.length:
            warped = warp_to_tempo(take, beats + shift - 1.0, bpm, fps)
    return lock_loop_feet(
        make_loop(
            warped,
            choice.start,
            choice.length,
            blend,
            meta={
                "beats": choice.length // bf,
                "beat_frames": bf,
                "loop_score": choice.score,
                "tempo_ratio": float(ratio),
                "bpm": float(bpm),
            },
        )
    )


@functools.cache
def idle_loop(name: str, fps: float, n_frames: int) -> MotionClip:
    """A loop of the idle take ``name`` at its own speed whose length divides ``n_frames``
    (the longest that fits and matches well), seam blended over 0.5 s."""
    take = load_mocap(name).resample(fps)
    blend = int(round(0.5 * fps))
    window = int(round(0.15 * fps))
    room = take.n_frames - blend - 2 * window - 1
    lengths = [
        n_frames // k
        for k in range(1, n_frames + 1)
        if n_frames % k == 0 and n_frames // k <= room and n_frames // k >= fps
    ]
    if not lengths:
        raise InvalidInputError(f"idle_loop: take {name!r} is too short to loop over {n_frames} frames")
    choice = find_loop(take.joint_positions(), lengths, window=window, min_start=blend, tolerance=1.5)
    return lock_loop_feet(make_loop(take, choice.start, choice.length, blend, meta={"loop_score": choice.score}))

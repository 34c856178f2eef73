"""What the motion library gives a crowd, measured: loops, beat, hands, feet, walks.

:func:`motion_report` returns one dict of tables (lists of rows) for a study design
(``crowdstudy motion report`` prints them):

* ``dances``: per motion-captured dance, the bounce period found, the tempo change to the
  design's tempo, the loop (beats, start) and its seam (largest joint step at the seam
  over the largest inside the loop, 1 = as smooth as any other frame step);
* ``beat``: the concert cell's crowd (``level``) danced three ways (procedural clips,
  motion capture at each take's own tempo, motion capture on the design's tempo) and the
  beat phase of their bounce (:func:`~crowdstudy.motion.beat.bounce_phase`);
* ``hands``: per dance, the deepest overlap of a hand with its own torso or head beyond the
  slack, before and after :func:`~crowdstudy.motion.selfcontact.clear_hands`, on 6 bodies;
* ``feet``: foot skate per contact of the concert and corridor Baselines;
* ``walks``: per walking loop, speed, cadence, stride and the skate of its planted feet.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from crowdstudy.body import load_body, sample_bodies
from crowdstudy.motion.baseline import animate_stationary, animate_walking, build_baseline
from crowdstudy.motion.beat import bounce_phase, circular_spread
from crowdstudy.motion.clip import seam_discontinuity
from crowdstudy.motion.diagnostics import foot_skate
from crowdstudy.motion.library import list_clips, load_clip, walk_clips
from crowdstudy.motion.mocap_library import dance_loop
from crowdstudy.motion.selfcontact import clear_hands, hand_penetration, self_penetration
from crowdstudy.scene import Crowd

__all__ = ["motion_report"]


def _dances(tempo: float, fps: float, duration: float) -> list[dict]:
    rows = []
    for name in list_clips("dance"):
        take = load_clip(name)
        loop = dance_loop(name, tempo, fps, duration)
        seam = seam_discontinuity(loop)
        rows.append(
            {
                "dance": name,
                "default": name in list_clips("dance", default_only=True),
                "bounce_period_s": round(take.meta["bounce_period"], 3),
                "bounce": take.meta["bounce_method"],
                "tempo_ratio": round(loop.meta["tempo_ratio"], 3),
                "loop_beats": loop.meta["beats"],
                "loop_s": round(loop.duration, 2),
                "seam_ratio": round(seam["step_seam"] / seam["step_max"], 2),
                "step_scale": round(take.meta.get("step_scale", 1.0), 2),
            }
        )
    return rows


def _beat(design, level: str, tempo: float) -> list[dict]:
    from crowdstudy.layout import concert_layout

    st = design.stage("stationary")
    seed = design.cell_seed(st, level)
    crowd = concert_layout(design, level, seed)
    rows = []
    runs: list[tuple[str, dict[str, Any]]] = [
        ("procedural clips", {"clip_names": list_clips("dance", "procedural")}),
        ("motion capture, own tempo", {"tempo": None}),
        (f"motion capture on {tempo:g} bpm", {"tempo": tempo}),
    ]
    for label, kwargs in runs:
        anim = animate_stationary(
            crowd, duration=design.duration, fps=design.fps, seed=seed, clear_self_contact=False, **kwargs
        )
        r = bounce_phase(anim.root_translation[:, :, 2], anim.fps, tempo)
        keep = r["consistency"] > 0.3
        spread = circular_spread(r["phase"][keep]) if keep.any() else {"circular_sd": float("nan")}
        rows.append(
            {
                "motion": label,
                "resultant": round(r["resultant"], 3),
                "circular_sd": round(r["circular_sd"], 3),
                "consistent": f"{int(keep.sum())}/{keep.size}",
                "phase_spread": round(spread["circular_sd"], 3),
            }
        )
    return rows


def _hands(fps: float) -> list[dict]:
    bodies = [load_body(b) for b in sample_bodies(6, 0)]
    rows = []
    for name in list_clips("dance") + list_clips("idle"):
        take = load_clip(name).resample(fps)
        rot = np.repeat(take.joint_rotations[:, None], len(bodies), axis=1)
        root = np.repeat(take.root_translation[:, None], len(bodies), axis=1)
        fixed = clear_hands(rot, root, bodies, take.fps)
        before = max(float(hand_penetration(b, rot[:, i], root[:, i]).max()) for i, b in enumerate(bodies))
        after = max(float(hand_penetration(b, fixed[:, i], root[:, i]).max()) for i, b in enumerate(bodies))
        worst = [self_penetration(b, fixed[:, i], root[:, i]) for i, b in enumerate(bodies)]
        w = max(worst, key=lambda r: r["p95_depth"])
        rows.append(
            {
                "clip": name,
                "default": name in list_clips("dance", default_only=True),
                "hands_before_cm": round(100 * before, 1),
                "hands_after_cm": round(100 * after, 1),
                "any_pair_p95_cm": round(100 * w["p95_depth"], 1),
                "pair": "-".join(w["worst_pair"]),
            }
        )
    return rows


def _skate(values: np.ndarray) -> dict:
    return {
        "contacts": int(values.size),
        "p50_cm": round(100 * float(np.percentile(values, 50)), 2),
        "p95_cm": round(100 * float(np.percentile(values, 95)), 2),
        "max_cm": round(100 * float(values.max()), 2),
    }


def motion_report(design, *, level: str = "D5", with_hands: bool = True) -> dict:
    """The tables described in the module docstring for ``design`` (its concert tempo,
    video duration and frame rate) and the density ``level``."""
    tempo = float(design.scenario_of("concert").params.get("tempo", 120.0))
    out = {
        "tempo": tempo,
        "level": level,
        "dances": _dances(tempo, float(design.fps), float(design.duration)),
        "beat": _beat(design, level, tempo),
    }
    if with_hands:
        out["hands"] = _hands(float(design.fps))
    feet = []
    for stage in ("stationary", "walking"):
        anim = build_baseline(design, stage, level)
        feet.append({"cell": f"{stage} {level}", **_skate(foot_skate(anim))})
    out["feet"] = feet
    walks = []
    for clip in walk_clips():
        n = 3 * clip.n_frames
        t = np.arange(n) / clip.fps
        pos = np.stack([np.zeros(n), clip.walk_speed * t], axis=-1)[:, None]
        crowd = Crowd(positions=pos, radius=np.full(1, 0.2), fps=clip.fps, meta={"scenario": "corridor"})
        anim = animate_walking(crowd, seed=0, walks=[clip, *[c for c in walk_clips() if c is not clip][:1]])
        walks.append(
            {
                "walk": clip.name,
                "speed_m_s": round(clip.walk_speed, 2),
                "cadence": round(clip.meta["cadence"], 1),
                "stride_m": round(clip.meta["stride_length"], 2),
                **_skate(foot_skate(anim)),
            }
        )
    out["walks"] = walks
    return out

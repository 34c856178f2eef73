"""The live walker of the paper's Fig. 6: a motion-captured walk carried straight through
the dancing concert crowd.

:func:`live_scene` builds its Baseline: the study's concert cell (default D5: 60 dancers on
the 3 m x 3 m floor, the design's cell seed) with one more character, a CMU walk
(:mod:`crowdstudy.motion.mocap_walks`; the in-place loop repeated and carried along a
straight line at the clip's own speed, scaled by the body's leg length) that enters the
floor from its side and leaves it on the other side. :func:`crowdstudy.physics.live.run_live`
corrects it one frame at a time.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdstudy.body.rotations import quat_about_z, quat_multiply, quaternion_to_axis_angle
from crowdstudy.errors import InvalidInputError

__all__ = ["WalkerPath", "walker_motion", "live_scene", "walker_index"]


@dataclasses.dataclass(frozen=True)
class WalkerPath:
    """Where and how the live walker walks.

    Attributes:
        clip: a walking clip of the library (``crowdstudy motion list``; a CMU walk).
        start: (x, y) m, where the walker's pelvis starts (outside the floor).
        heading: rad about +z, the direction of travel (0: along +x).
        distance: m walked (the animation lasts ``distance / speed``).
        body_seed: seed of the walker's body draw (:func:`~crowdstudy.body.sample_bodies`).
    """

    clip: str = "gait_neutral"
    start: tuple[float, float] = (-2.4, -0.3)
    heading: float = 0.0
    distance: float = 4.8
    body_seed: int = 6

    def __post_init__(self) -> None:
        if not (np.isfinite(self.distance) and self.distance > 0):
            raise InvalidInputError(f"WalkerPath.distance: expected a positive length in m, got {self.distance!r}")
        if len(self.start) != 2 or not np.all(np.isfinite(self.start)):
            raise InvalidInputError(f"WalkerPath.start: expected two finite numbers (x, y) in m, got {self.start!r}")
        if not np.isfinite(self.heading):
            raise InvalidInputError(f"WalkerPath.heading: expected a finite angle in rad, got {self.heading!r}")


def walker_motion(path: WalkerPath, body: dict, fps: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The walker's Baseline: ``(joint_rotations (T, 24, 3) rad, root_translation (T, 3) m,
    speed m/s)``. The clip's in-place loop is sampled at ``t = f / fps``, its root offsets
    and its travel (``clip.speed * t`` along the clip's +y) scaled by the body's leg scale
    (geometric similarity, as :func:`~crowdstudy.motion.baseline.animate_walking` does), then
    turned so that +y points along ``path.heading`` and moved to ``path.start``."""
    from crowdstudy.motion.baseline import body_scales
    from crowdstudy.motion.library import load_clip

    clip = load_clip(path.clip)
    if clip.kind != "walk" or not clip.speed:
        raise InvalidInputError(f"WalkerPath.clip: {path.clip!r} is not a walking clip (crowdstudy motion list)")
    scale = float(body_scales([body])[0])
    speed = clip.speed * scale
    n = max(2, int(round(path.distance / speed * fps)) + 1)
    t = np.arange(n) / fps
    quat, root_local = clip.sample_quaternions(t)
    local = (root_local + clip.travel(t)) * scale
    yaw = path.heading - np.pi / 2  # the clip walks along +y
    quat = quat.copy()
    quat[:, 0] = quat_multiply(np.broadcast_to(quat_about_z(np.array(yaw)), quat[:, 0].shape), quat[:, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    root = np.empty_like(local)
    root[:, 0] = path.start[0] + c * local[:, 0] - s * local[:, 1]
    root[:, 1] = path.start[1] + s * local[:, 0] + c * local[:, 1]
    root[:, 2] = local[:, 2]
    return quaternion_to_axis_angle(quat), root, speed


def live_scene(design=None, level: str = "D5", path: WalkerPath | None = None, *, fps: float | None = None):
    """The Baseline of the live case: the concert cell ``level`` of ``design`` (default the
    paper's) with the walker of ``path`` appended as its last character.

    Returns:
        :class:`~crowdstudy.scene.CrowdAnimation` of N + 1 characters over the walk's T
        frames; meta as the cell's, ``loop`` ``{"mode": "none"}`` and ``live_walker``
        ``{"index", "clip", "start", "heading", "distance", "speed"}`` (m, rad, m/s).
    """
    from crowdstudy.body import sample_bodies
    from crowdstudy.design import StudyDesign, load_design
    from crowdstudy.motion.baseline import build_baseline

    path = WalkerPath() if path is None else path
    if not isinstance(path, WalkerPath):
        raise InvalidInputError(f"path: expected a WalkerPath, got {type(path).__name__}")
    design = design if isinstance(design, StudyDesign) else load_design(design)
    fps = float(design.fps if fps is None else fps)
    body = sample_bodies(1, path.body_seed, shapes=design.body_shapes)[0]
    rot_w, root_w, speed = walker_motion(path, body, fps)
    n = len(root_w)
    crowd = build_baseline(design, "stationary", level, duration=n / fps, fps=fps)
    if crowd.n_frames < n:
        raise InvalidInputError(f"level {level!r}: the concert gave {crowd.n_frames} frames, the walk needs {n}")
    rot = np.concatenate([crowd.joint_rotations[:n], rot_w[:, None]], axis=1)
    root = np.concatenate([crowd.root_translation[:n], root_w[:, None]], axis=1)
    walker = {
        "index": crowd.n_characters,
        "clip": path.clip,
        "start": [float(v) for v in path.start],
        "heading": float(path.heading),
        "distance": float(path.distance),
        "speed": float(speed),
    }
    clip_rec = {"kind": "walk", "clips": [path.clip], "weights": [1.0], "phase": 0.0, "live_walker": True}
    return crowd.replace(
        root_translation=root,
        joint_rotations=rot,
        bodies=crowd.bodies + (body,),
        clips=crowd.clips + (clip_rec,),
        meta={"loop": {"mode": "none"}, "live_walker": walker, "n_characters": crowd.n_characters + 1},
    )


def walker_index(anim) -> int:
    """The live walker's character index (``meta["live_walker"]["index"]``)."""
    walker = anim.meta.get("live_walker")
    if not isinstance(walker, dict) or "index" not in walker:
        raise InvalidInputError("anim.meta.live_walker: not a live scene (crowdstudy.physics.live.live_scene)")
    return int(walker["index"])

"""Contact sheets: a row per character, 8 frames over 2 s, a camera that follows it.

The way to look at motion (docs/concepts/methods.md, "What a stimulus must be"): :func:`animation_sheet`
renders chosen characters of a crowd animation (Baseline beside Ours: call it on both with
the same characters and frames), :func:`clip_sheet` renders shipped clips on a row of
bodies (``crowdstudy sheet --clips twist,macarena``). The camera stands ``distance`` m in
front of (or beside, ``side=True``) the character's pelvis at each frame and looks at it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crowdstudy.body import sample_bodies
from crowdstudy.body.skeleton import JOINT_NAMES, PARENTS
from crowdstudy.errors import InvalidInputError
from crowdstudy.motion.clip import MotionClip
from crowdstudy.render.camera import Camera
from crowdstudy.render.renderer import CrowdRenderer
from crowdstudy.scene import CrowdAnimation

__all__ = ["animation_sheet", "clip_sheet", "clips_animation"]


def clips_animation(
    clips: list[MotionClip],
    *,
    start: float = 0.0,
    span: float = 2.0,
    fps: float = 30.0,
    spacing: float = 1.3,
    seed: int = 3,
) -> CrowdAnimation:
    """The clips side by side (``spacing`` m apart along x, facing +y, walks in place), ``span``
    s from ``start``."""
    n = len(clips)
    if n == 0:
        raise InvalidInputError("clips: expected at least one clip")
    t = start + np.arange(int(round(span * fps)) + 1) / fps
    rot = np.zeros((len(t), n, len(JOINT_NAMES), 3))
    root = np.zeros((len(t), n, 3))
    for i, clip in enumerate(clips):
        rot[:, i], root[:, i] = clip.sample(t)  # walks in place: the camera follows anyway
        root[:, i, 0] += i * spacing
    return CrowdAnimation(
        joint_names=JOINT_NAMES,
        parents=PARENTS,
        root_translation=root,
        joint_rotations=rot,
        fps=fps,
        bodies=tuple(sample_bodies(n, seed)),
        clips=tuple({"kind": c.kind, "clips": [c.name]} for c in clips),
        meta={"scenario": "concert", "method": "Baseline"},
    )


def _sheet_image(
    anim: CrowdAnimation,
    characters,
    *,
    start: float,
    span: float,
    frames: int,
    side: bool,
    distance: float,
    elevation: float | None,
    width: int,
    height: int,
    design,
    reference: CrowdAnimation | None,
):
    """The contact sheet of :func:`animation_sheet` as a PIL image."""
    from PIL import Image

    chars = [int(c) for c in characters]
    bad = [c for c in chars if not 0 <= c < anim.n_characters]
    if not chars or bad:
        raise InvalidInputError(f"characters: expected indices in [0, {anim.n_characters}), got {list(characters)}")
    first, last = int(round(start * anim.fps)), int(round((start + span) * anim.fps))
    if first < 0 or last >= anim.n_frames:
        raise InvalidInputError(
            f"start/span: {start:g} + {span:g} s is outside the animation's {anim.n_frames / anim.fps:.2f} s"
        )
    picks = np.linspace(first, last, frames).round().astype(int)
    if elevation is None:
        elevation = 0.25 if anim.n_characters == 1 else 1.4
    offset = np.array([distance, 0.0, elevation]) if side else np.array([0.0, distance, elevation])
    if reference is not None and (reference.n_characters != anim.n_characters or reference.n_frames < anim.n_frames):
        raise InvalidInputError(
            f"reference: expected an animation of the same {anim.n_characters} characters and "
            f"at least {anim.n_frames} frames, got {reference.n_characters} and "
            f"{reference.n_frames}"
        )
    layers = [reference, anim] if reference is not None else [anim]
    colours = reference.root_translation[0, :, :2] if reference is not None else None
    cams = reference if reference is not None else anim
    sheet = Image.new("RGB", (width * frames, height * len(chars) * len(layers)))
    for layer, a in enumerate(layers):
        with CrowdRenderer(
            a, design=design, width=width, height=height, msaa=2, shadows=False, color_positions=colours
        ) as r:
            for row, c in enumerate(chars):
                for col, f in enumerate(picks):
                    target = cams.root_translation[f, c].copy()
                    target[2] = 0.85
                    r.set_view(Camera(eye=tuple(target + offset), target=tuple(target), fov=40.0))
                    y = (row * len(layers) + layer) * height
                    sheet.paste(Image.fromarray(r.render(int(f))), (col * width, y))
    return sheet


def animation_sheet(
    anim: CrowdAnimation,
    out: str | Path,
    characters,
    *,
    start: float = 0.0,
    span: float = 2.0,
    frames: int = 8,
    side: bool = False,
    distance: float = 3.2,
    elevation: float | None = None,
    width: int = 240,
    height: int = 320,
    design=None,
    reference: CrowdAnimation | None = None,
) -> Path:
    """A PNG contact sheet of ``characters`` (indices) of ``anim``: ``frames`` frames evenly
    over ``span`` s from ``start`` s, one row per character. ``elevation`` (m above the
    pelvis) defaults to 0.25 for one character and 1.4 in a crowd (over the heads of the
    characters in between). With ``reference`` (the Baseline of a corrected ``anim``), each
    character gets two rows, the reference above, seen from the same cameras (placed on
    the reference's pelvis) and dressed in the same colours (the reference's)."""
    out = Path(out)
    _sheet_image(
        anim,
        characters,
        start=start,
        span=span,
        frames=frames,
        side=side,
        distance=distance,
        elevation=elevation,
        width=width,
        height=height,
        design=design,
        reference=reference,
    ).save(out)
    return out


def clip_sheet(
    clips: list[MotionClip],
    out: str | Path,
    *,
    start: float = 0.0,
    span: float = 2.0,
    side: bool = False,
    frames: int = 8,
    distance: float = 3.2,
    elevation: float | None = None,
    width: int = 240,
    height: int = 320,
    design=None,
) -> Path:
    """A contact sheet of shipped clips, one row per clip, each rendered alone (no other clip
    in the way of a side view)."""
    from PIL import Image

    if not clips:
        raise InvalidInputError("clips: expected at least one clip")
    rows = [
        _sheet_image(
            clips_animation([clip], start=start, span=span, seed=3 + k),
            [0],
            start=0.0,
            span=span,
            frames=frames,
            side=side,
            distance=distance,
            elevation=elevation,
            width=width,
            height=height,
            design=design,
            reference=None,
        )
        for k, clip in enumerate(clips)
    ]
    sheet = Image.new("RGB", (rows[0].width, sum(r.height for r in rows)))
    for k, row in enumerate(rows):
        sheet.paste(row, (0, k * row.height))
    out = Path(out)
    sheet.save(out)
    return out

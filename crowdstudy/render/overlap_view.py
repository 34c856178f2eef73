"""Overlap view (paper Fig. 5): interpenetrating body parts painted red.

Definition. A surface point of character A is *overlapping* when it lies inside another
character B, B's body being represented by its capsules (``Body.capsules``, posed with the
same skinning matrices as the mesh; a point counts when it is deeper than ``tolerance``
inside a capsule). With opaque, closed bodies the nearest visible surface is never inside
another body, so the overlapping surfaces are made visible by an x-ray rule:

1. id pass: the index (and periodic copy) of the character visible at each pixel;
2. overlap pass, without depth test: every fragment of every character is tested against
   the candidate capsules of the other characters (pre-culled on the CPU by bounding
   boxes); a fragment of A inside B marks its pixel when the pixel's visible surface
   belongs to A itself or to B. The overlap is therefore seen *through the two bodies
   that cause it*, but never through a third character or the floor.

The red fraction of a frame is (marked pixels) / (all pixels); ``crowd_fraction`` divides
by the pixels covered by characters instead.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.errors import InvalidInputError

if TYPE_CHECKING:
    from crowdstudy.render.passes import CharacterPass

__all__ = ["OverlapFrame", "OverlapPass", "overlap_frame", "capsules_from_skinning", "RED"]

RED = np.array([225, 25, 30], dtype=np.float32)
_MAX_CANDIDATES = 160
_MAX_OWNERS = 48  # owners of a character's candidates with a box each (more: scan them all)


@dataclasses.dataclass
class OverlapFrame:
    """One overlap-view frame.

    Attributes:
        image: (H, W, 3) uint8, the render, desaturated, with overlapping pixels in red
            (None when only the mask was asked for).
        mask: (H, W) bool, the overlapping pixels.
        red_fraction: mask pixels / all pixels.
        crowd_fraction: mask pixels / pixels covered by characters (0 when none).
    """

    image: np.ndarray | None
    mask: np.ndarray
    red_fraction: float
    crowd_fraction: float


def capsules_from_skinning(bodies: list, skinning: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World capsules of every character.

    Args:
        bodies: N bodies with ``capsules`` (start (24, 3), end (24, 3), radius (24,)) in
            the rest frame.
        skinning: (N, 24, 3, 4) skinning matrices of one frame.
    Returns:
        ``(start (N, 24, 3), end (N, 24, 3), radius (N, 24))`` float64, metres.
    """
    n = len(bodies)
    start, end, radius = np.zeros((n, 24, 3)), np.zeros((n, 24, 3)), np.zeros((n, 24))
    for i, body in enumerate(bodies):
        caps = getattr(body, "capsules", None)
        if caps is None:
            raise InvalidInputError(f"bodies[{i}]: no 'capsules' for the overlap view")
        m = np.asarray(skinning[i], dtype=np.float64)
        start[i] = np.einsum("jab,jb->ja", m[:, :, :3], np.asarray(caps.start)) + m[:, :, 3]
        end[i] = np.einsum("jab,jb->ja", m[:, :, :3], np.asarray(caps.end)) + m[:, :, 3]
        radius[i] = np.asarray(caps.radius)
    return start, end, radius


def _capsule_boxes(start, end, radius) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)``, each (N, 24, 3): the axis-aligned box around every capsule (its
    segment widened by its radius). A point outside a capsule's box is not inside it."""
    return np.minimum(start, end) - radius[..., None], np.maximum(start, end) + radius[..., None]


def _candidates(start, end, boxes: tuple[np.ndarray, np.ndarray], period: float | None) -> np.ndarray:
    """(N, K + 1) float32: count, then flat capsule ids (owner * 24 + bone) near each
    character, in increasing order; ``boxes`` are the capsules' (:func:`_capsule_boxes`)."""
    n = start.shape[0]
    lo, hi = boxes
    body_lo, body_hi = lo.min(axis=1), hi.max(axis=1)  # (N, 3)
    out = np.zeros((n, _MAX_CANDIDATES + 1), np.float32)
    centre = 0.5 * (body_lo + body_hi)
    for a in range(n):
        shift = np.zeros((n, 1, 3))
        if period:
            dx = centre[:, 0] - centre[a, 0]
            shift[:, 0, 0] = -period * np.round(dx / period)
        hit = np.all((lo + shift <= body_hi[a]) & (hi + shift >= body_lo[a]), axis=2)  # (N, 24)
        hit[a] = False
        owners, bones = np.nonzero(hit)
        if len(owners) > _MAX_CANDIDATES:
            mid = 0.5 * (start + end)[owners, bones] + shift[owners, 0]
            keep = np.argsort(np.linalg.norm(mid - centre[a], axis=1))[:_MAX_CANDIDATES]
            owners, bones = owners[keep], bones[keep]
        out[a, 0] = len(owners)
        out[a, 1 : 1 + len(owners)] = np.sort(owners * 24 + bones)  # sorted: overlap.frag bisects by owner
    return out


def _owner_boxes(boxes: tuple[np.ndarray, np.ndarray], candidates: np.ndarray) -> np.ndarray:
    """(N, 2 * _MAX_OWNERS + 1, 4) float32: per character, its candidates grouped by owner
    (they are sorted by id, so each owner's are contiguous): texel 0 holds the number of
    owners (-1: too many, scan the list), then per owner ``(lo.xyz, first)`` and
    ``(hi.xyz, last)``: the box around that owner's candidate capsules (each widened by its
    radius) and the owner's range ``[first, last)`` in the candidate list. A point outside
    the box is inside none of them, so ``overlap.frag`` skips the owner's capsules: the
    same mask for a fraction of the capsule tests. ``boxes``: :func:`_capsule_boxes`."""
    lo, hi = boxes
    n = lo.shape[0]
    out = np.zeros((n, 2 * _MAX_OWNERS + 1, 4), np.float32)
    for a in range(n):
        count = int(candidates[a, 0])
        if count == 0:
            continue  # no owners
        ids = candidates[a, 1 : 1 + count].astype(np.int64)
        owners, first = np.unique(ids // 24, return_index=True)
        if len(owners) > _MAX_OWNERS:
            out[a, 0, 0] = -1.0
            continue
        last = np.append(first[1:], count)
        out[a, 0, 0] = len(owners)
        for k, (o, f, e) in enumerate(zip(owners, first, last, strict=True)):
            bones = ids[f:e] - o * 24
            out[a, 1 + 2 * k, :3], out[a, 1 + 2 * k, 3] = lo[o, bones].min(axis=0), f
            out[a, 2 + 2 * k, :3], out[a, 2 + 2 * k, 3] = hi[o, bones].max(axis=0), e
    return out


class OverlapPass:
    """The id and overlap passes of the overlap view, drawn with a renderer's
    :class:`~crowdstudy.render.passes.CharacterPass` (its instances as the camera's
    colour pass left them) into their own ``width`` x ``height`` targets."""

    def __init__(self, ctx, characters: CharacterPass, width: int, height: int, n_characters: int):
        import moderngl

        self.ctx, self.characters, self.width, self.height = ctx, characters, width, height
        size = (width, height)
        self.tex_ids = ctx.texture(size, 2, dtype="f4")
        self.depth_ids = ctx.depth_renderbuffer(size)
        self.fbo_ids = ctx.framebuffer(color_attachments=[self.tex_ids], depth_attachment=self.depth_ids)
        self.tex_mask = ctx.texture(size, 1, dtype="f1")
        self.fbo_mask = ctx.framebuffer(color_attachments=[self.tex_mask])
        self.tex_caps = ctx.texture((48, n_characters), 4, dtype="f4")
        self.tex_cand = ctx.texture((_MAX_CANDIDATES + 1, n_characters), 1, dtype="f4")
        self.tex_owners = ctx.texture((2 * _MAX_OWNERS + 1, n_characters), 4, dtype="f4")
        self.tex_bodies = ctx.texture((2, n_characters), 4, dtype="f4")
        for tex in (self.tex_ids, self.tex_mask, self.tex_caps, self.tex_cand, self.tex_owners, self.tex_bodies):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        prog = characters.programs.overlap
        # moderngl's stub types prog[name] as any member (attribute, varying, block): these are uniforms
        for name, unit in (
            ("u_ids", 4),
            ("u_capsules", 5),
            ("u_candidates", 6),
            ("u_owners", 7),
            ("u_bodies", 8),
        ):
            if name in prog:  # the boxes are compiled out of the OVERLAP_SCAN_ALL variant
                prog[name].value = unit  # pyright: ignore[reportAttributeAccessIssue]
        prog["u_period"].value = float(characters.period or 0.0)  # pyright: ignore[reportAttributeAccessIssue]

    def run(
        self, vp: np.ndarray, capsules: tuple[np.ndarray, np.ndarray, np.ndarray], *, tolerance: float = 0.005
    ) -> tuple[np.ndarray, int]:
        """The overlapping pixels seen through ``vp`` (world-to-clip) of the world
        ``capsules`` (start, end, radius; :func:`capsules_from_skinning`), fragments deeper
        than ``tolerance`` m inside another character counting: ``(mask, crowd_pixels)``,
        the (H, W) bool mask (first row at the top) and how many pixels show a character."""
        import moderngl

        start, end, radius = capsules
        caps = np.zeros((start.shape[0], 24, 2, 4), np.float32)
        caps[:, :, 0, :3], caps[:, :, 0, 3] = start, radius
        caps[:, :, 1, :3], caps[:, :, 1, 3] = end, np.arange(start.shape[0])[:, None]
        self.tex_caps.write(caps.tobytes())
        boxes = _capsule_boxes(start, end, radius)
        candidates = _candidates(start, end, boxes, self.characters.period)
        self.tex_cand.write(candidates.tobytes())
        self.tex_owners.write(_owner_boxes(boxes, candidates).tobytes())
        bodies = np.stack([boxes[0].min(axis=1), boxes[1].max(axis=1)], axis=1)  # (N, 2, 3): each character's box
        self.tex_bodies.write(
            np.concatenate([bodies, np.zeros((len(bodies), 2, 1))], axis=2).astype(np.float32).tobytes()
        )
        ctx, view = self.ctx, (0, 0, self.width, self.height)
        ctx.viewport = view
        # pass 1: visible character ids
        self.fbo_ids.use()
        ctx.viewport = view
        self.fbo_ids.clear(-1.0, -1.0, 0.0, 0.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        self.characters.draw(self.characters.programs.id, vp)
        # pass 2: overlapping fragments, no depth test
        self.fbo_mask.use()
        ctx.viewport = view
        self.fbo_mask.clear(0.0, 0.0, 0.0, 0.0)
        ctx.disable(moderngl.DEPTH_TEST)
        self.tex_ids.use(4)
        self.tex_caps.use(5)
        self.tex_cand.use(6)
        self.tex_owners.use(7)
        self.tex_bodies.use(8)
        self.characters.programs.overlap["u_tolerance"].value = float(tolerance)  # pyright: ignore[reportAttributeAccessIssue]
        self.characters.draw(self.characters.programs.overlap, vp)
        ctx.enable(moderngl.DEPTH_TEST)
        mask = np.frombuffer(self.fbo_mask.read(components=1, alignment=1), np.uint8)
        mask = mask.reshape(self.height, self.width)[::-1] > 127
        ids = np.frombuffer(self.fbo_ids.read(components=1, dtype="f4", alignment=1), np.float32)
        return mask, int(np.count_nonzero(ids > -0.5))

    def release(self) -> None:
        for o in (
            self.fbo_ids,
            self.depth_ids,
            self.tex_ids,
            self.fbo_mask,
            self.tex_mask,
            self.tex_caps,
            self.tex_cand,
            self.tex_owners,
            self.tex_bodies,
        ):
            o.release()


def overlap_frame(picture: np.ndarray | None, mask: np.ndarray, crowd_pixels: int) -> OverlapFrame:
    """The overlap view's frame from the normal ``picture`` ((H, W, 3) uint8, or None for
    the mask alone), the ``mask`` of overlapping pixels and the pixels showing a character:
    the picture desaturated (so no red shirt can be taken for an overlap) with the masked
    pixels painted red."""
    n_red = int(np.count_nonzero(mask))
    out = None
    if picture is not None:
        picture = picture.astype(np.float32)
        luma = picture @ np.array([0.299, 0.587, 0.114], np.float32)
        picture = 0.3 * picture + 0.7 * (0.85 * luma[..., None] + 30.0)
        picture[mask] = 0.15 * picture[mask] + 0.85 * RED
        out = np.clip(picture, 0, 255).astype(np.uint8)
    return OverlapFrame(
        image=out,
        mask=mask,
        red_fraction=n_red / mask.size,
        crowd_fraction=n_red / crowd_pixels if crowd_pixels else 0.0,
    )

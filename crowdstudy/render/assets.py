"""CPU-side assets of a crowd render: plain numpy, no OpenGL context needed.

* :class:`RenderOptions`: the renderer's options, validated (image size, anti-aliasing,
  shadows, level of detail, static layers).
* :class:`CrowdAssets`: the animation and what it is drawn with: its loaded bodies, their
  clothing colours and looks (:mod:`crowdstudy.render.palette`,
  :mod:`crowdstudy.render.appearance`), the environment (:mod:`crowdstudy.render.scene`),
  the periodic wrap of a corridor, and the skinning matrices of each frame
  (:class:`FrameBones`).
* :class:`CharacterMeshes`: the surfaces actually drawn (dressed with cloth, shoes and
  hair volume from 540 px tall images) and their levels of detail (:func:`lod_levels`,
  :data:`LOD_PIXELS`: the one place that decides which mesh a character gets).
* :class:`Lighting`: the key light (direction, the shadow map's orthographic projection)
  and the lights' colours; :func:`shadow_receivers`, the part of the ground a character's
  shadow can reach; :class:`EnvironmentParts`, the environment's triangles split by how
  they are drawn.

:mod:`crowdstudy.render.gpu` makes the GPU resources from these and
:mod:`crowdstudy.render.passes` draws them. One GPU step feeds back into the CPU side: the
albedo textures are painted on the GPU (:func:`crowdstudy.render.gpu.paint_albedo`), and
what each vertex of a textured body shows (skin, cloth, hair: the *surface codes*) is read
from the painted texture; the dressing follows those codes (:meth:`CharacterMeshes.build`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.body.loading import body_key
from crowdstudy.errors import InvalidInputError
from crowdstudy.render.appearance import assign_appearance
from crowdstudy.render.bodies import SURFACE_FACE_SCALE, BodyGroup, default_body_loader, group_bodies
from crowdstudy.render.camera import look_at
from crowdstudy.render.garments import dress_body
from crowdstudy.render.hair import add_hair, crown_uv
from crowdstudy.render.palette import assign_colors
from crowdstudy.render.scene import Environment, build_environment, split_floor

if TYPE_CHECKING:
    from crowdstudy.scene import CrowdAnimation

__all__ = [
    "RenderOptions",
    "CrowdAssets",
    "FrameBones",
    "CharacterMeshes",
    "LodLevel",
    "Lighting",
    "EnvironmentParts",
    "lod_levels",
    "shadow_receivers",
    "scenario_of",
    "wrap_offsets",
    "wrapped_roots",
    "N_BONES",
    "COPIES",
    "BOUND_RADIUS",
    "LOD_PIXELS",
    "DRESS_MIN_HEIGHT",
    "POST_AA",
]

N_BONES = 24
#: the post-process anti-aliasing filters (:class:`~crowdstudy.render.gpu.ColorTargets`)
POST_AA = ("none", "fxaa")
#: periodic copies drawn of a corridor's crowd: at k * L along x, k in COPIES
COPIES = (-2, -1, 0, 1, 2)
#: m, bounding sphere of a character around its pelvis (arms raised)
BOUND_RADIUS = 1.3
#: on-screen height (px) below which the next coarser mesh is used
LOD_PIXELS = (600.0, 300.0)
#: image height (px) from which the characters' surfaces are dressed (cloth, shoes, hair
#: volume); below it the dressing would move the surface by less than a pixel
DRESS_MIN_HEIGHT = 540
_CHUNK = 32  # frames of skinning matrices computed at once


@dataclasses.dataclass(frozen=True)
class RenderOptions:
    """The renderer's options, validated (see :class:`~crowdstudy.render.renderer.CrowdRenderer`).

    Attributes:
        width, height: image size in pixels, each in [16, 8192].
        msaa: samples per pixel asked for (0 or 1 = off; the driver may allow fewer).
        shadows: draw the key light's shadow map.
        shadow_size: shadow map resolution (pixels per side).
        max_faces: faces per body template (None = full meshes), "auto" resolved from the
            height: 3000 at 1080p, scaled down to 600 for small previews.
        static_layer: draw what the characters do not change once per view.
        post_aa: "none" or "fxaa": a post-process anti-aliasing pass on the finished frame
            (cheaper than MSAA on a CPU rasteriser; see ``fxaa.frag``).
        detail_height: the image height (px) that chooses the characters' detail (texture
            size, mesh faces, levels of detail); the image height unless set. A frame
            rendered larger with the detail of a smaller one is its supersampled reference.
        lod_scale: how many times taller than :data:`LOD_PIXELS` says a character must be on
            screen to keep each finer level of detail (1: those bounds; 0: every character
            at the finest level).
    """

    width: int
    height: int
    msaa: int
    shadows: bool
    shadow_size: int
    max_faces: int | None
    static_layer: bool
    post_aa: str = "none"
    detail_height: int = 1080
    lod_scale: float = 1.0

    @classmethod
    def validated(
        cls,
        *,
        width: int = 1920,
        height: int = 1080,
        msaa: int = 4,
        shadows: bool = True,
        shadow_size: int = 2048,
        max_faces: int | str | None = "auto",
        static_layer: bool = True,
        post_aa: str = "none",
        detail_height: int | None = None,
        lod_scale: float = 1.0,
    ) -> RenderOptions:
        """The options, or an :class:`InvalidInputError` naming the bad one."""
        for name, value in (("width", width), ("height", height)):
            if not isinstance(value, (int, np.integer)) or value < 16 or value > 8192:
                raise InvalidInputError(f"{name}: expected an integer pixel size in [16, 8192], got {value!r}")
        if not isinstance(msaa, (int, np.integer)) or msaa < 0 or msaa > 16:
            raise InvalidInputError(f"msaa: expected 0..16 samples per pixel, got {msaa!r}")
        if post_aa not in POST_AA:
            raise InvalidInputError(f"post_aa: expected one of {', '.join(POST_AA)}, got {post_aa!r}")
        if detail_height is None:
            detail_height = height
        elif not isinstance(detail_height, (int, np.integer)) or not 16 <= detail_height <= 8192:
            raise InvalidInputError(
                f"detail_height: expected an integer pixel size in [16, 8192], got {detail_height!r}"
            )
        if isinstance(lod_scale, bool) or not isinstance(lod_scale, (int, float)) or not 0 <= lod_scale <= 8:
            raise InvalidInputError(f"lod_scale: expected a number in [0, 8], got {lod_scale!r}")
        if max_faces == "auto":
            max_faces = int(np.clip(3000 * int(detail_height) / 1080, 600, 3000))
        elif max_faces is not None and (not isinstance(max_faces, (int, np.integer)) or max_faces < 100):
            raise InvalidInputError(f"max_faces: expected 'auto', None or an integer >= 100, got {max_faces!r}")
        if not isinstance(shadow_size, (int, np.integer)) or not 64 <= shadow_size <= 8192:
            raise InvalidInputError(f"shadow_size: expected an integer in [64, 8192], got {shadow_size!r}")
        return cls(
            width=int(width),
            height=int(height),
            msaa=int(msaa),
            shadows=bool(shadows),
            shadow_size=int(shadow_size),
            max_faces=max_faces,
            static_layer=bool(static_layer),
            post_aa=str(post_aa),
            detail_height=int(detail_height),
            lod_scale=float(lod_scale),
        )


def scenario_of(anim) -> str:
    """The scenario of an animation: ``meta["scenario"]``, else corridor when periodic."""
    scen = anim.meta.get("scenario")
    if scen in ("concert", "corridor", "crossing"):
        return scen
    return "corridor" if anim.periodic_length else "concert"


def wrap_offsets(x: np.ndarray, period: float | None) -> np.ndarray:
    """Multiples of the period ``period`` (m) to subtract so x falls in [-L/2, L/2); zeros
    without a period."""
    if not period:
        return np.zeros_like(x)
    return period * np.floor((x + 0.5 * period) / period)


@dataclasses.dataclass
class CrowdAssets:
    """One animation and what it is drawn with.

    Attributes:
        anim: the :class:`~crowdstudy.scene.CrowdAnimation` (T frames, N characters).
        design: the study design (environment sizes, viewpoints).
        env: the scenario's environment (floor, walls, the venue's cut-away elements).
        period: the periodic length (m) of a corridor, None for the concert.
        bodies: N loaded bodies (``crowdstudy.body.Body`` interface).
        colors: (N, 6, 3) float32 linear-RGB clothing colours (palette.REGIONS order).
        looks: N :class:`~crowdstudy.render.appearance.Appearance`.
    """

    anim: CrowdAnimation
    design: object
    env: Environment
    period: float | None
    bodies: list
    colors: np.ndarray
    looks: list

    @classmethod
    def build(
        cls, anim, design=None, *, body_loader=None, color_seed: int | None = None, color_positions=None
    ) -> CrowdAssets:
        """Load the bodies and choose the colours and looks (see ``CrowdRenderer``'s
        ``body_loader``, ``color_seed`` and ``color_positions``)."""
        if design is None:
            from crowdstudy.design import load_design

            design = load_design()
        if anim.n_joints != N_BONES:
            raise InvalidInputError(
                f"anim.joint_names: the renderer needs the {N_BONES}-joint skeleton, got {anim.n_joints}"
            )
        kind = scenario_of(anim)
        if kind == "crossing":  # the plaza and its obstacles come from the animation's meta
            from crowdstudy.render.plaza import plaza_environment

            env = plaza_environment(design, anim.meta)
        else:
            env = build_environment(kind, design)
        loader = body_loader or default_body_loader
        bodies = [loader(rec) for rec in anim.bodies]
        n = anim.n_characters
        seed = int(anim.meta.get("seed", 0) if color_seed is None else color_seed)
        if color_positions is None:
            color_positions = wrapped_roots(anim, 0)[:, :2]
        color_positions = np.asarray(color_positions, dtype=np.float64)
        if color_positions.shape != (n, 2):
            raise InvalidInputError(f"color_positions: expected shape ({n}, 2), got {color_positions.shape}")
        colors, choice = assign_colors(color_positions, seed, period=anim.periodic_length)
        looks = assign_appearance(list(anim.bodies), choice, seed)
        return cls(
            anim=anim, design=design, env=env, period=anim.periodic_length, bodies=bodies, colors=colors, looks=looks
        )

    def wrapped_roots(self, frame: int) -> np.ndarray:
        """(N, 3) pelvis positions of ``frame`` as drawn (periodic scenes wrapped into
        [-L/2, L/2) along x)."""
        return wrapped_roots(self.anim, frame)


def wrapped_roots(anim, frame: int) -> np.ndarray:
    """(N, 3) pelvis positions of ``anim`` at ``frame``, wrapped into [-L/2, L/2) along x
    when periodic."""
    root = np.array(anim.root_translation[frame])
    if anim.periodic_length:
        root[:, 0] -= wrap_offsets(root[:, 0], anim.periodic_length)
    return root


class FrameBones:
    """The skinning matrices of an animation's frames, computed on the CPU 32 frames at a
    time (a video asks for them in order)."""

    def __init__(self, anim, bodies: list):
        self.anim, self.bodies = anim, bodies
        self._start, self._chunk = -1, None

    def __call__(self, frame: int) -> np.ndarray:
        """(N, 24, 3, 4) float32 skinning matrices of ``frame`` (periodic scenes wrapped)."""
        anim = self.anim
        if not 0 <= frame < anim.n_frames:
            raise InvalidInputError(f"frame: expected 0 <= frame < {anim.n_frames}, got {frame}")
        start = frame - frame % _CHUNK
        if start != self._start:
            stop = min(start + _CHUNK, anim.n_frames)
            rot = anim.joint_rotations[start:stop]
            root = anim.root_translation[start:stop]
            out = np.empty((stop - start, anim.n_characters, N_BONES, 3, 4), np.float32)
            for i, body in enumerate(self.bodies):
                m = np.asarray(body.skinning_matrices(rot[:, i], root[:, i]))
                out[:, i] = m[..., :3, :]
            if anim.periodic_length:
                out[..., 0, 3] -= wrap_offsets(root[..., 0], anim.periodic_length)[:, :, None].astype(np.float32)
            self._start, self._chunk = start, out
        return self._chunk[frame - start]


def lod_levels(pixels, n_levels: int = len(LOD_PIXELS) + 1) -> np.ndarray:
    """Level of detail (0 = the finest mesh) of characters ``pixels`` tall on screen: one
    level coarser below each bound of :data:`LOD_PIXELS` (600, then 300 px), at most
    ``n_levels - 1``; a smaller character never gets a finer level than a larger one."""
    p = np.asarray(pixels, dtype=np.float64)
    level = np.zeros(p.shape, dtype=np.int64)
    for k, bound in enumerate(LOD_PIXELS[: max(0, int(n_levels) - 1)]):
        level[p < bound] = k + 1
    return level


@dataclasses.dataclass
class LodLevel:
    """One level of detail: the template groups of every character at this level's face
    count, for characters between ``min_pixels`` and ``max_pixels`` tall on screen."""

    groups: list[BodyGroup]
    min_pixels: float
    max_pixels: float


def _lod_face_counts(max_faces: int | None) -> list[int | None]:
    """Faces per template of each level: ``max_faces``, half, a quarter (at least 600);
    the full meshes, 3000 and 1500 without ``max_faces``."""
    if max_faces:
        return sorted({max_faces, max(600, max_faces // 2), max(600, max_faces // 4)}, reverse=True)
    return [None, 3000, 1500]


@dataclasses.dataclass
class CharacterMeshes:
    """What is drawn of each character.

    Attributes:
        drawn_bodies: N bodies as drawn: dressed (cloth standing off the skin, shoes, hair
            with volume) in images at least :data:`DRESS_MIN_HEIGHT` px tall, else the
            loaded bodies.
        surface_codes: per character, the (R,) code of what each render vertex shows
            (:data:`crowdstudy.render.garments.CODES`), None for region-coloured bodies.
        surface_scale: textured bodies keep this many times ``max_faces`` (they carry face,
            hands and feet in their geometry): 2 at 1080p, 1 in small previews.
        max_faces: faces per template of the finest level (None = full meshes).
        lods: the levels of detail, finest first; shadow casters use the last.
    """

    drawn_bodies: list
    surface_codes: list
    surface_scale: float
    max_faces: int | None
    lods: list[LodLevel]

    @property
    def groups(self) -> list[BodyGroup]:
        """The template groups of the finest level."""
        return self.lods[0].groups

    @classmethod
    def build(cls, bodies: list, looks: list, codes: list, *, height: int, max_faces: int | None) -> CharacterMeshes:
        """Dress ``bodies`` by their ``codes`` and ``looks`` (from ``height`` px tall images)
        and group them into template groups at each level of detail."""
        dress = height >= DRESS_MIN_HEIGHT
        drawn = [
            b if c is None or not dress else _dressed(b, c, look)
            for b, c, look in zip(bodies, codes, looks, strict=True)
        ]
        scale = float(np.clip(SURFACE_FACE_SCALE * height / 1080, 1.0, SURFACE_FACE_SCALE))
        finest = group_bodies(drawn, max_faces=max_faces, surface_scale=scale)
        faces = _lod_face_counts(max_faces)
        bounds = [np.inf, *LOD_PIXELS[: len(faces) - 1], 0.0]
        lods = [
            LodLevel(
                finest if k == 0 else group_bodies(drawn, max_faces=f, surface_scale=scale),
                min_pixels=bounds[k + 1],
                max_pixels=bounds[k],
            )
            for k, f in enumerate(faces)
        ]
        return cls(drawn_bodies=drawn, surface_codes=codes, surface_scale=scale, max_faces=max_faces, lods=lods)


_DRESSED: dict = {}


def _dressed(body, codes: np.ndarray, look):
    """:func:`~crowdstudy.render.garments.dress_body`, memoised on the body's record, its
    look and its codes (renderers of the same crowd share the dressed bodies)."""
    key = (body_key(body.record), look, codes.tobytes())
    if key not in _DRESSED:
        if len(_DRESSED) > 256:
            _DRESSED.clear()
        dressed = dress_body(body, codes, look.hair_volume)
        _DRESSED[key] = add_hair(dressed, look.hair_style, crown_uv(body))
    return _DRESSED[key]


def _ortho(half: float, near: float, far: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = m[1, 1] = 1.0 / half
    m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return m


@dataclasses.dataclass(frozen=True, eq=False)
class Lighting:
    """The scene's lights (linear RGB): a key light from ``direction`` that casts the
    characters' shadows through an orthographic shadow map, a sky/ground hemisphere for
    the ambient term, exponential distance fog towards the clear colour.

    Attributes:
        direction: (3,) unit vector towards the key light.
        view_proj: (4, 4) the key light's world-to-clip matrix (row-major).
    """

    direction: np.ndarray
    view_proj: np.ndarray
    color: tuple = (1.55, 1.48, 1.38)
    sky: tuple = (0.36, 0.39, 0.46)
    ground: tuple = (0.16, 0.15, 0.14)
    fog_density: float = 0.012  # 1/m

    @classmethod
    def for_scene(cls, env: Environment, period: float | None) -> Lighting:
        """The key light over ``env``: its shadow map covers the environment's extent (and
        the periodic copies of a corridor's crowd)."""
        direction = np.array([0.35, 0.55, 1.0]) / np.linalg.norm([0.35, 0.55, 1.0])
        w, d = env.extent
        half = 0.5 * float(np.hypot(w, d)) + 1.5
        if period:
            half = max(half, 1.6 * period)
        centre = np.array([0.0, 0.0, 0.9])
        eye = centre + direction * 30.0
        return cls(direction=direction, view_proj=_ortho(half, 1.0, 60.0) @ look_at(eye, centre))

    def shadow_footprint(self, margin: float = 0.05) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) metres: a rectangle on the ground containing every point the
        shadow map covers (light clip x, y in [-1, 1] at z = 0 and at the lookup's offset
        of 0.02 m along the normal), grown by ``margin``."""
        m = self.view_proj
        corners = []
        for z in (0.0, 0.02):
            a = m[:2, :2]
            for cx in (-1.0, 1.0):
                for cy in (-1.0, 1.0):
                    rhs = np.array([cx, cy]) - m[:2, 2] * z - m[:2, 3]
                    corners.append(np.linalg.solve(a, rhs))
        corners = np.array(corners)
        lo, hi = corners.min(axis=0) - margin, corners.max(axis=0) + margin
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def shadow_receivers(anim, lighting: Lighting, margin: float = 0.3) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1) metres: the part of the ground that can receive a character's
    shadow in any frame of ``anim``: the shadow map's footprint, cut down to the characters'
    bounding spheres (over the whole animation, every periodic copy) and their projections
    along the light onto z = 0, grown by ``margin``."""
    fx0, fy0, fx1, fy1 = lighting.shadow_footprint()
    roots = np.asarray(anim.root_translation, dtype=np.float64).reshape(-1, 3)
    if not len(roots) or not np.all(np.isfinite(roots)):
        return fx0, fy0, fx1, fy1
    lo, hi = roots[:, :2].min(axis=0) - BOUND_RADIUS, roots[:, :2].max(axis=0) + BOUND_RADIUS
    period = anim.periodic_length
    if period:  # wrapped into [-L/2, L/2) and drawn at k * L, k in COPIES
        lo[0] = -0.5 * period + min(COPIES) * period - BOUND_RADIUS
        hi[0] = 0.5 * period + max(COPIES) * period + BOUND_RADIUS
    top = max(float(roots[:, 2].max()) + BOUND_RADIUS, 0.0)
    shift = -lighting.direction[:2] / lighting.direction[2] * top  # where the highest point's shadow falls
    lo, hi = np.minimum(lo, lo + shift) - margin, np.maximum(hi, hi + shift) + margin
    return max(fx0, lo[0]), max(fy0, lo[1]), min(fx1, hi[0]), min(fy1, hi[1])


def _outside(tris: np.ndarray, rect: tuple[float, float, float, float]) -> bool:
    """Whether every vertex of the (V, 10) triangle rows lies outside the floor rectangle
    (x0, y0, x1, y1) m: its bounding box does not reach into it."""
    if not len(tris):
        return True
    lo, hi = tris[:, :2].min(axis=0), tris[:, :2].max(axis=0)
    x0, y0, x1, y1 = rect
    return bool(hi[0] < x0 or lo[0] > x1 or hi[1] < y0 or lo[1] > y1)


@dataclasses.dataclass
class EnvironmentParts:
    """The environment's triangles, (K, 10) float32 rows ``x y z nx ny nz r g b pattern``,
    split by how they are drawn.

    Attributes:
        triangles: ``walls`` (back faces culled, per-pixel lighting with the shadow
            lookup), ``cutaway`` (the venue's cut-away elements, lit per vertex, no
            shadows), ``floor_shadowed`` (the ground a character's shadow can reach) and
            ``floor_plain`` (the rest of the ground, shaded without the shadow lookup);
            without shadows all the ground is ``floor_plain``.
        walls_static: no character's shadow can reach the walls (they may go into the
            static layers).
    """

    triangles: dict[str, np.ndarray]
    walls_static: bool

    @classmethod
    def build(cls, anim, env: Environment, lighting: Lighting, *, shadows: bool) -> EnvironmentParts:
        """Split ``env``'s ground at the rectangle that can receive the characters' shadows
        (:func:`shadow_receivers`; only that part pays for the shadow lookup)."""
        tris = {"walls": env.walls, "cutaway": env.cutaway.vertices}
        receivers = shadow_receivers(anim, lighting) if shadows else None
        if shadows:
            tris["floor_shadowed"], tris["floor_plain"] = split_floor(env.opaque, receivers)
        else:
            tris["floor_plain"] = env.opaque
        walls_static = bool(len(env.walls)) and (not shadows or _outside(env.walls, receivers))
        return cls(triangles=tris, walls_static=walls_static)

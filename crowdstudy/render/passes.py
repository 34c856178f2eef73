"""The passes that draw a crowd frame with the GPU resources of :mod:`crowdstudy.render.gpu`.

A frame, in order (:class:`~crowdstudy.render.renderer.CrowdRenderer` runs them):

1. the frame's skinning matrices are uploaded (one texture row per character);
2. :class:`ShadowPass`: every character near the lit area whose shadow can fall into the
   camera's view, with the coarsest mesh, into the key light's shadow map;
3. :meth:`CharacterPass.select`: the camera's instances: culled to the view frustum, each
   at its level of detail by on-screen size, sorted front to back;
4. :class:`ColorPass`: into the draw target, a copy of the view's static layer
   (:class:`StaticLayers`, else a clear), the characters, then the rest of the
   environment (:class:`EnvironmentPass`);
5. the MSAA resolve into the output (:meth:`crowdstudy.render.gpu.ColorTargets.resolve`).

The overlap view adds an id pass and an overlap pass
(:class:`crowdstudy.render.overlap_view.OverlapPass`), both through :class:`CharacterPass`.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.render.assets import BOUND_RADIUS, COPIES, lod_levels
from crowdstudy.render.gpu import (
    CharacterResources,
    ColorTargets,
    EnvironmentBuffers,
    Programs,
    ShadowMap,
    gl_matrix,
    set_uniform,
)
from crowdstudy.render.scene import Environment

__all__ = [
    "CharacterPass",
    "ShadowPass",
    "EnvironmentPass",
    "StaticLayers",
    "ColorPass",
    "cull_back_faces",
    "display_color",
    "ENV_PARTS",
    "MAX_LAYERS",
    "LAYER_BUDGET",
    "SHADOW_MARGIN",
]

#: the environment's parts: the ground with and without the shadow lookup, the venue's
#: static cut-away elements, its audience figures, the walls
ENV_PARTS = frozenset({"floor_shadowed", "floor_plain", "cut_static", "cut_figures", "walls"})
#: static layers kept per view: one per beat phase of the audience (15 at 120 bpm, 30 fps)
MAX_LAYERS = 16
#: bytes: beyond it the audience figures are drawn every frame instead of into layers
LAYER_BUDGET = 2 << 30
#: m beyond a character's bounding sphere that its shadow is still looked up: the lookup's
#: offset along the normal (0.02 m) and the filter's reach (a few shadow-map texels)
SHADOW_MARGIN = 0.15


def cull_back_faces(ctx, on: bool) -> None:
    """Cull back faces (counter-clockwise front faces) or stop culling."""
    import moderngl

    if on:
        ctx.enable(moderngl.CULL_FACE)
        ctx.front_face = "ccw"
        ctx.cull_face = "back"
    else:
        ctx.disable(moderngl.CULL_FACE)


def display_color(linear) -> tuple[float, float, float]:
    """A linear-RGB colour as the shaders write it (``display.glsl``: the tone curve, then
    the square root), for clearing to the fog colour."""
    c = np.asarray(linear, dtype=np.float64)
    c = (c * (2.51 * c + 0.03)) / (c * (2.43 * c + 0.59) + 0.14)
    r, g, b = (float(v) for v in np.sqrt(np.clip(c, 0, 1)))
    return r, g, b


def _frustum_planes(vp: np.ndarray) -> np.ndarray:
    rows = [vp[3] + vp[0], vp[3] - vp[0], vp[3] + vp[1], vp[3] - vp[1], vp[3] + vp[2], vp[3] - vp[2]]
    planes = np.array(rows)
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


_INSTANCE = np.dtype([("c", "<i4"), ("m", "<i4"), ("s", "<f4")])


def _shadow_reaches(centres: np.ndarray, planes: np.ndarray, light_dir: np.ndarray) -> np.ndarray:
    """Whether the shadow of a character with its bounding sphere at each of ``centres``
    (N, 3) can fall inside the frustum ``planes`` (a camera's): the sphere swept away
    from the light (unit vector ``light_dir`` towards it) down to the ground, a capsule,
    reaches into every plane's inner side. Conservative: the receivers (floor, walls,
    other characters) lie at or above the ground, and :data:`SHADOW_MARGIN` covers the
    lookup's offset and filter."""
    reach = BOUND_RADIUS + SHADOW_MARGIN
    t = (centres[:, 2] + reach) / max(float(light_dir[2]), 1e-3)  # m along -light_dir to the ground
    ends = centres - t[:, None] * light_dir
    near = np.maximum(centres @ planes[:, :3].T, ends @ planes[:, :3].T) + planes[:, 3]
    return np.all(near > -reach, axis=1)


def _instance_table(
    members: np.ndarray,
    roots: np.ndarray,
    planes: np.ndarray,
    copies,
    period: float | None,
    lod: tuple | None,
    receivers: tuple | None = None,
) -> np.ndarray:
    """The instances of one template group: (character, member index, x shift) of each of
    its ``members`` (and periodic copy) whose bounding sphere reaches into the frustum
    ``planes``, sorted front to back. ``lod`` (eye, focal length px, level, number of
    levels): only the instances drawn at that level of detail; None: all (shadow casters).
    ``receivers`` (a camera's frustum planes, the unit vector towards the light): only the
    casters whose shadow can fall inside that frustum (:func:`_shadow_reaches`)."""
    chars, local, shifts, depth = [], [], [], []
    for k in copies:
        shift = k * (period or 0.0)
        centres = roots[members] + np.array([shift, 0.0, 0.0])
        visible = np.all(centres @ planes[:, :3].T + planes[:, 3] > -BOUND_RADIUS, axis=1)
        if receivers is not None:
            visible &= _shadow_reaches(centres, *receivers)
        if lod is not None:
            eye, focal_px, level, n_levels = lod
            size = focal_px * 1.8 / np.maximum(np.linalg.norm(centres - eye, axis=1), 1e-6)  # pixels tall
            visible &= lod_levels(size, n_levels) == level
        idx = np.flatnonzero(visible)
        chars.append(members[idx])
        local.append(idx)
        shifts.append(np.full(len(idx), shift))
        depth.append(centres[idx] @ planes[4, :3] + planes[4, 3])  # distance from the near plane
    order = np.argsort(np.concatenate(depth), kind="stable")
    data = np.zeros(len(order), dtype=_INSTANCE)
    data["c"] = np.concatenate(chars)[order]
    data["m"] = np.concatenate(local)[order]
    data["s"] = np.concatenate(shifts)[order]
    return data


class CharacterPass:
    """Draws the characters: :meth:`select` fills each template group's instance buffer for
    a camera, :meth:`draw` draws every group with one instanced call of a program on
    ``character.vert`` (colour, depth, id or overlap).

    ``lod_scale``: a character keeps each finer level while it is ``lod_scale`` times
    taller on screen than :data:`~crowdstudy.render.assets.LOD_PIXELS` says (0: every
    character at the finest level).

    ``per_kind``: draw with the programs compiled for one kind of template group
    (textured or region-coloured) in place of the one that branches on it (the same
    picture; llvmpipe pays for both sides of a branch)."""

    def __init__(
        self,
        ctx,
        resources: CharacterResources,
        programs: Programs,
        *,
        period: float | None,
        height: int,
        lod_scale: float = 1.0,
    ):
        self.ctx, self.resources, self.programs = ctx, resources, programs
        self.period, self.height, self.lod_scale = period, height, lod_scale
        self.per_kind = True

    def select(
        self, roots: np.ndarray, vp: np.ndarray, camera, *, shadow: bool = False, receivers: tuple | None = None
    ) -> None:
        """Fill each group's instance buffer with the characters at ``roots`` (N, 3) (and
        their periodic copies) inside the frustum of ``vp``, sorted front to back so early
        depth testing skips the shading of hidden fragments (the crowd overdraws itself
        heavily). ``shadow``: every caster with the coarse mesh; else each level of detail
        by ``camera`` distance. ``receivers`` (shadow casters only: the camera's world-to-
        clip matrix, the unit vector towards the light): only the casters whose shadow can
        fall inside the camera's view."""
        planes = _frustum_planes(vp)
        seen = None if receivers is None else (_frustum_planes(receivers[0]), np.asarray(receivers[1], float))
        copies = COPIES if self.period else (0,)
        eye = np.asarray(camera.eye)
        focal_px = self.height / (2.0 * np.tan(np.radians(camera.fov) / 2.0))
        focal_px = focal_px / self.lod_scale if self.lod_scale > 0 else np.inf  # 0: all at the finest level
        for gl in self.resources.groups:
            if shadow and not gl.coarse:
                gl.count = 0
                continue
            lod = None if shadow else (eye, focal_px, gl.level, self.resources.n_levels)
            data = _instance_table(gl.group.members, roots, planes, copies, self.period, lod, seen)
            if len(data):
                gl.inst.write(data.tobytes())
            gl.count = len(data)

    def instances(self, gl) -> np.ndarray:
        """The instances selected of one group (``resources.groups`` entry): a structured
        array of character ``c``, member ``m``, x shift ``s`` (m)."""
        return np.frombuffer(gl.inst.read(), dtype=_INSTANCE)[: gl.count]

    def draw(self, prog, vp: np.ndarray) -> None:
        """Draw the selected instances of every group with ``prog`` seen through ``vp``."""
        variants = self.programs.variants if self.per_kind and prog is self.programs.character else {}
        for p in (prog, *variants.values()):
            set_uniform(p, "u_view_proj", gl_matrix(vp))
        res = self.resources
        res.tex_bones.use(0)
        res.tex_colors.use(2)
        res.tex_albedo.use(4)
        for gl in res.groups:
            if gl.count == 0:
                continue
            p = variants.get(bool(gl.group.textured), prog)
            gl.rest.use(1)
            set_uniform(p, "u_rest_width", gl.rest_width)
            set_uniform(p, "u_textured", int(gl.group.textured))
            set_uniform(p, "u_n_vertices", gl.group.n_vertices)
            gl.vaos[p].render(instances=gl.count)


class ShadowPass:
    """The shadow casters (the characters near the lit area whose shadow can fall into the
    camera's view, with the coarsest mesh) into the shadow map, seen from the key light
    (``light_vp``, the unit vector towards it ``light_dir``); nothing when ``enabled`` is
    False. Casters whose shadow cannot reach the view change no pixel of the frame, only
    the shadow map's unseen texels."""

    def __init__(
        self,
        ctx,
        shadow_map: ShadowMap,
        characters: CharacterPass,
        light_vp: np.ndarray,
        light_dir: np.ndarray,
        *,
        enabled: bool,
    ):
        self.ctx, self.shadow_map, self.characters = ctx, shadow_map, characters
        self.light_vp, self.light_dir, self.enabled = light_vp, np.asarray(light_dir, float), enabled

    def run(self, roots: np.ndarray, camera, view_proj: np.ndarray | None = None) -> None:
        """Draw the shadow map for the characters at ``roots``; ``view_proj`` (the camera's
        world-to-clip matrix): only the casters whose shadow can fall into its view; None:
        every caster in the light's frustum."""
        import moderngl

        if not self.enabled:
            return
        ctx, fbo, size = self.ctx, self.shadow_map.fbo, self.shadow_map.size
        fbo.use()
        ctx.viewport = (0, 0, size, size)
        fbo.clear(depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        # shadow casters: every instance near the lit area (the light's own frustum)
        receivers = None if view_proj is None else (view_proj, self.light_dir)
        self.characters.select(roots, self.light_vp, camera, shadow=True, receivers=receivers)
        cull_back_faces(ctx, True)
        self.characters.draw(self.characters.programs.depth, self.light_vp)
        cull_back_faces(ctx, False)


def _beat_period(fps: float, beat_hz: float) -> int | None:
    """Frames after which the audience's bobbing repeats exactly (1 without a beat), or
    None when a beat is not a whole number of frames."""
    if beat_hz <= 0:
        return 1
    frames = float(fps) / float(beat_hz)
    return int(round(frames)) if abs(frames - round(frames)) < 1e-9 and round(frames) >= 1 else None


class EnvironmentPass:
    """The floor, the walls and the venue's cut-away elements: the stage and hall fittings
    (static) and the audience figures, which bob on the beat (``u_beat``, the fraction of a
    beat; :meth:`beat`). :meth:`set_cutaway` chooses the elements a camera keeps, static
    ones first, then the figures."""

    def __init__(self, ctx, buffers: EnvironmentBuffers, programs: Programs, env: Environment, fps: float):
        self.ctx, self.buffers, self.programs, self.env, self.fps = ctx, buffers, programs, env, fps
        self.cut_count, self.cut_static = 0, 0  # corners kept; of them the static elements'
        #: frames after which the audience's bob repeats (None: not a whole number of frames)
        self.beat_frames = _beat_period(fps, env.beat_hz)

    @property
    def has_cutaway(self) -> bool:
        return self.buffers.cut_ibo is not None

    def set_cutaway(self, indices) -> None:
        """Draw these triangle corners (rows of ``env.cutaway.vertices``) of the cut-away
        elements: the static elements' triangles first, the audience figures' after them."""
        if self.buffers.cut_ibo is None:
            raise InvalidInputError("set_cutaway: this scene has no cut-away elements")
        rows = self.env.cutaway.vertices
        idx = np.asarray(indices, dtype=np.uint32).reshape(-1, 3)
        if len(idx) and int(idx.max()) >= len(rows):
            raise InvalidInputError(f"indices: expected rows < {len(rows)}, got {int(idx.max())}")
        figure = rows[idx[:, 0], 9] >= 2.5 if len(idx) else np.zeros(0, bool)
        ordered = np.concatenate([idx[~figure], idx[figure]]).reshape(-1)
        if len(ordered):
            self.buffers.cut_ibo.write(ordered.tobytes())
        self.cut_count, self.cut_static = len(ordered), 3 * int(np.count_nonzero(~figure))

    def beat(self, frame: int) -> float:
        """The audience's beat phase at ``frame``: the fraction of a beat, as float32."""
        return float(np.float32((frame / self.fps * self.env.beat_hz) % 1.0))

    def set_beat(self, beat: float) -> None:
        """Pose the audience figures at beat phase ``beat`` (see :meth:`beat`)."""
        set_uniform(self.programs.venue, "u_beat", beat)

    def draw(self, parts) -> None:
        """Draw those of ``parts`` (names in :data:`ENV_PARTS`) this scene has."""
        vaos = self.buffers.vaos
        for name in ("floor_shadowed", "floor_plain"):
            if name in parts and name in vaos:
                vaos[name].render()
        if "cut_static" in parts and self.cut_static:
            vaos["cutaway"].render(vertices=self.cut_static)
        if "cut_figures" in parts and self.cut_count > self.cut_static:
            vaos["cutaway"].render(vertices=self.cut_count - self.cut_static, first=self.cut_static)
        if "walls" in parts and "walls" in vaos:
            cull_back_faces(self.ctx, True)
            vaos["walls"].render()
            cull_back_faces(self.ctx, False)


class StaticLayers:
    """What the characters do not change, drawn once per view into framebuffers like the
    draw target (multisampled colour + depth); a frame starts from a copy of its layer.

    ``parts``: the unshadowed ground and the venue's static elements, the walls when no
    shadow reaches them, and the audience figures when their bob repeats within
    :data:`MAX_LAYERS` frames (one layer per beat phase, all within :data:`LAYER_BUDGET`);
    empty when not ``enabled``. A layer is drawn on first use after :meth:`invalidate`
    (a new camera or cut-away) into the same framebuffer."""

    def __init__(self, ctx, targets: ColorTargets, environment: EnvironmentPass, *, enabled: bool, walls_static: bool):
        self.ctx, self.targets, self.environment = ctx, targets, environment
        period = environment.beat_frames
        figures = period is not None and period <= MAX_LAYERS and period * targets.layer_bytes() <= LAYER_BUDGET
        self.parts = frozenset(
            (
                {"floor_plain", "cut_static"}
                | ({"walls"} if walls_static else set())
                | ({"cut_figures"} if figures else set())
            )
            if enabled
            else ()
        )
        self.layers: dict = {}  # beat phase (float32, or None) -> framebuffer
        self.drawn: set = set()

    def phases(self) -> int:
        """How many layers a view has (one per beat phase when the figures are in them)."""
        beat_frames = self.environment.beat_frames  # set whenever the figures are in the layers
        return int(beat_frames) if "cut_figures" in self.parts and beat_frames is not None else 1

    def invalidate(self) -> None:
        """Draw every layer anew on its next use."""
        self.drawn.clear()

    def get(self, beat: float):
        """The layer of beat phase ``beat``, drawn if not yet since :meth:`invalidate`."""
        import moderngl

        key = beat if "cut_figures" in self.parts else None
        if key not in self.layers:
            self.layers[key] = self.targets.layer_framebuffer()
        fbo = self.layers[key]
        if key not in self.drawn:
            fbo.use()
            self.ctx.viewport = (0, 0, self.targets.width, self.targets.height)
            fbo.clear(*display_color(self.environment.env.clear_color), 1.0, depth=1.0)
            self.ctx.enable(moderngl.DEPTH_TEST)
            self.environment.set_beat(beat)
            self.environment.draw(self.parts)
            self.drawn.add(key)
        return fbo


class ColorPass:
    """A frame's picture into a framebuffer: its static layer (or a clear to the fog
    colour), then the characters (front to back: the environment they hide fails the early
    depth test), then the parts of the environment not in the layer."""

    def __init__(
        self,
        ctx,
        programs: Programs,
        characters: CharacterPass,
        environment: EnvironmentPass,
        layers: StaticLayers,
        shadow_map: ShadowMap,
        targets: ColorTargets,
    ):
        self.ctx, self.programs, self.characters = ctx, programs, characters
        self.environment, self.layers, self.shadow_map, self.targets = environment, layers, shadow_map, targets

    def bind_camera(self, vp: np.ndarray, eye) -> None:
        """The camera's world-to-clip matrix ``vp`` and position ``eye`` (m) in every lit program."""
        eye = tuple(float(v) for v in eye)
        for prog in self.programs.lit:
            set_uniform(prog, "u_eye", eye)
            set_uniform(prog, "u_view_proj", gl_matrix(vp))

    def run(self, fbo, vp: np.ndarray, eye, beat: float) -> None:
        """Draw the frame into ``fbo`` seen through ``vp`` from ``eye`` (m), the audience at
        beat phase ``beat``; the characters' bones and instances must be loaded and
        selected, the shadow map drawn."""
        import moderngl

        ctx, size = self.ctx, (0, 0, self.targets.width, self.targets.height)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        self.shadow_map.texture.use(3)
        self.bind_camera(vp, eye)
        self.environment.set_beat(beat)
        parts = ENV_PARTS
        if self.layers.parts:
            layer = self.layers.get(beat)
            fbo.use()
            ctx.viewport = size
            ctx.copy_framebuffer(fbo, layer)  # colour and depth, sample by sample
            parts = ENV_PARTS - self.layers.parts
        else:
            fbo.use()
            ctx.viewport = size
            fbo.clear(*display_color(self.environment.env.clear_color), 1.0, depth=1.0)
        cull_back_faces(ctx, True)  # closed, outward-wound meshes: back faces are never seen
        self.characters.draw(self.programs.character, vp)
        cull_back_faces(ctx, False)
        self.environment.draw(parts)

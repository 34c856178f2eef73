"""The crowd renderer: GPU skinning, shadows, MSAA, environment, overlap view.

Per frame the CPU uploads one RGBA32F texture of skinning matrices (3 rows of 4 floats per
bone, one texture row per character, 69 KB for 60 characters) and the list of visible
instances; each body template group is drawn with ONE instanced call, in a shadow pass, a
colour pass (4x MSAA by default) and, for the overlap view, an id pass and an overlap pass
(see :mod:`crowdstudy.render.overlap_view`).

Periodic scenes (the corridor): every character is wrapped into the visible section
[-L/2, L/2) along x and drawn at offsets k*L, k in -2..2 (instances outside the view
frustum are culled), so the crowd looks continuous and nothing pops at the seams.

The concert venue's cut-away elements (stage, hall fittings, about 290 audience figures;
:mod:`crowdstudy.render.venue`) are drawn through an index buffer that ``set_view`` fills
with the elements that stand neither between the camera and the crowd nor next to the
camera, nearest first, lit per vertex.

Levels of detail (:func:`lod_levels`): characters less than 600 (300) pixels tall on screen are drawn with
half (a quarter) of the faces; shadow casters always with the coarsest mesh.

The ground is split at the rectangle that the characters' shadows can reach (over the
whole animation); only that part is shaded with the shadow-map lookup, the rest with a
variant compiled without it (same picture, half the floor's cost on llvmpipe).

Static layers: what the characters do not change (the unshadowed ground, the venue's stage
and hall, the audience figures at each of the 15 phases of their bob, walls no shadow can
reach) is drawn once per view into multisampled colour + depth framebuffers; a frame starts
from a copy of its phase's layer and draws only the characters, the shadowed ground and
what else moves (byte for byte the picture drawn from scratch, but for the odd pixel where
two surfaces meet at the same depth; ``static_layer=False`` draws it all every frame).
The layers cost 66 MB each at 1080p with 4x MSAA (1 GB for the concert's 15).

Shader variants: the characters' program is also compiled once per kind of template group
(textured, region-coloured), so llvmpipe, which runs both sides of a branch on a uniform
for every MSAA sample, does not pay for the other kind's shading (the same bytes).

Body meshes are decimated once per template (``max_faces``, 3000 at 1080p, hardly
distinguishable from the full mesh there; on llvmpipe the cost of a frame grows with the
triangle count), and characters less than 600 px tall on screen use half of that (under
300 px a quarter); characters are lit per vertex (see ``shaders/lighting.glsl``).
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np

from crowdstudy.body.loading import body_key
from crowdstudy.errors import InvalidInputError
from crowdstudy.render.appearance import assign_appearance, paint_textures, texture_size
from crowdstudy.render.bodies import SURFACE_FACE_SCALE, BodyGroup, default_body_loader, group_bodies
from crowdstudy.render.camera import Camera, frame_viewpoint, look_at
from crowdstudy.render.context import get_context
from crowdstudy.render.garments import dress_body
from crowdstudy.render.palette import assign_colors
from crowdstudy.render.scene import Environment, build_environment, split_floor
from crowdstudy.render.venue import BOB_AMPLITUDE, visible_indices

__all__ = ["CrowdRenderer", "lod_levels", "render_frame", "resolve_camera", "scenario_of", "baseline_color_positions",
           "N_BONES"]

N_BONES = 24
_CHUNK = 32          # frames of skinning matrices computed at once
_COPIES = (-2, -1, 0, 1, 2)
_BOUND_RADIUS = 1.3  # m, bounding sphere of a character around its pelvis (arms raised)
_LOD_PIXELS = (600.0, 300.0)  # on-screen height (px) below which the next coarser mesh is used
_MAX_LAYERS = 16     # static layers kept per view: one per beat phase of the audience (15 at 120 bpm, 30 fps)
_LAYER_BUDGET = 2 << 30  # bytes: beyond it the audience figures are drawn every frame instead
_ENV_PARTS = frozenset({"floor_shadowed", "floor_plain", "cut_static", "cut_figures", "walls"})


@functools.lru_cache(maxsize=None)
def _shader_source(name: str) -> str:
    return resources.files("crowdstudy.render").joinpath("shaders", name).read_text(encoding="utf-8")


def _program(ctx, vert: str, frag: str, *, lit_vertex: bool = False, lit_fragment: bool = False,
             defines: tuple[str, ...] = ()):
    """Compile a program; ``lit_*`` prepend the lighting functions to that stage."""
    head = "#version 330 core\n" + "".join(f"#define {d} 1\n" for d in defines)
    light = _shader_source("lighting.glsl")
    vs = head + ("#define LIT 1\n" + light if lit_vertex else "") + _shader_source(vert)
    fs = head + (light if lit_fragment else "") + _shader_source("display.glsl") + _shader_source(frag)
    return ctx.program(vertex_shader=vs, fragment_shader=fs)


def _group_vertex_array(ctx, prog, vbo, inst, ibo):
    """The vertex array of one template group for ``prog`` (a program on ``character.vert``):
    the group's static attributes ``vbo``, its per-instance buffer ``inst``, its faces ``ibo``."""
    return ctx.vertex_array(prog, [(vbo, "4i 4f 4f 2f 3f", "in_joints", "in_weights", "in_scores_a", "in_scores_b",
                                    "in_material"), (inst, "1i 1i 1f /i", "in_char", "in_member", "in_shift")],
                            index_buffer=ibo, index_element_size=4, skip_errors=True)


def _set(prog, name: str, value) -> None:
    if name in prog:
        if isinstance(value, np.ndarray):
            prog[name].write(np.ascontiguousarray(value, dtype=np.float32).tobytes())
        else:
            prog[name].value = value


def _mat(m: np.ndarray) -> np.ndarray:
    """Row-major numpy (4, 4) -> the column-major float32 layout GLSL expects."""
    return np.ascontiguousarray(np.asarray(m, dtype=np.float64).T, dtype=np.float32)


def _ortho(half: float, near: float, far: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = m[1, 1] = 1.0 / half
    m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return m


def _frustum_planes(vp: np.ndarray) -> np.ndarray:
    rows = [vp[3] + vp[0], vp[3] - vp[0], vp[3] + vp[1], vp[3] - vp[1], vp[3] + vp[2], vp[3] - vp[2]]
    planes = np.array(rows)
    return planes / np.linalg.norm(planes[:, :3], axis=1, keepdims=True)


def scenario_of(anim) -> str:
    """The scenario of an animation: ``meta["scenario"]``, else corridor when periodic."""
    scen = anim.meta.get("scenario")
    if scen in ("concert", "corridor"):
        return scen
    return "corridor" if anim.periodic_length else "concert"


def resolve_camera(view, design, env_extent: tuple[float, float], aspect: float) -> Camera:
    """A :class:`Camera` from a viewpoint id ("V1".."V4"), a Viewpoint, or a Camera."""
    if isinstance(view, Camera):
        return view
    if isinstance(view, str):
        if view not in design.viewpoints:
            raise InvalidInputError(f"viewpoint: unknown viewpoint {view!r}; the design defines "
                                    f"{', '.join(design.viewpoints)} (or use a free camera)")
        view = design.viewpoints[view]
    return frame_viewpoint(view, env_extent, aspect)


class CrowdRenderer:
    """Renders one :class:`~crowdstudy.scene.CrowdAnimation` frame by frame.

    Args:
        anim: the animation (T frames, N characters).
        design: the study design (environment sizes, viewpoints); default the paper's.
        width, height: image size in pixels.
        msaa: samples per pixel (0 or 1 = off; clamped to what the driver supports).
        shadows: draw the key light's shadow map.
        shadow_size: shadow map resolution (pixels per side).
        body_loader: record -> Body (default ``crowdstudy.body.load_body``).
        color_seed: seed of the clothing colours (default the animation's seed).
        color_positions: (N, 2) metres, the floor positions that decide which characters
            are neighbours for the colour assignment (default: frame 0 of ``anim``). Pass
            the Baseline's to render its corrected version with the same colours.
        max_faces: level of detail of the body meshes (faces per template, None = full
            meshes); "auto" scales with the image height: 3000 at 1080p (hardly
            distinguishable from the full mesh there), down to 600 for tiny previews.
        static_layer: draw what the characters do not change (the unshadowed ground, the
            venue's stage, hall and, when their bobbing repeats within 16 frames, the
            audience figures at each phase of the beat; walls out of the characters'
            shadows) once per view into multisampled colour + depth layers, and start each
            frame from a copy of its layer (the same picture, byte for byte; False draws
            everything every frame).
    """

    def __init__(self, anim, *, design=None, width: int = 1920, height: int = 1080, msaa: int = 4,
                 shadows: bool = True, shadow_size: int = 2048, body_loader=None, color_seed: int | None = None,
                 max_faces: int | str | None = "auto", color_positions=None, static_layer: bool = True):
        import moderngl

        if design is None:
            from crowdstudy.design import load_design
            design = load_design()
        for name, value in (("width", width), ("height", height)):
            if not isinstance(value, (int, np.integer)) or value < 16 or value > 8192:
                raise InvalidInputError(f"{name}: expected an integer pixel size in [16, 8192], got {value!r}")
        if not isinstance(msaa, (int, np.integer)) or msaa < 0 or msaa > 16:
            raise InvalidInputError(f"msaa: expected 0..16 samples per pixel, got {msaa!r}")
        if anim.n_joints != N_BONES:
            raise InvalidInputError(f"anim.joint_names: the renderer needs the {N_BONES}-joint skeleton, got {anim.n_joints}")
        self.anim, self.design = anim, design
        self.width, self.height = int(width), int(height)
        self.ctx = ctx = get_context()
        self._owned: list = []  # every GL object created here, released by release()
        self._overlap = None
        own = self._own
        self.samples = int(min(msaa, ctx.max_samples)) if msaa > 1 else 0
        self.shadows = bool(shadows)
        self.env: Environment = build_environment(scenario_of(anim), design)
        self.period = anim.periodic_length
        loader = body_loader or default_body_loader
        self.bodies = [loader(rec) for rec in anim.bodies]
        if max_faces == "auto":
            max_faces = int(np.clip(3000 * self.height / 1080, 600, 3000))
        elif max_faces is not None and (not isinstance(max_faces, (int, np.integer)) or max_faces < 100):
            raise InvalidInputError(f"max_faces: expected 'auto', None or an integer >= 100, got {max_faces!r}")
        self.max_faces = max_faces
        # what each character wears: painted once on its UVs (textured bodies), and the
        # drawn surface dressed to match (cloth, shoes and hair with volume)
        n = anim.n_characters
        seed = int(anim.meta.get("seed", 0) if color_seed is None else color_seed)
        if color_positions is None:
            color_positions = self._wrapped_roots(0)[:, :2]
        color_positions = np.asarray(color_positions, dtype=np.float64)
        if color_positions.shape != (n, 2):
            raise InvalidInputError(f"color_positions: expected shape ({n}, 2), got {color_positions.shape}")
        self.colors, choice = assign_colors(color_positions, seed, period=self.period)
        self.looks = assign_appearance(list(anim.bodies), choice, seed)
        prog_paint = _program(ctx, "paint.vert", "paint.frag")
        try:
            tex_albedo, codes = paint_textures(ctx, self.bodies, self.looks, prog_paint,
                                               size=texture_size(self.height, len(self.bodies)))
            self.tex_albedo = own(tex_albedo)
        finally:
            prog_paint.release()
        self.surface_codes = codes   # per character: what each render vertex shows (garments.CODES)
        # the dressing moves the surface by millimetres: below 540 px tall images it is under a
        # pixel, and skipped
        dress = self.height >= _DRESS_MIN_HEIGHT
        self.drawn_bodies = [b if c is None or not dress else _dressed(b, c, look)
                             for b, c, look in zip(self.bodies, codes, self.looks)]
        # textured bodies carry face, hands and feet in their geometry: twice the faces at
        # 1080p, the mannequins' count in small previews
        self.surface_scale = float(np.clip(SURFACE_FACE_SCALE * self.height / 1080, 1.0, SURFACE_FACE_SCALE))
        self.groups: list[BodyGroup] = group_bodies(self.drawn_bodies, max_faces=max_faces,
                                                    surface_scale=self.surface_scale)
        # levels of detail by on-screen size: a character under _LOD_PIXELS[k] pixels tall uses
        # level k + 1 (half, then a quarter of the faces); shadow casters use the coarsest
        if max_faces:
            faces = sorted({max_faces, max(600, max_faces // 2), max(600, max_faces // 4)}, reverse=True)
        else:
            faces = [None, 3000, 1500]
        bounds = [np.inf, *_LOD_PIXELS[:len(faces) - 1], 0.0]
        self._lods = [(self.groups if k == 0 else group_bodies(self.drawn_bodies, max_faces=f,
                                                               surface_scale=self.surface_scale), bounds[k + 1], bounds[k])
                      for k, f in enumerate(faces)]
        self.camera: Camera | None = None
        self._chunk_start, self._chunk = -1, None
        self._frame_loaded = -1

        # programs
        self.prog_char = own(_program(ctx, "character.vert", "character.frag", lit_vertex=True, lit_fragment=True))
        # ... and its variants for one kind of group (textured or region-coloured), which
        # _draw_characters uses in its place: the same picture without the other kind's code
        self._char_variants = {self.prog_char: {
            kind: own(_program(ctx, "character.vert", "character.frag", lit_vertex=True, lit_fragment=True,
                               defines=(define,)))
            for kind, define in ((True, "TEXTURED_ONLY"), (False, "REGIONS_ONLY"))}}
        self.prog_depth = own(_program(ctx, "character.vert", "depth.frag"))
        self.prog_static = own(_program(ctx, "static.vert", "static.frag", lit_fragment=True))
        self.prog_floor = own(_program(ctx, "static.vert", "static.frag", lit_fragment=True, defines=("FLOOR",)))
        # the ground where no character's shadow can fall: the same shading without the
        # shadow lookup (llvmpipe samples textures even in branches no pixel takes; the
        # lookup was half of the floor's cost)
        self.prog_floor_plain = own(_program(ctx, "static.vert", "static.frag", lit_fragment=True,
                                             defines=("FLOOR", "UNSHADOWED")))
        # the venue's cut-away elements (hundreds of small figures, out of the characters'
        # shadows): lit per vertex, without the shadow lookup
        self.prog_venue = own(_program(ctx, "static.vert", "static.frag", lit_vertex=True,
                                       defines=("VERTEX_LIT", "UNSHADOWED")))
        variants = tuple(self._char_variants[self.prog_char].values())
        self._lit_programs = (self.prog_char, *variants, self.prog_static, self.prog_floor, self.prog_floor_plain,
                              self.prog_venue)
        self.prog_id = own(_program(ctx, "character.vert", "id.frag"))
        self.prog_overlap = own(_program(ctx, "character.vert", "overlap.frag"))
        self._char_programs = (self.prog_char, *variants, self.prog_depth, self.prog_id, self.prog_overlap)

        # per-character textures
        self.tex_bones = own(ctx.texture((3 * N_BONES, n), 4, dtype="f4"))
        self.tex_colors = own(ctx.texture((6, n), 4, data=np.concatenate(
            [self.colors, np.ones((n, 6, 1), np.float32)], axis=2).astype("f4").tobytes(), dtype="f4"))
        for tex in (self.tex_bones, self.tex_colors):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)

        # template groups: static vertex attributes, rest-shape texture, instance buffer
        self._gl_groups = []
        last = len(self._lods) - 1
        for g, level, coarse in ((g, k, k == last) for k, (groups, lo, hi) in enumerate(self._lods) for g in groups):
            material = g.material if g.material is not None else np.zeros((g.n_vertices, 3), np.float32)
            vbo = own(ctx.buffer(np.concatenate([g.joints.view(np.float32), g.weights, g.scores, material],
                                                axis=1).astype(np.float32, copy=False).tobytes()))
            ibo = own(ctx.buffer(g.faces.astype(np.uint32).tobytes()))
            texels = g.rest.reshape(-1, 4)
            rest_w = 4096
            rows = -(-len(texels) // rest_w)
            padded = np.zeros((rows * rest_w, 4), np.float32)
            padded[:len(texels)] = texels
            tex_rest = own(ctx.texture((rest_w, rows), 4, data=padded.tobytes(), dtype="f4"))
            tex_rest.filter = (moderngl.NEAREST, moderngl.NEAREST)
            inst = own(ctx.buffer(reserve=len(g.members) * len(_COPIES) * 12, dynamic=True))
            vaos = {prog: own(_group_vertex_array(ctx, prog, vbo, inst, ibo)) for prog in self._char_programs}
            self._gl_groups.append({"group": g, "vbo": vbo, "ibo": ibo, "rest": tex_rest, "rest_width": rest_w,
                                    "inst": inst, "vaos": vaos, "count": 0, "level": level, "coarse": coarse})

        # shadow map
        if not isinstance(shadow_size, (int, np.integer)) or not 64 <= shadow_size <= 8192:
            raise InvalidInputError(f"shadow_size: expected an integer in [64, 8192], got {shadow_size!r}")
        self.shadow_size = int(shadow_size)
        self.tex_shadow = own(ctx.depth_texture((self.shadow_size, self.shadow_size)))
        self.tex_shadow.compare_func = "<="
        self.tex_shadow.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.fbo_shadow = own(ctx.framebuffer(depth_attachment=self.tex_shadow))
        self.light_dir = np.array([0.35, 0.55, 1.0]) / np.linalg.norm([0.35, 0.55, 1.0])
        self.light_vp = self._light_view_proj()

        # environment; the ground is split at the rectangle that can receive the characters'
        # shadows (see _shadow_receivers); the rest is drawn without the shadow lookup
        self._static = {}
        parts = {"walls": (self.env.walls, self.prog_static), "cutaway": (self.env.cutaway.vertices, self.prog_venue)}
        if self.shadows:
            inner, outer = split_floor(self.env.opaque, self._shadow_receivers())
            parts["floor_shadowed"] = (inner, self.prog_floor)
            parts["floor_plain"] = (outer, self.prog_floor_plain)
        else:
            parts["floor_plain"] = (self.env.opaque, self.prog_floor_plain)
        # the cut-away elements this camera keeps (set_view): the static ones first, then the
        # audience figures (which bob on the beat, so are drawn every frame)
        self._cut_ibo, self._cut_count, self._cut_static = None, 0, 0
        for name, (tris, prog) in parts.items():
            if len(tris):
                buf = own(ctx.buffer(tris.astype("f4").tobytes()))
                ibo = None
                if name == "cutaway":
                    ibo = self._cut_ibo = own(ctx.buffer(reserve=4 * max(1, len(self.env.cutaway.indices)),
                                                         dynamic=True))
                self._static[name] = own(ctx.vertex_array(prog, [(buf, "3f 3f 4f", "in_position", "in_normal",
                                                                  "in_color")], index_buffer=ibo,
                                                          index_element_size=4, skip_errors=True))

        # colour targets
        size = (self.width, self.height)
        if self.samples:
            self.fbo_msaa = own(ctx.framebuffer(
                color_attachments=[own(ctx.renderbuffer(size, 4, samples=self.samples))],
                depth_attachment=own(ctx.depth_renderbuffer(size, samples=self.samples))))
        else:
            self.fbo_msaa = None
        self.fbo_out = own(ctx.framebuffer(color_attachments=[own(ctx.renderbuffer(size, 4))],
                                           depth_attachment=own(ctx.depth_renderbuffer(size))))
        # the static layer (see static_layer): what no frame changes, drawn once per view (and
        # per phase of the audience's beat when it repeats within _MAX_LAYERS frames)
        self.static_layer = bool(static_layer)
        self._layers: dict = {}        # beat phase (float32, or None) -> framebuffer
        self._layers_drawn: set = set()
        period = self._beat_frames = _beat_period(self.anim.fps, self.env.beat_hz)
        walls_static = "walls" in self._static and (not self.shadows or
                                                    _outside(self.env.walls, self._shadow_receivers()))
        self._layer_parts = frozenset(({"floor_plain", "cut_static"} | ({"walls"} if walls_static else set())
                                       | ({"cut_figures"} if period is not None and period <= _MAX_LAYERS
                                          and period * self.layer_bytes() <= _LAYER_BUDGET else set()))
                                      if self.static_layer else ())

        # constant uniforms
        for prog in self._lit_programs:
            _set(prog, "u_light_dir", tuple(self.light_dir))
            _set(prog, "u_light_color", (1.55, 1.48, 1.38))
            _set(prog, "u_sky_color", (0.36, 0.39, 0.46))
            _set(prog, "u_ground_color", (0.16, 0.15, 0.14))
            _set(prog, "u_fog_color", tuple(self.env.clear_color))
            _set(prog, "u_fog_density", 0.012)
            _set(prog, "u_use_shadows", int(self.shadows))
            _set(prog, "u_light_view_proj", _mat(self.light_vp))
            _set(prog, "u_shadow_texel", 1.0 / self.shadow_size)
            _set(prog, "u_shadow", 3)
        pool = self.env.pool
        for prog in (self.prog_static, self.prog_floor, self.prog_floor_plain, self.prog_venue):
            _set(prog, "u_pool", tuple(pool[:4]) if pool else (0.0, 0.0, 0.0, 0.0))
            _set(prog, "u_pool_fade", tuple(pool[4:]) if pool else (0.0, 1.0))
            _set(prog, "u_bob_amplitude", BOB_AMPLITUDE)
        for prog in self._char_programs:
            _set(prog, "u_bones", 0)
            _set(prog, "u_rest", 1)
            _set(prog, "u_colors", 2)  # character.frag
            _set(prog, "u_albedo", 4)
            _set(prog, "u_n_characters", n)
            _set(prog, "u_period", float(self.period or 0.0))

    # -- camera and geometry -------------------------------------------------------------
    def set_view(self, view) -> Camera:
        """Use a viewpoint id ("V1".."V4"), a design Viewpoint or a :class:`Camera`."""
        self.camera = resolve_camera(view, self.design, self.env.extent, self.width / self.height)
        if self._cut_ibo is not None:  # the cutaway: drop the elements between this camera and the crowd
            self.set_cutaway(visible_indices(self.env.cutaway, self.camera.eye, self.env.extent,
                                             self.camera.view_projection(self.width / self.height)))
        self._layers_drawn.clear()
        return self.camera

    def set_cutaway(self, indices) -> None:
        """Draw these triangle corners (rows of ``env.cutaway.vertices``, in drawing order)
        of the venue's cut-away elements; ``set_view`` sets the camera's. Their static
        triangles go first (into the static layer), the audience figures' after them."""
        if self._cut_ibo is None:
            raise InvalidInputError("set_cutaway: this scene has no cut-away elements")
        idx = np.asarray(indices, dtype=np.uint32).reshape(-1, 3)
        if len(idx) and int(idx.max()) >= len(self.env.cutaway.vertices):
            raise InvalidInputError(f"indices: expected rows < {len(self.env.cutaway.vertices)}, got {int(idx.max())}")
        figure = self.env.cutaway.vertices[idx[:, 0], 9] >= 2.5 if len(idx) else np.zeros(0, bool)
        ordered = np.concatenate([idx[~figure], idx[figure]]).reshape(-1)
        if len(ordered):
            self._cut_ibo.write(ordered.tobytes())
        self._cut_count, self._cut_static = len(ordered), 3 * int(np.count_nonzero(~figure))
        self._layers_drawn.clear()

    def _light_view_proj(self) -> np.ndarray:
        w, d = self.env.extent
        half = 0.5 * float(np.hypot(w, d)) + 1.5
        if self.period:
            half = max(half, 1.6 * self.period)
        centre = np.array([0.0, 0.0, 0.9])
        eye = centre + self.light_dir * 30.0
        return _ortho(half, 1.0, 60.0) @ look_at(eye, centre)

    def _wrapped_roots(self, frame: int) -> np.ndarray:
        root = np.array(self.anim.root_translation[frame])
        if self.period:
            root[:, 0] -= self._wrap_offsets(root[:, 0])
        return root

    def _wrap_offsets(self, x: np.ndarray) -> np.ndarray:
        """Multiples of the period to subtract so x falls in [-L/2, L/2)."""
        if not self.period:
            return np.zeros_like(x)
        return self.period * np.floor((x + 0.5 * self.period) / self.period)

    def skinning(self, frame: int) -> np.ndarray:
        """(N, 24, 3, 4) float32 skinning matrices of ``frame`` (periodic scenes wrapped)."""
        if not 0 <= frame < self.anim.n_frames:
            raise InvalidInputError(f"frame: expected 0 <= frame < {self.anim.n_frames}, got {frame}")
        start = frame - frame % _CHUNK
        if start != self._chunk_start:
            stop = min(start + _CHUNK, self.anim.n_frames)
            rot = self.anim.joint_rotations[start:stop]
            root = self.anim.root_translation[start:stop]
            out = np.empty((stop - start, self.anim.n_characters, N_BONES, 3, 4), np.float32)
            for i, body in enumerate(self.bodies):
                m = np.asarray(body.skinning_matrices(rot[:, i], root[:, i]))
                out[:, i] = m[..., :3, :]
            if self.period:
                out[..., 0, 3] -= self._wrap_offsets(root[..., 0])[:, :, None].astype(np.float32)
            self._chunk_start, self._chunk = start, out
        return self._chunk[frame - start]

    def _instances(self, roots: np.ndarray, vp: np.ndarray, *, shadow: bool = False) -> None:
        """Fill each group's instance buffer with the characters (and periodic copies)
        inside the frustum of ``vp``, sorted front to back so early depth testing skips
        the shading of hidden fragments (the crowd overdraws itself heavily). ``shadow``:
        every caster with the coarse mesh; else each level of detail by camera distance."""
        planes = _frustum_planes(vp)
        copies = _COPIES if self.period else (0,)
        eye = np.asarray(self.camera.eye)
        focal_px = self.height / (2.0 * np.tan(np.radians(self.camera.fov) / 2.0))
        n_levels = len(self._lods)
        for gl in self._gl_groups:
            members = gl["group"].members
            if shadow and not gl["coarse"]:
                gl["count"] = 0
                continue
            chars, local, shifts, depth = [], [], [], []
            for k in copies:
                shift = k * (self.period or 0.0)
                centres = roots[members] + np.array([shift, 0.0, 0.0])
                visible = np.all(centres @ planes[:, :3].T + planes[:, 3] > -_BOUND_RADIUS, axis=1)
                if not shadow:
                    size = focal_px * 1.8 / np.maximum(np.linalg.norm(centres - eye, axis=1), 1e-6)  # pixels tall
                    visible &= lod_levels(size, n_levels) == gl["level"]
                idx = np.flatnonzero(visible)
                chars.append(members[idx])
                local.append(idx)
                shifts.append(np.full(len(idx), shift))
                depth.append(centres[idx] @ planes[4, :3] + planes[4, 3])  # distance from the near plane
            order = np.argsort(np.concatenate(depth), kind="stable")
            data = np.zeros(len(order), dtype=[("c", "<i4"), ("m", "<i4"), ("s", "<f4")])
            data["c"] = np.concatenate(chars)[order]
            data["m"] = np.concatenate(local)[order]
            data["s"] = np.concatenate(shifts)[order]
            if len(data):
                gl["inst"].write(data.tobytes())
            gl["count"] = len(data)

    def _load_frame(self, frame: int) -> None:
        mats = self.skinning(frame)
        self.tex_bones.write(np.ascontiguousarray(mats, dtype=np.float32).tobytes())
        self._frame_loaded = frame

    def _cull_back_faces(self, on: bool) -> None:
        import moderngl
        if on:
            self.ctx.enable(moderngl.CULL_FACE)
            self.ctx.front_face = "ccw"
            self.ctx.cull_face = "back"
        else:
            self.ctx.disable(moderngl.CULL_FACE)

    def _draw_characters(self, prog, vp: np.ndarray) -> None:
        for p in (prog, *self._char_variants.get(prog, {}).values()):
            _set(p, "u_view_proj", _mat(vp))
        self.tex_bones.use(0)
        self.tex_colors.use(2)
        self.tex_albedo.use(4)
        for gl in self._gl_groups:
            if gl["count"] == 0:
                continue
            p = self._char_variants.get(prog, {}).get(bool(gl["group"].textured), prog)
            gl["rest"].use(1)
            _set(p, "u_rest_width", gl["rest_width"])
            _set(p, "u_textured", int(gl["group"].textured))
            _set(p, "u_n_vertices", gl["group"].n_vertices)
            gl["vaos"][p].render(instances=gl["count"])

    # -- passes --------------------------------------------------------------------------
    def _prepare(self, frame: int, *, upload: bool = True) -> np.ndarray:
        """Upload the frame's bones (unless done) and the camera's instances; the camera's
        world-to-clip matrix."""
        if self.camera is None:
            raise InvalidInputError("no camera: call set_view() with a viewpoint or a free camera first")
        if upload:
            self._load_frame(frame)
        vp = self.camera.view_projection(self.width / self.height)
        self._instances(self._wrapped_roots(frame), vp)
        return vp

    def _shadow_pass(self) -> None:
        import moderngl
        if not self.shadows:
            return
        ctx = self.ctx
        self.fbo_shadow.use()
        ctx.viewport = (0, 0, self.shadow_size, self.shadow_size)
        self.fbo_shadow.clear(depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        # Shadow casters: every instance near the lit area (use the light's own frustum).
        self._instances(self._wrapped_roots(self._frame_loaded), self.light_vp, shadow=True)
        self._cull_back_faces(True)
        self._draw_characters(self.prog_depth, self.light_vp)
        self._cull_back_faces(False)

    def _color_pass(self, vp: np.ndarray, fbo) -> None:
        import moderngl
        ctx = self.ctx
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        self.tex_shadow.use(3)
        eye = tuple(float(v) for v in self.camera.eye)
        for prog in self._lit_programs:
            _set(prog, "u_eye", eye)
            _set(prog, "u_view_proj", _mat(vp))
        beat = self._beat(self._frame_loaded)
        _set(self.prog_venue, "u_beat", beat)
        parts = _ENV_PARTS
        if self._layer_parts:
            layer = self._layer(beat if "cut_figures" in self._layer_parts else None, beat)
            fbo.use()
            ctx.viewport = (0, 0, self.width, self.height)
            ctx.copy_framebuffer(fbo, layer)   # colour and depth, sample by sample
            parts = _ENV_PARTS - self._layer_parts
        else:
            fbo.use()
            ctx.viewport = (0, 0, self.width, self.height)
            fbo.clear(*_display(self.env.clear_color), 1.0, depth=1.0)
        # characters first (sorted front to back), then the environment: the floor hidden
        # behind the crowd fails the early depth test instead of being shaded and overdrawn
        self._cull_back_faces(True)  # closed, outward-wound meshes: back faces are never seen
        self._draw_characters(self.prog_char, vp)
        self._cull_back_faces(False)
        self._draw_environment(parts)

    def layer_bytes(self) -> int:
        """Bytes of one static layer: RGBA8 colour and a 32-bit depth per sample."""
        return self.width * self.height * max(1, self.samples) * 8

    def _layer_phases(self) -> int:
        """How many static layers a view has (one per beat phase when the figures are in them)."""
        return int(self._beat_frames) if "cut_figures" in self._layer_parts else 1

    def _beat(self, frame: int) -> float:
        """The audience's beat phase at ``frame``: the fraction of a beat, as float32."""
        return float(np.float32((frame / self.anim.fps * self.env.beat_hz) % 1.0))

    def _layer(self, key, beat: float):
        """The static layer of the beat phase ``key`` (None: the one without the figures),
        drawn on first use after ``set_view``."""
        import moderngl
        if key not in self._layers:
            size = (self.width, self.height)
            self._layers[key] = self._own(self.ctx.framebuffer(
                color_attachments=[self._own(self.ctx.renderbuffer(size, 4, samples=self.samples))],
                depth_attachment=self._own(self.ctx.depth_renderbuffer(size, samples=self.samples))))
        fbo = self._layers[key]
        if key not in self._layers_drawn:
            fbo.use()
            self.ctx.viewport = (0, 0, self.width, self.height)
            fbo.clear(*_display(self.env.clear_color), 1.0, depth=1.0)
            self.ctx.enable(moderngl.DEPTH_TEST)
            _set(self.prog_venue, "u_beat", beat)
            self._draw_environment(self._layer_parts)
            self._layers_drawn.add(key)
        return fbo

    def _draw_environment(self, parts) -> None:
        """The floor, venue and walls, those of ``parts`` (names in :data:`_ENV_PARTS`):
        the shadowed and unshadowed ground, the venue's static elements and its audience
        figures, the walls."""
        for name in ("floor_shadowed", "floor_plain"):
            if name in parts and name in self._static:
                self._static[name].render()
        if "cut_static" in parts and self._cut_static:
            self._static["cutaway"].render(vertices=self._cut_static)
        if "cut_figures" in parts and self._cut_count > self._cut_static:
            self._static["cutaway"].render(vertices=self._cut_count - self._cut_static, first=self._cut_static)
        if "walls" in parts and "walls" in self._static:
            self._cull_back_faces(True)
            self._static["walls"].render()
            self._cull_back_faces(False)

    def _shadow_receivers(self, margin: float = 0.3) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) metres: the part of the ground that can receive a character's
        shadow in any frame: the shadow map's footprint, cut down to the characters'
        bounding spheres (over the whole animation, every periodic copy) and their
        projections along the light onto z = 0, grown by ``margin``."""
        fx0, fy0, fx1, fy1 = self._shadow_footprint()
        roots = np.asarray(self.anim.root_translation, dtype=np.float64).reshape(-1, 3)
        if not len(roots) or not np.all(np.isfinite(roots)):
            return fx0, fy0, fx1, fy1
        lo, hi = roots[:, :2].min(axis=0) - _BOUND_RADIUS, roots[:, :2].max(axis=0) + _BOUND_RADIUS
        if self.period:  # wrapped into [-L/2, L/2) and drawn at k * L, k in _COPIES
            lo[0] = -0.5 * self.period + min(_COPIES) * self.period - _BOUND_RADIUS
            hi[0] = 0.5 * self.period + max(_COPIES) * self.period + _BOUND_RADIUS
        top = max(float(roots[:, 2].max()) + _BOUND_RADIUS, 0.0)
        shift = -self.light_dir[:2] / self.light_dir[2] * top  # where the highest point's shadow falls
        lo, hi = np.minimum(lo, lo + shift) - margin, np.maximum(hi, hi + shift) + margin
        return max(fx0, lo[0]), max(fy0, lo[1]), min(fx1, hi[0]), min(fy1, hi[1])

    def _shadow_footprint(self, margin: float = 0.05) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) metres: a rectangle on the ground containing every point the
        shadow map covers (light clip x, y in [-1, 1] at z = 0 and at the lookup's offset
        of 0.02 m along the normal), grown by ``margin``."""
        m = self.light_vp
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

    def render(self, frame: int) -> np.ndarray:
        """The image of ``frame``: (H, W, 3) uint8, first row at the top."""
        return _flip(self.render_raw(frame), self.height, self.width)

    def render_raw(self, frame: int) -> bytes:
        """The image of ``frame`` as raw RGB bytes, bottom row first (what OpenGL reads)."""
        self._draw_frame(frame)
        return self.fbo_out.read(components=3, alignment=1)

    def render_into(self, frame: int, buffer) -> None:
        """Render ``frame`` and start reading it back into a ``moderngl.Buffer`` (a pixel
        pack buffer of W*H*3 bytes). On a GPU the copy runs asynchronously: read the
        buffer after the next frame has been submitted (double buffering)."""
        self._draw_frame(frame)
        self.fbo_out.read_into(buffer, components=3, alignment=1)

    def _draw_frame(self, frame: int) -> None:
        if self.camera is None:
            raise InvalidInputError("no camera: call set_view() with a viewpoint or a free camera first")
        self._load_frame(frame)
        self._shadow_pass()
        vp = self._prepare(frame, upload=False)
        if self.fbo_msaa is not None:
            self._color_pass(vp, self.fbo_msaa)
            self.ctx.copy_framebuffer(self.fbo_out, self.fbo_msaa)
        else:
            self._color_pass(vp, self.fbo_out)

    def overlap(self, frame: int, *, tolerance: float = 0.005, image: bool = True):
        """Overlap view of ``frame``: see :func:`crowdstudy.render.overlap_view.overlap_mask`
        (``image`` False: the mask and fractions only, without rendering the picture)."""
        from crowdstudy.render.overlap_view import OverlapPass
        if self._overlap is None:
            self._overlap = OverlapPass(self)
        return self._overlap.run(frame, tolerance=tolerance, image=image)

    def draw_layers(self) -> int:
        """Draw every static layer of the current view now (else each is drawn on its first
        frame); returns how many. A video's set-up does this, so its frames cost the same."""
        if self.camera is None:
            raise InvalidInputError("no camera: call set_view() with a viewpoint or a free camera first")
        if not self._layer_parts:
            return 0
        import moderngl
        vp = self.camera.view_projection(self.width / self.height)
        eye = tuple(float(v) for v in self.camera.eye)
        for prog in self._lit_programs:
            _set(prog, "u_eye", eye)
            _set(prog, "u_view_proj", _mat(vp))
        self.ctx.disable(moderngl.CULL_FACE)
        n = self._layer_phases()
        for f in range(n):
            beat = self._beat(f)
            self._layer(beat if "cut_figures" in self._layer_parts else None, beat)
        return n

    def character_positions(self, frame: int) -> np.ndarray:
        """(N, 3) pelvis positions in world space as drawn (wrapped for periodic scenes)."""
        return self._wrapped_roots(frame)

    def _own(self, obj):
        self._owned.append(obj)
        return obj

    def release(self) -> None:
        """Free the GL objects (the context stays, for reuse by the thread)."""
        if self._overlap is not None:
            self._overlap.release()
            self._overlap = None
        for obj in reversed(self._owned):
            obj.release()
        self._owned.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


_DRESSED: dict = {}
#: image height (px) from which the characters' surfaces are dressed (cloth, shoes, hair volume)
_DRESS_MIN_HEIGHT = 540


def _dressed(body, codes: np.ndarray, look):
    """:func:`~crowdstudy.render.garments.dress_body`, memoised on the body's record, its
    look and its codes (renderers of the same crowd share the dressed bodies)."""
    key = (body_key(body.record), look, codes.tobytes())
    if key not in _DRESSED:
        if len(_DRESSED) > 256:
            _DRESSED.clear()
        _DRESSED[key] = dress_body(body, codes, look.hair_volume)
    return _DRESSED[key]


def lod_levels(pixels, n_levels: int = len(_LOD_PIXELS) + 1) -> np.ndarray:
    """Level of detail (0 = the finest mesh) of characters ``pixels`` tall on screen: one
    level coarser below each bound of ``_LOD_PIXELS`` (600, then 300 px), at most
    ``n_levels - 1``; a smaller character never gets a finer level than a larger one."""
    p = np.asarray(pixels, dtype=np.float64)
    level = np.zeros(p.shape, dtype=np.int64)
    for k, bound in enumerate(_LOD_PIXELS[:max(0, int(n_levels) - 1)]):
        level[p < bound] = k + 1
    return level


def _beat_period(fps: float, beat_hz: float) -> int | None:
    """Frames after which the audience's bobbing repeats exactly (1 without a beat), or
    None when a beat is not a whole number of frames."""
    if beat_hz <= 0:
        return 1
    frames = float(fps) / float(beat_hz)
    return int(round(frames)) if abs(frames - round(frames)) < 1e-9 and round(frames) >= 1 else None


def _outside(tris: np.ndarray, rect: tuple[float, float, float, float]) -> bool:
    """Whether every vertex of the (V, 10) triangle rows lies outside the floor rectangle
    (x0, y0, x1, y1) m: its bounding box does not reach into it."""
    if not len(tris):
        return True
    lo, hi = tris[:, :2].min(axis=0), tris[:, :2].max(axis=0)
    x0, y0, x1, y1 = rect
    return bool(hi[0] < x0 or lo[0] > x1 or hi[1] < y0 or lo[1] > y1)


def _display(linear) -> tuple[float, float, float]:
    c = np.asarray(linear, dtype=np.float64)
    c = (c * (2.51 * c + 0.03)) / (c * (2.43 * c + 0.59) + 0.14)
    return tuple(float(v) for v in np.sqrt(np.clip(c, 0, 1)))  # as display.glsl


def _flip(raw: bytes, height: int, width: int) -> np.ndarray:
    return np.frombuffer(raw, dtype=np.uint8).reshape(height, width, 3)[::-1].copy()


def baseline_color_positions(path) -> np.ndarray:
    """(N, 2) frame-0 floor positions of an animation file (wrapped into the periodic
    section), the ``color_positions`` that give its corrected version the same colours."""
    from crowdstudy.scene import CrowdAnimation
    anim = CrowdAnimation.load(path)
    pos = np.array(anim.root_translation[0, :, :2])
    if anim.periodic_length:
        length = anim.periodic_length
        pos[:, 0] -= length * np.floor((pos[:, 0] + 0.5 * length) / length)
    return pos


def render_frame(anim, viewpoint, frame: int, *, width: int = 1920, height: int = 1080, overlap_view: bool = False,
                 msaa: int = 4, design=None, body_loader=None, color_positions=None) -> np.ndarray:
    """Render one frame.

    Args:
        anim: CrowdAnimation.
        viewpoint: "V1".."V4" (design viewpoints), a Viewpoint, or a Camera (free camera).
        frame: frame index in [0, T).
        overlap_view: paint the interpenetrating surfaces red (paper Fig. 5).
    Returns:
        (H, W, 3) uint8 image, first row at the top.
    """
    with CrowdRenderer(anim, design=design, width=width, height=height, msaa=msaa, body_loader=body_loader,
                       color_positions=color_positions) as r:
        r.set_view(viewpoint)
        if overlap_view:
            return r.overlap(frame).image
        return r.render(frame)

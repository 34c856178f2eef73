"""GPU resources of the crowd renderer: the programs, textures, buffers and framebuffers
made from the CPU assets (:mod:`crowdstudy.render.assets`) in one moderngl context.

* :class:`GpuObjects`: every GL object a renderer creates, released together.
* :class:`Programs`: the compiled shaders (``shaders/``) and their constant uniforms.
* :func:`paint_albedo`: the characters' albedo texture array, painted on their UVs.
* :class:`CharacterResources`: the per-frame bone texture, the clothing colours, and per
  template group (at each level of detail) its static vertex attributes, faces,
  rest-shape texture and instance buffer (:class:`GroupBuffers`).
* :class:`EnvironmentBuffers`: the floor, walls and cut-away elements as vertex arrays.
* :class:`ShadowMap`: the key light's depth texture and its framebuffer.
* :class:`ColorTargets`: where a frame is drawn and read back, the one place that knows
  about anti-aliasing (4x MSAA by default, resolved into the output).

The passes that draw with these are in :mod:`crowdstudy.render.passes`.
"""

from __future__ import annotations

import dataclasses
import functools
from importlib import resources
from typing import TYPE_CHECKING

import numpy as np

from crowdstudy.render.appearance import paint_textures, texture_size
from crowdstudy.render.assets import COPIES, N_BONES, CharacterMeshes, EnvironmentParts, Lighting
from crowdstudy.render.bodies import BodyGroup
from crowdstudy.render.scene import Environment
from crowdstudy.render.venue import BOB_AMPLITUDE

if TYPE_CHECKING:  # for annotations only: moderngl loads with the first GL context
    import moderngl

__all__ = [
    "GpuObjects",
    "Programs",
    "GroupBuffers",
    "CharacterResources",
    "EnvironmentBuffers",
    "ShadowMap",
    "ColorTargets",
    "paint_albedo",
    "shader_source",
    "compile_program",
    "group_vertex_array",
    "set_uniform",
    "gl_matrix",
    "REST_WIDTH",
    "FXAA_SETTINGS",
]

#: texels per row of a group's rest-shape texture
REST_WIDTH = 4096

#: the FXAA pass's thresholds (``fxaa.frag``): edges with a luma contrast under 1/32, or
#: under 1/8 of the brightest neighbour, are left alone; the sub-pixel blend at 3/4
FXAA_SETTINGS = {"u_edge_min": 1.0 / 32.0, "u_edge_rel": 1.0 / 8.0, "u_subpix": 0.75}


@functools.cache
def shader_source(name: str) -> str:
    """The text of ``shaders/<name>`` (shipped with the package)."""
    return resources.files("crowdstudy.render").joinpath("shaders", name).read_text(encoding="utf-8")


def compile_program(
    ctx, vert: str, frag: str, *, lit_vertex: bool = False, lit_fragment: bool = False, defines: tuple[str, ...] = ()
):
    """Compile a program from the shader files ``vert`` and ``frag``; ``lit_*`` prepend the
    lighting functions (``lighting.glsl``) to that stage, ``defines`` are set to 1 in both."""
    head = "#version 330 core\n" + "".join(f"#define {d} 1\n" for d in defines)
    light = shader_source("lighting.glsl")
    vs = head + ("#define LIT 1\n" + light if lit_vertex else "") + shader_source(vert)
    fs = head + (light if lit_fragment else "") + shader_source("display.glsl") + shader_source(frag)
    return ctx.program(vertex_shader=vs, fragment_shader=fs)


def group_vertex_array(ctx, prog, vbo, inst, ibo):
    """The vertex array of one template group for ``prog`` (a program on ``character.vert``):
    the group's static attributes ``vbo``, its per-instance buffer ``inst``, its faces ``ibo``."""
    return ctx.vertex_array(
        prog,
        [
            (vbo, "4i 4f 4f 2f 3f", "in_joints", "in_weights", "in_scores_a", "in_scores_b", "in_material"),
            (inst, "1i 1i 1f /i", "in_char", "in_member", "in_shift"),
        ],
        index_buffer=ibo,
        index_element_size=4,
        skip_errors=True,
    )


def set_uniform(prog, name: str, value) -> None:
    """Set ``prog``'s uniform ``name`` when the program has it (arrays as float32 bytes)."""
    if name in prog:
        if isinstance(value, np.ndarray):
            prog[name].write(np.ascontiguousarray(value, dtype=np.float32).tobytes())
        else:
            prog[name].value = value


def gl_matrix(m: np.ndarray) -> np.ndarray:
    """Row-major numpy (4, 4) -> the column-major float32 layout GLSL expects."""
    return np.ascontiguousarray(np.asarray(m, dtype=np.float64).T, dtype=np.float32)


class GpuObjects:
    """The GL objects of one renderer in ``ctx``: :meth:`own` records one, :meth:`release`
    frees them all, newest first (the context itself stays, for reuse by the thread)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._objects: list = []

    def own(self, obj):
        self._objects.append(obj)
        return obj

    def release(self) -> None:
        for obj in reversed(self._objects):
            obj.release()
        self._objects.clear()


@dataclasses.dataclass
class Programs:
    """The renderer's programs.

    Characters (``character.vert``): ``character`` (colour; textured bodies lit per pixel,
    region-coloured ones per vertex), its ``variants`` compiled for one kind of template
    group (True: textured, False: region-coloured; llvmpipe runs both sides of a branch on
    a uniform for every sample, so a variant does not pay for the other kind's shading),
    ``depth`` (shadow casters), ``id`` and ``overlap`` (the overlap view). Environment
    (``static.vert``): ``static`` (walls, lit per pixel with the shadow lookup), ``floor``
    (the ground characters' shadows can reach), ``floor_plain`` (the rest of the ground,
    without the shadow lookup), ``venue`` (the cut-away elements, lit per vertex, no
    shadows)."""

    character: moderngl.Program
    variants: dict
    depth: moderngl.Program
    static: moderngl.Program
    floor: moderngl.Program
    floor_plain: moderngl.Program
    venue: moderngl.Program
    id: moderngl.Program
    overlap: moderngl.Program

    @classmethod
    def compile(cls, objects: GpuObjects) -> Programs:
        ctx, own = objects.ctx, objects.own
        character = own(compile_program(ctx, "character.vert", "character.frag", lit_vertex=True, lit_fragment=True))
        variants = {
            kind: own(
                compile_program(
                    ctx, "character.vert", "character.frag", lit_vertex=True, lit_fragment=True, defines=(define,)
                )
            )
            for kind, define in ((True, "TEXTURED_ONLY"), (False, "REGIONS_ONLY"))
        }
        depth = own(compile_program(ctx, "character.vert", "depth.frag"))
        static = own(compile_program(ctx, "static.vert", "static.frag", lit_fragment=True))
        floor = own(compile_program(ctx, "static.vert", "static.frag", lit_fragment=True, defines=("FLOOR",)))
        floor_plain = own(
            compile_program(ctx, "static.vert", "static.frag", lit_fragment=True, defines=("FLOOR", "UNSHADOWED"))
        )
        venue = own(
            compile_program(ctx, "static.vert", "static.frag", lit_vertex=True, defines=("VERTEX_LIT", "UNSHADOWED"))
        )
        return cls(
            character=character,
            variants=variants,
            depth=depth,
            static=static,
            floor=floor,
            floor_plain=floor_plain,
            venue=venue,
            id=own(compile_program(ctx, "character.vert", "id.frag")),
            overlap=own(compile_program(ctx, "character.vert", "overlap.frag")),
        )

    @property
    def lit(self) -> tuple:
        """The programs that light (they take the camera's eye and the light's uniforms)."""
        return (self.character, *self.variants.values(), self.static, self.floor, self.floor_plain, self.venue)

    @property
    def environment(self) -> tuple:
        return self.static, self.floor, self.floor_plain, self.venue

    @property
    def characters(self) -> tuple:
        """The programs on ``character.vert`` (each template group has a vertex array for each)."""
        return (self.character, *self.variants.values(), self.depth, self.id, self.overlap)

    def set_constants(
        self,
        lighting: Lighting,
        env: Environment,
        *,
        shadows: bool,
        shadow_size: int,
        n_characters: int,
        period: float | None,
    ) -> None:
        """The uniforms that stay for the renderer's life: the lights, fog, shadow map,
        texture units, the venue's pool of light and the figures' bob, the crowd's size and
        period."""
        for prog in self.lit:
            set_uniform(prog, "u_light_dir", tuple(lighting.direction))
            set_uniform(prog, "u_light_color", lighting.color)
            set_uniform(prog, "u_sky_color", lighting.sky)
            set_uniform(prog, "u_ground_color", lighting.ground)
            set_uniform(prog, "u_fog_color", tuple(env.clear_color))
            set_uniform(prog, "u_fog_density", lighting.fog_density)
            set_uniform(prog, "u_use_shadows", int(shadows))
            set_uniform(prog, "u_light_view_proj", gl_matrix(lighting.view_proj))
            set_uniform(prog, "u_shadow_texel", 1.0 / shadow_size)
            set_uniform(prog, "u_shadow", 3)
        pool = env.pool
        for prog in self.environment:
            set_uniform(prog, "u_pool", tuple(pool[:4]) if pool else (0.0, 0.0, 0.0, 0.0))
            set_uniform(prog, "u_pool_fade", tuple(pool[4:]) if pool else (0.0, 1.0))
            set_uniform(prog, "u_bob_amplitude", BOB_AMPLITUDE)
        for prog in self.characters:
            set_uniform(prog, "u_bones", 0)
            set_uniform(prog, "u_rest", 1)
            set_uniform(prog, "u_colors", 2)  # character.frag
            set_uniform(prog, "u_albedo", 4)
            set_uniform(prog, "u_n_characters", n_characters)
            set_uniform(prog, "u_period", float(period or 0.0))


def paint_albedo(objects: GpuObjects, bodies: list, looks: list, height: int):
    """The characters' albedo texture array (owned by ``objects``) and, per character, the
    surface codes read from it (see :func:`crowdstudy.render.appearance.paint_textures`);
    the layers are sized for ``height`` px tall images."""
    prog = compile_program(objects.ctx, "paint.vert", "paint.frag")
    try:
        tex, codes = paint_textures(objects.ctx, bodies, looks, prog, size=texture_size(height, len(bodies)))
        return objects.own(tex), codes
    finally:
        prog.release()


@dataclasses.dataclass
class GroupBuffers:
    """One template group at one level of detail on the GPU.

    Attributes:
        group: the CPU template group.
        level: its level of detail (0 = finest); ``coarse``: the last (shadow casters).
        vbo: static attributes (joints, weights, colour-region scores, texture coordinates).
        ibo: faces (uint32). rest: RGBA32F rest positions and normals of every member,
            ``rest_width`` texels per row. vaos: a vertex array per character program.
        inst: instance buffer ((character, member, x shift) per drawn instance), of which
            the first ``count`` are drawn (set by the character pass).
    """

    group: BodyGroup
    level: int
    coarse: bool
    vbo: moderngl.Buffer
    ibo: moderngl.Buffer
    rest: moderngl.Texture
    rest_width: int
    inst: moderngl.Buffer
    vaos: dict
    count: int = 0


class CharacterResources:
    """The characters on the GPU: ``tex_bones`` (RGBA32F, 3 texels per bone and a row per
    character: the only per-frame upload), ``tex_colors`` (RGBA32F (6, N) clothing colours
    of region-coloured bodies), ``tex_albedo`` (the painted texture array), ``groups``
    (:class:`GroupBuffers` of every level of detail, finest first; ``n_levels`` levels)."""

    def __init__(
        self, objects: GpuObjects, meshes: CharacterMeshes, colors: np.ndarray, tex_albedo, programs: Programs
    ):
        import moderngl

        ctx, own = objects.ctx, objects.own
        n = len(colors)
        self.tex_albedo = tex_albedo
        self.tex_bones = own(ctx.texture((3 * N_BONES, n), 4, dtype="f4"))
        self.tex_colors = own(
            ctx.texture(
                (6, n),
                4,
                data=np.concatenate([colors, np.ones((n, 6, 1), np.float32)], axis=2).astype("f4").tobytes(),
                dtype="f4",
            )
        )
        for tex in (self.tex_bones, self.tex_colors):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.n_levels = len(meshes.lods)
        last = self.n_levels - 1
        self.groups = [
            self._group(objects, g, k, k == last, programs) for k, lod in enumerate(meshes.lods) for g in lod.groups
        ]

    @staticmethod
    def _group(objects: GpuObjects, g: BodyGroup, level: int, coarse: bool, programs: Programs) -> GroupBuffers:
        import moderngl

        ctx, own = objects.ctx, objects.own
        material = g.material if g.material is not None else np.zeros((g.n_vertices, 3), np.float32)
        vbo = own(
            ctx.buffer(
                np.concatenate([g.joints.view(np.float32), g.weights, g.scores, material], axis=1)
                .astype(np.float32, copy=False)
                .tobytes()
            )
        )
        ibo = own(ctx.buffer(g.faces.astype(np.uint32).tobytes()))
        texels = g.rest.reshape(-1, 4)
        rows = -(-len(texels) // REST_WIDTH)
        padded = np.zeros((rows * REST_WIDTH, 4), np.float32)
        padded[: len(texels)] = texels
        rest = own(ctx.texture((REST_WIDTH, rows), 4, data=padded.tobytes(), dtype="f4"))
        rest.filter = (moderngl.NEAREST, moderngl.NEAREST)
        inst = own(ctx.buffer(reserve=len(g.members) * len(COPIES) * 12, dynamic=True))
        vaos = {prog: own(group_vertex_array(ctx, prog, vbo, inst, ibo)) for prog in programs.characters}
        return GroupBuffers(
            group=g,
            level=level,
            coarse=coarse,
            vbo=vbo,
            ibo=ibo,
            rest=rest,
            rest_width=REST_WIDTH,
            inst=inst,
            vaos=vaos,
        )

    def upload_bones(self, skinning: np.ndarray) -> None:
        """Upload one frame's (N, 24, 3, 4) skinning matrices."""
        self.tex_bones.write(np.ascontiguousarray(skinning, dtype=np.float32).tobytes())


class EnvironmentBuffers:
    """The environment's triangles as vertex arrays (``vaos``, by part name of
    :class:`~crowdstudy.render.assets.EnvironmentParts`, each on its program), and the
    index buffer ``cut_ibo`` of the cut-away elements a camera keeps (None without any)."""

    def __init__(self, objects: GpuObjects, parts: EnvironmentParts, programs: Programs, n_cut_corners: int):
        ctx, own = objects.ctx, objects.own
        program = {
            "walls": programs.static,
            "cutaway": programs.venue,
            "floor_shadowed": programs.floor,
            "floor_plain": programs.floor_plain,
        }
        self.vaos: dict = {}
        self.cut_ibo = None
        for name, tris in parts.triangles.items():
            if not len(tris):
                continue
            buf = own(ctx.buffer(tris.astype("f4").tobytes()))
            ibo = None
            if name == "cutaway":
                ibo = self.cut_ibo = own(ctx.buffer(reserve=4 * max(1, n_cut_corners), dynamic=True))
            self.vaos[name] = own(
                ctx.vertex_array(
                    program[name],
                    [(buf, "3f 3f 4f", "in_position", "in_normal", "in_color")],
                    index_buffer=ibo,
                    index_element_size=4,
                    skip_errors=True,
                )
            )


class ShadowMap:
    """The key light's ``size`` x ``size`` depth ``texture`` (compared, linearly filtered:
    2x2 percentage-closer filtering per lookup) and its framebuffer ``fbo``."""

    def __init__(self, objects: GpuObjects, size: int):
        import moderngl

        self.size = int(size)
        self.texture = objects.own(objects.ctx.depth_texture((self.size, self.size)))
        self.texture.compare_func = "<="
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.fbo = objects.own(objects.ctx.framebuffer(depth_attachment=self.texture))


class ColorTargets:
    """Where a frame is drawn and read back, the one place that knows about anti-aliasing.

    With MSAA (``samples`` > 0: the ``msaa`` samples asked for, at most what the driver
    supports) the passes draw into the multisampled ``fbo_msaa`` and :meth:`resolve`
    averages it; without, they draw into a single-sampled target. ``post_aa`` "fxaa"
    then smooths the edges into ``fbo_out``, from which the frame is read: the passes draw
    into ``fbo_scene`` (a colour texture) and :meth:`resolve` runs the filter
    (``fxaa.frag``) in two full-screen passes, a copy that marks the edge pixels in
    ``fbo_out``'s depth buffer, then the filter where marked. The static layers are made here too
    (:meth:`layer_framebuffer`), with the draw target's samples, so a frame can start from
    a copy of one."""

    def __init__(self, objects: GpuObjects, width: int, height: int, msaa: int, post_aa: str = "none"):
        ctx, own = objects.ctx, objects.own
        self.objects, self.width, self.height, self.post_aa = objects, width, height, post_aa
        self.samples = int(min(msaa, ctx.max_samples)) if msaa > 1 else 0
        size = (width, height)
        self.fbo_msaa = self.layer_framebuffer() if self.samples else None
        self.fbo_out = own(
            ctx.framebuffer(
                color_attachments=[own(ctx.renderbuffer(size, 4))], depth_attachment=own(ctx.depth_renderbuffer(size))
            )
        )
        self.fbo_scene = self._fxaa = None
        if post_aa == "fxaa":
            import moderngl

            scene = own(ctx.texture(size, 4))
            scene.filter = (moderngl.LINEAR, moderngl.LINEAR)
            scene.repeat_x = scene.repeat_y = False
            depth = own(ctx.depth_renderbuffer(size))
            self.fbo_scene = own(ctx.framebuffer(color_attachments=[scene], depth_attachment=depth))
            passes = []
            for head in ("#define FXAA_MARK 1\n", ""):
                prog = own(
                    ctx.program(
                        vertex_shader="#version 330 core\n" + shader_source("fullscreen.vert"),
                        fragment_shader="#version 330 core\n" + head + shader_source("fxaa.frag"),
                    )
                )
                for name, value in FXAA_SETTINGS.items():
                    set_uniform(prog, name, value)
                set_uniform(prog, "u_texel", (1.0 / width, 1.0 / height))
                set_uniform(prog, "u_color", 7)
                passes.append(own(ctx.vertex_array(prog, [])))
            self._fxaa = (scene, *passes)
        elif post_aa != "none":
            raise ValueError(f"post_aa: expected 'none' or 'fxaa', got {post_aa!r}")

    @property
    def draw(self):
        """The framebuffer the passes draw a frame into."""
        if self.fbo_msaa is not None:
            return self.fbo_msaa
        return self.fbo_scene if self.fbo_scene is not None else self.fbo_out

    def layer_framebuffer(self):
        """A new colour (RGBA8) + depth framebuffer like the draw target."""
        ctx, own = self.objects.ctx, self.objects.own
        size = (self.width, self.height)
        return own(
            ctx.framebuffer(
                color_attachments=[own(ctx.renderbuffer(size, 4, samples=self.samples))],
                depth_attachment=own(ctx.depth_renderbuffer(size, samples=self.samples)),
            )
        )

    def layer_bytes(self) -> int:
        """Bytes of one framebuffer like the draw target: RGBA8 colour and a 32-bit depth per sample."""
        return self.width * self.height * max(1, self.samples) * 8

    def resolve(self) -> None:
        """Finish the frame in ``fbo_out``: average the MSAA samples, then the post-process
        filter (nothing to do without either)."""
        ctx = self.objects.ctx
        if self.fbo_msaa is not None:
            ctx.copy_framebuffer(self.fbo_scene if self.fbo_scene is not None else self.fbo_out, self.fbo_msaa)
        if self._fxaa is not None:
            import moderngl

            scene, mark, blend = self._fxaa
            out = self.fbo_out
            out.use()
            ctx.viewport = (0, 0, self.width, self.height)
            ctx.disable(moderngl.CULL_FACE)
            ctx.enable(moderngl.DEPTH_TEST)
            scene.use(7)
            # every pixel copied, the edge pixels marked in the depth buffer (0)...
            ctx.depth_func = "1"
            mark.render(moderngl.TRIANGLES, vertices=3)
            # ... and filtered where marked: the triangle at depth 0.5 passes the early
            # depth test there only, so the rasteriser skips the unmarked blocks' shading
            ctx.depth_func = ">"
            out.depth_mask = False
            blend.render(moderngl.TRIANGLES, vertices=3)
            out.depth_mask = True
            ctx.depth_func = "<"

    def read(self) -> bytes:
        """The output as raw RGB bytes, bottom row first."""
        return self.fbo_out.read(components=3, alignment=1)

    def read_into(self, buffer) -> None:
        """Start reading the output into a ``moderngl.Buffer`` of W*H*3 bytes."""
        self.fbo_out.read_into(buffer, components=3, alignment=1)

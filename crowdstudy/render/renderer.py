"""The crowd renderer: :class:`CrowdRenderer` draws a CrowdAnimation frame by frame.

It orchestrates three layers, each in its own module:

* CPU assets (:mod:`crowdstudy.render.assets`): the validated options, the loaded bodies,
  their clothing colours and looks, the dressed surfaces and their levels of detail, the
  key light, the environment's triangles split by how they are drawn. Plain numpy.
* GPU resources (:mod:`crowdstudy.render.gpu`): the programs, the painted albedo
  textures, the characters' buffers and textures, the environment's vertex arrays, the
  shadow map and the colour targets (the one place that knows about MSAA and its resolve).
* Passes (:mod:`crowdstudy.render.passes`, :mod:`crowdstudy.render.overlap_view`): shadow,
  characters, environment, static layers, colour, and the overlap view's id and overlap
  passes.

Per frame the CPU uploads one RGBA32F texture of skinning matrices (3 rows of 4 floats per
bone, one texture row per character, 69 KB for 60 characters) and the list of visible
instances; each body template group is drawn with ONE instanced call, in a shadow pass, a
colour pass (4x MSAA by default) and, for the overlap view, an id pass and an overlap pass.

Shading (``shaders/``, all in linear RGB, then an ACES-like tone curve and a square root
for display): a key light with a shadow map, a sky/ground hemisphere ambient and distance
fog. The textured characters (the MakeHuman bodies: a painted albedo per character) are lit
per pixel: diffuse key light, ambient, a faint rim and a specular highlight; only their
shadow factor is looked up per vertex (4 filtered taps) and interpolated. Region-coloured
bodies (the generated mannequins) take the same terms per vertex and choose their colour
region per pixel. The ground and the corridor's walls are lit per pixel; the venue's
cut-away elements per vertex, without shadows.

Periodic scenes (the corridor): every character is wrapped into the visible section
[-L/2, L/2) along x and drawn at offsets k*L, k in -2..2 (instances outside the view
frustum are culled), so the crowd looks continuous and nothing pops at the seams.

The concert venue's cut-away elements (stage, hall fittings, about 290 audience figures;
:mod:`crowdstudy.render.venue`) are drawn through an index buffer that ``set_view`` fills
with the elements that stand neither between the camera and the crowd nor next to the
camera, nearest first.

Levels of detail (:func:`~crowdstudy.render.assets.lod_levels`): body meshes are
decimated once per template (``max_faces``, 3000 at 1080p, hardly distinguishable from the
full mesh there; the cost of a frame on a CPU rasteriser grows with the triangle count);
characters less than 600 (300) pixels tall on screen are drawn with half (a quarter) of
the faces; shadow casters always with the coarsest mesh.

The ground is split at the rectangle that the characters' shadows can reach (over the
whole animation); only that part is shaded with the shadow-map lookup, the rest with a
variant compiled without it (the same picture for less work).

Static layers: what the characters do not change (the unshadowed ground, the venue's stage
and hall, the audience figures at each of the 15 phases of their bob, walls no shadow can
reach) is drawn once per view into multisampled colour + depth framebuffers; a frame starts
from a copy of its phase's layer and draws only the characters, the shadowed ground and
what else moves (byte for byte the picture drawn from scratch, but for the odd pixel where
two surfaces meet at the same depth; ``static_layer=False`` draws it all every frame).
The layers take 66 MB each at 1080p with 4x MSAA (1 GB for the concert's 15).

Shader variants: the characters' program is also compiled once per kind of template group
(textured, region-coloured), so llvmpipe, which runs both sides of a branch on a uniform
for every MSAA sample, does not pay for the other kind's shading (the same bytes).
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.render.assets import (
    CharacterMeshes,
    CrowdAssets,
    EnvironmentParts,
    FrameBones,
    Lighting,
    RenderOptions,
    wrapped_roots,
)
from crowdstudy.render.camera import Camera, frame_viewpoint
from crowdstudy.render.context import get_context
from crowdstudy.render.gpu import (
    CharacterResources,
    ColorTargets,
    EnvironmentBuffers,
    GpuObjects,
    Programs,
    ShadowMap,
    paint_albedo,
)
from crowdstudy.render.passes import CharacterPass, ColorPass, EnvironmentPass, ShadowPass, StaticLayers
from crowdstudy.render.venue import visible_indices

__all__ = ["CrowdRenderer", "render_frame", "resolve_camera", "baseline_color_positions"]


def resolve_camera(view, design, env_extent: tuple[float, float], aspect: float) -> Camera:
    """A :class:`Camera` from a viewpoint id ("V1".."V4"), a Viewpoint, or a Camera."""
    if isinstance(view, Camera):
        return view
    if isinstance(view, str):
        if view not in design.viewpoints:
            raise InvalidInputError(
                f"viewpoint: unknown viewpoint {view!r}; the design defines "
                f"{', '.join(design.viewpoints)} (or use a free camera)"
            )
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
        post_aa: "none", or "fxaa": smooth the finished frame's edges with a full-screen
            pass (with ``msaa`` 0, a fraction of MSAA's cost on a CPU rasteriser).
        detail_height: the image height that chooses the characters' detail (texture
            size, faces, levels of detail); default ``height``. The supersampled reference
            of a frame (:mod:`crowdstudy.render.fidelity`) is rendered larger with the
            detail of the frame it checks.
        lod_scale: characters keep each finer level of detail while this many times taller
            on screen than :data:`~crowdstudy.render.assets.LOD_PIXELS` says (0: all at the
            finest level, as the supersampled reference draws them).

    The parts it is made of are attributes: ``options``, ``assets``, ``meshes``,
    ``lighting`` (CPU); ``programs``, ``character_resources``, ``shadow_map``, ``targets``
    (GPU); ``characters``, ``shadow_pass``, ``environment``, ``layers``, ``color_pass``.
    """

    def __init__(
        self,
        anim,
        *,
        design=None,
        width: int = 1920,
        height: int = 1080,
        msaa: int = 4,
        shadows: bool = True,
        shadow_size: int = 2048,
        body_loader=None,
        color_seed: int | None = None,
        max_faces: int | str | None = "auto",
        color_positions=None,
        static_layer: bool = True,
        post_aa: str = "none",
        detail_height: int | None = None,
        lod_scale: float = 1.0,
    ):
        self.options = opts = RenderOptions.validated(
            width=width,
            height=height,
            msaa=msaa,
            shadows=shadows,
            shadow_size=shadow_size,
            max_faces=max_faces,
            static_layer=static_layer,
            post_aa=post_aa,
            detail_height=detail_height,
            lod_scale=lod_scale,
        )
        self.width, self.height, self.shadows = opts.width, opts.height, opts.shadows
        self.assets = a = CrowdAssets.build(
            anim, design, body_loader=body_loader, color_seed=color_seed, color_positions=color_positions
        )
        self.ctx = ctx = get_context()
        self.gpu = gpu = GpuObjects(ctx)
        self._overlap = None
        self.camera: Camera | None = None
        self._bones = FrameBones(a.anim, a.bodies)
        # what each character wears, painted once on its UVs (textured bodies); the drawn
        # surface dressed to match
        tex_albedo, codes = paint_albedo(gpu, a.bodies, a.looks, opts.detail_height)
        self.meshes = CharacterMeshes.build(
            a.bodies, a.looks, codes, height=opts.detail_height, max_faces=opts.max_faces
        )
        self.lighting = Lighting.for_scene(a.env, a.period)
        self.programs = programs = Programs.compile(gpu)
        self.character_resources = CharacterResources(gpu, self.meshes, a.colors, tex_albedo, programs)
        self.shadow_map = ShadowMap(gpu, opts.shadow_size)
        parts = EnvironmentParts.build(a.anim, a.env, self.lighting, shadows=opts.shadows)
        buffers = EnvironmentBuffers(gpu, parts, programs, len(a.env.cutaway.indices))
        self.targets = ColorTargets(gpu, opts.width, opts.height, opts.msaa, opts.post_aa)
        programs.set_constants(
            self.lighting,
            a.env,
            shadows=opts.shadows,
            shadow_size=opts.shadow_size,
            n_characters=a.anim.n_characters,
            period=a.period,
        )
        # the passes
        self.characters = CharacterPass(
            ctx,
            self.character_resources,
            programs,
            period=a.period,
            height=opts.detail_height,
            lod_scale=opts.lod_scale,
        )
        self.shadow_pass = ShadowPass(
            ctx,
            self.shadow_map,
            self.characters,
            self.lighting.view_proj,
            self.lighting.direction,
            enabled=opts.shadows,
        )
        self.environment = EnvironmentPass(ctx, buffers, programs, a.env, a.anim.fps)
        self.layers = StaticLayers(
            ctx, self.targets, self.environment, enabled=opts.static_layer, walls_static=parts.walls_static
        )
        self.color_pass = ColorPass(
            ctx, programs, self.characters, self.environment, self.layers, self.shadow_map, self.targets
        )

    # -- the CPU assets, by their names --------------------------------------------------
    anim = property(lambda self: self.assets.anim, doc="The animation.")
    design = property(lambda self: self.assets.design, doc="The study design.")
    env = property(lambda self: self.assets.env, doc="The scenario's environment.")
    period = property(lambda self: self.assets.period, doc="The corridor's periodic length (m), else None.")
    bodies = property(lambda self: self.assets.bodies, doc="The N loaded bodies.")
    colors = property(lambda self: self.assets.colors, doc="(N, 6, 3) float32 linear-RGB clothing colours.")
    looks = property(lambda self: self.assets.looks, doc="What each character wears (Appearance).")
    drawn_bodies = property(lambda self: self.meshes.drawn_bodies, doc="The bodies as drawn (dressed).")
    surface_codes = property(lambda self: self.meshes.surface_codes, doc="Per character, what each vertex shows.")
    groups = property(lambda self: self.meshes.groups, doc="The template groups of the finest level of detail.")
    max_faces = property(lambda self: self.meshes.max_faces, doc="Faces per template of the finest level.")
    samples = property(lambda self: self.targets.samples, doc="MSAA samples per pixel (0 = off).")

    # -- camera --------------------------------------------------------------------------
    def set_view(self, view) -> Camera:
        """Use a viewpoint id ("V1".."V4"), a design Viewpoint or a :class:`Camera`."""
        self.camera = resolve_camera(view, self.design, self.env.extent, self.width / self.height)
        if self.environment.has_cutaway:  # the cutaway: drop the elements between this camera and the crowd
            self.set_cutaway(
                visible_indices(
                    self.env.cutaway,
                    self.camera.eye,
                    self.env.extent,
                    self.camera.view_projection(self.width / self.height),
                )
            )
        self.layers.invalidate()
        return self.camera

    def set_cutaway(self, indices) -> None:
        """Draw these triangle corners (rows of ``env.cutaway.vertices``, in drawing order)
        of the venue's cut-away elements; ``set_view`` sets the camera's. Their static
        triangles go first (into the static layer), the audience figures' after them."""
        self.environment.set_cutaway(indices)
        self.layers.invalidate()

    def _require_camera(self) -> Camera:
        if self.camera is None:
            raise InvalidInputError("no camera: call set_view() with a viewpoint or a free camera first")
        return self.camera

    # -- frames --------------------------------------------------------------------------
    def skinning(self, frame: int) -> np.ndarray:
        """(N, 24, 3, 4) float32 skinning matrices of ``frame`` (periodic scenes wrapped)."""
        return self._bones(frame)

    def character_positions(self, frame: int) -> np.ndarray:
        """(N, 3) pelvis positions in world space as drawn (wrapped for periodic scenes)."""
        return wrapped_roots(self.anim, frame)

    def load_frame(self, frame: int) -> None:
        """Upload the skinning matrices of ``frame``."""
        self.character_resources.upload_bones(self.skinning(frame))

    def prepare(self, frame: int, *, upload: bool = True) -> np.ndarray:
        """Upload the frame's bones (unless ``upload`` is False: done) and select the
        camera's instances; the camera's (4, 4) world-to-clip matrix."""
        camera = self._require_camera()
        if upload:
            self.load_frame(frame)
        vp = camera.view_projection(self.width / self.height)
        self.characters.select(self.character_positions(frame), vp, camera)
        return vp

    def draw_shadows(self, frame: int) -> None:
        """The shadow map of ``frame`` (its bones loaded): the casters whose shadow can fall
        into the camera's view."""
        camera = self._require_camera()
        vp = camera.view_projection(self.width / self.height)
        self.shadow_pass.run(self.character_positions(frame), camera, vp)

    def _draw_frame(self, frame: int) -> None:
        camera = self._require_camera()
        self.load_frame(frame)
        self.draw_shadows(frame)
        vp = self.prepare(frame, upload=False)
        self.color_pass.run(self.targets.draw, vp, camera.eye, self.environment.beat(frame))
        self.targets.resolve()

    def render(self, frame: int) -> np.ndarray:
        """The image of ``frame``: (H, W, 3) uint8, first row at the top."""
        return _flip(self.render_raw(frame), self.height, self.width)

    def render_raw(self, frame: int) -> bytes:
        """The image of ``frame`` as raw RGB bytes, bottom row first (what OpenGL reads)."""
        self._draw_frame(frame)
        return self.targets.read()

    def render_into(self, frame: int, buffer) -> None:
        """Render ``frame`` and start reading it back into a ``moderngl.Buffer`` (a pixel
        pack buffer of W*H*3 bytes). On a GPU the copy runs asynchronously: read the
        buffer after the next frame has been submitted (double buffering)."""
        self._draw_frame(frame)
        self.targets.read_into(buffer)

    def overlap(self, frame: int, *, tolerance: float = 0.005, image: bool = True):
        """Overlap view of ``frame`` (an :class:`~crowdstudy.render.overlap_view.OverlapFrame`;
        the rule is :mod:`crowdstudy.render.overlap_view`'s); ``tolerance`` (m) how deep a
        surface point must lie inside another character to count; ``image`` False: the
        mask and fractions only, without rendering the picture."""
        from crowdstudy.render.overlap_view import OverlapPass, capsules_from_skinning, overlap_frame

        if self._overlap is None:
            self._overlap = OverlapPass(self.ctx, self.characters, self.width, self.height, self.anim.n_characters)
        if image:
            picture = self.render(frame)  # the normal look; also the frame's bones and instances
        else:
            picture = None
            self.prepare(frame)  # the camera's instances, as render leaves them
        capsules = capsules_from_skinning(self.bodies, self.skinning(frame))
        vp = self._require_camera().view_projection(self.width / self.height)
        mask, crowd_pixels = self._overlap.run(vp, capsules, tolerance=tolerance)
        return overlap_frame(picture, mask, crowd_pixels)

    # -- static layers -------------------------------------------------------------------
    def layer_bytes(self) -> int:
        """Bytes of one static layer: RGBA8 colour and a 32-bit depth per sample."""
        return self.targets.layer_bytes()

    def draw_layers(self) -> int:
        """Draw every static layer of the current view now (else each is drawn on its first
        frame); returns how many. A video's set-up does this, so its frames cost the same."""
        camera = self._require_camera()
        if not self.layers.parts:
            return 0
        import moderngl

        self.color_pass.bind_camera(camera.view_projection(self.width / self.height), camera.eye)
        self.ctx.disable(moderngl.CULL_FACE)
        n = self.layers.phases()
        for f in range(n):
            self.layers.get(self.environment.beat(f))
        return n

    def release(self) -> None:
        """Free the GL objects (the context stays, for reuse by the thread)."""
        if self._overlap is not None:
            self._overlap.release()
            self._overlap = None
        self.gpu.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _flip(raw: bytes, height: int, width: int) -> np.ndarray:
    return np.frombuffer(raw, dtype=np.uint8).reshape(height, width, 3)[::-1].copy()


def baseline_color_positions(path) -> np.ndarray:
    """(N, 2) frame-0 floor positions of an animation file (wrapped into the periodic
    section), the ``color_positions`` that give its corrected version the same colours."""
    from crowdstudy.scene import CrowdAnimation

    return wrapped_roots(CrowdAnimation.load(path), 0)[:, :2].copy()


def render_frame(
    anim,
    viewpoint,
    frame: int,
    *,
    width: int = 1920,
    height: int = 1080,
    overlap_view: bool = False,
    msaa: int = 4,
    design=None,
    body_loader=None,
    color_positions=None,
) -> np.ndarray:
    """Render one frame.

    Args:
        anim: CrowdAnimation.
        viewpoint: "V1".."V4" (design viewpoints), a Viewpoint, or a Camera (free camera).
        frame: frame index in [0, T).
        overlap_view: paint the interpenetrating surfaces red (paper Fig. 5).
    Returns:
        (H, W, 3) uint8 image, first row at the top.
    """
    with CrowdRenderer(
        anim,
        design=design,
        width=width,
        height=height,
        msaa=msaa,
        body_loader=body_loader,
        color_positions=color_positions,
    ) as r:
        r.set_view(viewpoint)
        if overlap_view:
            image = r.overlap(frame).image
            if image is None:  # overlap() draws the picture unless asked for the mask alone
                raise RuntimeError("the overlap view drew no picture")
            return image
        return r.render(frame)

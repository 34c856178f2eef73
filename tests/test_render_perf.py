"""The renderer's shortcuts keep the picture: static layers, per-kind shader variants, the
level of detail by screen size, the mask-only overlap samples, the pipelined encoder."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from render_fixtures import H, W, crowd_animation, grid_positions, mannequin_loader, mannequin_renderer  # noqa: E402

from crowdstudy.design import load_design  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return load_design()


def test_lod_level_by_screen_size_is_monotone_and_deterministic():
    from crowdstudy.render.assets import lod_levels

    pixels = np.linspace(2000.0, 1.0, 500)  # characters ever smaller on screen
    levels = lod_levels(pixels)
    assert np.all(np.diff(levels) >= 0), "a smaller character got a finer mesh"
    assert levels[0] == 0 and levels[-1] == 2 and set(levels.tolist()) == {0, 1, 2}
    assert lod_levels([600.0, 599.9, 300.0, 299.9]).tolist() == [0, 1, 1, 2]
    assert np.array_equal(lod_levels(pixels[::-1])[::-1], levels)
    assert lod_levels([10.0], n_levels=2).tolist() == [1] and lod_levels([10.0], n_levels=1).tolist() == [0]


def test_renderer_draws_each_character_at_its_screen_size_level(design):
    """A crowd seen from V1: the near characters use finer meshes than the far ones, and
    every visible character is drawn exactly once."""
    from crowdstudy.render.assets import lod_levels

    anim = crowd_animation(grid_positions(12, margin=0.45), n_frames=1)
    with mannequin_renderer(anim, design, width=1920, height=1080, msaa=0, shadows=False, max_faces=1200) as r:
        r.set_view("V1")
        r.prepare(0)
        by_level = {}
        for gl in r.character_resources.groups:
            by_level[gl.level] = by_level.get(gl.level, 0) + gl.count
        eye = np.asarray(r.camera.eye)
        focal = r.height / (2.0 * np.tan(np.radians(r.camera.fov) / 2.0))
        size = focal * 1.8 / np.linalg.norm(r.character_positions(0) - eye, axis=1)
        expected = np.bincount(lod_levels(size, len(r.meshes.lods)), minlength=len(r.meshes.lods))
    assert sum(by_level.values()) == anim.n_characters
    assert [by_level.get(k, 0) for k in range(len(expected))] == expected.tolist()
    assert len(np.flatnonzero(expected)) >= 2, "the scene should span two levels of detail"


@pytest.mark.parametrize("view", ["V1", "V2", "V3", "V4"])
def test_static_layers_give_the_per_frame_picture(design, view):
    """Frames drawn over the static layers (one per beat phase of the audience) equal
    frames drawn from scratch, over more than one beat; a handful of pixels may differ where
    two surfaces meet at the same depth (drawn in another order)."""
    anim = crowd_animation(grid_positions(10, margin=0.45), n_frames=20)
    with (
        mannequin_renderer(anim, design, msaa=4) as layered,
        mannequin_renderer(anim, design, msaa=4, static_layer=False) as plain,
    ):
        for r in (layered, plain):
            r.set_view(view)
        assert layered.layers.phases() == 15 and "cut_figures" in layered.layers.parts
        assert not plain.layers.parts
        for f in (0, 7, 15, 19):
            a, b = layered.render(f).astype(int), plain.render(f).astype(int)
            diff = np.abs(a - b).max(axis=2)
            assert np.mean(diff > 0) < 2e-3, f"frame {f}: {np.mean(diff > 0):.4f} of the pixels differ"
            assert np.mean(diff > 2) < 1e-3
        assert len(layered.layers.layers) == len({f % 15 for f in (0, 7, 15, 19)})  # drawn on first use


def _corridor(n_frames: int):
    """Six walkers in a 4 m periodic corridor (drawn as five copies along it)."""
    return crowd_animation(
        grid_positions(6, extent=(4.0, 3.0), margin=0.45),
        n_frames=n_frames,
        scenario="corridor",
        period=4.0,
        velocity=(1.0, 0.0),
    )


def test_static_layers_follow_the_camera_and_the_corridor_walls(design):
    """set_view redraws the layers; in the corridor the walls, which the characters'
    shadows reach, stay in the per-frame pass."""
    anim = _corridor(n_frames=3)
    with mannequin_renderer(anim, design) as layered, mannequin_renderer(anim, design, static_layer=False) as plain:
        assert "walls" not in layered.layers.parts
        for view in ("V3", "V4"):
            for r in (layered, plain):
                r.set_view(view)
            for f in (0, 2):
                diff = np.abs(layered.render(f).astype(int) - plain.render(f).astype(int)).max(axis=2)
                assert np.mean(diff > 2) < 1e-3, f"{view} frame {f}"


def test_draw_layers_draws_each_beat_phase_once(design):
    anim = crowd_animation(grid_positions(4, margin=0.45), n_frames=2)
    with mannequin_renderer(anim, design) as r:
        with pytest.raises(Exception, match="set_view"):
            r.draw_layers()
        r.set_view("V2")
        assert r.draw_layers() == 15
        assert len(r.layers.layers) == 15 and len(r.layers.drawn) == 15
        before = r.render(1)
        r.set_view("V2")  # the same camera again: layers drawn anew
        assert not r.layers.drawn
        assert np.array_equal(r.render(1), before)
        assert len(r.layers.layers) == 15  # ... into the same framebuffers


def test_shader_variants_equal_the_branching_program(design):
    """The per-kind programs (textured / region-coloured) draw the same bytes as the one
    program that branches on u_textured."""
    anim = crowd_animation(grid_positions(8, margin=0.45), n_frames=1)
    with mannequin_renderer(anim, design) as r:
        r.set_view("V1")
        a = r.render(0)
        r.characters.per_kind = False
        b = r.render(0)
    assert np.array_equal(a, b)


def test_overlap_mask_without_the_picture_is_the_same(design):
    pos = np.array([[0.0, 0.0], [0.25, 0.0], [1.0, 1.0]])  # two interpenetrating characters
    anim = crowd_animation(pos, n_frames=2)
    with mannequin_renderer(anim, design) as r:
        r.set_view("V3")
        full = r.overlap(1)
        r.render(0)  # another frame's state in between
        quick = r.overlap(1, image=False)
    assert quick.image is None and full.image is not None
    assert full.red_fraction > 0
    assert np.array_equal(full.mask, quick.mask) and full.red_fraction == quick.red_fraction
    assert full.crowd_fraction == quick.crowd_fraction


def test_pipelined_encode_gives_the_serial_bytes(design, tmp_path):
    """render_video (two pixel-pack buffers, a writer thread, ffmpeg in its own process)
    writes the same file as rendering each frame and writing it in turn."""
    from crowdstudy.render.video import VideoWriter, render_video, sha256_file

    anim = crowd_animation(grid_positions(6, margin=0.45), n_frames=8)
    res = render_video(
        anim,
        "V3",
        tmp_path / "pipelined.mp4",
        width=W,
        height=H,
        design=design,
        progress=False,
        body_loader=mannequin_loader,
        preset="superfast",
    )
    with mannequin_renderer(anim, design) as r:
        r.set_view("V3")
        writer = VideoWriter(tmp_path / "serial.mp4", W, H, 30.0, preset="superfast", crf=18)
        for f in range(anim.n_frames):
            writer.write(r.render_raw(f))
        writer.close()
    assert res["frames"] == 8
    assert sha256_file(tmp_path / "pipelined.mp4") == sha256_file(tmp_path / "serial.mp4")
    t = res["timings"]
    assert {"setup_wall_s", "setup_cpu_s", "first_frame_cpu_s", "frames_cpu_s", "red_wall_s"} <= set(t)
    assert all(v >= 0 for v in t.values())


def test_overlap_bisection_marks_the_pixels_of_the_full_scan(design, monkeypatch):
    """overlap.frag bisects a hidden fragment's sorted candidates to the visible character's
    capsules; compiled to scan them all (OVERLAP_SCAN_ALL), it marks the same pixels."""
    import crowdstudy.render.gpu as gpu_module

    anim = crowd_animation(grid_positions(16, extent=(1.6, 1.6), margin=0.2, seed=3), n_frames=2)
    compile_program = gpu_module.compile_program

    def with_define(ctx, vert, frag, **kw):
        if frag == "overlap.frag":
            kw["defines"] = (*kw.get("defines", ()), "OVERLAP_SCAN_ALL")
        return compile_program(ctx, vert, frag, **kw)

    masks = []
    for scan_all in (False, True):
        if scan_all:
            monkeypatch.setattr(gpu_module, "compile_program", with_define)
        with mannequin_renderer(anim, design, width=384, height=216) as r:
            r.set_view("V3")
            masks.append([r.overlap(f, image=False).mask for f in (0, 1)])
    for fast, full in zip(*masks, strict=True):
        assert full.mean() > 0.005, "the crowd should interpenetrate"
        assert np.array_equal(fast, full)


def test_taking_the_character_pass_apart_leaves_the_renderer_as_it_was(design):
    """``crowdstudy bench render``'s probe of the characters' pass (a 1x1 scissor, a
    constant-colour program) draws into the renderer's own buffers: afterwards the picture,
    the scissor and the vertex arrays are as before, and every part it reports is a duration
    (their sizes are the benchmark's, not a test's)."""
    from crowdstudy.bench import load_benchmark

    probe = load_benchmark("render")
    anim = crowd_animation(grid_positions(8, margin=0.45), n_frames=2)
    with mannequin_renderer(anim, design) as r:
        r.set_view("V1")
        before = r.render(1)
        keys = [set(gl.vaos) for gl in r.character_resources.groups]
        parts = probe._character_parts(r, 1, reps=1)
        assert [set(gl.vaos) for gl in r.character_resources.groups] == keys
        assert r.ctx.scissor == (0, 0, r.width, r.height) or r.ctx.scissor is None
        after = r.render(1)
    assert set(parts) == {"full", "vertex+setup", "constant-colour fragments", "fragments", "shading"}
    assert all(np.isfinite(v) for v in parts.values()) and parts["full"] > 0
    assert parts["fragments"] == pytest.approx(parts["full"] - parts["vertex+setup"])
    assert np.array_equal(before, after)


def test_overlap_owner_boxes_hold_their_owners_capsules():
    """The boxes overlap.frag skips owners by: each owner's range of a character's sorted
    candidates holds that owner's capsules only, and its box holds every one of them
    (ends widened by the radius); a character without candidates has no owners."""
    from crowdstudy.render.overlap_view import _candidates, _capsule_boxes, _owner_boxes

    rng = np.random.default_rng(4)
    n = 6
    centre = np.c_[rng.uniform(0, 1.2, n), rng.uniform(0, 1.2, n), np.ones(n)]
    centre[-1] = [40.0, 40.0, 1.0]  # far from everyone: no candidates
    start = centre[:, None, :] + rng.normal(0, 0.2, (n, 24, 3))
    end = start + rng.normal(0, 0.1, (n, 24, 3))
    radius = rng.uniform(0.03, 0.12, (n, 24))
    cand = _candidates(start, end, _capsule_boxes(start, end, radius), None)
    boxes = _owner_boxes(_capsule_boxes(start, end, radius), cand)
    assert cand[-1, 0] == 0 and boxes[-1, 0, 0] == 0
    for a in range(n - 1):
        ids = cand[a, 1 : 1 + int(cand[a, 0])].astype(int)
        n_owners = int(boxes[a, 0, 0])
        assert n_owners == len(np.unique(ids // 24)) > 0
        covered = 0
        for k in range(n_owners):
            lo, hi = boxes[a, 1 + 2 * k], boxes[a, 2 + 2 * k]
            part = ids[int(lo[3]) : int(hi[3])]
            assert len(np.unique(part // 24)) == 1
            o, b = part // 24, part % 24
            for pts in (start[o, b], end[o, b]):
                assert np.all(pts - radius[o, b, None] >= lo[:3] - 1e-5) and np.all(
                    pts + radius[o, b, None] <= hi[:3] + 1e-5
                )
            covered += len(part)
        assert covered == len(ids)


def test_shadow_casters_are_culled_to_the_view_without_changing_a_pixel(design):
    """In the corridor (five periodic copies) the shadow pass draws only the casters whose
    shadow can reach the camera's view; the picture equals the one drawn with every caster
    in the light's frustum, and the copies far along the corridor are left out."""
    anim = _corridor(n_frames=2)

    def casters(r):
        return sum(gl.count for gl in r.character_resources.groups if gl.coarse)

    with mannequin_renderer(anim, design) as r:
        for view in ("V1", "V3"):
            r.set_view(view)
            culled = r.render(1)
            r.load_frame(1)
            r.draw_shadows(1)
            n_culled = casters(r)
            r.shadow_pass.run(r.character_positions(1), r.camera)  # every caster in the light's frustum
            n_all = casters(r)
            vp = r.prepare(1, upload=False)
            r.color_pass.run(r.targets.draw, vp, r.camera.eye, r.environment.beat(1))
            r.targets.resolve()
            every = np.frombuffer(r.targets.read(), np.uint8).reshape(r.height, r.width, 3)[::-1]
            assert np.array_equal(culled, every), view
            assert 0 < n_culled < n_all, (view, n_culled, n_all)


def test_the_constant_colour_probe_draws_the_characters_where_the_renderer_does(design):
    """The breakdown's constant-colour program runs the characters' vertex stage as the
    renderer's program does: the same depth at every pixel."""
    from crowdstudy.bench import load_benchmark
    from crowdstudy.render.gpu import group_vertex_array

    probe = load_benchmark("render")
    anim = crowd_animation(grid_positions(8, margin=0.45), n_frames=2)
    with mannequin_renderer(anim, design, msaa=0) as r:  # a depth buffer glReadPixels reads
        r.set_view("V1")
        r.render(1)
        flat = probe._constant_colour_program(r.ctx)
        for gl in r.character_resources.groups:
            gl.vaos[flat] = group_vertex_array(r.ctx, flat, gl.vbo, gl.inst, gl.ibo)
        vp = r.prepare(1)
        depths = []
        for prog in (r.programs.character, flat):
            fbo = probe._bind_frame_target(r, vp)
            fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
            probe._draw_characters(r, prog, vp)
            depths.append(np.frombuffer(fbo.read(attachment=-1, components=1, dtype="f4"), np.float32))
        for gl in r.character_resources.groups:
            gl.vaos.pop(flat).release()
        flat.release()
    assert 0.01 < np.mean(depths[0] < 1.0) < 0.9
    assert np.array_equal(depths[0], depths[1])

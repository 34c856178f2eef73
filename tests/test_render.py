"""Renderer tests: frames, cameras, overlap view, MP4 output, bad input (tiny sizes)."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_fixtures import H, W, crowd_animation, grid_positions, mannequin_loader, mannequin_renderer  # noqa: E402

from crowdstudy.body.skeleton import JOINT_NAMES  # noqa: E402
from crowdstudy.design import load_design  # noqa: E402
from crowdstudy.errors import InvalidInputError, MissingDependencyError  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def concert():
    return crowd_animation(grid_positions(12, margin=0.45), n_frames=6)


@pytest.mark.parametrize("view", ["V1", "V2", "V3", "V4"])
def test_frame_is_not_blank_and_frames_every_character(concert, design, view):
    with mannequin_renderer(concert, design) as r:
        cam = r.set_view(view)
        img = r.render(2)
        empty = mannequin_renderer(concert.replace(root_translation=concert.root_translation + [0, 0, -50.0]), design)
        empty.set_view(view)
        background = empty.render(2)
        empty.release()
    assert img.shape == (H, W, 3) and img.dtype == np.uint8
    assert img.std() > 10, "the frame is (nearly) uniform"
    # every character's feet and head project inside the image ...
    roots = concert.root_translation[2]
    for z in (0.02, 1.75):
        px, front = cam.project(np.c_[roots[:, :2], np.full(len(roots), z)], W, H)
        assert front.all()
        assert np.all((px[:, 0] >= 0) & (px[:, 0] < W) & (px[:, 1] >= 0) & (px[:, 1] < H)), px
    # ... and the crowd changes the image where it stands
    diff = np.abs(img.astype(int) - background.astype(int)).sum(axis=2) > 30
    assert 0.02 < diff.mean() < 0.9
    px, _ = cam.project(np.c_[roots[:, :2], np.full(len(roots), 1.0)], W, H)
    ix = np.clip(px.astype(int), 0, [W - 1, H - 1])
    assert diff[ix[:, 1], ix[:, 0]].mean() > 0.5


def _pinhole(points, eye, target, fov, width, height):
    """Pixel (x right, y down) of world points for a camera at ``eye`` looking at ``target``
    (+z up, vertical field of view ``fov`` deg): plain pinhole geometry, independent of
    crowdstudy.render.camera."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(points, float) - eye
    depth = d @ forward
    f = 0.5 * height / np.tan(np.radians(fov) / 2)
    return np.stack([0.5 * width + f * (d @ right) / depth, 0.5 * height - f * (d @ up) / depth], axis=-1), depth


def _posed_capsules(anim, frame):
    """World capsules (start, end, radius) of every mannequin bone with a drawn limb."""
    out = []
    for i, record in enumerate(anim.bodies):
        body = mannequin_loader(record)
        m = body.skinning_matrices(anim.joint_rotations[frame, i], anim.root_translation[frame, i])
        caps = body.capsules
        for j in np.flatnonzero(caps.radius > 0.03):
            a, b = (m[j, :3, :3] @ p + m[j, :3, 3] for p in (caps.start[j], caps.end[j]))
            out.append((i, a, b, float(caps.radius[j])))
    return out


def test_known_scene_silhouettes_sit_where_the_bodies_project(design):
    """Two mannequins, a tall one on the right (x = +0.7 m) raising its arm across, a short
    one on the left, seen from behind by a free camera, no shadows. Against the same scene
    with the characters moved 50 m under the floor: the image changes at every projected
    bone axis (a point inside a body is covered by its silhouette), nowhere away from the
    projected capsules, and the rest is the concert's grey floor. The projection is
    computed here from the camera's definition, so a mirrored image or camera fails.

    Measured (192x108, MSAA 4): 100 % of both characters' axis samples covered; 0 of the 1121
    changed pixels away from the projected capsules; the crowd area's floor pixels (21 % of
    the image) unchanged, median (155, 153, 161), all within 25 of it; the stage at the top
    (27, 51, 55)."""
    from crowdstudy.render.camera import Camera
    from crowdstudy.render.scene import build_environment

    w, h = 192, 108
    anim = crowd_animation([[0.7, 0.0], [-0.6, 0.4]], n_frames=1, heights=[1.85, 1.6])
    rot = np.array(anim.joint_rotations)
    rot[0, 0, JOINT_NAMES.index("left_shoulder")] = [0.0, 0.0, 1.3]  # arm out towards -x
    anim = anim.replace(joint_rotations=rot)
    eye, target, fov = (0.3, -4.5, 1.5), (0.0, 0.0, 0.9), 40.0
    images = []
    for a in (anim, anim.replace(root_translation=anim.root_translation + [0, 0, -50.0])):
        with mannequin_renderer(a, design, width=w, height=h, shadows=False) as r:
            r.set_view(Camera(eye=eye, target=target, fov=fov))
            images.append(r.render(0).astype(int))
    img, empty = images
    silhouette = np.abs(img - empty).sum(axis=2) > 3  # dark clothes are nearly the stage's colour
    caps = _posed_capsules(anim, 0)
    # 1. every character covers the pixels of its projected bone axes
    for who in (0, 1):
        axis_pts = np.concatenate([a + np.linspace(0, 1, 9)[:, None] * (b - a) for i, a, b, _ in caps if i == who])
        px, depth = _pinhole(axis_pts, eye, target, fov, w, h)
        assert np.all(depth > 0) and np.all((px >= 0) & (px < [w, h]))
        ix = px.astype(int)
        assert silhouette[ix[:, 1], ix[:, 0]].mean() > 0.95, who
    # 2. nothing changes away from the projected capsules (their surfaces, grown by 2 px)
    rng = np.random.default_rng(0)
    near = np.zeros((h, w), bool)
    for _, a, b, r in caps:
        t = rng.uniform(0, 1, (400, 1))
        v = rng.normal(size=(400, 3))
        pts = a + t * (b - a) + r * v / np.linalg.norm(v, axis=1, keepdims=True) * rng.uniform(0, 1, (400, 1)) ** 0.3
        ix = _pinhole(pts, eye, target, fov, w, h)[0].astype(int)
        for dx in range(-2, 3):
            for dy in range(-2, 3):
                near[np.clip(ix[:, 1] + dy, 0, h - 1), np.clip(ix[:, 0] + dx, 0, w - 1)] = True
    assert silhouette.mean() > 0.03
    assert (silhouette & ~near).sum() <= 0.01 * silhouette.sum()
    # 3. pixels whose ray meets the floor (z = 0) of the crowd area (grown by the venue's
    #    cutaway margin: nothing of the venue covers it) show the floor: the neutral grey of
    #    the concert floor, not the background colour
    env = build_environment("concert", design)
    yy, xx = np.mgrid[0:h, 0:w]
    e = np.asarray(eye)
    fwd = (np.asarray(target) - e) / np.linalg.norm(np.asarray(target) - e)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    f = 0.5 * h / np.tan(np.radians(fov) / 2)
    rays = fwd + ((xx + 0.5 - w / 2) / f)[..., None] * right - ((yy + 0.5 - h / 2) / f)[..., None] * up
    s = -e[2] / np.where(rays[..., 2] < 0, rays[..., 2], -1e-9)
    hit = e + s[..., None] * rays
    half = np.asarray(env.extent) / 2 + 0.3
    floor = (rays[..., 2] < 0) & np.all(np.abs(hit[..., :2]) < half, axis=-1) & ~near
    floor[:, :2] = floor[:, -2:] = False
    floor[:2] = floor[-2:] = False
    assert floor.mean() > 0.15
    pixels = img[floor]
    assert np.abs(pixels - empty[floor]).max() <= 3  # untouched by the characters
    grey = np.median(pixels, axis=0)
    assert np.ptp(grey) < 20 and 100 < grey.mean() < 230  # a neutral, lit grey ...
    assert np.mean(np.abs(pixels - grey).max(axis=1) < 25) > 0.95  # ... over the whole floor ...
    top = np.median(empty[: h // 8].reshape(-1, 3), axis=0)  # ... below the dark stage (upright)
    assert grey.mean() > top.mean() + 60
    # 4. left/right: the tall character (x > 0) is right of the short one, its hand left of its head

    def cols(who):  # image columns of the capsule ends of character ``who``
        return np.concatenate(
            [_pinhole(np.array([a, b]), eye, target, fov, w, h)[0][:, 0] for i, a, b, _ in caps if i == who]
        )

    assert cols(0).mean() > w / 2 > cols(1).mean()
    assert silhouette[:, int(cols(0).mean()) :].sum() > silhouette[:, : int(cols(1).mean())].sum()


def test_animation_moves_and_is_deterministic(concert, design):
    with mannequin_renderer(concert, design) as r:
        r.set_view("V3")
        a, b, a2 = r.render(0), r.render(5), r.render(0)
    assert np.array_equal(a, a2)
    assert np.abs(a.astype(int) - b.astype(int)).sum() > 0


def test_neighbours_have_different_clothes():
    from crowdstudy.render.palette import assign_colors

    pos = grid_positions(60, margin=0.2)
    colors, choice = assign_colors(pos, seed=3)
    d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    np.fill_diagonal(d, np.inf)
    nearest = np.argmin(d, axis=1)
    assert np.all(choice[:, 2] != choice[nearest, 2])  # shirts differ from the nearest neighbour
    assert len(np.unique(choice[:, 0])) >= 6  # a diverse range of skin tones
    assert colors.shape == (60, 6, 3) and np.all((colors >= 0) & (colors <= 1))
    close = d < 0.9
    assert not np.any(close & (choice[:, None, 2] == choice[None, :, 2]))
    assert np.array_equal(assign_colors(pos, seed=3)[1], choice)


def test_overlap_view_marks_forced_overlap(design):
    pos = grid_positions(6, margin=0.6)
    forced = pos.copy()
    forced[1] = forced[0] + [0.12, 0.04]  # two bodies sharing the same space
    with mannequin_renderer(crowd_animation(forced, n_frames=2), design, width=240, height=136) as r:
        r.set_view("V1")
        hit = r.overlap(0)
    with mannequin_renderer(crowd_animation(pos, n_frames=2), design, width=240, height=136) as r:
        r.set_view("V1")
        clear = r.overlap(0)
    assert hit.red_fraction > 0.003
    assert clear.red_fraction < 0.1 * hit.red_fraction
    red = (hit.image[..., 0] > 180) & (hit.image[..., 1] < 90) & (hit.image[..., 2] < 90)
    assert red[hit.mask].mean() > 0.5 and hit.mask.sum() == int(round(hit.red_fraction * hit.mask.size))


def test_corridor_draws_periodic_copies(design):
    anim = crowd_animation(
        np.array([[2.1, 0.0], [-0.5, 0.3]]), n_frames=3, scenario="corridor", period=4.5, velocity=(1.2, 0.0)
    )
    with mannequin_renderer(anim, design) as r:
        r.set_view("V4")
        img = r.render(2)
        shifts = {round(float(s), 2) for gl in r.character_resources.groups for s in r.characters.instances(gl)["s"]}
        wrapped = r.character_positions(2)
    assert {-4.5, 0.0} <= shifts  # the copy across the seam is drawn
    assert np.all(np.abs(wrapped[:, 0]) <= 2.25)  # unwrapped positions are wrapped for drawing
    assert img.std() > 10


def test_video_decodes_with_right_frames_and_size(concert, design, tmp_path):
    from crowdstudy.render.video import probe_video, render_video

    out = tmp_path / "clip.mp4"
    res = render_video(
        concert,
        "V2",
        out,
        width=W,
        height=H,
        fps=30,
        design=design,
        progress=False,
        body_loader=mannequin_loader,
        red_sample_frames=2,
    )
    info = probe_video(out)
    assert (info["codec"], info["pix_fmt"], info["width"], info["height"]) == ("h264", "yuv420p", W, H)
    assert info["frames"] == res["frames"] == concert.n_frames
    data = out.read_bytes()
    assert data.index(b"moov") < data.index(b"mdat"), "moov atom must come first (+faststart)"
    assert len(res["red_fraction"]) == 2 and len(res["sha256"]) == 64
    assert not list(tmp_path.glob("*.part.mp4"))
    # the decoded frames are the rendered ones, upright and in order
    from crowdstudy.render.video import find_ffmpeg

    raw = subprocess.run(
        [find_ffmpeg(), "-loglevel", "error", "-i", str(out), "-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"],
        capture_output=True,
        check=True,
    ).stdout
    decoded = np.frombuffer(raw, np.uint8).reshape(-1, H, W, 3).astype(int)
    with mannequin_renderer(concert, design) as r:
        r.set_view("V2")
        first, last = r.render(0).astype(int), r.render(concert.n_frames - 1).astype(int)
    assert np.abs(decoded[0] - first).mean() < 6 and np.abs(decoded[-1] - last).mean() < 6
    assert np.abs(decoded[0] - last).mean() > np.abs(decoded[0] - first).mean()


def test_overlap_video_and_resampling(concert, design, tmp_path):
    from crowdstudy.render.video import probe_video, render_video

    res = render_video(
        concert,
        "V1",
        tmp_path / "o.mp4",
        width=W,
        height=H,
        fps=15,
        overlap_view=True,
        design=design,
        progress=False,
        body_loader=mannequin_loader,
    )
    assert res["frames"] == 3 and len(res["red_fraction"]) == 3
    assert probe_video(tmp_path / "o.mp4")["frames"] == 3
    with pytest.raises(InvalidInputError, match="duration"):
        render_video(
            concert,
            "V1",
            tmp_path / "x.mp4",
            width=W,
            height=H,
            duration=5.0,
            design=design,
            progress=False,
            body_loader=mannequin_loader,
        )


def test_bad_inputs(concert, design, tmp_path):
    from crowdstudy.render.video import render_video

    with pytest.raises(InvalidInputError, match="viewpoint.*V9"):
        with mannequin_renderer(concert, design) as r:
            r.set_view("V9")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(InvalidInputError, match="output folder"):
        render_video(
            concert,
            "V1",
            blocker / "sub" / "clip.mp4",
            width=W,
            height=H,
            design=design,
            progress=False,
            body_loader=mannequin_loader,
        )
    with pytest.raises(InvalidInputError, match="even"):
        render_video(
            concert,
            "V1",
            tmp_path / "odd.mp4",
            width=W + 1,
            height=H,
            design=design,
            progress=False,
            body_loader=mannequin_loader,
        )


def test_missing_egl_names_packages(monkeypatch):
    import moderngl

    from crowdstudy.render import context

    def broken(*args, **kwargs):
        raise Exception("libEGL.so: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_standalone_context", broken)
    errors = []

    def attempt():  # a fresh thread has no cached context
        try:
            context.get_context()
        except MissingDependencyError as exc:
            errors.append(str(exc))

    t = threading.Thread(target=attempt)
    t.start()
    t.join()
    assert errors and "apt-get install" in errors[0] and "libegl1" in errors[0]


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "crowdstudy", "render", *map(str, args)], capture_output=True, text=True, timeout=120
    )


def test_cli_png_with_real_bodies_and_errors(tmp_path):
    pytest.importorskip("crowdstudy.body.model")
    anim = crowd_animation(grid_positions(4, margin=0.6), n_frames=3)
    bodies = tuple({"model": "open", "sex": b["sex"], "height": b["height"], "shape": [0.0, 0.0]} for b in anim.bodies)
    path = anim.replace(bodies=bodies).save(tmp_path / "a.npz")
    out = tmp_path / "f.png"
    proc = _cli(path, "--view", "V3", "--frame", 1, "--png", "--out", out, "--width", 160, "--height", 90)
    assert proc.returncode == 0, proc.stderr
    from PIL import Image

    img = np.asarray(Image.open(out))
    assert img.shape == (90, 160, 3) and img.std() > 10
    clip = tmp_path / "free.mp4"
    proc = _cli(
        path,
        "--eye",
        "5,4,3",
        "--target",
        "0,0,1",
        "--out",
        clip,
        "--width",
        96,
        "--height",
        54,
        "--duration",
        0.1,
        "--quiet",
        "--no-shadows",
        "--msaa",
        0,
    )
    assert proc.returncode == 0, proc.stderr
    from crowdstudy.render.video import probe_video

    assert probe_video(clip)["frames"] == 3
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    proc = _cli(bad, "--out", tmp_path / "x.mp4")
    assert proc.returncode == 2 and "bad.npz" in proc.stderr and "error" in proc.stderr
    proc = _cli(tmp_path / "missing.npz", "--out", tmp_path / "x.mp4")
    assert proc.returncode == 2 and "does not exist" in proc.stderr
    proc = _cli(path, "--view", "V7", "--out", tmp_path / "x.mp4")
    assert proc.returncode == 2 and "V7" in proc.stderr


def test_corrected_crowd_keeps_the_baseline_colours(design):
    base = crowd_animation(grid_positions(20, margin=0.3), n_frames=2)
    shift = np.random.default_rng(0).normal(0, 0.08, base.root_translation.shape) * [1, 1, 0]
    moved = base.replace(root_translation=base.root_translation + shift)
    with (
        mannequin_renderer(base, design) as a,
        mannequin_renderer(moved, design, color_positions=base.root_translation[0, :, :2]) as b,
    ):
        assert np.array_equal(a.colors, b.colors)
    with pytest.raises(InvalidInputError, match="color_positions"):
        mannequin_renderer(base, design, color_positions=np.zeros((3, 2)))


def test_level_of_detail_and_culling_keep_the_picture(concert, design):
    with (
        mannequin_renderer(concert, design, max_faces=None) as full,
        mannequin_renderer(concert, design, width=W, height=H) as lod,
    ):
        full.set_view("V3")
        lod.set_view("V3")
        a, b = full.render(1).astype(int), lod.render(1).astype(int)
        assert lod.max_faces == 600 and lod.groups[0].faces.shape[0] <= 700
        assert full.groups[0].faces.shape[0] > 2 * lod.groups[0].faces.shape[0]
    assert np.abs(a - b).mean() < 6
    with pytest.raises(InvalidInputError, match="max_faces"):
        mannequin_renderer(concert, design, max_faces=5)


def test_floor_split_is_exact(concert, design, monkeypatch):
    """The ground is drawn in two parts, only the part that can receive a character's
    shadow with the shadow lookup: same area, same picture as shading it all."""
    from crowdstudy.render import assets
    from crowdstudy.render.scene import build_environment, split_floor

    for scenario in ("concert", "corridor"):
        ground = build_environment(scenario, design).opaque
        inside, outside = split_floor(ground, (-1.0, -2.0, 3.0, 1.5))

        def area(tris):
            t = tris[:, :2].reshape(-1, 3, 2).astype(np.float64)
            u, v = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
            return 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum()

        assert area(inside) + area(outside) == pytest.approx(area(ground), rel=1e-6)
        assert inside[:, 0].min() >= -1.0 and inside[:, 0].max() <= 3.0 and inside[:, 1].max() <= 1.5
    with mannequin_renderer(concert, design) as split:
        split.set_view("V2")
        a = split.render(2).astype(int)
        x0, y0, x1, y1 = assets.shadow_receivers(split.anim, split.lighting)
        assert x1 - x0 < 12 and y1 - y0 < 12  # a few metres around the crowd, not the 80 m ground
    monkeypatch.setattr(assets, "shadow_receivers", lambda anim, lighting: (-1e3, -1e3, 1e3, 1e3))
    with mannequin_renderer(concert, design) as whole:
        whole.set_view("V2")
        b = whole.render(2).astype(int)
    diff = np.abs(a - b).max(axis=2)
    assert (diff > 2).mean() < 2e-3 and diff.mean() < 0.1

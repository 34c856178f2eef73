"""The physics takes the scene's geometry from the animation's meta (never from a default
design); the same input gives the same bytes (timings stay out of the file); ``crowdstudy
correct`` checks its output path and arguments before the long run."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.design import default_design_path, load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.physics.collision import KIND_ENVIRONMENT
from crowdstudy.physics.config import PhysicsConfig
from crowdstudy.scene_meta import static_walls_from_meta


def _custom_design(folder: Path, name: str, pattern: str, replacement: str):
    """The default design with one line changed, written to ``folder / name``."""
    text = default_design_path().read_text()
    new, count = re.subn(pattern, replacement, text, count=1, flags=re.M)
    assert count == 1, pattern
    path = folder / name
    path.write_text(new)
    return load_design(path)


@pytest.fixture(scope="module")
def wide_floor(tmp_path_factory):
    """A 5.5 m x 5.5 m concert floor: the stage front at 5.5 / 2 + 1.0 = 3.75 m."""
    folder = tmp_path_factory.mktemp("wide_floor")
    design = _custom_design(
        folder, "floor.toml", r"^\[floor\]\nwidth = 3\.0(.*)\ndepth = 3\.0", r"[floor]\nwidth = 5.5\1\ndepth = 5.5"
    )
    assert (design.floor_width, design.floor_depth) == (5.5, 5.5)
    from crowdstudy.motion.baseline import build_baseline

    return design, build_baseline(design, "stationary", "D1", duration=1.0)


@pytest.fixture(scope="module")
def wide_corridor(tmp_path_factory):
    """A 3 m wide corridor: walls at y = +-1.5 m."""
    folder = tmp_path_factory.mktemp("wide_corridor")
    design = _custom_design(folder, "corridor.toml", r"^(\[scenarios\.corridor\]\nwidth = )2\.0", r"\g<1>3.0")
    assert design.scenarios["corridor"]["width"] == 3.0
    from crowdstudy.motion.baseline import build_baseline

    return design, build_baseline(design, "walking", "D1", duration=1.0)


@pytest.fixture(scope="module")
def default_d1():
    from crowdstudy.motion.baseline import build_baseline

    return build_baseline(load_design(), "stationary", "D1", duration=1.0)


def _environment_contacts(anim, walls, frames) -> list[int]:
    """Penetrating environment contacts of each pose of ``anim`` against ``walls`` (what the
    physics' collision pipeline sees), one count per frame."""
    from crowdstudy.physics.corrector import CrowdCorrector, load_bodies

    cfg = PhysicsConfig()
    corr = CrowdCorrector(
        load_bodies(anim.bodies),
        config=cfg,
        device="cpu",
        fps=anim.fps,
        periodic_length=anim.periodic_length,
        static_walls=walls,
    )
    counts = []
    for f in frames:
        corr.reset(anim.joint_rotations[f], anim.root_translation[f])
        corr.pipeline.collide(corr.state, corr.contacts)
        c = corr.contacts.to_numpy()
        counts.append(int(((c["kind"] == KIND_ENVIRONMENT) & (c["depth"] > 0)).sum()))
    return counts


# -- Task A: the scene's geometry travels in the meta ------------------------------------------
def test_concert_meta_carries_the_custom_stage(wide_floor):
    from crowdstudy.body.skeleton import forward_kinematics
    from crowdstudy.layout import concert_layout
    from crowdstudy.physics.corrector import load_bodies

    design, base = wide_floor
    front = 5.5 / 2 + 1.0
    crowd = concert_layout(design, "D1", 3)
    for meta in (crowd.meta, base.meta):
        assert meta["floor"] == {"width": 5.5, "depth": 5.5}
        assert meta["stage_front"] == pytest.approx(front) and meta["stage_distance"] == 1.0
        assert np.allclose(meta["obstacles"], [[[-5.5, front], [5.5, front]]])
    walls = static_walls_from_meta(base.meta)
    assert walls.shape == (1, 2, 2) and np.allclose(walls[0, :, 1], front)
    # every joint of the front row stays well in front of the stage wall
    rest = np.stack([np.asarray(b.rest_joints) for b in load_bodies(base.bodies)])
    _, joints = forward_kinematics(rest[None], base.joint_rotations, base.root_translation)
    assert joints[..., 1].max() < front - 0.5


def test_corridor_meta_carries_the_custom_width(wide_corridor):
    design, base = wide_corridor
    assert base.meta["corridor_width"] == 3.0 and base.meta["corridor_length"] == 4.5
    assert base.meta["floor"] == {"width": 4.5, "depth": 3.0}
    assert base.meta["periodic"] == {"axis": 0, "length": 4.5}
    walls = static_walls_from_meta(base.meta)
    assert walls.shape == (2, 2, 2)
    assert sorted(walls[:, 0, 1]) == [-1.5, 1.5] and np.array_equal(walls[:, 0, 1], walls[:, 1, 1])
    # the walls ORCA used (the section's, extended by a period each side) cover every wrapped x
    assert walls[:, :, 0].min() <= -0.6 and walls[:, :, 0].max() >= 4.5 + 0.6
    assert np.abs(base.root_translation[..., 1]).max() < 1.5


def test_crowd_files_keep_the_geometry(tmp_path, wide_floor):
    from crowdstudy.layout import concert_layout
    from crowdstudy.motion.baseline import animate_stationary
    from crowdstudy.scene import Crowd

    design, _ = wide_floor
    crowd = Crowd.load(concert_layout(design, "D1", 3).save(tmp_path / "layout.npz"))
    anim = animate_stationary(crowd, duration=0.2, seed=1)
    assert anim.meta["stage_front"] == pytest.approx(3.75)
    assert np.allclose(static_walls_from_meta(anim.meta)[0, :, 1], 3.75)


@pytest.mark.parametrize("scene", ["wide_floor", "wide_corridor"])
def test_the_physics_uses_the_scene_walls(scene, request):
    """A few correction steps add no environment contacts beyond the Baseline's own (none),
    and the concert's front row is not pushed back by a misplaced stage wall."""
    from crowdstudy.physics.corrector import correct

    _, base = request.getfixturevalue(scene)
    clip = base.frames(0, 4)
    walls = static_walls_from_meta(clip.meta)
    cfg = PhysicsConfig()
    ours = correct(clip, cfg, progress=False, device="cpu")
    assert ours.meta["physics"]["static_walls"] == len(walls) > 0  # the physics used these walls
    frames = range(clip.n_frames)
    before = _environment_contacts(clip, walls, frames)
    after = _environment_contacts(ours, walls, frames)
    assert all(a <= b for a, b in zip(after, before, strict=True)), (before, after)
    assert sum(after) == 0
    if scene == "wide_floor":
        y0 = clip.root_translation[0, :, 1]
        row = y0 > y0.max() - 0.5
        dy = ours.root_translation[:, row, 1] - clip.root_translation[:, row, 1]
        assert dy.min() > -0.03  # the stage wall inside the front row pushed it 2-16 cm


def test_geometry_missing_from_an_old_file_is_an_error(default_d1):
    import dataclasses

    from crowdstudy.physics.corrector import correct

    old_meta = {k: v for k, v in default_d1.meta.items() if k not in ("obstacles", "floor", "stage_front")}
    old = dataclasses.replace(default_d1.frames(0, 2), meta=old_meta)  # as an older version wrote it
    with pytest.raises(InvalidInputError, match=r"meta\['obstacles'\].*regenerate"):
        correct(old, progress=False, device="cpu")
    # a hand-made scene states its walls explicitly (an empty list: none)
    assert static_walls_from_meta({**old_meta, "obstacles": []}).shape == (0, 2, 2)


# -- Task B: same input, same bytes; checks before the long run ---------------------------------
def test_correct_twice_gives_the_same_bytes(tmp_path, default_d1):
    from crowdstudy.physics.corrector import correct

    paths, runs = [], []
    for k in range(2):
        timings: dict = {}
        out = correct(default_d1, progress=False, device="cpu", timings=timings)
        paths.append(out.save(tmp_path / f"ours{k}.npz"))
        runs.append(timings)
        phys = out.meta["physics"]
        assert not {"wall_seconds", "ms_per_step", "settle_seconds"} & set(phys)
        assert phys["steps"] == (default_d1.n_frames - 1) * phys["substeps_per_frame"]
    assert paths[0].read_bytes() == paths[1].read_bytes()
    for t in runs:
        assert t["steps"] == t["timed_steps"] == (default_d1.n_frames - 1) * 2
        assert t["ms_per_step"] > 0 and t["settle_seconds"] > 0
        assert t["ms_per_step"] == pytest.approx(1000 * t["simulate_seconds"] / t["timed_steps"])
        assert t["simulate_seconds"] + t["settle_seconds"] <= t["wall_seconds"]
    with pytest.raises(InvalidInputError, match="timings"):
        correct(default_d1, progress=False, device="cpu", timings=[])


@pytest.fixture(scope="module")
def baseline_file(tmp_path_factory, default_d1):
    return default_d1.save(tmp_path_factory.mktemp("cli") / "base.npz")


def _no_simulation(monkeypatch):
    import crowdstudy.physics.corrector as corrector

    def refuse(*args, **kwargs):
        raise AssertionError("correct() ran although the arguments were bad")

    monkeypatch.setattr(corrector, "correct", refuse)


def test_cli_rejects_a_folder_output_before_simulating(tmp_path, monkeypatch, capsys, baseline_file):
    from crowdstudy.cli import main

    _no_simulation(monkeypatch)
    folder = tmp_path / "out_dir"
    folder.mkdir()
    rc = main(["correct", str(baseline_file), str(folder), "--no-progress", "--device", "cpu"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and str(folder) in err and "folder" in err and len(err.splitlines()) == 1
    assert not list(tmp_path.rglob("*.tmp"))
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    rc = main(["correct", str(baseline_file), str(blocker / "out.npz"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and str(blocker) in err and len(err.splitlines()) == 1


def test_cli_rejects_too_many_frames(tmp_path, monkeypatch, capsys, baseline_file, default_d1):
    from crowdstudy.cli import main

    _no_simulation(monkeypatch)
    rc = main(["correct", str(baseline_file), str(tmp_path / "out.npz"), "--frames", "10000", "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "--frames" in err and str(default_d1.n_frames) in err
    assert not (tmp_path / "out.npz").exists()


def test_failed_save_leaves_no_tmp(tmp_path, default_d1):
    folder = tmp_path / "taken.npz"
    folder.mkdir()
    with pytest.raises(OSError):
        default_d1.save(folder)
    assert not list(tmp_path.rglob("*.tmp"))


def test_cli_prints_and_writes_the_timings(tmp_path, capsys, baseline_file):
    from crowdstudy.cli import main
    from crowdstudy.scene import CrowdAnimation

    out = tmp_path / "sub" / "ours.npz"
    rc = main(["correct", str(baseline_file), str(out), "--frames", "6", "--no-progress", "--device", "cpu"])
    assert rc == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    sidecar = tmp_path / "sub" / "ours.timings.json"
    timings = json.loads(sidecar.read_text())
    assert printed["timings"] == str(sidecar) and printed["ms_per_step"] > 0
    # a D1 concert: sparse, corrected with the sparse profile's skins
    assert printed["crowd_density"] < 4.5 and printed["profile_weight"] == 0.0
    assert printed["mesh_skin_max"] == timings["mesh_skin_max"] == 0.04
    assert timings["ms_per_step"] > 0 and timings["steps"] == (6 - 1) * timings["substeps_per_frame"] == 10
    anim = CrowdAnimation.load(out)
    assert anim.n_frames == 6 and "ms_per_step" not in anim.meta["physics"]
    assert not list(tmp_path.rglob("*.tmp"))

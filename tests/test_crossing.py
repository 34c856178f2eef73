"""The crossing scenario (a plaza where two flows cross): design keys, navigation with
obstacles, the Baseline's loop and meta, the physics' obstacle walls, the plaza's render."""

from __future__ import annotations

import copy
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.design import parse_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.navigation import crossing_crowd, obstacle_clearance, obstacle_polygons, obstacle_segments
from crowdstudy.scene_meta import check_meta, static_walls_from_meta

sys.path.insert(0, str(Path(__file__).resolve().parent))

EXAMPLE = Path(__file__).resolve().parents[1] / "stimuli" / "examples" / "plaza.toml"
RAW = tomllib.loads(EXAMPLE.read_text())
#: a planter across flow 1's path, upstream of the crossing area
PLANTER = {"label": "planter", "polygon": [[-3.0, -0.5], [-2.4, -0.5], [-2.4, 0.4], [-3.0, 0.4]], "height": 0.5}


def _design(edit=None):
    raw = copy.deepcopy(RAW)
    if edit is not None:
        edit(raw["scenarios"]["plaza"])
    return parse_design(raw, "plaza.toml")


def test_the_example_design_reads_its_plaza():
    design = _design()
    sc = design.scenarios["plaza"]
    assert sc.kind == "crossing" and design.scenario_of("crossing") is sc
    assert sc["angle"] == 90.0 and sc["share"] == 0.5 and sc["preferred_speed"] == [1.2, 1.2]
    shapes = {ob["shape"] for ob in sc["obstacles"]}
    assert shapes == {"circle", "polygon"} and all(ob["height"] > 0 for ob in sc["obstacles"])
    assert [s.stimulus_id for s in design.stimuli()][:2] == ["S1-D1-V5-Baseline", "S1-D1-V5-Ours"]
    assert set(design.viewpoints) == {"V5", "V6"}


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: t.update(obstacle=[]), r"plaza\.toml: unknown key 'scenarios\.plaza\.obstacle'"),
        (lambda t: t.update(kind="square"), r"'scenarios\.plaza\.kind' must be one of concert, corridor, crossing"),
        (lambda t: t.update(angle=5.0), r"'scenarios\.plaza\.angle' must be a finite number >= 20"),
        (lambda t: t.update(share=1.0), r"'scenarios\.plaza\.share'"),
        (lambda t: t.update(plaza_width=2.0), r"'scenarios\.plaza\.plaza_width' must be a finite number >= 3"),
        (lambda t: t.update(preferred_speed=[1.2, 1.0, 0.8]), r"'scenarios\.plaza\.preferred_speed'.*two numbers"),
        (lambda t: t["obstacles"].append({"radius": 0.2}), r"'scenarios\.plaza\.obstacles\[6\]\.polygon'.*exactly one"),
        (lambda t: t["obstacles"].append({"center": [0, 0]}), r"'scenarios\.plaza\.obstacles\[6\]\.radius' is missing"),
        (
            lambda t: t["obstacles"].append({"center": [0, 0], "radius": 0.3, "hieght": 1.0}),
            r"unknown key 'scenarios\.plaza\.obstacles\[6\]\.hieght'",
        ),
        (
            lambda t: t["obstacles"].append({"polygon": [[0, 0], [2, 0], [1, 0.5], [2, 2], [0, 2]]}),
            r"'scenarios\.plaza\.obstacles\[6\]\.polygon' must be convex",
        ),
        (
            lambda t: t["obstacles"].append({"polygon": [[0, 0], [1, 0]]}),
            r"'scenarios\.plaza\.obstacles\[6\]\.polygon' must list at least 3 corners",
        ),
        (
            lambda t: t["obstacles"].append({"center": [4.9, 0.0], "radius": 0.3}),
            r"'scenarios\.plaza\.obstacles\[6\]\.center' reaches outside the plaza",
        ),
        (lambda t: t["obstacles"].append("kiosk"), r"'scenarios\.plaza\.obstacles\[6\]' must be a table"),
    ],
)
def test_bad_plaza_keys_are_named(edit, match):
    with pytest.raises(InvalidInputError, match=match):
        _design(edit)


def test_polygons_are_counter_clockwise_and_circles_enclosed():
    design = _design(lambda t: t["obstacles"].append({"polygon": [[0, 0], [0, 1], [1, 1], [1, 0]]}))
    pts = np.array(design.scenarios["plaza"]["obstacles"][-1]["points"])
    x, y = pts[:, 0], pts[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) == pytest.approx(1.0)
    circle = obstacle_polygons([{"shape": "circle", "center": [1.0, 2.0], "radius": 0.5}])[0]
    edge_mid = 0.5 * (circle + np.roll(circle, -1, axis=0))
    np.testing.assert_allclose(np.linalg.norm(edge_mid - [1.0, 2.0], axis=1), 0.5)  # edges touch the circle
    assert obstacle_segments([circle]).shape == (16, 2, 2)


@pytest.fixture(scope="module")
def crowd():
    """D3 for 6 s at 10 fps with a planter across flow 1's path."""
    design = _design(lambda t: t["obstacles"].append(PLANTER))
    return design, crossing_crowd(design, "D3", 4, duration=6.0, fps=10.0, scenario="plaza")


def test_walkers_stay_out_of_the_obstacles_and_pass_them(crowd):
    design, c = crowd
    polygons = obstacle_polygons(design.scenarios["plaza"]["obstacles"])
    assert obstacle_clearance(c, polygons) > -0.005 * c.radius[0]  # discs never reach into an obstacle
    flow = np.array(c.meta["flow"])
    assert set(flow.tolist()) == {0, 1}
    # every walker of flow 1 that starts up to 2 m before the planters walks on past them
    x0, y0 = c.positions[0, :, 0], c.positions[0, :, 1]
    behind = (flow == 0) & (x0 > -5.0) & (x0 < -3.0) & (np.abs(y0) < 1.5)
    assert behind.sum() >= 10
    assert np.all(c.positions[-1, behind, 0] > -2.0)


def test_the_crossing_area_stays_at_the_density(crowd):
    design, c = crowd
    inside = np.all(np.abs(c.positions) < 1.5, axis=-1)  # the 3 m x 3 m crossing area
    count = inside.sum(axis=1)
    target = design.n_characters("D3")
    assert count.mean() == pytest.approx(target, rel=0.25)
    assert count[-10:].mean() > 0.75 * target  # walkers keep coming to the end of the clip
    assert {0, 1} <= set(np.array(c.meta["flow"])[inside.any(axis=0)].tolist())  # both flows cross it
    assert c.n_agents > 3 * target  # the bands upstream feed the clip


def test_navigation_is_deterministic_and_checks_its_arguments(crowd):
    design, c = crowd
    again = crossing_crowd(design, "D3", 4, duration=6.0, fps=10.0, scenario="plaza")
    assert np.array_equal(again.positions, c.positions)
    with pytest.raises(InvalidInputError, match="level"):
        crossing_crowd(design, "D9", 1)
    with pytest.raises(InvalidInputError, match="seed"):
        crossing_crowd(design, "D1", -1)
    paper = parse_design(tomllib.loads((EXAMPLE.parents[1] / "study.toml").read_text()), "study.toml")
    with pytest.raises(InvalidInputError, match="no scenario 'crossing'"):
        crossing_crowd(paper, "D1", 1)
    with pytest.raises(InvalidInputError, match="not a crossing"):
        crossing_crowd(paper, "D1", 1, scenario="corridor")


@pytest.fixture(scope="module")
def baseline():
    from crowdstudy.motion import build_baseline

    return build_baseline(_design(), "crossing", "D1", duration=1.0, fps=30, dissolve=0.2)


def test_baseline_meta_carries_the_plaza_and_the_obstacle_walls(baseline):
    meta = baseline.meta
    check_meta(meta)
    assert meta["scenario"] == "crossing" and meta["scenario_name"] == "plaza"
    assert meta["n_characters"] == 20 and baseline.n_characters > 20
    assert meta["floor"] == {"width": 3.0, "depth": 3.0}
    assert meta["plaza"]["width"] == 10.0 and len(meta["plaza"]["obstacles"]) == 6
    walls = static_walls_from_meta(meta)
    expected = obstacle_segments(obstacle_polygons(meta["plaza"]["obstacles"]))
    np.testing.assert_allclose(walls, expected)
    assert len(walls) == 2 * 4 + 4 * 16  # two boxes, four circles
    with pytest.raises(InvalidInputError, match=r"meta\['obstacles'\].*regenerate"):
        static_walls_from_meta({"scenario": "crossing"})


def test_baseline_loops_by_a_dissolve_without_a_jump(baseline):
    assert baseline.meta["loop"] == {"mode": "dissolve", "frames": 6, "video_frames": 30}
    assert baseline.n_frames == 36
    step = np.linalg.norm(np.diff(baseline.root_translation[..., :2], axis=0), axis=-1)
    assert step.max() * baseline.fps < 3.0  # m/s: every walker walks on, none is moved


def _walker_past(obstacle_x: float):
    """One walker passing a planter along x 16 cm from its face, so that its arm swings
    up to 14 cm into it; the planter's edges in meta["obstacles"] as a crossing writes them."""
    from crowdstudy.motion import animate_walking
    from crowdstudy.scene import Crowd

    fps, n = 30.0, 40
    x = np.linspace(-0.8, 0.5, n)
    planter = np.array([[obstacle_x, 0.16], [obstacle_x + 2.0, 0.16], [obstacle_x + 2.0, 1.0], [obstacle_x, 1.0]])
    walls = obstacle_segments([planter])
    meta = {"scenario": "crossing", "obstacles": walls.tolist(), "floor": {"width": 3.0, "depth": 3.0}}
    crowd = Crowd(
        positions=np.stack([x, np.zeros(n)], 1)[:, None, :],
        radius=np.array([0.22]),
        fps=fps,
        velocities=np.tile([[[1.0, 0.0]]], (n, 1, 1)),
        headings=np.zeros((n, 1)),
        meta=meta,
    )
    return animate_walking(crowd, seed=3, bodies=None)


def test_correct_keeps_a_body_out_of_a_planter():
    from crowdstudy.metrics import wall_penetration
    from crowdstudy.physics import correct

    base = _walker_past(-1.0)
    before = wall_penetration(base).per_character[:, 0]
    assert before.max() > 0.10 and before.mean() > 0.05  # m of the arm inside the planter
    ours = correct(base, progress=False, device="cpu")
    assert ours.meta["physics"]["static_walls"] == 4
    after = wall_penetration(ours).per_character[:, 0]
    # the walls push the arm back out (the mesh's skin stays a few cm past the capsules'
    # reach at most, as on the corridor's walls) and do not hold the walker back
    assert after.max() < 0.05 and after.mean() < 0.2 * before.mean()
    lag = np.abs(ours.root_translation[:, 0, :2] - base.root_translation[:, 0, :2]).max()
    assert lag < 0.05


def test_a_plaza_frame_draws_the_obstacles_where_they_stand():
    from render_fixtures import crowd_animation, mannequin_renderer

    design = _design()
    sc = design.scenarios["plaza"]
    anim = crowd_animation(np.array([[-0.8, 0.6], [0.7, -0.9]]), n_frames=2, scenario="crossing")  # off the view line
    plaza = {"width": 10.0, "depth": 10.0, "angle": 90.0, "obstacles": sc["obstacles"]}
    anim = anim.replace(meta={**anim.meta, "plaza": plaza, "obstacles": [], "floor": {"width": 3.0, "depth": 3.0}})
    kiosk = next(ob for ob in sc["obstacles"] if ob["label"] == "kiosk")
    top = np.array([kiosk["points"][0][0] + 0.6, kiosk["points"][0][1] + 0.05, 0.5])  # its wall facing V5
    with mannequin_renderer(anim, design, width=384, height=216) as r:
        cam = r.set_view("V5")
        img = r.render(0)
        assert r.env.extent == (3.0, 3.0) and len(r.env.walls) > 0
        pixels, front = cam.project(top[None], 384, 216)
        px, py = (int(v) for v in pixels[0])
        assert front[0] and 2 <= px < 382 and 2 <= py < 214
        patch = img[py - 2 : py + 3, px - 2 : px + 3].reshape(-1, 3).astype(int)
        # the kiosk's warm wall: red well above green and blue (the paving and sky are grey)
        assert np.all(patch[:, 0] > patch[:, 1] + 25) and np.all(patch[:, 0] > patch[:, 2] + 25)
        without = anim.replace(meta={**anim.meta, "plaza": {**plaza, "obstacles": []}})
    with mannequin_renderer(without, design, width=384, height=216) as r:
        r.set_view("V5")
        bare = r.render(0)[py - 2 : py + 3, px - 2 : px + 3].reshape(-1, 3)
        assert np.all(np.abs(bare.astype(int)[:, 0] - bare.astype(int)[:, 2]) < 25)  # grey paving there


def test_navigate_cli_walks_a_crossing(tmp_path, capsys):
    from crowdstudy.cli import main as cli_main

    out = tmp_path / "plaza.npz"
    args = ["navigate", "--design", str(EXAMPLE), "--density", "D1", "--duration", "1", "--fps", "10"]
    assert cli_main([*args, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "crossing plaza D1" in text and "obstacle clearance" in text and out.is_file()
    assert cli_main([*args, "--bidirectional", "--out", str(tmp_path / "b.npz")]) == 2
    assert "--bidirectional" in capsys.readouterr().err and not (tmp_path / "b.npz").exists()
    assert cli_main([*args, "--scenario", "hall", "--out", str(tmp_path / "c.npz")]) == 2

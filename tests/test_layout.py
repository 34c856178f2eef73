"""Poisson-disk layouts and the concert crowd (crowdstudy.layout)."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from crowdstudy.cli import main as cli_main
from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.layout import concert_layout, disc_radius, poisson_disk
from crowdstudy.scene import Crowd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from figure_fixtures import plotted_discs, xy_order  # noqa: E402


@pytest.fixture(scope="module")
def design():
    return load_design()


def _point_segment_distance(points, a, b):
    ab = b - a
    t = np.clip(((points - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


@pytest.mark.parametrize("n", [1, 2, 20, 60, 500])
def test_rectangle_exact_n_inside_and_spaced(n):
    layout = poisson_disk((3.0, 2.0), n, seed=7, margin=0.2)
    pts = layout.points
    assert pts.shape == (n, 2)
    assert np.all(np.abs(pts[:, 0]) <= 1.3 + 1e-12) and np.all(np.abs(pts[:, 1]) <= 0.8 + 1e-12)
    area = 2.6 * 1.6
    assert layout.area == pytest.approx(area)
    assert layout.target_distance >= 0.75 * math.sqrt(area / n) - 1e-12
    if n > 1:
        true_min = pdist(pts).min()
        assert true_min >= layout.target_distance
        assert layout.min_distance == pytest.approx(true_min)


def test_polygon_with_margin_keeps_points_inside_and_away_from_edges():
    poly = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.0], [1.5, 1.2], [1.0, 3.0], [0.0, 2.5]])
    layout = poisson_disk(poly[::-1], 45, seed=3, margin=0.15)  # clockwise input is accepted
    pts = layout.points
    from matplotlib.path import Path

    assert Path(poly).contains_points(pts).all()
    edges = [(poly[i], poly[(i + 1) % len(poly)]) for i in range(len(poly))]
    dist_to_boundary = np.min([_point_segment_distance(pts, a, b) for a, b in edges], axis=0)
    assert dist_to_boundary.min() >= 0.15 - 1e-9
    assert pdist(pts).min() >= 0.75 * math.sqrt(layout.area / 45)
    # the placement area estimate is close to the shrunk polygon's area (polygon area 6.6 m^2)
    assert 4.5 < layout.area < 6.6


def test_deterministic_for_a_seed():
    a = poisson_disk((3.0, 3.0), 60, seed=11, margin=0.2).points
    b = poisson_disk((3.0, 3.0), 60, seed=11, margin=0.2).points
    c = poisson_disk((3.0, 3.0), 60, seed=12, margin=0.2).points
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)


def test_ten_thousand_points_keep_the_spacing():
    layout = poisson_disk((100.0, 100.0), 10_000, seed=0)
    from scipy.spatial import cKDTree

    d, _ = cKDTree(layout.points).query(layout.points, k=2)
    assert layout.points.shape == (10_000, 2)
    assert d[:, 1].min() >= 0.75 * math.sqrt(1e4 / 1e4) - 1e-12
    assert np.all(np.abs(layout.points) <= 50.0)


def test_min_distance_option_and_too_many_points():
    layout = poisson_disk((3.0, 3.0), 30, seed=1, min_distance=0.45)
    assert pdist(layout.points).min() >= 0.45
    with pytest.raises(InvalidInputError, match=r"^n: "):
        poisson_disk((3.0, 3.0), 60, seed=1, min_distance=0.5)  # beyond even hexagonal packing
    with pytest.raises(InvalidInputError, match=r"^n: "):
        poisson_disk((3.0, 3.0), 50, seed=1, min_distance=0.42)  # fits hexagonally, not at random


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(region=(3, 3), n=0), "n"),
        (dict(region=(3, 3), n=-5), "n"),
        (dict(region=(3, 3), n=float("nan")), "n"),
        (dict(region=(3, 3), n=2.5), "n"),
        (dict(region=(3, float("nan")), n=10), "region"),
        (dict(region=(3, -1), n=10), "region"),
        (dict(region=[[0, 0], [1, 1], [2, 2]], n=10), "region"),  # collinear
        (dict(region=[[0, 0], [1, 0]], n=10), "region"),  # two vertices
        (dict(region=[[0, 0], [1, 1], [1, 0], [0, 1]], n=10), "region"),  # bow tie
        (dict(region=[[0, 0], [1, 0], [np.nan, 1]], n=10), "region"),
        (dict(region=(3, 3), n=10, margin=1.6), "margin"),
        (dict(region=(3, 3), n=10, margin=-0.1), "margin"),
        (dict(region=(3, 3), n=10, margin=float("nan")), "margin"),
        (dict(region=(3, 3), n=10, min_distance=float("nan")), "min_distance"),
    ],
)
def test_bad_inputs_name_the_argument(kwargs, name):
    with pytest.raises(InvalidInputError, match=rf"^{name}\b"):
        poisson_disk(seed=0, **kwargs)


def test_bad_seed_names_seed():
    with pytest.raises(InvalidInputError, match=r"^seed"):
        poisson_disk((3, 3), 10, seed=-1)


def test_concert_layouts_for_the_study(design):
    margin = design.scenarios["concert"]["margin"]
    counts = []
    for level, density in design.densities.items():
        crowd = concert_layout(design, level, seed=design.cell_seed(design.stage("stationary"), level))
        assert isinstance(crowd, Crowd)
        n = design.n_characters(level)
        counts.append(n)
        pos = crowd.positions[0]
        assert crowd.positions.shape == (1, n, 2)
        assert np.all(np.abs(pos) <= 1.5 - margin + 1e-12)
        area = (3.0 - 2 * margin) ** 2
        assert pdist(pos).min() >= 0.75 * math.sqrt(area / n)
        assert crowd.meta["min_distance"] == pytest.approx(pdist(pos).min())
        assert crowd.radius[0] == pytest.approx(disc_radius(density))
        np.testing.assert_allclose(crowd.headings, np.pi / 2)  # facing the stage at +y
        assert crowd.meta["density_level"] == level and crowd.meta["scenario"] == "concert"
    assert counts == [20, 30, 40, 50, 60]
    with pytest.raises(InvalidInputError, match=r"^level"):
        concert_layout(design, "D7", seed=1)


def test_disc_radius_fits_the_densest_cell():
    r = disc_radius(6.66)
    assert 0.15 < r < 0.22
    assert 6.66 * math.pi * r * r <= 0.6 + 1e-9  # packing fraction at most 0.6
    assert disc_radius(2.22) == pytest.approx(0.22)
    with pytest.raises(InvalidInputError, match=r"^density"):
        disc_radius(0.0)


def test_layout_cli(tmp_path, capsys, saved_figures):
    out = tmp_path / "layout.npz"
    assert cli_main(["layout", "--all", "--seed", "1", "--out", str(out), "--plot", str(tmp_path / "l.png")]) == 0
    crowds = {}
    for level in ("D1", "D2", "D3", "D4", "D5"):
        crowds[level] = Crowd.load(tmp_path / f"layout-{level}.npz")
        assert crowds[level].meta["density_level"] == level
    # the plot draws each saved layout: one panel per level, a disc of the crowd's radius
    # at every character's position (read back from the figure's artists)
    assert (tmp_path / "l.png").is_file() and len(saved_figures) == 1
    panels = [ax for ax in saved_figures[0].axes if plotted_discs(ax)[0].size]
    assert len(panels) == 5
    counts = []
    for ax, (level, crowd) in zip(panels, crowds.items(), strict=True):
        centres, radii = plotted_discs(ax)
        pos = crowd.positions[0]
        counts.append(len(centres))
        assert len(centres) == crowd.n_agents and ax.get_title().startswith(f"{level}: {crowd.n_agents} chars")
        np.testing.assert_allclose(centres[xy_order(centres)], pos[xy_order(pos)], atol=1e-6)
        np.testing.assert_allclose(radii, crowd.radius[0], rtol=1e-3)
        x0, x1 = ax.get_xlim()
        y0, y1 = ax.get_ylim()
        assert x0 <= pos[:, 0].min() and pos[:, 0].max() <= x1 and y0 <= pos[:, 1].min() and pos[:, 1].max() <= y1
    assert counts == sorted(counts) and counts[0] < counts[-1]  # more characters at higher density
    radii = [plotted_discs(ax)[1][0] for ax in panels]
    assert radii == sorted(radii, reverse=True)  # smaller discs when denser
    assert "D5" in capsys.readouterr().out
    assert cli_main(["layout", "--density", "D9", "--out", str(out)]) == 2
    assert "--density" in capsys.readouterr().err


@pytest.mark.parametrize("level,n", [("D3", 1000), ("D5", 5000)])
def test_stadium_layout_keeps_the_density(design, level, n):
    crowd = concert_layout(design, level, 11, n_characters=n)
    m = crowd.meta
    width, depth = m["floor"]["width"], m["floor"]["depth"]
    assert crowd.n_agents == n and m["n_characters"] == n
    assert n / (width * depth) == pytest.approx(design.densities[level], rel=1e-9)
    assert width / depth == pytest.approx(design.floor_width / design.floor_depth)
    pos = crowd.positions[0]
    margin = design.scenarios["concert"]["margin"]
    assert np.all(np.abs(pos[:, 0]) <= width / 2 - margin + 1e-9)
    assert np.all(np.abs(pos[:, 1]) <= depth / 2 - margin + 1e-9)
    # the points fill the whole larger floor, not only its middle
    assert pos[:, 0].max() - pos[:, 0].min() > 0.9 * (width - 2 * margin)
    assert pos[:, 1].max() - pos[:, 1].min() > 0.9 * (depth - 2 * margin)
    assert pdist(pos).min() >= m["target_distance"]
    # the scene geometry later stages read: the stage front moves with the floor's front edge
    assert m["stage_front"] == pytest.approx(depth / 2 + design.scenarios["concert"]["stage_distance"])
    assert m["obstacles"] == [[[-width, m["stage_front"]], [width, m["stage_front"]]]]
    assert crowd.radius[0] == pytest.approx(disc_radius(design.densities[level]))


def test_stadium_layout_is_deterministic_and_default_unchanged(design):
    a = concert_layout(design, "D2", 5, n_characters=300)
    b = concert_layout(design, "D2", 5, n_characters=300)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, concert_layout(design, "D2", 6, n_characters=300).positions)
    # n_characters equal to the design's count keeps the design's floor and points
    d = concert_layout(design, "D2", 5)
    e = concert_layout(design, "D2", 5, n_characters=design.n_characters("D2"))
    assert d.meta["floor"] == pytest.approx(e.meta["floor"], rel=1e-3)
    with pytest.raises(InvalidInputError, match="n_characters"):
        concert_layout(design, "D2", 5, n_characters=0)


def test_stadium_layout_cli_feeds_animate(tmp_path, capsys, design):
    out = tmp_path / "stadium.npz"
    assert cli_main(["layout", "--density", "D1", "--characters", "26", "--seed", "3", "--out", str(out)]) == 0
    crowd = Crowd.load(out)
    assert crowd.n_agents == 26 and crowd.meta["density_level"] == "D1"
    assert " 26 " in capsys.readouterr().out
    anim_path = tmp_path / "anim.npz"
    assert cli_main(["animate", str(out), "--out", str(anim_path), "--duration", "0.1"]) == 0
    from crowdstudy.scene import CrowdAnimation

    anim = CrowdAnimation.load(anim_path)
    assert anim.n_characters == 26
    for key in ("floor", "stage_front", "obstacles"):
        assert anim.meta[key] == crowd.meta[key]
    assert cli_main(["layout", "--density", "D2", "--characters", "0", "--out", str(out)]) == 2
    assert "--characters" in capsys.readouterr().err

"""ORCA simulator, corridor scenario, plots and the pyrvo comparison (crowdstudy.navigation)."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from crowdstudy.cli import main as cli_main
from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.navigation import (
    MAX_TURN_RATE,
    ORCAParams,
    ORCASimulator,
    corridor_crowd,
    smooth_headings,
    speed_factor,
    trajectory_summary,
)
from crowdstudy.scene import Crowd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from figure_fixtures import plotted_discs, xy_order  # noqa: E402


@pytest.fixture(scope="module")
def kernels():
    """Compile (or load from the cache) the Warp kernels once for this module."""
    sim = ORCASimulator([[0.0, 0.0], [1.0, 0.0]], 0.2, 1.0)
    sim.step()
    return True


@pytest.fixture(scope="module")
def design():
    return load_design()


@pytest.fixture(scope="module")
def corridor_d5(kernels, design):
    return corridor_crowd(design, "D5", 1, duration=4.0)


def _run(sim, pref, steps):
    sim.set_preferred_velocities(pref)
    traj = []
    for _ in range(steps):
        sim.step()
        traj.append(sim.positions)
    return np.array(traj)


def test_two_agents_head_on_avoid_each_other(kernels):
    r = 0.25
    sim = ORCASimulator([[-2.0, 0.0], [2.0, 0.0]], r, 1.5, params=ORCAParams(time_step=0.05))
    traj = _run(sim, [[1.2, 0.0], [-1.2, 0.0]], 100)
    gap = np.linalg.norm(traj[:, 0] - traj[:, 1], axis=1)
    assert gap.min() >= 2 * r * (1 - 0.01)
    assert traj[-1, 0, 0] > 2.0 and traj[-1, 1, 0] < -2.0  # both got past
    assert np.abs(traj[:, :, 1]).max() > 0.1  # by stepping sideways
    np.testing.assert_allclose(traj[:, 0], -traj[:, 1], atol=1e-4)  # reciprocal: symmetric manoeuvre


def test_agents_do_not_cross_a_wall(kernels):
    wall_y, r = 1.0, 0.25
    starts = np.array([[x, 0.0] for x in np.linspace(-2.0, 2.0, 5)])
    sim = ORCASimulator(
        starts, r, 1.5, obstacles=[[[-10.0, wall_y], [10.0, wall_y]]], params=ORCAParams(time_step=0.05)
    )
    pref = np.tile([[0.4, 1.4]], (5, 1))  # walking into the wall at an angle
    traj = _run(sim, pref, 80)
    assert traj[..., 1].max() + r <= wall_y + 1e-3
    assert traj[-1, :, 1].min() > wall_y - r - 0.05  # they did reach it
    assert np.all(traj[-1, :, 0] > starts[:, 0] + 1.0)  # and slide along it


def test_wall_end_vertex_is_walked_around(kernels):
    # a short wall across an oblique path: the agent slides along it and round its end
    sim = ORCASimulator(
        [[-2.0, 0.8]], 0.25, 1.5, obstacles=[[[0.0, -0.5], [0.0, 1.0]]], params=ORCAParams(time_step=0.05)
    )
    traj = _run(sim, [[1.2, -0.5]], 120)
    assert traj[-1, 0, 0] > 1.0
    crossing = np.flatnonzero(np.diff(np.sign(traj[:, 0, 0])) != 0)
    assert crossing.size == 1
    assert traj[crossing[0], 0, 1] < -0.5 - 0.2
    end = np.array([0.0, -0.5])
    assert np.linalg.norm(traj[:, 0] - end, axis=1).min() >= 0.25 * 0.99  # never cut the corner


def test_periodic_neighbours_across_the_seam(kernels):
    length, r = 4.0, 0.25
    # agent 0 walks +x towards the seam; agent 1 stands just beyond it (x = -1.9 ~ 2.1)
    sim = ORCASimulator(
        [[1.0, 0.0], [-1.9, 0.15]],
        r,
        1.5,
        periodic=(-2.0, length),
        params=ORCAParams(time_step=0.05, neighbor_dist=1.5),
    )
    traj = _run(sim, [[1.2, 0.0], [0.0, 0.0]], 60)
    rel = traj[:, 0] - traj[:, 1]
    rel[:, 0] -= length * np.round(rel[:, 0] / length)
    assert np.linalg.norm(rel, axis=1).min() >= 2 * r * 0.99
    assert np.abs(traj[:, 0, 1]).max() > 0.2  # it did step aside
    assert traj[-1, 0, 0] > 2.5  # positions stay unwrapped


def test_simulator_bad_inputs_name_the_argument(kernels):
    with pytest.raises(InvalidInputError, match=r"^positions"):
        ORCASimulator([[0.0, np.nan]], 0.2, 1.0)
    with pytest.raises(InvalidInputError, match=r"^radius"):
        ORCASimulator([[0.0, 0.0]], -0.2, 1.0)
    with pytest.raises(InvalidInputError, match=r"^max_speed"):
        ORCASimulator([[0.0, 0.0], [1.0, 0.0]], 0.2, [1.0, 2.0, 3.0])
    with pytest.raises(InvalidInputError, match=r"neighbor_dist"):
        ORCASimulator([[0.0, 0.0]], 0.2, 1.0, periodic=(0.0, 2.0), params=ORCAParams(neighbor_dist=1.5))
    with pytest.raises(InvalidInputError, match=r"^ORCAParams.time_step"):
        ORCAParams(time_step=0.0)
    with pytest.raises(InvalidInputError, match=r"^obstacles"):
        ORCASimulator([[0.0, 0.0]], 0.2, 1.0, obstacles=[[[1.0, 1.0], [1.0, 1.0]]])
    sim = ORCASimulator([[0.0, 0.0]], 0.2, 1.0)
    with pytest.raises(InvalidInputError, match=r"^pref"):
        sim.set_preferred_velocities([[1.0, 0.0], [0.0, 1.0]])


def test_corridor_bars_at_d5(corridor_d5, design):
    crowd = corridor_d5
    assert isinstance(crowd, Crowd)
    n = design.n_characters("D5")
    t = int(round(4.0 * design.fps))
    assert crowd.positions.shape == (t, n, 2) and crowd.velocities.shape == (t, n, 2)
    assert crowd.headings.shape == (t, n)
    assert crowd.meta["periodic"] == {"axis": 0, "length": 4.5}
    s = trajectory_summary(crowd)
    assert s["max_overlap"] <= 0.01  # no overlap above 1 % of the radius
    assert s["overlapping_pairs"] == 0
    assert s["wall_clearance"] >= 0.0  # no disc crosses a wall
    assert s["mean_speed"] > 0.3
    assert s["max_turn_rate"] <= MAX_TURN_RATE * (1 + 1e-9)
    # unwrapped positions are continuous; frame 0 lies in the section
    assert np.abs(np.diff(crowd.positions[..., 0], axis=0)).max() < 0.1
    assert np.all(np.abs(crowd.positions[0, :, 0]) <= 2.25)
    # the velocities are the frame-to-frame motion
    np.testing.assert_allclose(np.diff(crowd.positions, axis=0) * crowd.fps, crowd.velocities[1:], atol=1e-9)
    # discs fit the densest cell: packing fraction of the section at most 0.6
    assert n * math.pi * crowd.radius[0] ** 2 / 9.0 <= 0.6 * (n / 9.0) / 6.66 + 1e-9


def test_corridor_is_deterministic_and_saves(corridor_d5, design, tmp_path):
    again = corridor_crowd(design, "D5", 1, duration=4.0)
    assert again.positions.tobytes() == corridor_d5.positions.tobytes()
    path = corridor_d5.save(tmp_path / "walk.npz")
    loaded = Crowd.load(path)
    np.testing.assert_array_equal(loaded.positions, corridor_d5.positions)
    assert loaded.periodic_length == 4.5


def test_corridor_bidirectional_and_density_slowdown(kernels, design):
    crowd = corridor_crowd(design, "D4", 2, duration=3.0, direction="bidirectional")
    signs = np.array(crowd.meta["directions"])
    assert (signs < 0).sum() == crowd.n_agents // 2
    vx = crowd.velocities[..., 0].mean(axis=0)
    assert np.mean(vx[signs > 0] > 0) > 0.8 and np.mean(vx[signs < 0] < 0) > 0.8  # a few can be swept along
    assert np.mean(crowd.positions[:, signs > 0, 1]) < -0.2 < 0.2 < np.mean(crowd.positions[:, signs < 0, 1])  # lanes
    s = trajectory_summary(crowd)
    assert s["max_overlap"] <= 0.01 and s["wall_clearance"] >= 0.0
    assert s["mean_speed"] > 0.3
    assert s["max_turn_rate"] <= MAX_TURN_RATE * (1 + 1e-9)
    assert speed_factor(2.22) > speed_factor(6.66) > 0.3
    with pytest.raises(InvalidInputError, match=r"^direction"):
        corridor_crowd(design, "D1", 2, duration=1.0, direction="sideways")
    with pytest.raises(InvalidInputError, match=r"^level"):
        corridor_crowd(design, "D0", 2, duration=1.0)
    with pytest.raises(InvalidInputError, match=r"^duration"):
        corridor_crowd(design, "D1", 2, duration=-1.0)


def test_smooth_headings_bound_the_turn_rate_and_handle_wrap():
    fps = 30.0
    t = np.arange(90)
    vel = np.zeros((90, 3, 2))
    vel[:, 0] = [1.0, 0.0]
    vel[45:, 0] = [-1.0, 0.0]  # sudden reversal
    ang = np.pi - 0.05 + 0.1 * (t % 2)  # jitter across the +-pi seam
    vel[:, 1] = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    vel[:, 2] = 0.0  # standing still: heading held
    h = smooth_headings(vel, fps, initial=[0.0, np.pi, 1.0])
    dh = (np.diff(h, axis=0) + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(dh).max() * fps <= MAX_TURN_RATE * (1 + 1e-9)
    assert abs(abs(h[-1, 0]) - np.pi) < 0.05  # finished the half turn
    assert np.abs((h[:, 1] - np.pi + np.pi) % (2 * np.pi) - np.pi).max() < 0.06  # no spin at the seam
    np.testing.assert_allclose(h[:, 2], 1.0)


def test_plot_layouts_and_trajectories(corridor_d5, design, tmp_path, saved_figures):
    from matplotlib.colors import to_rgba

    from crowdstudy.layout import concert_layout
    from crowdstudy.navigation.plot import plot_layouts_and_trajectories

    layouts = [concert_layout(design, level, 1) for level in design.densities]
    walk = corridor_d5.replace(
        positions=corridor_d5.positions[::4], velocities=corridor_d5.velocities[::4], headings=corridor_d5.headings[::4]
    )
    path = plot_layouts_and_trajectories(layouts, walk, tmp_path / "fig.png")
    assert path.is_file() and len(saved_figures) == 1
    axes = saved_figures[0].axes
    assert len(axes) == len(layouts) + 1
    # top row: each layout's discs where its characters stand
    for ax, crowd in zip(axes[: len(layouts)], layouts, strict=True):
        centres, radii = plotted_discs(ax)
        pos = crowd.positions[0]
        np.testing.assert_allclose(centres[xy_order(centres)], pos[xy_order(pos)], atol=1e-6)
        np.testing.assert_allclose(radii, crowd.radius, rtol=1e-3)
    # bottom: every agent's path, wrapped into the periodic section [x0, x0 + L), walls in black
    ax = axes[-1]
    length = walk.periodic_length
    x0 = float(walk.region[:, 0].min())
    wrapped = walk.positions.copy()
    wrapped[..., 0] = x0 + np.mod(wrapped[..., 0] - x0, length)
    walls = [ln for ln in ax.lines if to_rgba(ln.get_color()) == to_rgba("k")]
    paths = [ln for ln in ax.lines if ln not in walls]
    assert len(walls) == len(walk.obstacles)
    for ln, seg in zip(walls, walk.obstacles, strict=True):
        np.testing.assert_allclose(np.c_[ln.get_xdata(), ln.get_ydata()], seg)
    points = np.concatenate([np.c_[ln.get_xdata(), ln.get_ydata()] for ln in paths])
    assert len(paths) >= walk.n_agents
    assert points.shape == (walk.n_frames * walk.n_agents, 2)  # each sample drawn once
    assert points[:, 0].min() >= x0 and points[:, 0].max() < x0 + length
    expected = wrapped.reshape(-1, 2)
    np.testing.assert_allclose(points[np.lexsort(points.T[::-1])], expected[np.lexsort(expected.T[::-1])], atol=1e-9)
    for ln in paths:  # no segment jumps across the seam
        assert np.abs(np.diff(ln.get_xdata())).max(initial=0.0) < length / 2
    centres, _ = plotted_discs(ax)  # the final discs
    last = wrapped[-1]
    np.testing.assert_allclose(centres[np.lexsort(centres.T[::-1])], last[np.lexsort(last.T[::-1])], atol=1e-6)
    with pytest.raises(InvalidInputError, match=r"^layouts"):
        plot_layouts_and_trajectories([], None, tmp_path / "empty.png")


def test_navigate_cli(kernels, tmp_path, capsys):
    out = tmp_path / "walk.npz"
    assert cli_main(["navigate", "--density", "D2", "--seed", "3", "--duration", "1", "--out", str(out)]) == 0
    crowd = Crowd.load(out)
    assert crowd.positions.shape[:2] == (30, 30)
    assert "mean speed" in capsys.readouterr().out
    assert cli_main(["navigate", "--density", "D8", "--out", str(out)]) == 2


def test_matches_pyrvo_on_a_small_room(kernels):
    pytest.importorskip("pyrvo")
    from crowdstudy.navigation.room import RoomScenario, run_room

    # identical state -> identical first step (same algorithm, same float32 arithmetic)
    sc = RoomScenario(n_agents=150, density=2.0, seed=5)
    ours, ref = run_room(sc, 1, engine="crowdstudy"), run_room(sc, 1, engine="pyrvo")
    assert np.abs(ours.positions - ref.positions).max() < 1e-5
    # the same scenario over 2.5 s: both collision-free, same mean speed within 10 %
    sc = RoomScenario(n_agents=100, density=1.5, seed=0, safety_margin=1.03)
    ours, ref = run_room(sc, 150, engine="crowdstudy", check_every=5), run_room(sc, 150, engine="pyrvo", check_every=5)
    assert ours.overlaps == 0 and ref.overlaps == 0
    assert ours.outside == 0 and ref.outside == 0
    assert abs(ours.mean_speed - ref.mean_speed) <= 0.1 * ref.mean_speed
    assert ours.mean_speed > 0.5

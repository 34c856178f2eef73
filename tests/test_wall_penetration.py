"""crowdstudy.metrics.wall_penetration: skin through the scene's walls, on known geometry."""

from __future__ import annotations

import numpy as np
import pytest
from test_metrics import animation, sphere_body

from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics import summarize, wall_penetration

trimesh = pytest.importorskip("trimesh")

R = 0.3
CORRIDOR = {
    "scenario": "corridor",
    "periodic": {"axis": 0, "length": 4.5},
    "obstacles": [[[-1.0, -1.0], [5.5, -1.0]], [[-1.0, 1.0], [5.5, 1.0]]],
}


@pytest.fixture(scope="module")
def ball():
    body = sphere_body(R)
    return body, float(body.rest_vertices[:, 1].max()), float(-body.rest_vertices[:, 1].min())


def test_depth_of_a_ball_pressed_into_a_corridor_wall(ball):
    body, top, bottom = ball
    anim = animation([[[0.5, 0.0, 1.0]], [[0.5, 0.8, 1.0]], [[0.5, -0.9, 1.0]]], meta=CORRIDOR)
    res = wall_penetration(anim, bodies=[body])
    assert res.n_walls == 2 and res.per_character.shape == (3, 1)
    np.testing.assert_allclose(res.per_character[:, 0], [0.0, 0.8 + top - 1.0, bottom - 0.1], atol=1e-9)
    assert res.max_cm == pytest.approx(100 * (bottom - 0.1))
    assert res.fraction_through == pytest.approx(2 / 3)


def test_the_walls_repeat_with_the_period_and_end_where_they_end(ball):
    body, top, _ = ball
    # the same pose many periods on (a walker's unwrapped x) is as deep
    far = animation([[[0.5 + 4.5 * 7, 0.8, 1.0]], [[0.5 - 4.5 * 3, 0.8, 1.0]]], meta=CORRIDOR)
    np.testing.assert_allclose(wall_penetration(far, bodies=[body]).per_character[:, 0], 0.8 + top - 1.0, atol=1e-9)
    # a 2 m wall: beside it, past its end, and beside it again at the next period's image
    short = {**CORRIDOR, "obstacles": [[[-1.0, 1.0], [1.0, 1.0]]]}
    anim = animation([[[0.0, 0.8, 1.0]], [[3.0, 0.8, 1.0]], [[4.4, 0.8, 1.0]]], meta=short)
    depth = wall_penetration(anim, bodies=[body]).per_character[:, 0]
    assert depth[0] == pytest.approx(0.8 + top - 1.0) and depth[1] == 0.0 and depth[2] == pytest.approx(depth[0])


def test_a_wall_is_seen_from_the_side_the_root_stands_on(ball):
    body, _, bottom = ball
    # outside the corridor, beyond the y = 1 wall: clear of it at y = 1.5, 0.1 m through at 1.2
    anim = animation([[[0.5, 1.5, 1.0]], [[0.5, 1.2, 1.0]]], meta=CORRIDOR)
    np.testing.assert_allclose(
        wall_penetration(anim, bodies=[body]).per_character[:, 0], [0.0, bottom - 0.2], atol=1e-9
    )


def test_no_walls_and_bad_input(ball):
    body, _, _ = ball
    anim = animation([[[0.5, 0.9, 1.0]]], meta={"scenario": "concert", "obstacles": []})
    res = wall_penetration(anim, bodies=[body])
    assert res.n_walls == 0 and res.max_cm == 0.0
    with pytest.raises(InvalidInputError, match="anim"):
        wall_penetration("not an animation")
    with pytest.raises(InvalidInputError, match="obstacles"):
        wall_penetration(animation([[[0.0, 0.0, 1.0]]], meta={"scenario": "corridor"}), bodies=[body])


def test_summary_reports_skin_through_walls(ball):
    body, top, _ = ball
    base = animation([[[0.5, 0.8, 1.0]]] * 4, meta=CORRIDOR)
    ours = animation([[[0.5, 0.75, 1.0]]] * 4, meta=CORRIDOR)
    s = summarize(ours, base, geometries=("capsule",), bodies=[body])
    assert s["reference_wall_penetration_p99_cm"] == pytest.approx(100 * (0.8 + top - 1.0))
    assert s["wall_penetration_max_cm"] == pytest.approx(100 * (0.75 + top - 1.0))

"""crowdstudy.metrics.separation_floor: the least displacement that takes capsules apart,
on geometry whose answer is known."""

from __future__ import annotations

import re

import numpy as np
import pytest
from test_metrics import animation, sphere_body

from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics import separation_floor

pytest.importorskip("trimesh")

R = 0.3
OPEN = {"scenario": "concert", "obstacles": []}
LOOP = {"scenario": "corridor", "periodic": {"axis": 0, "length": 4.5}, "obstacles": []}
CORRIDOR = {**LOOP, "obstacles": [[[-1.0, -1.0], [5.5, -1.0]], [[-1.0, 1.0], [5.5, 1.0]]]}


@pytest.fixture(scope="module")
def ball():
    return sphere_body(R)


def _floor(anim, body, **kw):
    return separation_floor(anim, frames="all", bodies=[body] * anim.n_characters, margin=0.0, **kw)


def test_two_balls_each_move_half_the_overlap(ball):
    anim = animation([[[0.0, 0.0, 1.0], [0.5, 0.0, 1.0]], [[0.0, 0.0, 1.0], [0.7, 0.0, 1.0]]], meta=OPEN)
    res = _floor(anim, ball)
    assert res.per_joint.shape == (2, 2, 24)
    np.testing.assert_allclose(res.per_joint[0, :, 0], [0.05, 0.05], atol=2e-4)  # 0.1 m overlap, half each
    assert res.per_joint[1].max() == 0.0  # apart already
    assert not res.per_joint[:, :, 1:].any()  # capsule-less joints stay
    assert res.mean_cm == pytest.approx(100 * 0.05 * 2 / (2 * 2 * 24), rel=1e-2)
    assert res.residual.max() <= 1e-4


def test_a_ball_between_two_stays_and_the_outer_ones_make_room(ball):
    """Three balls 0.5 m apart in a row need 1.2 m: the least displacement leaves the middle
    one and moves each outer one 0.1 m out."""
    anim = animation([[[0.0, 0.0, 1.0], [0.5, 0.0, 1.0], [1.0, 0.0, 1.0]]], meta=OPEN)
    move = _floor(anim, ball).per_joint[0, :, 0]
    np.testing.assert_allclose(move, [0.1, 0.0, 0.1], atol=1e-3)


def test_the_period_joins_the_corridor_ends(ball):
    # x = 0.1 and x = 4.4 are 0.2 m apart across the seam of a 4.5 m period (0.4 m overlap)
    anim = animation([[[0.1, 0.0, 1.0], [4.4 + 4.5 * 3, 0.0, 1.0]]], meta=LOOP)
    np.testing.assert_allclose(_floor(anim, ball).per_joint[0, :, 0], [0.2, 0.2], atol=1e-3)


def test_walls_push_back_to_the_roots_side(ball):
    # 0.1 m through the y = 1 wall, seen from inside; the same many periods on; the
    # same pose from outside the corridor (root at y = 1.2) is 0.1 m through from there
    anim = animation(
        [[[0.5, 0.8, 1.0], [2.5 + 4.5 * 5, -0.75, 1.0]], [[0.5, 1.2, 1.0], [2.5, 0.0, 1.0]]], meta=CORRIDOR
    )
    res = _floor(anim, ball)
    np.testing.assert_allclose(res.per_joint[:, :, 0], [[0.1, 0.05], [0.1, 0.0]], atol=2e-4)
    assert not _floor(anim, ball, walls=False).per_joint.any()


def test_it_says_whom_each_character_touches_and_how_deep(ball):
    """Frame 0: ball 1 reaches 0.1 m into ball 0 and 0.05 m into ball 2 (its deeper partner
    is 0); ball 3 stands alone. Frame 1: all apart."""
    anim = animation(
        [
            [[0.0, 0.0, 1.0], [0.5, 0.0, 1.0], [1.05, 0.0, 1.0], [4.0, 0.0, 1.0]],
            [[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [2.0, 0.0, 1.0], [4.0, 0.0, 1.0]],
        ],
        meta=OPEN,
    )
    res = _floor(anim, ball)
    np.testing.assert_allclose(res.contact_depth, [[0.1, 0.1, 0.05, 0.0], [0.0, 0.0, 0.0, 0.0]], atol=1e-9)
    np.testing.assert_array_equal(res.partner, [[1, 0, 1, -1], [-1, -1, -1, -1]])
    who = res.contacts_per_character()
    np.testing.assert_allclose(who["contact_fraction"], [0.5, 0.5, 0.5, 0.0])
    np.testing.assert_array_equal(who["partner"], [1, 0, 1, -1])
    np.testing.assert_allclose(who["partner_fraction"], [0.5, 0.5, 0.5, 0.0])
    np.testing.assert_allclose(who["deepest_cm"], [10.0, 10.0, 5.0, 0.0], atol=1e-7)
    per = res.as_dict(per_character=True)["separation_floor_per_character"]
    assert per["partner"] == [1, 0, 1, -1] and len(per["floor_cm"]) == 4
    np.testing.assert_allclose(per["floor_cm"], res.per_character_cm)
    assert per["floor_cm"][3] == 0.0 and per["floor_cm"][1] < per["floor_cm"][0]  # the middle one moves least
    assert "separation_floor_per_character" not in res.as_dict()


def test_bad_input_is_named(ball):
    anim = animation([[[0.0, 0.0, 1.0]]], meta=OPEN)
    with pytest.raises(TypeError, match="anim"):
        separation_floor("not an animation")
    with pytest.raises(InvalidInputError, match="tolerance"):
        separation_floor(anim, bodies=[ball], tolerance=0.0)
    with pytest.raises(InvalidInputError, match="obstacles"):
        separation_floor(animation([[[0.0, 0.0, 1.0]]], meta={"scenario": "corridor"}), bodies=[ball])


def test_metrics_cli_reports_the_floor_of_the_reference(ball, tmp_path, monkeypatch, capsys):
    import json

    import crowdstudy.metrics.floor as floor_module
    import crowdstudy.metrics.summary as summary_module
    from crowdstudy import cli

    both = lambda anim, bodies=None: [ball, ball]  # noqa: E731
    monkeypatch.setattr(summary_module, "resolve_bodies", both)
    monkeypatch.setattr(floor_module, "resolve_bodies", both)
    base = animation([[[0.0, 0.0, 1.0], [0.5, 0.0, 1.0]]] * 4, meta={**OPEN, "method": "Baseline"})
    ours = animation([[[-0.06, 0.0, 1.0], [0.56, 0.0, 1.0]]] * 4, meta={**OPEN, "method": "Ours"})
    f_base, f_ours = base.save(tmp_path / "b.npz"), ours.save(tmp_path / "o.npz")
    js = tmp_path / "m.json"
    assert (
        cli.main(
            [
                "metrics",
                str(f_ours),
                "--reference",
                str(f_base),
                "--floor",
                "--geometry",
                "capsule",
                "--json",
                str(js),
                "--no-progress",
            ]
        )
        == 0
    )
    assert "tracking floor (estimate)" in capsys.readouterr().out
    # --per-character: where each character's tracking goes, beside its floor and partner
    assert (
        cli.main(
            [
                "metrics",
                str(f_ours),
                "--reference",
                str(f_base),
                "--floor",
                "--geometry",
                "capsule",
                "--per-character",
                "--no-progress",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    head = next(line for line in out.splitlines() if line.lstrip().startswith("character  tracking cm"))
    assert "placement cm" in head and "floor cm" in head and "deepest cm" in head
    rows = {line.split()[0]: line.split() for line in out.splitlines()[out.splitlines().index(head) + 1 :][:2]}
    # each ball 6 cm off at joint 0 of 24 (the capsule-less joints follow the root too): 6 cm everywhere
    assert float(rows["0"][1]) == pytest.approx(6.0, abs=0.01) and float(rows["1"][2]) == pytest.approx(6.0, abs=0.01)
    assert rows["0"][-3] == "1" and rows["1"][-3] == "0"  # each other's partner
    assert float(rows["0"][-1]) == pytest.approx(11.0, abs=0.05)  # 0.1 m overlap + 2 x 5 mm margin
    assert re.search(r"largest tracking: character [01] \(6\.00 cm\), character [01] \(6\.00 cm\)", out)
    metrics = json.loads(js.read_text())["metrics"]
    # the Baseline's balls overlap by 0.1 m, plus 5 mm of margin on each: 5.5 cm each for joint 0 of 24
    assert metrics["separation_floor_cm"] == pytest.approx(5.5 / 24, rel=1e-2)
    assert metrics["separation_floor_frames"] == 1  # every 30th frame of 4

"""The acceptance bars of Ours against its Baseline (crowdstudy.metrics.bars) and the overlap
of a large crowd's neighbourhoods (crowdstudy.metrics.neighbourhoods)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics import BAR_NAMES, BarTolerances, check_bars, failed_bars, loop_mode, tile_ratios

BARS = BarTolerances()


def _passing_row(t: BarTolerances = BARS) -> dict:
    """A row a hair inside every bar of ``t`` (a looped concert at the densest level)."""
    return {
        "jerk_ratio": t.jerk_ratio - 0.01,
        "hf_share_baseline": 0.02,
        "hf_share_ours": 0.02 * t.hf_share_ratio - 1e-4,
        "max_joint_speed_baseline": 5.0,
        "max_joint_speed_ours": 5.0 + t.joint_speed_increase_m_s - 0.01,
        "pelvis_p99_baseline": 3.0,
        "pelvis_p99_ours": t.pelvis_accel_ratio * 3.0 + t.pelvis_accel_increase_m_s2 - 0.01,
        "foot_slide_p99_ours": t.foot_slide_p99_m_s - 0.001,
        "mesh_ratio": t.overlap_ratio - 0.001,
        "tracking_cm": t.tracking_densest_cm - 0.1,
        "seam_ratio_baseline": 1.0,
        "seam_ratio_ours": t.seam_ratio - 0.01,
        "loop": "periodic",
    }


def test_a_row_inside_every_bar_meets_them_all():
    checks = check_bars(_passing_row(), BARS, 4, 5)
    assert list(checks) == list(BAR_NAMES) and all(checks.values())
    assert failed_bars(checks) == "-"


# each bar's measurement moved just past its tolerance
PAST = {
    "jerk": {"jerk_ratio": BARS.jerk_ratio + 0.01},
    "hf": {"hf_share_ours": 0.02 * BARS.hf_share_ratio + 1e-4},
    "speed": {"max_joint_speed_ours": 5.0 + BARS.joint_speed_increase_m_s + 0.01},
    "pelvis": {"pelvis_p99_ours": BARS.pelvis_accel_ratio * 3.0 + BARS.pelvis_accel_increase_m_s2 + 0.01},
    "slide": {"foot_slide_p99_ours": BARS.foot_slide_p99_m_s + 0.001},
    "overlap": {"mesh_ratio": BARS.overlap_ratio + 0.001},
    "tracking": {"tracking_cm": BARS.tracking_densest_cm + 0.1},
    "seam": {"seam_ratio_ours": BARS.seam_ratio + 0.01},
}


@pytest.mark.parametrize("bar", BAR_NAMES)
def test_each_bar_fails_alone_just_past_its_tolerance(bar):
    checks = check_bars({**_passing_row(), **PAST[bar]}, BARS, 4, 5)
    assert [k for k, ok in checks.items() if not ok] == [bar]
    assert failed_bars(checks) == bar


def test_the_tolerances_decide():
    """A looser bar passes what the default fails, a tighter one fails what it passes."""
    row = {**_passing_row(), **PAST["jerk"], **PAST["overlap"]}
    assert failed_bars(check_bars(row, BARS, 4, 5)) == "jerk,overlap"
    loose = dataclasses.replace(BARS, jerk_ratio=BARS.jerk_ratio + 0.1, overlap_ratio=BARS.overlap_ratio + 0.01)
    assert failed_bars(check_bars(row, loose, 4, 5)) == "-"
    tight = dataclasses.replace(BARS, tracking_densest_cm=1.0)
    assert failed_bars(check_bars(_passing_row(), tight, 4, 5)) == "tracking"
    with pytest.raises(dataclasses.FrozenInstanceError):
        BARS.jerk_ratio = 2.0


def test_the_tracking_bar_holds_at_the_sparsest_and_densest_levels_only():
    assert [BARS.tracking_cm(i, 5) for i in range(5)] == [
        BARS.tracking_sparsest_cm,
        None,
        None,
        None,
        BARS.tracking_densest_cm,
    ]
    row = {**_passing_row(), "tracking_cm": BARS.tracking_sparsest_cm + 0.1}
    assert "tracking" not in check_bars(row, BARS, 2, 5)
    assert check_bars(row, BARS, 0, 5)["tracking"] is False and check_bars(row, BARS, 4, 5)["tracking"] is True
    with pytest.raises(InvalidInputError, match="level_index"):
        BARS.tracking_cm(5, 5)


def test_the_seam_bar_applies_to_a_looped_concert_only():
    """A concert clip too short to hold whole loops is not looped: its last-to-first jump is
    no seam a viewer sees, so the bar is not checked (the corridor dissolves instead)."""
    from crowdstudy.design import load_design
    from crowdstudy.motion.baseline import build_baseline

    design = load_design()
    looped = build_baseline(design, "stationary", "D1", duration=2.0, body_model="open")
    short = build_baseline(design, "stationary", "D1", duration=0.3, body_model="open")
    assert loop_mode(looped) == "periodic" and loop_mode(short) == "none"
    row = {**_passing_row(), "seam_ratio_baseline": 7.4, "seam_ratio_ours": 7.5}
    assert check_bars({**row, "loop": "periodic"}, BARS, 2, 5)["seam"] is False
    assert "seam" not in check_bars({**row, "loop": "none"}, BARS, 2, 5)
    assert "seam" not in check_bars({**row, "loop": "dissolve"}, BARS, 2, 5)


def test_bad_tolerances_and_rows_are_named():
    for field in ("jerk_ratio", "overlap_ratio", "seam_ratio"):
        for bad in (0.0, -1.0, float("nan"), True):
            with pytest.raises(InvalidInputError, match=f"BarTolerances.{field}"):
                BarTolerances(**{field: bad})
    row = _passing_row()
    del row["mesh_ratio"]
    with pytest.raises(InvalidInputError, match="mesh_ratio"):
        check_bars(row, BARS, 0, 5)


def test_the_text_follows_the_tolerances():
    text = BARS.text()
    assert list(text) == list(BAR_NAMES)
    assert text["jerk"] == "mean jerk <= 1.3x" and text["overlap"] == "mesh overlap <= 5 %"
    assert text["tracking"] == "tracking <= 1.5 cm at D1, <= 5 cm at D5"
    assert dataclasses.replace(BARS, overlap_ratio=0.03).text()["overlap"] == "mesh overlap <= 3 %"


def test_tile_ratios_are_the_overlap_of_each_neighbourhood():
    """Characters binned into floor tiles: each tile's summed Ours over summed Baseline; a
    tile with too few characters, or no Baseline overlap, is left out."""
    xy = np.array(
        [
            [0.5, 0.5],
            [1.0, 2.0],
            [2.9, 0.1],  # tile (0, 0)
            [3.5, 0.5],
            [5.0, 2.5],  # tile (1, 0)
            [0.5, 3.5],  # tile (0, 1): one character
            [4.0, 4.0],
            [5.5, 3.1],
        ]
    )  # tile (1, 1): no Baseline overlap
    base = np.array([1.0, 2.0, 1.0, 4.0, 4.0, 9.0, 0.0, 0.0])
    ours = np.array([0.1, 0.0, 0.1, 0.2, 0.6, 9.0, 0.5, 0.5])
    ratios = tile_ratios(xy, base, ours, (3.0, 3.0), min_characters=2)
    assert ratios == pytest.approx([0.05, 0.1])
    assert tile_ratios(xy, base, ours, (3.0, 3.0), min_characters=1) == pytest.approx([0.05, 0.1, 1.0])
    whole = tile_ratios(xy, base, ours, (10.0, 10.0), min_characters=1)
    assert whole == pytest.approx([ours.sum() / base.sum()])
    with pytest.raises(InvalidInputError, match="xy"):
        tile_ratios(xy[:, :1], base, ours, (3.0, 3.0), 1)

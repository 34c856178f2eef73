"""The layout figure of ``crowdstudy layout --plot`` (crowdstudy.layout.plot)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from figure_fixtures import plotted_discs  # noqa: E402

from crowdstudy.design import load_design
from crowdstudy.errors import InvalidInputError
from crowdstudy.layout import concert_layout
from crowdstudy.layout.plot import plot_layouts


def test_plot_layouts_draws_every_character(tmp_path, saved_figures):
    design = load_design()
    crowds = [concert_layout(design, level, 1) for level in ("D1", "D2")]
    path = plot_layouts(crowds, tmp_path / "sub" / "layouts.png")
    assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the figure's data: one panel per layout, a disc of the crowd's radius at every position
    (fig,) = saved_figures
    panels = [ax for ax in fig.axes if plotted_discs(ax)[0].size]
    assert len(panels) == 2
    for ax, crowd in zip(panels, crowds, strict=True):
        centres, radii = plotted_discs(ax)
        want = crowd.positions[0]
        assert len(centres) == len(want)
        d = np.linalg.norm(centres[:, None] - want[None], axis=-1)
        assert d.min(axis=1).max() < 1e-6 and d.min(axis=0).max() < 1e-6
        np.testing.assert_allclose(radii, crowd.radius, rtol=1e-3)
    with pytest.raises(InvalidInputError, match="nothing to plot"):
        plot_layouts([], tmp_path / "empty.png")
    with pytest.raises(InvalidInputError, match=r"layouts\[1\]"):
        plot_layouts([crowds[0], "not a crowd"], tmp_path / "bad.png")

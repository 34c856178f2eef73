"""Figures of crowd layouts: discs of one frame (matplotlib, imported lazily).

:mod:`crowdstudy.navigation.plot` builds on these for the corridor trajectories.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.scene import Crowd

__all__ = ["plot_layouts", "draw_layout", "draw_layout_row", "check_layouts", "pyplot"]


def pyplot():
    """``matplotlib.pyplot``, switched to the Agg backend unless one for files or notebooks
    is set (files only: never open a window)."""
    import matplotlib

    interactive = matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "cairo")
    if interactive and "inline" not in matplotlib.get_backend():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_layout(ax, crowd: Crowd, frame: int = 0, title: str | None = None) -> None:
    """Discs of one frame of ``crowd`` with the region outline on a matplotlib Axes."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Circle, Polygon

    pos = crowd.positions[frame]
    length = crowd.periodic_length
    if length:
        x0 = float(crowd.region[:, 0].min()) if len(crowd.region) else -length / 2
        pos = pos.copy()
        pos[:, 0] = x0 + np.mod(pos[:, 0] - x0, length)
    if len(crowd.region):
        ax.add_patch(Polygon(crowd.region, closed=True, fill=False, ls="--", lw=0.8, color="0.4"))
    discs = [Circle(p, r) for p, r in zip(pos, crowd.radius, strict=True)]
    ax.add_collection(PatchCollection(discs, facecolor="tab:blue", edgecolor="navy", alpha=0.55, lw=0.6))
    if crowd.headings is not None:
        h = crowd.headings[frame]
        ax.quiver(
            pos[:, 0],
            pos[:, 1],
            np.cos(h) * crowd.radius,
            np.sin(h) * crowd.radius,
            angles="xy",
            scale_units="xy",
            scale=1,
            width=0.004,
            color="navy",
        )
    for seg in crowd.obstacles:
        ax.plot(seg[:, 0], seg[:, 1], color="k", lw=2.5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    if title:
        ax.set_title(title, fontsize=9)


def check_layouts(layouts) -> list[Crowd]:
    """``layouts`` as a list, each checked to be a Crowd (errors name the index)."""
    layouts = list(layouts)
    for i, c in enumerate(layouts):
        if not isinstance(c, Crowd):
            raise InvalidInputError(f"layouts[{i}]: expected a Crowd, got {type(c).__name__}")
    return layouts


def draw_layout_row(fig, grid, layouts: list[Crowd]) -> None:
    """The layouts side by side in the first row of ``grid`` (a matplotlib GridSpec)."""
    for k, crowd in enumerate(layouts):
        ax = fig.add_subplot(grid[0, k])
        m = crowd.meta
        title = f"{m.get('density_level', f'layout {k}')}: {crowd.n_agents} chars"
        if "min_distance" in m:
            title += f"\nmin dist {m['min_distance']:.2f} m"
        draw_layout(ax, crowd, title=title)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.tick_params(labelsize=7)


def plot_layouts(layouts: list[Crowd], path) -> Path:
    """One figure of the layouts (T = 1 crowds, e.g. the five concert densities) side by
    side; returns the image file written (.png, .pdf, .svg)."""
    layouts = check_layouts(layouts)
    if not layouts:
        raise InvalidInputError("layouts: nothing to plot")
    plt = pyplot()
    fig = plt.figure(figsize=(3.0 * len(layouts), 3.5), constrained_layout=True)
    draw_layout_row(fig, fig.add_gridspec(1, len(layouts)), layouts)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path

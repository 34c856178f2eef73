"""Figures of corridor trajectories, with the layouts of :mod:`crowdstudy.layout.plot`
(matplotlib, imported lazily)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.layout.plot import check_layouts, draw_layout, draw_layout_row, pyplot
from crowdstudy.scene import Crowd

__all__ = ["plot_layouts_and_trajectories", "draw_layout", "draw_trajectories"]


def draw_trajectories(ax, crowd: Crowd, title: str | None = None, every: int = 1) -> None:
    """Paths of all agents, wrapped to the periodic section, walls and final discs."""
    pos = crowd.positions[::every]
    length = crowd.periodic_length
    x0 = float(crowd.region[:, 0].min()) if len(crowd.region) else (-length / 2 if length else 0.0)
    cmap = pyplot().get_cmap("viridis")
    n = pos.shape[1]
    for i in range(n):
        xy = pos[:, i].copy()
        if length:
            xy[:, 0] = x0 + np.mod(xy[:, 0] - x0, length)
            jumps = np.flatnonzero(np.abs(np.diff(xy[:, 0])) > length / 2) + 1
            pieces = np.split(xy, jumps)
        else:
            pieces = [xy]
        for piece in pieces:
            ax.plot(piece[:, 0], piece[:, 1], lw=0.7, alpha=0.7, color=cmap(i / max(n - 1, 1)))
    last = crowd.replace(
        positions=crowd.positions[-1:],
        velocities=None,
        headings=None if crowd.headings is None else crowd.headings[-1:],
    )
    draw_layout(ax, last)
    if title:
        ax.set_title(title, fontsize=9)


def plot_layouts_and_trajectories(layouts: list[Crowd], corridor: Crowd | None, path) -> Path:
    """One figure: the density layouts (top row of discs) and the corridor trajectories.

    Args:
        layouts: layout crowds (T = 1), e.g. the five concert densities.
        corridor: trajectory crowd of the corridor, or None.
        path: output image file (.png, .pdf, .svg).

    Returns:
        The path written.
    """
    layouts = check_layouts(layouts)
    if not layouts and corridor is None:
        raise InvalidInputError("layouts: nothing to plot (no layouts and no corridor)")
    if corridor is not None and not isinstance(corridor, Crowd):
        raise InvalidInputError(f"corridor: expected a Crowd or None, got {type(corridor).__name__}")
    plt = pyplot()
    cols = max(len(layouts), 1)
    rows = (1 if layouts else 0) + (1 if corridor is not None else 0)
    fig = plt.figure(figsize=(3.0 * cols, 3.2 * rows + 0.3), constrained_layout=True)
    grid = fig.add_gridspec(rows, cols)
    draw_layout_row(fig, grid, layouts)
    if corridor is not None:
        ax = fig.add_subplot(grid[rows - 1, :])
        m = corridor.meta
        speed = float(np.linalg.norm(corridor.velocities, axis=2).mean()) if corridor.velocities is not None else None
        kind = m.get("scenario", "corridor")
        how = m.get("direction", "") if kind == "corridor" else f"{m.get('plaza', {}).get('angle', 90):g} deg"
        title = (
            f"{kind} {m.get('density_level', '')} ({how}): {corridor.n_agents} agents, "
            f"{corridor.n_frames / corridor.fps:.1f} s"
        )
        if speed is not None:
            title += f", mean speed {speed:.2f} m/s"
        draw_trajectories(ax, corridor, title=title)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path

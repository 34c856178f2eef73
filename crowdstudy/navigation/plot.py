"""Figures of crowd layouts (discs) and corridor trajectories (matplotlib, imported lazily)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.scene import Crowd

__all__ = ["plot_layouts_and_trajectories", "draw_layout", "draw_trajectories"]


def _pyplot():
    import matplotlib

    interactive = matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "cairo")
    if interactive and "inline" not in matplotlib.get_backend():
        matplotlib.use("Agg")            # files only: never open a window
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
    discs = [Circle(p, r) for p, r in zip(pos, crowd.radius)]
    ax.add_collection(PatchCollection(discs, facecolor="tab:blue", edgecolor="navy", alpha=0.55, lw=0.6))
    if crowd.headings is not None:
        h = crowd.headings[frame]
        ax.quiver(pos[:, 0], pos[:, 1], np.cos(h) * crowd.radius, np.sin(h) * crowd.radius, angles="xy",
                  scale_units="xy", scale=1, width=0.004, color="navy")
    for seg in crowd.obstacles:
        ax.plot(seg[:, 0], seg[:, 1], color="k", lw=2.5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    if title:
        ax.set_title(title, fontsize=9)


def draw_trajectories(ax, crowd: Crowd, title: str | None = None, every: int = 1) -> None:
    """Paths of all agents, wrapped to the periodic section, walls and final discs."""
    pos = crowd.positions[::every]
    length = crowd.periodic_length
    x0 = float(crowd.region[:, 0].min()) if len(crowd.region) else (-length / 2 if length else 0.0)
    cmap = _pyplot().get_cmap("viridis")
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
    last = crowd.replace(positions=crowd.positions[-1:], velocities=None,
                         headings=None if crowd.headings is None else crowd.headings[-1:])
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
    layouts = list(layouts)
    if not layouts and corridor is None:
        raise InvalidInputError("layouts: nothing to plot (no layouts and no corridor)")
    for i, c in enumerate(layouts):
        if not isinstance(c, Crowd):
            raise InvalidInputError(f"layouts[{i}]: expected a Crowd, got {type(c).__name__}")
    if corridor is not None and not isinstance(corridor, Crowd):
        raise InvalidInputError(f"corridor: expected a Crowd or None, got {type(corridor).__name__}")
    plt = _pyplot()
    cols = max(len(layouts), 1)
    rows = (1 if layouts else 0) + (1 if corridor is not None else 0)
    fig = plt.figure(figsize=(3.0 * cols, 3.2 * rows + 0.3), constrained_layout=True)
    grid = fig.add_gridspec(rows, cols)
    for k, crowd in enumerate(layouts):
        ax = fig.add_subplot(grid[0, k])
        m = crowd.meta
        title = f"{m.get('density_level', f'layout {k}')}: {crowd.n_agents} chars"
        if "min_distance" in m:
            title += f"\nmin dist {m['min_distance']:.2f} m"
        draw_layout(ax, crowd, title=title)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.tick_params(labelsize=7)
    if corridor is not None:
        ax = fig.add_subplot(grid[rows - 1, :])
        m = corridor.meta
        speed = float(np.linalg.norm(corridor.velocities, axis=2).mean()) if corridor.velocities is not None else None
        title = (f"corridor {m.get('density_level', '')} ({m.get('direction', '')}): {corridor.n_agents} agents, "
                 f"{corridor.n_frames / corridor.fps:.1f} s")
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

"""Assumption checks of the repeated-measures ANOVA: normality of the residuals per cell
(Shapiro-Wilk, Q-Q plots). Sphericity (Mauchly) is part of :func:`~crowdstudy.stats.anova.rm_anova`.

Residuals of the cell-means model: for subject ``s`` and cell ``c``,
``e_sc = y_sc - mean_s(y_sc)`` (the ANOVA's per-cell deviations; the subject effect does
not change their shape within a cell).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from scipy import stats as _st

from crowdstudy.stats._data import CellMatrix, cell_matrix

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["cell_residuals", "shapiro_by_cell", "shapiro_from_cells", "qq_figure", "qq_figure_from_cells"]


def cell_residuals(cm: CellMatrix) -> np.ndarray:
    """(n_subjects, n_cells) residuals ``y - cell mean`` in the cell matrix's units."""
    return cm.values - cm.values.mean(axis=0, keepdims=True)


def shapiro_from_cells(cm: CellMatrix, *, alpha: float = 0.05) -> pd.DataFrame:
    """Shapiro-Wilk of the residuals of each cell: one row per cell (factor columns,
    ``cell`` label, ``n``, ``W``, ``p``, ``normal`` = p >= alpha; W and p are NaN when a
    cell's residuals are constant or n < 3)."""
    res = cell_residuals(cm)
    rows = []
    for j, cell in enumerate(cm.cells()):
        r = res[:, j]
        if len(r) >= 3 and np.ptp(r) > 1e-12:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                w, p = _st.shapiro(r)
            w, p = float(w), float(p)
        else:
            w = p = float("nan")
        rows.append(
            {
                **dict(zip(cm.factors, cell, strict=True)),
                "cell": " ".join(map(str, cell)),
                "n": len(r),
                "W": w,
                "p": p,
                "normal": bool(p >= alpha) if np.isfinite(p) else True,
            }
        )
    return pd.DataFrame(rows)


def shapiro_by_cell(
    data: pd.DataFrame, dv: str | None, within, subject: str | None, *, alpha: float = 0.05, missing: str = "raise"
) -> pd.DataFrame:
    """:func:`shapiro_from_cells` from long or wide data (arguments as ``rm_anova``)."""
    return shapiro_from_cells(cell_matrix(data, dv, within, subject, missing=missing), alpha=alpha)


def qq_figure_from_cells(
    cm: CellMatrix,
    out_path: str | Path,
    *,
    title: str | None = None,
    shapiro: pd.DataFrame | None = None,
    dpi: int = 110,
) -> Path:
    """Grid of normal Q-Q plots of the residuals, one panel per cell (rows: levels of the
    first factor; columns: combinations of the others), Shapiro-Wilk p in each panel.
    Saved to ``out_path`` (PNG/PDF/SVG by extension)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    res = cell_residuals(cm)
    shp = shapiro if shapiro is not None else shapiro_from_cells(cm)
    n_rows = len(cm.levels[0])
    n_cols = res.shape[1] // n_rows
    # a fixed layout (margins in inches) and one limit set on the shared axes: tight_layout on
    # a 5x8 grid of shared axes re-measures every tick label many times (seconds per figure)
    panel_w, panel_h, gap_w, gap_h = 1.35, 1.05, 0.2, 0.4
    left, right, bottom, top = 0.65, 0.15, 0.55, 0.45 + (0.2 if title else 0.0)
    width = left + right + n_cols * panel_w + (n_cols - 1) * gap_w
    height = bottom + top + n_rows * panel_h + (n_rows - 1) * gap_h
    fig, axes = plt.subplots(
        n_rows,
        n_cols,
        figsize=(width, height),
        sharex=True,
        sharey=True,
        squeeze=False,
        gridspec_kw={
            "left": left / width,
            "right": 1 - right / width,
            "bottom": bottom / height,
            "top": 1 - top / height,
            "wspace": gap_w / panel_w,
            "hspace": gap_h / panel_h,
        },
    )
    lim = float(np.abs(res).max()) or 1.0
    axes[0, 0].set_ylim(-1.1 * lim, 1.1 * lim)
    axes[0, 0].yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4, steps=[1, 2, 5, 10], symmetric=True))
    axes[0, 0].xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4, steps=[1, 2, 5, 10], symmetric=True))
    for j, cell in enumerate(cm.cells()):
        ax: Axes = axes[j // n_cols, j % n_cols]  # pyright: ignore[reportAssignmentType]  # stubs: an array of Axes
        (osm, osr), (slope, icpt, _) = _st.probplot(res[:, j], dist="norm")
        ax.plot(osm, osr, "o", ms=2.2, color="#1f4e79")
        xs = np.array([osm.min(), osm.max()])
        fit = icpt + slope * xs  # pyright: ignore[reportOperatorIssue]  # scipy stubs: the fit is two floats
        ax.plot(xs, fit, "-", lw=0.8, color="#c0392b")
        p = shp["p"].iloc[j]
        # y given: matplotlib then skips placing each title above its axes' tick labels (none
        # are on top), which would measure the ticks of the 40 panels a second time (the
        # same pixels)
        ax.set_title(" ".join(map(str, cell)) + (f"\np={p:.3f}" if np.isfinite(p) else "\np=n/a"), fontsize=6, y=1.0)
        ax.tick_params(labelsize=5)
    fig.supxlabel("theoretical quantiles (standard normal)", fontsize=8, y=0.12 / height)
    fig.supylabel("residual (cell value - cell mean)", fontsize=8, x=0.12 / width)
    if title:
        fig.suptitle(title, fontsize=9, y=1 - 0.08 / height)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    # the whole figure as laid out above, whatever the caller's rcParams["savefig.bbox"] says
    fig.savefig(
        out, dpi=dpi, bbox_inches=fig.bbox_inches, metadata={"Software": None} if out.suffix.lower() == ".png" else None
    )
    plt.close(fig)
    return out


def qq_figure(
    data: pd.DataFrame,
    dv: str | None,
    within,
    subject: str | None,
    out_path: str | Path,
    *,
    title: str | None = None,
    missing: str = "raise",
) -> Path:
    """:func:`qq_figure_from_cells` from long or wide data."""
    return qq_figure_from_cells(cell_matrix(data, dv, within, subject, missing=missing), out_path, title=title)

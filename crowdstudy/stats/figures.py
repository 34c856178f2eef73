"""Paper-style figure: composite score by density for each method, one panel per viewpoint,
mean with error bars across participants and * / ** / *** for the Method effect at each
density (post hoc comparison of the methods within each Density x Viewpoint cell).

The caption under the title says what the stars are (:func:`stars_caption`): which test,
which adjustment, and whether they are drawn only where the omnibus ANOVA effect is
significant; ``note`` (e.g. "SIMULATED data") is printed in red above the panels."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from crowdstudy.errors import InvalidInputError
from crowdstudy.stats._data import CellMatrix
from crowdstudy.stats.report import stars

__all__ = ["method_figure", "stars_caption"]

_COLORS = {"Baseline": "#b03a2e", "Ours": "#1f618d"}
_MARKERS = {"Baseline": "s", "Ours": "o"}


def stars_caption(adjust: str, n_methods: int, *, rule: str = "always", gate: str = "") -> str:
    """What the stars of :func:`method_figure` mean, for its caption.

    ``adjust``: the post hoc adjustment of the per-cell comparisons; ``n_methods``: levels
    of Method (with 2 the Tukey adjustment is the plain paired t test); ``rule``:
    ``"always"`` or ``"omnibus"`` (stars only where the ANOVA effect(s) named by ``gate``,
    joined by " or ", are significant)."""
    if n_methods == 2:
        test = "paired t test of the two methods in each density x viewpoint cell"
        adj = "unadjusted: one contrast per cell, no correction across cells"
    else:
        test = f"paired comparisons of the {n_methods} methods in each density x viewpoint cell"
        adj = f"{adjust}-adjusted within a cell, not across cells"
    text = f"stars: {test} ({adj}); * p<.05, ** p<.01, *** p<.001"
    if rule == "omnibus":
        which = "an ANOVA effect involving Method" if " or " in gate else f"the ANOVA's {gate or 'Method'} effect"
        text += f"; drawn only if {which} is significant"
    return text


def method_figure(
    panels: dict[str, tuple[CellMatrix, pd.DataFrame | None]],
    out_path: str | Path,
    *,
    density_values: dict[str, float] | None = None,
    error: str = "sd",
    title: str | None = None,
    ylim: tuple[float, float] = (1.0, 6.0),
    dpi: int = 150,
    caption: str | None = None,
    note: str = "",
) -> Path:
    """Draw composite scores by density, one row per composite and one column per viewpoint.

    ``panels``: composite name -> (cell matrix with factors ("Density", "Viewpoint",
    "Method"), post hoc table of Method within Density x Viewpoint (columns Density,
    Viewpoint, p_adj) or None for no stars). ``density_values``: level -> characters/m^2
    for the tick labels. ``error``: "sd" (the paper's mean +- SD), "se" or "ci95".
    ``caption``: the stars' explanation (default: the significance levels only; see
    :func:`stars_caption`); ``note``: a warning line above the panels ("SIMULATED data").
    Saved to ``out_path`` (extension picks the format); the plotted means, error bars,
    stars, caption and note go to ``out_path`` with the suffix ``.json``.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if error not in ("sd", "se", "ci95"):
        raise InvalidInputError(f"error must be 'sd', 'se' or 'ci95', got {error!r}")
    if not panels:
        raise InvalidInputError("method_figure needs at least one composite panel")
    first = next(iter(panels.values()))[0]
    if tuple(first.factors) not in (("Density", "Viewpoint", "Method"), ("Density", "Method")):
        raise InvalidInputError(f"method_figure expects factors (Density, [Viewpoint,] Method), got {first.factors}")
    with_views = len(first.factors) == 3
    dens, methods = first.levels[0], first.levels[-1]
    views = first.levels[1] if with_views else ("",)
    n_rows, n_cols = len(panels), len(views)
    fig, axes = plt.subplots(
        n_rows,
        n_cols,
        figsize=(max(4.2, 2.6 * n_cols + 0.8), 2.3 * n_rows + 1.1),
        sharex=True,
        sharey=True,
        squeeze=False,
        layout="constrained",
    )
    x = np.arange(len(dens))
    width = 0.08 * (len(methods) - 1)
    plotted = {}  # the drawn numbers, written beside the figure (OUT.json)
    for r, (comp, (cm, ph)) in enumerate(panels.items()):
        n = cm.values.shape[0]
        shape = cm.shape if with_views else (cm.shape[0], 1, cm.shape[1])
        grid = cm.values.reshape(n, *shape)
        mean = grid.mean(axis=0)
        sd = grid.std(axis=0, ddof=1)
        err = {"sd": sd, "se": sd / np.sqrt(n), "ci95": sd / np.sqrt(n) * _t975(n - 1)}[error]
        pmap = {}
        if ph is not None and len(ph):
            vcol = ph["Viewpoint"] if with_views else [""] * len(ph)
            pmap = {(str(a), str(b)): p for a, b, p in zip(ph["Density"], vcol, ph["p_adj"], strict=True)}
        for c, vp in enumerate(views):
            ax = axes[r, c]
            for m, meth in enumerate(methods):
                off = (m - (len(methods) - 1) / 2) * width * 2 / max(1, len(methods) - 1) if len(methods) > 1 else 0
                ax.errorbar(
                    x + off,
                    mean[:, c, m],
                    yerr=err[:, c, m],
                    color=_COLORS.get(meth, f"C{m}"),
                    marker=_MARKERS.get(meth, "o"),
                    ms=4,
                    lw=1.3,
                    capsize=2.5,
                    label=str(meth),
                )
            for d, lvl in enumerate(dens):
                s = stars(pmap.get((str(lvl), str(vp)), np.nan))
                plotted.setdefault(comp, []).extend(
                    {
                        "density": str(lvl),
                        "viewpoint": str(vp),
                        "method": str(meth),
                        "mean": float(mean[d, c, m]),
                        "error": float(err[d, c, m]),
                        "stars": s,
                    }
                    for m, meth in enumerate(methods)
                )
                if s:
                    top = float(np.max(mean[d, c, :] + err[d, c, :]))
                    ax.text(x[d], min(top + 0.12, ylim[1] - 0.05), s, ha="center", va="bottom", fontsize=9)
            _style_panel(
                ax,
                ylim,
                [f"{density_values[d]:.2f}" if density_values and d in density_values else str(d) for d in dens],
                title=f"Viewpoint {vp}" if r == 0 and with_views else None,
                ylabel=f"{comp} score" if c == 0 else None,
                xlabel=("density (characters/m$^2$)" if density_values else "density") if r == n_rows - 1 else None,
            )
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(methods), fontsize=8, frameon=False)
    bars = {"sd": "mean +- SD", "se": "mean +- SE", "ci95": "mean +- 95% CI"}[error]
    caption = caption or "* p<.05, ** p<.01, *** p<.001 (Method)"
    head = (f"{note}\n" if note else "") + (title + "\n" if title else "")
    fig.suptitle(
        head + f"{bars}; {caption}",
        fontsize=8 if len(caption) > 70 else 9,
        color="#b03a2e" if note else "black",
        wrap=True,
    )
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, metadata={"Software": None} if out.suffix.lower() == ".png" else None)
    plt.close(fig)
    out.with_suffix(".json").write_text(
        json.dumps({"figure": out.name, "error": error, "caption": caption, "note": note, "series": plotted}, indent=1)
    )
    return out


def _style_panel(
    ax, ylim: tuple[float, float], labels: list[str], *, title: str | None, ylabel: str | None, xlabel: str | None
) -> None:
    """One panel's axes: the y range around ``ylim`` (room for the stars), one x tick per
    density level with its label, a light grid, and the titles it carries (None: none)."""
    ax.set_ylim(ylim[0] - 0.2, ylim[1] + 0.5)
    ax.set_xticks(np.arange(len(labels)))
    ax.set_xticklabels(labels, fontsize=7)
    ax.grid(axis="y", lw=0.4, alpha=0.5)
    if title is not None:
        ax.set_title(title, fontsize=9)
    if ylabel is not None:
        ax.set_ylabel(ylabel, fontsize=9)
    if xlabel is not None:
        ax.set_xlabel(xlabel, fontsize=8)


def _t975(df: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, df))

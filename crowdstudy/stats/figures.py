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
from crowdstudy.stats.scoring import FACTOR_NAMES, FactorNames

__all__ = ["method_figure", "stars_caption", "method_styles"]

#: Colours and markers of the methods by their position in the design's order (the
#: reference first): distinguishable in colour and shape; beyond eight, matplotlib's cycle.
_COLORS = ("#b03a2e", "#1f618d", "#1e8449", "#b9770e", "#6c3483", "#117a65", "#7b7d7d", "#a04000")
_MARKERS = ("s", "o", "^", "D", "v", "P", "X", "<")


def method_styles(methods) -> dict[str, tuple[str, str]]:
    """method name -> (colour, marker), by position in ``methods`` (the design's order)."""
    return {
        str(m): (_COLORS[i] if i < len(_COLORS) else f"C{i}", _MARKERS[i % len(_MARKERS)])
        for i, m in enumerate(methods)
    }


def stars_caption(
    adjust: str, n_methods: int, *, rule: str = "always", gate: str = "", method: str = FACTOR_NAMES.method
) -> str:
    """What the stars of :func:`method_figure` mean, for its caption.

    ``adjust``: the post hoc adjustment of the per-cell comparisons; ``n_methods``: levels
    of Method (with 2 the Tukey adjustment is the plain paired t test); ``rule``:
    ``"always"`` or ``"omnibus"`` (stars only where the ANOVA effect(s) named by ``gate``,
    joined by " or ", are significant)."""
    if n_methods == 2:
        test = "paired t test of the two methods in each density x viewpoint cell"
        adj = "unadjusted: one contrast per cell, no correction across cells"
    else:
        test = "each method against the reference in each density x viewpoint cell, in the method's colour"
        adj = f"{adjust}-adjusted within a cell over the pairs of the {n_methods} methods, not across cells"
    text = f"stars: {test} ({adj}); * p<.05, ** p<.01, *** p<.001"
    if rule == "omnibus":
        which = f"an ANOVA effect involving {method}" if " or " in gate else f"the ANOVA's {gate or method} effect"
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
    names: FactorNames = FACTOR_NAMES,
    scale: str = "",
) -> Path:
    """Draw composite scores by density, one row per composite and one column per viewpoint.

    ``panels``: composite name -> (cell matrix with factors ("Density", "Viewpoint",
    "Method") as ``names`` names them, post hoc table of the methods within Density x
    Viewpoint (columns Density, Viewpoint, contrast, p_adj) or None for no stars). With two
    methods a cell's stars are their comparison's; with more, each other method's
    comparison with the reference (the first level) is drawn in that method's colour above
    its points. ``ylim``: the answer scale (1..6 Likert; 0..100 slider, ``scale`` then
    names it on the y axis). ``density_values``: level -> characters/m^2
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
    if tuple(first.factors) not in (names.order, (names.density, names.method)):
        raise InvalidInputError(
            f"method_figure expects factors ({names.density}, [{names.viewpoint},] {names.method}), got {first.factors}"
        )
    with_views = len(first.factors) == 3
    dens, methods = first.levels[0], first.levels[-1]
    styles = method_styles(methods)
    unit = (ylim[1] - ylim[0]) / 5.0  # the paper's offsets are in points of its 1..6 scale
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
        pmap = _cell_pvalues(ph, methods, with_views, names)
        for c, vp in enumerate(views):
            ax = axes[r, c]
            for m, meth in enumerate(methods):
                off = (m - (len(methods) - 1) / 2) * width * 2 / max(1, len(methods) - 1) if len(methods) > 1 else 0
                ax.errorbar(
                    x + off,
                    mean[:, c, m],
                    yerr=err[:, c, m],
                    color=styles[str(meth)][0],
                    marker=styles[str(meth)][1],
                    ms=4,
                    lw=1.3,
                    capsize=2.5,
                    label=str(meth),
                )
            for d, lvl in enumerate(dens):
                top = float(np.max(mean[d, c, :] + err[d, c, :]))
                marks = _cell_stars(ax, x[d], top, methods, pmap, (str(lvl), str(vp)), width, unit, ylim[1])
                plotted.setdefault(comp, []).extend(
                    {
                        "density": str(lvl),
                        "viewpoint": str(vp),
                        "method": str(meth),
                        "mean": float(mean[d, c, m]),
                        "error": float(err[d, c, m]),
                        "stars": marks[str(meth)],
                    }
                    for m, meth in enumerate(methods)
                )
            ax.set_ylim(ylim[0] - 0.2 * unit, ylim[1] + 0.5 * unit)
            ax.set_xticks(x)
            labels = [f"{density_values[d]:.2f}" if density_values and d in density_values else str(d) for d in dens]
            ax.set_xticklabels(labels, fontsize=7)
            ax.grid(axis="y", lw=0.4, alpha=0.5)
            if r == 0 and with_views:
                ax.set_title(f"{names.viewpoint} {vp}", fontsize=9)
            if c == 0:
                ax.set_ylabel(f"{comp} score" + (f" ({scale})" if scale else ""), fontsize=9)
            if r == n_rows - 1:
                ax.set_xlabel("density (characters/m$^2$)" if density_values else "density", fontsize=8)
    caption = caption or f"* p<.05, ** p<.01, *** p<.001 ({names.method})"
    head = (f"{note}\n" if note else "") + (title + "\n" if title else "")
    return _finish(fig, axes, len(methods), head, caption, note, Path(out_path), dpi, error, plotted)


def _finish(fig, axes, n_methods: int, head: str, caption: str, note: str, out: Path, dpi: int, error: str, plotted):
    """Legend, title, the file and its .json of the plotted numbers."""
    import matplotlib.pyplot as plt

    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=n_methods, fontsize=8, frameon=False)
    bars = {"sd": "mean +- SD", "se": "mean +- SE", "ci95": "mean +- 95% CI"}[error]
    fig.suptitle(
        head + f"{bars}; {caption}",
        fontsize=8 if len(caption) > 70 else 9,
        color="#b03a2e" if note else "black",
        wrap=True,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, metadata={"Software": None} if out.suffix.lower() == ".png" else None)
    plt.close(fig)
    out.with_suffix(".json").write_text(
        json.dumps({"figure": out.name, "error": error, "caption": caption, "note": note, "series": plotted}, indent=1)
    )
    return out


def _cell_stars(
    ax, xd: float, top: float, methods, pmap: dict, cell: tuple[str, str], width: float, unit: float, ymax: float
) -> dict:
    """Draw one cell's stars (see :func:`method_figure`); returns method -> its stars."""
    styles = method_styles(methods)
    if len(methods) == 2:
        s = stars(pmap.get((*cell, ""), np.nan))
        if s:
            ax.text(xd, min(top + 0.12 * unit, ymax - 0.05 * unit), s, ha="center", va="bottom", fontsize=9)
        return {str(meth): s for meth in methods}
    marks = {str(methods[0]): ""}
    for m, meth in enumerate(methods[1:], start=1):
        s = stars(pmap.get((*cell, str(meth)), np.nan))
        marks[str(meth)] = s
        if s:
            off = (m - (len(methods) - 1) / 2) * width * 2 / max(1, len(methods) - 1)
            y = min(top + (0.12 + 0.22 * (m - 1)) * unit, ymax + 0.3 * unit)
            ax.text(xd + off, y, s, ha="center", va="bottom", fontsize=8, color=styles[str(meth)][0])
    return marks


def _cell_pvalues(ph: pd.DataFrame | None, methods, with_views: bool, names: FactorNames) -> dict:
    """(density, viewpoint, method) -> adjusted p of the cell's comparison: with two methods
    the one comparison (method ""), with more each other method against the reference."""
    if ph is None or not len(ph):
        return {}
    vcol = ph[names.viewpoint] if with_views else [""] * len(ph)
    if len(methods) == 2:
        return {(str(a), str(b), ""): p for a, b, p in zip(ph[names.density], vcol, ph["p_adj"], strict=True)}
    out = {}
    ref = str(methods[0])
    for a, b, con, p in zip(ph[names.density], vcol, ph["contrast"], ph["p_adj"], strict=True):
        left, _, right = str(con).partition(" - ")
        if ref in (left, right):
            out[(str(a), str(b), right if left == ref else left)] = p
    return out


def _t975(df: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, df))

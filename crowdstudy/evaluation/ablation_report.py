"""What each addition buys, from the rows of ``crowdstudy bench physics --ablation``
(:func:`~crowdstudy.evaluation.ablation_run.run_ablation`): the noise of each bar, a summary
row per variant and the figure.

Every bar's value is positive and larger is worse (:data:`~crowdstudy.evaluation.ablation_run.BAR_VALUES`),
so a variant's effect on a bar in a cell is the ratio of its value to the defaults' in the
same cell: above 1 the variant is worse there, that is, the addition it switches off buys
that much. The noise variants (:data:`~crowdstudy.evaluation.ablation_run.NOISE_VARIANTS`:
nothing of the method changed) say how far a ratio strays from 1 by chance:
:func:`noise_bands`.
"""

from __future__ import annotations

import math
import statistics
import textwrap
from collections.abc import Sequence
from pathlib import Path

from crowdstudy.evaluation.ablation_run import BAR_VALUES, NOISE_VARIANTS
from crowdstudy.metrics.bars import BarTolerances

__all__ = ["NUMERICAL_NOISE", "effects", "noise_bands", "summarize", "ablation_figure"]

#: a relative change this small is round-off, whatever the noise variants gave
NUMERICAL_NOISE = 1e-9


def _by_cell(rows: Sequence[dict]) -> dict[str, dict[str, dict]]:
    """{cell: {variant: row}}, cells and variants in the rows' order."""
    out: dict[str, dict[str, dict]] = {}
    for row in rows:
        out.setdefault(row["cell"], {})[row["variant"]] = row
    return out


def effects(rows: Sequence[dict]) -> dict[tuple[str, str, str], float]:
    """{(variant, cell, bar): the variant's value over the defaults' in that cell} for every
    bar with a value in both (a seam on a looped concert only)."""
    out = {}
    for cell, variants in _by_cell(rows).items():
        default = variants.get("default")
        if default is None:
            continue
        for variant, row in variants.items():
            for bar, column in BAR_VALUES.items():
                value, ref = row.get(column), default.get(column)
                if value is not None and ref is not None and ref > 0:
                    out[(variant, cell, bar)] = float(value) / float(ref)
                elif value is not None and ref == 0:  # nothing left in the defaults either
                    out[(variant, cell, bar)] = 1.0 if value == 0 else math.inf
    return out


def noise_bands(rows: Sequence[dict]) -> dict[str, dict]:
    """Per bar, how far the noise variants stray from the defaults: ``{bar: {"band": the
    largest |ratio - 1| over the cells and the noise variants, "where": which variant in
    which cell}}`` (a bar no cell measured both ways is left out)."""
    out: dict[str, dict] = {}
    for (variant, cell, bar), ratio in effects(rows).items():
        if variant not in NOISE_VARIANTS:
            continue
        if bar not in out or abs(ratio - 1.0) > out[bar]["band"]:
            out[bar] = {"band": abs(ratio - 1.0), "where": f"{variant} {cell}"}
    return out


def _fmt_effect(bar: str, cell: str, ratio: float) -> str:
    return f"{bar} {100.0 * (ratio - 1.0):+.0f}% ({cell})"


def summarize(rows: Sequence[dict]) -> list[dict]:
    """One row per variant: over the cells, the median change of each bar against the
    defaults (``BAR_pct``: +10 = the bar's value 10 % above the defaults', worse), how many
    (cell, bar) pairs move beyond the noise band of their bar (:func:`noise_bands`) and the
    largest such move, the failed bars (``cell: bars``), and the median ``ms_ratio``."""
    ratios = effects(rows)
    bands = noise_bands(rows)
    variants = list(dict.fromkeys(row["variant"] for row in rows))
    out = []
    for variant in variants:
        mine = [row for row in rows if row["variant"] == variant]
        summary: dict = {"variant": variant, "cells": len(mine)}
        beyond = []
        for bar in BAR_VALUES:
            values = [r for (v, _, b), r in ratios.items() if v == variant and b == bar]
            summary[f"{bar}_pct"] = 100.0 * (statistics.median(values) - 1.0) if values else None
            band = max(bands.get(bar, {}).get("band", 0.0), NUMERICAL_NOISE)
            beyond += [
                (abs(math.log(max(r, 1e-6))), bar, cell, r)
                for (v, cell, b), r in ratios.items()
                if v == variant and b == bar and abs(r - 1.0) > band
            ]
        summary["beyond_noise"] = len(beyond)
        largest = max(beyond, default=None)
        summary["largest"] = _fmt_effect(*largest[1:]) if largest else "-"
        failed = [f"{r['cell']}: {r['bars_failed']}" for r in mine if r["bars_failed"] != "-"]
        summary["failed"] = "; ".join(failed) or "-"
        ms = [r["ms_ratio"] for r in mine if r.get("ms_ratio") is not None]
        summary["ms_ratio"] = statistics.median(ms) if ms else None
        out.append(summary)
    return out


#: the figure's colour bins, |log2 of a variant's value over the defaults'|: within the noise
#: band (white), then up to 3 %, 10 %, 25 %, 2x, beyond
_BINS = (0.0, math.log2(1.03), math.log2(1.1), math.log2(1.25), 1.0, 3.0)


def _grid(ratios, bands, variants, cells, bar):
    """(variants, cells) log2 ratios for one bar: 0 within the bar's noise band, NaN where
    the bar has no value."""
    import numpy as np

    band = bands.get(bar, {}).get("band", 0.0)
    grid = np.full((len(variants), len(cells)), np.nan)
    for i, variant in enumerate(variants):
        for j, cell in enumerate(cells):
            ratio = ratios.get((variant, cell, bar))
            if ratio is not None:
                inside = abs(ratio - 1.0) <= max(band, NUMERICAL_NOISE)
                grid[i, j] = 0.0 if inside else float(np.clip(math.log2(max(ratio, 1e-6)), -_BINS[-1], _BINS[-1]))
    return grid


def _ratio_label(log2_ratio: float) -> str:
    """A colour bar tick: ``noise`` at 0, a percentage within a factor 2, ``x2``/``/2`` beyond."""
    if log2_ratio == 0.0:
        return "noise"
    ratio = 2.0**log2_ratio
    if 0.5 < ratio < 2.0:
        return f"{100.0 * (ratio - 1.0):+.0f} %"
    return f"x{ratio:.0f}" if ratio > 1 else f"/{1.0 / ratio:.0f}"


def ablation_figure(rows: Sequence[dict], path: Path, tolerances: BarTolerances | None = None) -> Path:
    """A heat map per bar (PNG at ``path``): variants as rows, cells as columns, the colour
    the variant's value over the defaults' in that cell, binned (:data:`_BINS`; red: worse
    than the defaults, i.e. what the switched-off addition buys; blue: better; white: within
    the bar's noise band, :func:`noise_bands`), a cross where the variant fails that bar,
    grey where the bar has no value (the seam outside the looped concert). ``tolerances``
    only names the bars (None: the defaults)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import BoundaryNorm

    from crowdstudy.metrics.bars import BAR_NAMES

    tolerances = BarTolerances() if tolerances is None else tolerances
    text = tolerances.text()
    ratios, bands = effects(rows), noise_bands(rows)
    cells = list(dict.fromkeys(row["cell"] for row in rows))
    variants = [v for v in dict.fromkeys(row["variant"] for row in rows) if v != "default"]
    failed = {(r["variant"], r["cell"], bar) for r in rows for bar in BAR_NAMES if r.get(f"ok_{bar}") is False}
    bars = list(BAR_VALUES)
    ncols = 4
    nrows = math.ceil(len(bars) / ncols)
    panel = max(0.3 * len(cells), 1.8)  # inches: room for the bar's title with few cells
    size = (2.6 + panel * ncols, 1.4 + (0.17 * len(variants) + 1.1) * nrows)
    fig, axes = plt.subplots(nrows, ncols, figsize=size, dpi=110, squeeze=False, sharey=True, layout="constrained")
    edges = [-b for b in reversed(_BINS[1:])] + [-1e-12, 1e-12] + list(_BINS[1:])
    norm = BoundaryNorm(edges, ncolors=256)
    cmap = plt.get_cmap("RdBu_r").with_extremes(bad="0.8")
    image = None
    for ax, bar in zip(axes.flat, bars, strict=False):
        image = ax.imshow(_grid(ratios, bands, variants, cells, bar), cmap=cmap, norm=norm, aspect="auto")
        for i, variant in enumerate(variants):
            for j, cell in enumerate(cells):
                if (variant, cell, bar) in failed:
                    ax.text(j, i, "x", ha="center", va="center", fontsize=7, color="k")
        ax.set_title(f"{bar}\n" + "\n".join(textwrap.wrap(text[bar], int(panel * 14))), fontsize=7)
        ax.set_xticks(range(len(cells)), [c.replace(":", " ") for c in cells], fontsize=6, rotation=90)
        ax.set_yticks(range(len(variants)), variants, fontsize=7)
    for ax in list(axes.flat)[len(bars) :]:
        ax.axis("off")
    if image is not None:
        colorbar = fig.colorbar(image, ax=axes, shrink=0.5, pad=0.01)
        ticks = [-b for b in reversed(_BINS[1:])] + [0.0] + list(_BINS[1:])
        colorbar.set_ticks(ticks, labels=[_ratio_label(t) for t in ticks])
        colorbar.ax.tick_params(labelsize=7)
        colorbar.set_label("value / the defaults' value (red: worse without the addition)", fontsize=7)
    fig.suptitle(
        "What each addition buys: each variant's bars over the defaults' in each cell\n"
        "paper: the paper's method alone; noise_*: nothing of the method changed;\n"
        "other rows: the defaults without that addition; x: bar failed",
        fontsize=8,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path

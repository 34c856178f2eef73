"""What each addition buys, from the rows of ``crowdstudy bench physics --ablation``
(:func:`~crowdstudy.physics.ablation_run.run_ablation`): the noise of each bar, a summary
row per variant and the figure.

Every bar's value is positive and larger is worse (:data:`~crowdstudy.physics.ablation_run.BAR_VALUES`),
so a variant's effect on a bar in a cell is the ratio of its value to the defaults' in the
same cell: above 1 the variant is worse there, that is, the addition it switches off buys
that much. The noise variants (:data:`~crowdstudy.physics.ablation_run.NOISE_VARIANTS`:
nothing of the method changed) say how far a ratio strays from 1 by chance:
:func:`noise_bands`.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from pathlib import Path

from crowdstudy.metrics.bars import BarTolerances
from crowdstudy.physics.ablation_run import BAR_VALUES, NOISE_VARIANTS

__all__ = ["effects", "noise_bands", "summarize", "ablation_figure"]


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
            band = bands.get(bar, {}).get("band")
            beyond += [
                (abs(math.log(max(r, 1e-6))), bar, cell, r)
                for (v, cell, b), r in ratios.items()
                if v == variant and b == bar and band is not None and abs(r - 1.0) > band
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


def ablation_figure(rows: Sequence[dict], path: Path, tolerances: BarTolerances | None = None) -> Path:
    """A heat map per bar (PNG at ``path``): variants as rows, cells as columns, the colour
    the variant's value over the defaults' in that cell (log scale, red: worse than the
    defaults, i.e. what the addition switched off buys; blue: better), a cross where the
    variant fails that bar, grey where the bar has no value (the seam outside the looped
    concert). ``tolerances`` only names the figure's bars (None: the defaults)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from crowdstudy.metrics.bars import BAR_NAMES

    tolerances = BarTolerances() if tolerances is None else tolerances
    text = tolerances.text()
    ratios = effects(rows)
    cells = list(dict.fromkeys(row["cell"] for row in rows))
    variants = [v for v in dict.fromkeys(row["variant"] for row in rows) if v != "default"]
    failed = {(r["variant"], r["cell"], bar) for r in rows for bar in BAR_NAMES if r.get(f"ok_{bar}") is False}
    bars = list(BAR_VALUES)
    ncols = 4
    nrows = math.ceil(len(bars) / ncols)
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(3.2 * ncols + 1.5, 0.22 * len(variants) * nrows + 2.2 * nrows), dpi=110, squeeze=False
    )
    image = None
    for ax, bar in zip(axes.flat, bars, strict=False):
        grid = np.full((len(variants), len(cells)), np.nan)
        for i, variant in enumerate(variants):
            for j, cell in enumerate(cells):
                ratio = ratios.get((variant, cell, bar))
                if ratio is not None:
                    grid[i, j] = float(np.clip(math.log2(max(ratio, 1e-6)), -3.0, 3.0))
        cmap = plt.get_cmap("RdBu_r").with_extremes(bad="0.85")
        image = ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, vmin=-2, vmax=2, aspect="auto")
        for i, variant in enumerate(variants):
            for j, cell in enumerate(cells):
                if (variant, cell, bar) in failed:
                    ax.text(j, i, "x", ha="center", va="center", fontsize=7, color="k")
        ax.set_title(f"{bar}: {text[bar]}", fontsize=7)
        ax.set_xticks(range(len(cells)), [c.replace(":", "\n") for c in cells], fontsize=6)
        ax.set_yticks(range(len(variants)), variants, fontsize=6)
    for ax in list(axes.flat)[len(bars) :]:
        ax.axis("off")
    if image is not None:
        bar_ax = fig.colorbar(image, ax=axes, shrink=0.6, pad=0.01)
        bar_ax.set_ticks([-2, -1, 0, 1, 2], labels=["1/4", "1/2", "1", "2", "4+"])
        bar_ax.set_label("value / the defaults' (red: worse without the addition)", fontsize=7)
    fig.suptitle(
        "What each addition buys: each variant's bars over the defaults' in each cell "
        "(paper = the paper's method alone; noise_* = nothing of the method changed; x = bar failed)",
        fontsize=9,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path

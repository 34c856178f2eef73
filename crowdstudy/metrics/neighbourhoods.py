"""Overlap neighbourhood by neighbourhood: a large crowd cut into study-cell-sized tiles.

A stadium crowd of thousands is one measurement of the overlap ratio where the study's cells
are many small ones; cutting its floor into tiles the size of a cell's floor gives the ratio
a cell-sized neighbourhood would show, and its spread over the crowd.
"""

from __future__ import annotations

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["tile_ratios"]


def tile_ratios(
    xy: np.ndarray, baseline: np.ndarray, ours: np.ndarray, tile: tuple[float, float], min_characters: int
) -> np.ndarray:
    """The overlap ratio of each neighbourhood of a large crowd: the characters binned by
    their floor position ``xy`` (N, 2) m into ``tile`` = (width, depth) m rectangles (a study
    cell's floor), and per tile the sum of Ours' per-character overlap over the Baseline's
    (``ours``, ``baseline``: (N,) m^3). Tiles with fewer than ``min_characters`` characters
    (the crowd's ragged edge) or no Baseline overlap are left out. Returns the ratios, in
    tile order (row-major from the smallest x and y)."""
    xy = np.asarray(xy, float)
    if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) != len(baseline) or len(xy) != len(ours):
        raise InvalidInputError(
            f"xy (N, 2), baseline (N,) and ours (N,): got {xy.shape}, {np.shape(baseline)}, {np.shape(ours)}"
        )
    if len(xy) == 0:
        return np.zeros(0)
    cell = np.floor((xy - xy.min(axis=0)) / np.asarray(tile, float)).astype(int)
    _, tile_of = np.unique(cell[:, 1] * (cell[:, 0].max() + 1) + cell[:, 0], return_inverse=True)
    count = np.bincount(tile_of)
    b = np.bincount(tile_of, weights=np.asarray(baseline, float))
    o = np.bincount(tile_of, weights=np.asarray(ours, float))
    keep = (count >= min_characters) & (b > 0)
    return o[keep] / b[keep]

"""Helpers reading plotted data back from matplotlib artists (see the ``saved_figures``
fixture of conftest.py)."""

from __future__ import annotations


def plotted_discs(ax):
    """(centres (K, 2), radii (K,)) of the circles drawn on ``ax`` through PatchCollections
    (data coordinates, read back from the collection's paths)."""
    import numpy as np
    from matplotlib.collections import PatchCollection

    centres, radii = [], []
    for coll in ax.collections:
        if not isinstance(coll, PatchCollection):
            continue
        for path in coll.get_paths():
            v = path.vertices
            lo, hi = v.min(axis=0), v.max(axis=0)
            centres.append((lo + hi) / 2)
            radii.append(float((hi - lo).mean() / 2))
    return np.array(centres).reshape(-1, 2), np.array(radii)


def xy_order(points):
    """Indices (K,) that sort points (K, 2) by x, then y: plotted and placed discs compared
    in one order."""
    import numpy as np

    return np.lexsort((points[:, 1], points[:, 0]))

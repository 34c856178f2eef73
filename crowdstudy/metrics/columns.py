"""Volumes of solids and of their overlaps, measured along vertical grid columns.

The floor plane is covered by a regular grid of columns of side ``h`` (the *resolution*);
column ``(ix, iy)`` is the vertical line through the cell centre ``((ix + 0.5) h,
(iy + 0.5) h)``. Along each column, each solid is a union of exact z-intervals:

* a triangle mesh crosses the line where the line pierces its triangles; each crossing
  carries the sign of the triangle's facing (entering or leaving), and the inside is where
  the running winding number is non-zero (so self-intersecting posed meshes, an arm pushed
  into the torso, stay correct, unlike a parity rule);
* a capsule (points within ``r`` of a segment) meets the line in one interval, solved
  analytically.

Along z nothing is discretised: the overlap length of a character in a column is exact
and the volume is ``h^2`` times the summed lengths, a midpoint rule in (x, y) only. The
volume of a character inside *any* other solid is the length where the character is
inside and at least two solids are inside (its own plus one more), so a point inside two
neighbours is counted once.

All functions work on flat numpy arrays for one frame; ``crowdstudy.metrics.overlap``
poses the characters and calls them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Crossings", "mesh_crossings", "capsule_crossings", "solid_intervals", "overlap_lengths"]

# z is quantised to this step (metres) inside the integer sort keys.
_Z_QUANTUM = 1e-7


class Crossings:
    """Signed surface crossings along grid columns (one frame).

    Attributes:
        solid: (K,) int64, index of the solid crossed.
        ix, iy: (K,) int64, column indices.
        z: (K,) float64 metres, height of the crossing.
        sign: (K,) int64, +1 entering / -1 leaving (for an outward-oriented surface,
            going up the column), or the reverse for an inward-oriented one.
    """

    __slots__ = ("solid", "ix", "iy", "z", "sign")

    def __init__(self, solid, ix, iy, z, sign):
        self.solid, self.ix, self.iy, self.z, self.sign = solid, ix, iy, z, sign

    @classmethod
    def concatenate(cls, parts: list[Crossings]) -> Crossings:
        if not parts:
            empty_i = np.zeros(0, np.int64)
            return cls(empty_i, empty_i, empty_i, np.zeros(0), empty_i)
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls.__slots__))

    def __len__(self) -> int:
        return len(self.z)


def _column_ranges(lo: np.ndarray, hi: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """First and last column index whose centre lies in [lo, hi] (may give last < first)."""
    first = np.ceil(lo / h - 0.5).astype(np.int64)
    last = np.floor(hi / h - 0.5).astype(np.int64)
    return first, last


def _enumerate_columns(x_lo, x_hi, y_lo, y_hi, h):
    """For K boxes, every (box, ix, iy) column whose centre lies inside the box.

    Returns ``(owner (M,), ix (M,), iy (M,))`` int64 arrays.
    """
    x0, x1 = _column_ranges(x_lo, x_hi, h)
    y0, y1 = _column_ranges(y_lo, y_hi, h)
    nx = np.maximum(x1 - x0 + 1, 0)
    ny = np.maximum(y1 - y0 + 1, 0)
    count = nx * ny
    total = int(count.sum())
    if total == 0:
        z = np.zeros(0, np.int64)
        return z, z, z
    owner = np.repeat(np.arange(len(count), dtype=np.int64), count)
    starts = np.cumsum(count) - count
    local = np.arange(total, dtype=np.int64) - starts[owner]
    nx_o = nx[owner]
    return owner, x0[owner] + local % nx_o, y0[owner] + local // nx_o


def mesh_crossings(vertices: np.ndarray, faces: np.ndarray, solid: np.ndarray, h: float) -> Crossings:
    """Where the columns pierce the given triangles.

    Args:
        vertices: (V, 3) float64 metres, all solids' vertices stacked.
        faces: (F, 3) int, rows of ``vertices``; each solid's faces form a closed surface
            with consistent orientation.
        solid: (F,) int64, the solid each face belongs to.
        h: column spacing, metres.

    A column through a shared edge or vertex is counted once, by the top-left fill rule
    applied to the triangles oriented counter-clockwise in (x, y); triangles seen edge-on
    from above are skipped (the column grazes them).
    """
    faces = np.asarray(faces, dtype=np.int64)
    x = vertices[:, 0]
    y = vertices[:, 1]
    fx = x[faces]
    fy = y[faces]
    area = (fx[:, 1] - fx[:, 0]) * (fy[:, 2] - fy[:, 0]) - (fy[:, 1] - fy[:, 0]) * (fx[:, 2] - fx[:, 0])
    x_lo = np.minimum(np.minimum(fx[:, 0], fx[:, 1]), fx[:, 2])
    x_hi = np.maximum(np.maximum(fx[:, 0], fx[:, 1]), fx[:, 2])
    y_lo = np.minimum(np.minimum(fy[:, 0], fy[:, 1]), fy[:, 2])
    y_hi = np.maximum(np.maximum(fy[:, 0], fy[:, 1]), fy[:, 2])
    keep = area != 0.0
    owner, ix, iy = _enumerate_columns(
        np.where(keep, x_lo, 1.0), np.where(keep, x_hi, 0.0), np.where(keep, y_lo, 1.0), np.where(keep, y_hi, 0.0), h
    )
    if len(owner) == 0:
        return Crossings.concatenate([])
    px = (ix + 0.5) * h
    py = (iy + 0.5) * h
    # Orient each triangle counter-clockwise in (x, y): swap vertices 1 and 2 when area < 0.
    tri_v = faces[owner]
    flip = area[owner] < 0
    tri_v[flip, 1], tri_v[flip, 2] = tri_v[flip, 2], tri_v[flip, 1].copy()
    inside = np.ones(len(owner), bool)
    weights = []
    for k in range(3):  # the edge opposite vertex k, traversed counter-clockwise
        vi = tri_v[:, (k + 1) % 3]
        vj = tri_v[:, (k + 2) % 3]
        # Evaluate every edge from its lower-index end, so the two triangles sharing it get
        # exactly opposite values and the fill rule gives the column to exactly one of them.
        forward = vi < vj
        lo_v = np.where(forward, vi, vj)
        hi_v = np.where(forward, vj, vi)
        ex = x[hi_v] - x[lo_v]
        ey = y[hi_v] - y[lo_v]
        w = ex * (py - y[lo_v]) - ey * (px - x[lo_v])
        w = np.where(forward, w, -w)
        dx = np.where(forward, ex, -ex)
        dy = np.where(forward, ey, -ey)
        top_left = (dy < 0) | ((dy == 0) & (dx < 0))
        inside &= (w > 0) | ((w == 0) & top_left)
        weights.append(w)
    wa, wb, wc = weights
    denom = wa + wb + wc
    sel = inside & (denom > 0)
    tv = tri_v[sel]
    z = vertices[:, 2]
    z = (wa[sel] * z[tv[:, 0]] + wb[sel] * z[tv[:, 1]] + wc[sel] * z[tv[:, 2]]) / denom[sel]
    tri = owner[sel]
    # Going up: a face whose outward normal points down (area < 0 with outward winding)
    # is entered (+1); one pointing up is left (-1).
    sign = np.where(area[tri] > 0, -1, 1).astype(np.int64)
    return Crossings(solid[tri].astype(np.int64), ix[sel], iy[sel], z, sign)


def capsule_crossings(start: np.ndarray, end: np.ndarray, radius: np.ndarray, solid: np.ndarray, h: float) -> Crossings:
    """Each column's interval through each capsule, as a +1 / -1 crossing pair.

    Args:
        start, end: (C, 3) float64 metres, segment endpoints.
        radius: (C,) float64 metres (capsules with radius <= 0 are ignored).
        solid: (C,) int64, the solid (character) each capsule belongs to; a solid is the
            union of its capsules.
        h: column spacing, metres.
    """
    ok = radius > 0
    start, end, radius, solid = start[ok], end[ok], radius[ok], solid[ok]
    lo = np.minimum(start, end) - radius[:, None]
    hi = np.maximum(start, end) + radius[:, None]
    owner, ix, iy = _enumerate_columns(lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1], h)
    if len(owner) == 0:
        return Crossings.concatenate([])
    px = (ix + 0.5) * h
    py = (iy + 0.5) * h
    r2 = radius[owner] ** 2
    z_lo = np.full(len(owner), np.inf)
    z_hi = np.full(len(owner), -np.inf)

    def merge(valid, a, b):
        np.minimum(z_lo, np.where(valid, a, np.inf), out=z_lo)
        np.maximum(z_hi, np.where(valid, b, -np.inf), out=z_hi)

    for cap in (start, end):  # the two spherical caps
        c = cap[owner]
        d2 = (px - c[:, 0]) ** 2 + (py - c[:, 1]) ** 2
        valid = d2 <= r2
        half = np.sqrt(np.maximum(r2 - d2, 0.0))
        merge(valid, c[:, 2] - half, c[:, 2] + half)
    # The cylinder: |q(z) - (q(z).u) u| <= r with 0 <= q(z).u <= length, q(z) = (px, py, z) - s.
    s = start[owner]
    axis = end[owner] - s
    length = np.linalg.norm(axis, axis=1)
    has_axis = length > 1e-12
    u = axis / np.where(has_axis, length, 1.0)[:, None]
    q0 = np.stack([px - s[:, 0], py - s[:, 1], -s[:, 2]], axis=1)  # q(z) = q0 + z e_z
    q0u = np.einsum("ij,ij->i", q0, u)
    q0_perp = q0 - q0u[:, None] * u
    e_perp = -u[:, 2:3] * u
    e_perp[:, 2] += 1.0
    qa = np.einsum("ij,ij->i", e_perp, e_perp)
    qb = np.einsum("ij,ij->i", q0_perp, e_perp)
    qc = np.einsum("ij,ij->i", q0_perp, q0_perp) - r2
    vertical = qa < 1e-12
    disc = qb * qb - qa * qc
    safe_a = np.where(vertical, 1.0, qa)
    root = np.sqrt(np.maximum(disc, 0.0))
    c_lo = np.where(vertical, -np.inf, (-qb - root) / safe_a)
    c_hi = np.where(vertical, np.inf, (-qb + root) / safe_a)
    c_valid = has_axis & np.where(vertical, qc <= 0, disc >= 0)
    # Clip to the slab 0 <= q0u + z u_z <= length.
    uz = u[:, 2]
    flat = np.abs(uz) < 1e-12
    safe_uz = np.where(flat, 1.0, uz)
    t0 = (0.0 - q0u) / safe_uz
    t1 = (length - q0u) / safe_uz
    s_lo = np.where(flat, -np.inf, np.minimum(t0, t1))
    s_hi = np.where(flat, np.inf, np.maximum(t0, t1))
    c_valid &= np.where(flat, (q0u >= 0) & (q0u <= length), True)
    lo_z = np.maximum(c_lo, s_lo)
    hi_z = np.minimum(c_hi, s_hi)
    merge(c_valid & (lo_z <= hi_z), lo_z, hi_z)
    hit = z_lo < z_hi
    n = int(hit.sum())
    sid = np.repeat(solid[owner[hit]].astype(np.int64), 2)
    return Crossings(
        sid,
        np.repeat(ix[hit], 2),
        np.repeat(iy[hit], 2),
        np.stack([z_lo[hit], z_hi[hit]], axis=1).ravel(),
        np.tile(np.array([1, -1], np.int64), n),
    )


def _column_keys(ix: np.ndarray, iy: np.ndarray) -> tuple[np.ndarray, int]:
    """Compact non-negative int64 keys for columns, and the number of distinct keys bound."""
    if len(ix) == 0:
        return np.zeros(0, np.int64), 1
    x0, y0 = ix.min(), iy.min()
    ny = int(iy.max() - y0 + 1)
    nx = int(ix.max() - x0 + 1)
    return (ix - x0) * ny + (iy - y0), nx * ny


def _sorted_order(group: np.ndarray, z: np.ndarray, z_min: float) -> np.ndarray:
    """Argsort by (group, z) through one int64 key (z quantised to 0.1 micrometre)."""
    zq = np.round((z - z_min) / _Z_QUANTUM).astype(np.int64)
    span = int(zq.max()) + 1 if len(zq) else 1
    if group.max(initial=0) < (np.iinfo(np.int64).max // span) - 1:
        return np.argsort(group * span + zq, kind="stable")
    return np.lexsort((z, group))


def solid_intervals(cr: Crossings) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Merge each solid's crossings into disjoint inside intervals per column.

    Inside is where the running sum of crossing signs (the winding number, counted from
    below) is non-zero. A (solid, column) whose crossings do not sum to zero (a surface
    that is not closed there, or round-off at a grazing contact) is dropped and counted.

    Returns:
        ``(solid (I,), column_key (I,), z_start (I,), z_end (I,), n_dropped)``.
    """
    if len(cr) == 0:
        e = np.zeros(0, np.int64)
        return e, e, np.zeros(0), np.zeros(0), 0
    col, n_cols = _column_keys(cr.ix, cr.iy)
    group = cr.solid * n_cols + col
    order = _sorted_order(group, cr.z, float(cr.z.min()))
    g = group[order]
    z = cr.z[order]
    s = cr.sign[order]
    new_group = np.ones(len(g), bool)
    new_group[1:] = g[1:] != g[:-1]
    csum = np.cumsum(s)
    group_start = np.flatnonzero(new_group)
    group_id = np.cumsum(new_group) - 1
    offset = (csum[group_start] - s[group_start])[group_id]
    after = csum - offset
    before = after - s
    # Groups whose winding does not come back to zero are unreliable: drop them.
    group_end = np.append(group_start[1:], len(g)) - 1
    bad_group = after[group_end] != 0
    bad = bad_group[group_id]
    opens = (before == 0) & (after != 0) & ~bad
    closes = (before != 0) & (after == 0) & ~bad
    starts = np.flatnonzero(opens)
    ends = np.flatnonzero(closes)
    # Every kept group opens and closes alternately, so the k-th start pairs with the k-th end.
    solid_of = g[starts] // n_cols
    col_of = g[starts] % n_cols
    return solid_of, col_of, z[starts], z[ends], int(bad_group.sum())


def overlap_lengths(solid: np.ndarray, column: np.ndarray, z0: np.ndarray, z1: np.ndarray, n_solids: int) -> np.ndarray:
    """Per solid, the summed length of its intervals where at least one other solid is inside.

    Args:
        solid, column, z0, z1: (I,) the disjoint inside intervals of each solid
            (:func:`solid_intervals`).
        n_solids: number of solids (length of the result).

    Returns:
        (n_solids,) float64, metres of column length (multiply by h^2 for a volume).
    """
    out = np.zeros(n_solids)
    n = len(solid)
    if n == 0:
        return out
    col = np.concatenate([column, column])
    z = np.concatenate([z0, z1])
    step = np.concatenate([np.ones(n, np.int64), -np.ones(n, np.int64)])
    order = _sorted_order(col, z, float(z.min()))
    c_sorted = col[order]
    z_sorted = z[order]
    depth_after = np.cumsum(step[order])  # solids inside just above each event
    seg = np.zeros(len(z_sorted))
    seg[:-1] = np.where(c_sorted[1:] == c_sorted[:-1], z_sorted[1:] - z_sorted[:-1], 0.0)
    shared = np.where(depth_after >= 2, seg, 0.0)
    cum = np.concatenate([[0.0], np.cumsum(shared)])  # cum[k]: shared length below event k
    position = np.empty(2 * n, np.int64)
    position[order] = np.arange(2 * n)
    length = cum[position[n:]] - cum[position[:n]]
    np.add.at(out, solid, np.maximum(length, 0.0))
    return out

"""Poisson-disk point sets: exactly n points in a rectangle or polygon, at least a given
distance apart.

Method (vectorised, grid-accelerated dart throwing with a shrinking radius):

1. The placement region is the input region shrunk by ``margin`` (a point is accepted when
   it lies inside the polygon and at least ``margin`` from every edge). Its area ``A``
   gives the spacing bound ``d_min = max(0.75 * sqrt(A / n), min_distance)``.
2. A background grid with cells of side ``d_min / sqrt(2)`` holds at most one point per
   cell. Cells are split into ``(k + 1)^2`` phase classes (``k = ceil(r / cell)``): two
   cells of one class are at least ``r`` apart, so every empty cell of a class can throw
   one candidate at the same time (one numpy pass) and candidates never conflict with each
   other, only with the points already placed in the ``(2k + 1)^2`` neighbouring cells.
3. The radius starts above the bound (about the spacing of a saturated random packing of n
   points) and shrinks geometrically towards ``d_min`` whenever a round accepts few
   candidates; placement stops the moment n points are placed (the last phase keeps a
   random subset of its accepted candidates). The result is exactly n points, every pair at
   least ``d_min`` apart, the early (sparser) points spreading evenly over the region.

If n points do not fit at ``d_min`` (only possible with a user ``min_distance``), the
function raises :class:`~crowdstudy.errors.InvalidInputError` naming ``n``.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["PoissonLayout", "poisson_disk", "region_polygon", "SPACING_FACTOR"]

#: The guaranteed spacing is at least ``SPACING_FACTOR * sqrt(area / n)``.
SPACING_FACTOR = 0.75
_HEX_FRACTION = math.pi / (2.0 * math.sqrt(3.0))  # densest packing of equal discs
_SHRINK = 0.96  # radius factor between levels
_MAX_FINAL_ROUNDS = 80  # rounds at d_min before giving up


@dataclasses.dataclass(frozen=True, eq=False)
class PoissonLayout:
    """A Poisson-disk point set.

    Attributes:
        points: (n, 2) float64 metres, inside the region and at least ``margin`` from its
            boundary.
        min_distance: achieved smallest pairwise distance (m); ``inf`` when n == 1.
        target_distance: guaranteed lower bound on the pairwise distance (m),
            ``max(0.75 * sqrt(area / n), min_distance argument)``.
        area: area of the placement region (the region shrunk by the margin), m^2.
        region: (K, 2) float64 metres, the input region as a counter-clockwise polygon.
        margin: metres kept between every point and the region's boundary.
        seed: the seed the set was drawn with (None when a Generator was given).
    """

    points: np.ndarray
    min_distance: float
    target_distance: float
    area: float
    region: np.ndarray
    margin: float
    seed: int | None

    @property
    def n(self) -> int:
        return int(self.points.shape[0])


def _finite_number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidInputError(f"{name}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise InvalidInputError(f"{name}: expected a finite number, got {value!r}")
    return value


def region_polygon(region) -> tuple[np.ndarray, bool]:
    """The region as a counter-clockwise (K, 2) float64 polygon and whether it is an
    axis-aligned rectangle centred on the origin.

    ``region`` is ``(width, height)`` (metres, rectangle centred on the origin) or a (K, 2)
    array of polygon vertices (K >= 3, simple, non-zero area).
    """
    try:
        arr = np.asarray(region, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"region: expected (width, height) or a (K, 2) polygon, got {region!r}") from None
    if arr.shape == (2,):
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            raise InvalidInputError(f"region: width and height must be positive finite numbers, got {arr.tolist()}")
        w, h = arr / 2.0
        return np.array([[-w, -h], [w, -h], [w, h], [-w, h]]), True
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise InvalidInputError(f"region: expected (width, height) or a (K, 2) polygon, got shape {arr.shape}")
    if arr.shape[0] < 3:
        raise InvalidInputError(f"region: a polygon needs at least 3 vertices, got {arr.shape[0]} (degenerate)")
    if not np.all(np.isfinite(arr)):
        raise InvalidInputError("region: polygon vertices must be finite (found NaN or inf)")
    area2 = _signed_area2(arr)
    scale = max(float(np.ptp(arr[:, 0])), float(np.ptp(arr[:, 1])), 1e-300)
    if abs(area2) <= 1e-9 * scale * scale:
        raise InvalidInputError("region: the polygon has zero area (degenerate: collinear or repeated vertices)")
    if _self_intersects(arr):
        raise InvalidInputError("region: the polygon's edges cross each other (expected a simple polygon)")
    if area2 < 0:
        arr = arr[::-1].copy()
    return arr, False


def _signed_area2(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _self_intersects(poly: np.ndarray) -> bool:
    k = poly.shape[0]
    a, b = poly, np.roll(poly, -1, axis=0)
    for i in range(k):
        for j in range(i + 2, k):
            if i == 0 and j == k - 1:
                continue  # adjacent through the closing edge
            if _segments_cross(a[i], b[i], a[j], b[j]):
                return True
    return False


def _segments_cross(p1, p2, q1, q2) -> bool:
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    d1, d2 = orient(q1, q2, p1), orient(q1, q2, p2)
    d3, d4 = orient(p1, p2, q1), orient(p1, p2, q2)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


class _Region:
    """Membership test of the placement region (polygon shrunk by the margin)."""

    def __init__(self, poly: np.ndarray, is_rect: bool, margin: float):
        self.poly, self.is_rect, self.margin = poly, is_rect, margin
        lo, hi = poly.min(axis=0) + margin, poly.max(axis=0) - margin
        if np.any(hi <= lo):
            raise InvalidInputError(
                f"margin: {margin} m leaves no room inside the region (extent {np.ptp(poly, axis=0).tolist()} m)"
            )
        self.lo, self.hi = lo, hi
        if is_rect:
            self.area = float(np.prod(hi - lo))
        else:
            self.area = self._estimate_area()
            if self.area <= 0:
                raise InvalidInputError(f"margin: {margin} m leaves no room inside the polygon region")

    def contains(self, pts: np.ndarray) -> np.ndarray:
        """(M,) bool: inside the region and at least ``margin`` from its boundary."""
        if self.is_rect:
            return np.all((pts >= self.lo) & (pts <= self.hi), axis=1)
        x, y = pts[:, 0:1], pts[:, 1:2]
        a = self.poly[None]
        b = np.roll(self.poly, -1, axis=0)[None]
        ax, ay, bx, by = a[..., 0], a[..., 1], b[..., 0], b[..., 1]
        cond = (ay > y) != (by > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xcross = ax + (y - ay) * (bx - ax) / (by - ay)
        inside = (np.sum(cond & (x < xcross), axis=1) % 2) == 1
        if self.margin > 0:
            ex, ey = bx - ax, by - ay
            t = np.clip(((x - ax) * ex + (y - ay) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
            d2 = (x - ax - t * ex) ** 2 + (y - ay - t * ey) ** 2
            inside &= np.min(d2, axis=1) >= self.margin**2
        return inside

    def _estimate_area(self, resolution: int = 256) -> float:
        xs = np.linspace(self.lo[0], self.hi[0], resolution + 1)
        ys = np.linspace(self.lo[1], self.hi[1], resolution + 1)
        cx, cy = (xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2
        gx, gy = np.meshgrid(cx, cy)
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        inside = np.concatenate([self.contains(chunk) for chunk in np.array_split(pts, 16)])
        return float(inside.mean() * np.prod(self.hi - self.lo))


def _check_n(n) -> int:
    if isinstance(n, bool) or not isinstance(n, numbers.Integral):
        if isinstance(n, numbers.Real) and not math.isfinite(float(n)):
            raise InvalidInputError(f"n: expected a positive integer, got {n!r}")
        if isinstance(n, numbers.Real) and float(n).is_integer():
            n = int(float(n))
        else:
            raise InvalidInputError(f"n: expected a positive integer, got {n!r}")
    n = int(n)
    if n <= 0:
        raise InvalidInputError(f"n: expected a positive integer, got {n}")
    return n


def _rng(seed) -> tuple[np.random.Generator, int | None]:
    if isinstance(seed, np.random.Generator):
        return seed, None
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or int(seed) < 0:
        raise InvalidInputError(f"seed: expected a non-negative integer or numpy Generator, got {seed!r}")
    return np.random.default_rng(int(seed)), int(seed)


def poisson_disk(region, n: int, *, seed, margin: float = 0.0, min_distance: float | None = None) -> PoissonLayout:
    """Place exactly ``n`` points in ``region`` as a Poisson-disk set.

    Args:
        region: ``(width, height)`` in metres (rectangle centred on the origin) or a (K, 2)
            polygon (metres, either orientation, simple, non-zero area).
        n: number of points (> 0).
        seed: int or ``numpy.random.Generator``; the same seed gives the same points.
        margin: metres kept between each point and the region's boundary (>= 0).
        min_distance: optional stronger spacing requirement (m); the guaranteed spacing is
            ``max(0.75 * sqrt(area / n), min_distance)`` with ``area`` the placement area.

    Returns:
        :class:`PoissonLayout` with ``points`` (n, 2) float64 metres.

    Raises:
        InvalidInputError: naming ``region``, ``n``, ``margin``, ``min_distance`` or
            ``seed``; in particular when n points cannot be placed at the spacing.
    """
    n = _check_n(n)
    margin = _finite_number(margin, "margin")
    if margin < 0:
        raise InvalidInputError(f"margin: expected >= 0 metres, got {margin}")
    poly, is_rect = region_polygon(region)
    rng, seed_value = _rng(seed)
    shape = _Region(poly, is_rect, margin)
    area = shape.area
    d_min = SPACING_FACTOR * math.sqrt(area / n)
    if min_distance is not None:
        md = _finite_number(min_distance, "min_distance")
        if md < 0:
            raise InvalidInputError(f"min_distance: expected >= 0 metres, got {md}")
        d_min = max(d_min, md)
    # Necessary condition: discs of radius d/2 are disjoint and lie in the region grown by d/2.
    perimeter = (
        2.0 * float(np.sum(shape.hi - shape.lo))
        if is_rect
        else float(np.sum(np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)))
    )
    capacity = _HEX_FRACTION * (area + perimeter * d_min / 2 + math.pi * d_min**2 / 4) / (math.pi * d_min**2 / 4)
    if n > capacity:
        raise InvalidInputError(
            f"n: {n} points do not fit {d_min:.4g} m apart in a region of {area:.4g} m^2 "
            f"(at most about {int(capacity)} even in a hexagonal packing)"
        )
    points = _dart_throw(shape, n, d_min, rng)
    return PoissonLayout(
        points=points,
        min_distance=_min_pair_distance(points),
        target_distance=d_min,
        area=area,
        region=poly,
        margin=margin,
        seed=seed_value,
    )


def _min_pair_distance(points: np.ndarray) -> float:
    if len(points) < 2:
        return math.inf
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    dist, _ = cKDTree(points).query(points, k=2)
    return float(dist[:, 1].min())


def _dart_throw(shape: _Region, n: int, d_min: float, rng: np.random.Generator) -> np.ndarray:
    cell = d_min / math.sqrt(2.0)
    lo = shape.lo
    nx = max(1, int(math.ceil((shape.hi[0] - lo[0]) / cell)))
    ny = max(1, int(math.ceil((shape.hi[1] - lo[1]) / cell)))
    # Start near the spacing of a saturated random packing of n points (density ~0.7 / r^2).
    r = max(d_min, math.sqrt(0.75 * shape.area / n))
    pad = int(math.ceil(r / cell - 1e-12))  # the largest neighbourhood reach in cells
    width = nx + 2 * pad
    # owner[cell] = index of the point in that cell, n = empty (a sentinel point far away)
    owner = np.full((ny + 2 * pad) * width, n, dtype=np.int64)
    pts = np.zeros((n + 1, 2))
    pts[n] = 1e30
    cy_all, cx_all = np.divmod(np.arange(nx * ny), nx)
    flat_all = (cy_all + pad) * width + (cx_all + pad)
    count = 0
    final_rounds = 0
    k_prev, phase_cells, offsets = -1, [], np.zeros(0, dtype=np.int64)  # set in the first round
    while count < n:
        k = int(math.ceil(r / cell - 1e-12))
        if k != k_prev:
            period = k + 1
            phase_cells = [
                np.flatnonzero((cy_all % period == py) & (cx_all % period == px))
                for py in range(period)
                for px in range(period)
            ]
            oy, ox = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
            keep = (np.maximum(np.abs(oy) - 1, 0) ** 2 + np.maximum(np.abs(ox) - 1, 0) ** 2) * cell * cell < r * r
            offsets = (oy * width + ox)[keep]
            k_prev = k
        tried = accepted = 0
        r2 = r * r
        for cells in phase_cells:
            cells = cells[owner[flat_all[cells]] == n]
            if cells.size == 0:
                continue
            cand = lo + (np.stack([cx_all[cells], cy_all[cells]], axis=1) + rng.random((cells.size, 2))) * cell
            inside = shape.contains(cand)
            cells, cand = cells[inside], cand[inside]
            tried += cells.size
            if cells.size == 0:
                continue
            near = pts[owner[flat_all[cells][:, None] + offsets[None]]]
            dx = near[..., 0] - cand[:, 0:1]
            dy = near[..., 1] - cand[:, 1:2]
            new = np.flatnonzero(np.all(dx * dx + dy * dy >= r2, axis=1))
            if new.size == 0:
                continue
            if count + new.size > n:
                new = np.sort(rng.choice(new, size=n - count, replace=False))
            pts[count : count + new.size] = cand[new]
            owner[flat_all[cells[new]]] = np.arange(count, count + new.size)
            count += new.size
            accepted += new.size
            if count >= n:
                break
        if count >= n:
            break
        if r > d_min:
            if accepted < 0.05 * max(tried, 1):
                r = max(d_min, r * _SHRINK)
        else:
            final_rounds += 1
            if final_rounds >= _MAX_FINAL_ROUNDS:
                raise InvalidInputError(
                    f"n: could place only {count} of {n} points {d_min:.4g} m apart in a region "
                    f"of {shape.area:.4g} m^2; lower n or min_distance"
                )
    return pts[:n]

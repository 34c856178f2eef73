"""Capsule proxies (paper Fig. 2): one capsule per bone, fitted to the body mesh.

A capsule is a segment ``start``-``end`` and a radius: the points within ``radius`` of the
segment. Capsule j belongs to joint j's bone (the body part that joint j's rotation moves)
and lives in the body's rest frame; at a pose, a rest point p of capsule j goes to
``G_j @ (p - rest_joints[j]) + joint_position_j`` (:func:`posed_capsules`).

Fitting: the vertices whose largest skinning weight is bone j are that bone's vertices.
Limb bones keep the bone's axis (joint to child joint; leaf bones continue their parent's
direction, the head points up); torso bones (pelvis, spine1-3) lie across the body (along
x) through their vertices' centroid. The radius is a robust percentile of the vertices'
distances to the axis line and the segment spans the vertices' extent along the axis,
less one radius at each end (the caps).

:func:`cached_fit_capsules` keeps each fit in the cache folder (``<cache>/capsules``), keyed
on a digest of what the fit reads (rest vertices, joints, faces, skinning weights, the grid
resolution) and of this module's source, so a body is fitted once per machine and a change
to the fit or to the body refits it.

Fit quality: :func:`capsule_mesh_iou` voxelises the body mesh (ray parity) and the capsule
union on the same grid and reports their volume intersection-over-union.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crowdstudy.body.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS, forward_kinematics
from crowdstudy.errors import InvalidInputError
from crowdstudy.paths import cache_dir

__all__ = [
    "Capsules",
    "fit_capsules",
    "cached_fit_capsules",
    "fit_digest",
    "touching_pairs",
    "posed_capsules",
    "closest_points_on_segments",
    "segment_distance",
    "mesh_occupancy",
    "capsule_occupancy",
    "capsule_mesh_iou",
    "capsule_skin",
    "HAND_BONES",
    "SKIN_PERCENTILE",
    "SKIN_MAX",
    "SKIN_HAND_SCALE",
]
_TORSO = (0, 3, 6, 9)
#: the palm and finger bones of the 24-joint skeleton (left/right wrist, left/right hand)
HAND_BONES = tuple(JOINT_INDEX[name] for name in ("left_wrist", "right_wrist", "left_hand", "right_hand"))
_FEET = {7: 10, 8: 11, 10: 10, 11: 11}  # bone -> the joint its floor direction points to
#: :func:`capsule_skin`'s defaults, which the physics (``PhysicsConfig.skin.percentile`` and
#: the dense end of ``PhysicsConfig.profile``) and the separation floor
#: (``crowdstudy.metrics.floor``) take as theirs
SKIN_PERCENTILE, SKIN_MAX, SKIN_HAND_SCALE = 90.0, 0.015, 0.5


@dataclass(frozen=True)
class Capsules:
    """Capsules in a body's rest frame: ``start`` (24, 3), ``end`` (24, 3) m, ``radius`` (24,) m."""

    start: np.ndarray
    end: np.ndarray
    radius: np.ndarray

    def __post_init__(self):
        for name in ("start", "end"):
            if np.shape(getattr(self, name)) != (NUM_JOINTS, 3):
                raise InvalidInputError(
                    f"Capsules.{name}: expected shape ({NUM_JOINTS}, 3), got {np.shape(getattr(self, name))}"
                )
        if np.shape(self.radius) != (NUM_JOINTS,):
            raise InvalidInputError(f"Capsules.radius: expected shape ({NUM_JOINTS},), got {np.shape(self.radius)}")

    @property
    def length(self) -> np.ndarray:
        """(24,) segment lengths, m (the cylinder part; the caps add 2 r)."""
        return np.linalg.norm(self.end - self.start, axis=1)

    @property
    def volume(self) -> np.ndarray:
        """(24,) volumes, m^3 (cylinder plus two hemispheres)."""
        r = self.radius
        return np.pi * r**2 * self.length + 4.0 / 3.0 * np.pi * r**3

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.start + self.end)


def _bone_axes(joints: np.ndarray) -> np.ndarray:
    """(24, 3) unit direction of each limb bone in the rest pose."""
    kids = [[] for _ in range(NUM_JOINTS)]
    for c, p in enumerate(PARENTS):
        if p >= 0:
            kids[int(p)].append(c)
    axes = np.zeros((NUM_JOINTS, 3))
    for b in range(NUM_JOINTS):
        if b in _TORSO:
            axes[b] = (1.0, 0.0, 0.0)
        elif len(kids[b]) == 1 and b not in _FEET:
            axes[b] = joints[kids[b][0]] - joints[b]
        elif b == 15:  # head: up
            axes[b] = (0.0, 0.0, 1.0)
        elif b in _FEET:  # feet and toes: along the floor
            d = joints[_FEET[b]] - joints[b if b in (7, 8) else PARENTS[b]]
            axes[b] = (d[0], d[1], 0.0)
        else:  # other leaves continue the parent bone
            axes[b] = joints[b] - joints[PARENTS[b]]
    return axes / np.linalg.norm(axes, axis=1, keepdims=True)


def fit_capsules(body, *, resolution: float = 0.02) -> Capsules:
    """Fit one capsule per bone to ``body``'s rest mesh.

    The mesh interior is sampled on a voxel grid (``resolution`` m); each interior sample
    belongs to the bone that dominates its nearest vertex. Per bone the capsule axis
    passes through its samples' centroid along the bone direction (torso bones: across
    the body, along x; feet: along the floor); among candidate radii (percentiles of the
    samples' distances to the axis) and end insets, the one with the best IoU against the
    bone's own samples wins.
    """
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    verts = np.asarray(body.rest_vertices, dtype=np.float64)
    joints = np.asarray(body.rest_joints, dtype=np.float64)
    owner_v = np.argmax(body.weights, axis=1)
    axes = _bone_axes(joints)
    origin, shape = _grid_for(verts, resolution, pad=1, symmetric_x=True)
    occ = mesh_occupancy(verts, body.faces, origin, resolution, shape)
    pts = origin + resolution * np.argwhere(occ)
    owner = owner_v[cKDTree(verts).query(pts)[1]]
    cell = resolution**3
    start = np.zeros((NUM_JOINTS, 3))
    end = np.zeros((NUM_JOINTS, 3))
    radius = np.zeros(NUM_JOINTS)
    for b in range(NUM_JOINTS):
        sel = pts[owner == b]
        if len(sel) < 4:  # too small to sample: the bone's vertices stand in
            sel = verts[owner_v == b]
        if len(sel) < 4:
            start[b] = end[b] = joints[b]
            radius[b] = 0.01
            continue
        d = axes[b]
        center = sel.mean(axis=0)
        if b in _TORSO:
            center[0] = 0.0
        rel = sel - center
        t = rel @ d
        radial = np.linalg.norm(rel - t[:, None] * d, axis=1)
        t_lo, t_hi = np.percentile(t, [1.0, 99.0])
        radii = np.percentile(radial, np.arange(40.0, 100.0, 2.5)) + 0.5 * resolution
        insets = np.array([0.25, 0.5, 0.75, 1.0])
        r = np.repeat(radii, len(insets))[:, None]  # (K, 1) candidates
        inset = np.tile(insets, len(radii))[:, None]
        lo, hi = t_lo + inset * r, t_hi - inset * r
        short = hi < lo  # shorter than its caps: a sphere at the middle
        lo = np.where(short, 0.5 * (t_lo + t_hi), lo)
        hi = np.where(short, 0.5 * (t_lo + t_hi), hi)
        along = t[None, :] - np.clip(t[None, :], lo, hi)
        inside = np.count_nonzero(along**2 + radial[None, :] ** 2 <= r * r, axis=1)
        vol = (np.pi * r[:, 0] ** 2 * (hi - lo)[:, 0] + 4.0 / 3.0 * np.pi * r[:, 0] ** 3) / cell
        # volume inside the body but owned by a neighbouring bone is not an error of the
        # union: only the part outside the mesh is penalised
        near = pts[np.all(np.abs(pts - center) <= (t_hi - t_lo) / 2 + radii[-1] + resolution, axis=1)]
        rel_n = near - center
        t_n = rel_n @ d
        rad_n = np.linalg.norm(rel_n - t_n[:, None] * d, axis=1)
        along_n = t_n[None, :] - np.clip(t_n[None, :], lo, hi)
        in_body = np.count_nonzero(along_n**2 + rad_n[None, :] ** 2 <= r * r, axis=1)
        iou = inside / (len(sel) + np.maximum(vol - in_body, 0.0))
        k = int(np.argmax(iou))
        r, lo, hi = float(r[k, 0]), float(lo[k, 0]), float(hi[k, 0])
        start[b] = center + lo * d
        end[b] = center + hi * d
        radius[b] = r
    return Capsules(start=start, end=end, radius=radius)


def _grid_for(
    points: np.ndarray, step: float, pad: int = 1, symmetric_x: bool = False
) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Grid origin and shape covering ``points`` with ``pad`` cells to spare; an irrational
    offset keeps the parity rays off mesh edges and vertices. ``symmetric_x`` mirrors the
    sample columns about x = 0 (a left-right symmetric body gets a symmetric fit)."""
    lo = points.min(axis=0) - pad * step
    hi = points.max(axis=0) + pad * step
    origin = lo + step * np.array([0.5 / np.sqrt(2), 0.5 / np.sqrt(3), 0.5 / np.sqrt(5)])
    if symmetric_x:
        half = np.ceil(max(-lo[0], hi[0]) / step)
        origin[0] = -(half + 0.5) * step
        hi[0] = (half + 0.5) * step
    nx, ny, nz = (int(np.ceil((hi[i] - origin[i]) / step)) + 1 for i in range(3))
    return origin, (nx, ny, nz)


def closest_points_on_segments(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of segments [p0, p1] and [q0, q1] (Ericson, Real-Time Collision
    Detection, 5.1.9), vectorised.

    Args:
        p0, p1, q0, q1: (..., 3) float, metres (broadcast against each other).

    Returns:
        ``(s (...,), t (...,), distance (...,) m)``: the closest points are
        ``p0 + s (p1 - p0)`` and ``q0 + t (q1 - q0)``, s, t in [0, 1]. Parallel segments are
        detected with a test relative to the segment lengths (so short segments are not
        mistaken for parallel ones) and take ``s = 0`` unless the partner point of p0 falls
        outside [q0, q1]; a zero-length segment is projected onto the other one.
    """
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = np.einsum("...i,...i->...", d1, d1)
    e = np.einsum("...i,...i->...", d2, d2)
    f = np.einsum("...i,...i->...", d2, r)
    c = np.einsum("...i,...i->...", d1, r)
    b = np.einsum("...i,...i->...", d1, d2)
    eps = 1e-14
    a_ok = a > eps
    e_ok = e > eps
    safe_a = np.where(a_ok, a, 1.0)
    safe_e = np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    skew = denom > 1e-12 * np.maximum(a * e, eps)  # not parallel: unique closest points
    s = np.where(skew, np.clip((b * f - c * e) / np.where(skew, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / safe_e
    s = np.where(t < 0, np.clip(-c / safe_a, 0.0, 1.0), s)
    s = np.where(t > 1, np.clip((b - c) / safe_a, 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    # Degenerate segments (points): project onto the other one.
    s = np.where(~e_ok, np.clip(-c / safe_a, 0.0, 1.0), s)
    t = np.where(~e_ok, 0.0, t)
    s = np.where(~a_ok, 0.0, s)
    t = np.where(~a_ok & e_ok, np.clip(f / safe_e, 0.0, 1.0), t)
    cp = p0 + s[..., None] * d1
    cq = q0 + t[..., None] * d2
    return s, t, np.linalg.norm(cp - cq, axis=-1)


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Closest distance between segments p0-p1 and q0-q1, all (..., 3) m -> (...,) m
    (see :func:`closest_points_on_segments`)."""
    return closest_points_on_segments(p0, p1, q0, q1)[2]


@functools.lru_cache(maxsize=1)
def _source_digest() -> bytes:
    return hashlib.sha256(Path(__file__).read_bytes()).digest()


#: per-array results remembered for read-only arrays that own their data (the shared
#: MakeHuman template's weights and faces): {(id, what): (weak reference, value)}
_FROZEN: dict = {}


def _frozen(arr: np.ndarray, what: str, compute):
    """``compute(arr)``, remembered while ``arr`` lives when nothing can change it (read-only
    and owning its data); computed afresh for any other array."""
    if arr.flags.writeable or not arr.flags.owndata:
        return compute(arr)
    key = (id(arr), what)
    hit = _FROZEN.get(key)
    if hit is not None and hit[0]() is arr:
        return hit[1]
    value = compute(arr)
    _FROZEN[key] = (weakref.ref(arr, lambda _ref, key=key: _FROZEN.pop(key, None)), value)
    return value


def _array_digest(arr, dtype) -> bytes:
    """SHA-256 of an array's shape and contiguous bytes as ``dtype``."""

    def digest(a: np.ndarray) -> bytes:
        c = np.ascontiguousarray(a, dtype=dtype)
        h = hashlib.sha256(repr(c.shape).encode())
        h.update(c.tobytes())
        return h.digest()

    return _frozen(np.asarray(arr), f"sha256/{np.dtype(dtype).str}", digest)


def fit_digest(body, resolution: float = 0.02) -> str:
    """Hex digest of everything :func:`fit_capsules` reads from ``body`` (rest vertices and
    joints, faces, skinning weights), the grid ``resolution`` and this module's source. The
    digests of read-only arrays (the weights and faces every MakeHuman body shares) are
    computed once per process."""
    h = hashlib.sha256(_source_digest())
    for arr, dtype in (
        (body.rest_vertices, np.float64),
        (body.rest_joints, np.float64),
        (body.faces, np.int64),
        (body.weights, np.float64),
    ):
        h.update(_array_digest(arr, dtype))
    h.update(repr(float(resolution)).encode())
    return h.hexdigest()


def cached_fit_capsules(body, *, resolution: float = 0.02, cache: Path | str | None = None) -> Capsules:
    """:func:`fit_capsules`, kept in ``cache`` (default ``<cache>/capsules``, see
    :mod:`crowdstudy.paths`) under :func:`fit_digest`: the same capsules, fitted once.

    A cache file that cannot be read is fitted again and rewritten; the file is written
    atomically (a temporary file renamed), so parallel processes may share the folder."""
    folder = Path(cache) if cache is not None else cache_dir("capsules")
    path = folder / f"{fit_digest(body, resolution)}.npz"
    try:
        with np.load(path) as data:
            return Capsules(start=data["start"], end=data["end"], radius=data["radius"])
    except (OSError, KeyError, ValueError, InvalidInputError):
        pass
    caps = fit_capsules(body, resolution=resolution)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, start=caps.start, end=caps.end, radius=caps.radius)
        os.replace(tmp, path)
    except OSError:  # a read-only cache: the fit is still returned
        pass
    return caps


def touching_pairs(capsules: Capsules, margin: float = 0.005) -> np.ndarray:
    """(P, 2) int32 pairs (i < j), sorted, that an intra-body collision test should skip:
    every parent-child pair of bones plus every pair of capsules closer than
    ``r_i + r_j + margin`` in the rest pose (e.g. both thighs at the crotch, the collars
    and the neck)."""
    i, j = np.triu_indices(NUM_JOINTS, k=1)
    dist = segment_distance(capsules.start[i], capsules.end[i], capsules.start[j], capsules.end[j])
    touch = dist < capsules.radius[i] + capsules.radius[j] + margin
    touch |= PARENTS[j] == i
    return np.stack([i[touch], j[touch]], axis=1).astype(np.int32)


def posed_capsules(
    body, joint_rotations: np.ndarray, root_translation: np.ndarray, parents: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """World capsule segments at a pose: ``(start (..., J, 3), end (..., J, 3))`` m.

    Args:
        body: a Body (or anything with ``rest_joints`` (J, 3) m and ``capsules`` with
            ``start``, ``end`` (J, 3) m in the rest frame); joint_rotations: (..., J, 3)
            axis-angle rad; root_translation: (..., 3) m; parents: (J,) parent indices
            (default: the 24-joint skeleton's ``PARENTS``).
    """
    caps = body.capsules
    rest = np.asarray(body.rest_joints, dtype=np.float64)
    glob, pos = forward_kinematics(
        rest, joint_rotations, root_translation, PARENTS if parents is None else np.asarray(parents)
    )
    start = np.einsum("...jab,jb->...ja", glob, np.asarray(caps.start, dtype=np.float64) - rest) + pos
    end = np.einsum("...jab,jb->...ja", glob, np.asarray(caps.end, dtype=np.float64) - rest) + pos
    return start, end


# ---------------------------------------------------------------------- voxel occupancy


def mesh_occupancy(
    vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, step: float, shape: tuple[int, int, int]
) -> np.ndarray:
    """Which voxel centres ``origin + step * (i, j, k)`` lie inside a closed mesh.

    Casts one ray along +z per (i, j) column and fills between alternate crossings
    (parity), so it needs a watertight mesh. Returns a (nx, ny, nz) bool array.
    """
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces)]
    nx, ny, nz = shape
    origin = np.asarray(origin, dtype=np.float64)
    # grid-local 2D coordinates of the vertices, in columns
    gx = (tri[..., 0] - origin[0]) / step
    gy = (tri[..., 1] - origin[1]) / step
    i0 = np.clip(np.ceil(gx.min(axis=1)), 0, nx).astype(np.int64)
    i1 = np.clip(np.floor(gx.max(axis=1)), -1, nx - 1).astype(np.int64)
    j0 = np.clip(np.ceil(gy.min(axis=1)), 0, ny).astype(np.int64)
    j1 = np.clip(np.floor(gy.max(axis=1)), -1, ny - 1).astype(np.int64)
    wi = np.maximum(i1 - i0 + 1, 0)
    wj = np.maximum(j1 - j0 + 1, 0)
    count = wi * wj
    tid = np.repeat(np.arange(len(tri)), count)
    if len(tid) == 0:
        return np.zeros(shape, dtype=bool)
    first = np.cumsum(count) - count
    local = np.arange(len(tid)) - np.repeat(first, count)
    ci = i0[tid] + local // np.maximum(wj[tid], 1)
    cj = j0[tid] + local % np.maximum(wj[tid], 1)
    px, py = ci.astype(np.float64), cj.astype(np.float64)
    ax, ay = gx[tid, 0], gy[tid, 0]
    bx, by = gx[tid, 1], gy[tid, 1]
    cx, cy = gx[tid, 2], gy[tid, 2]
    w0 = (bx - px) * (cy - py) - (by - py) * (cx - px)
    w1 = (cx - px) * (ay - py) - (cy - py) * (ax - px)
    w2 = (ax - px) * (by - py) - (ay - py) * (bx - px)
    inside = ((w0 >= 0) & (w1 >= 0) & (w2 >= 0)) | ((w0 <= 0) & (w1 <= 0) & (w2 <= 0))
    total = w0 + w1 + w2
    inside &= np.abs(total) > 1e-15
    tid, ci, cj = tid[inside], ci[inside], cj[inside]
    w0, w1, w2, total = w0[inside], w1[inside], w2[inside], total[inside]
    z = (w0 * tri[tid, 0, 2] + w1 * tri[tid, 1, 2] + w2 * tri[tid, 2, 2]) / total
    kz = (z - origin[2]) / step
    column = ci * ny + cj
    order = np.lexsort((kz, column))
    column, kz = column[order], kz[order]
    # parity: the n-th crossing of a column opens (+1) or closes (-1) the inside
    starts = np.r_[0, np.flatnonzero(np.diff(column)) + 1]
    counts = np.diff(np.r_[starts, len(column)])
    rank = np.arange(len(column)) - np.repeat(starts, counts)
    even_cols = np.repeat(counts % 2 == 0, counts)  # tangent rays (odd counts) are dropped
    sign = np.where(rank % 2 == 0, 1, -1)[even_cols]
    column, kz = column[even_cols], kz[even_cols]
    cell = np.clip(np.ceil(kz), 0, nz).astype(np.int64)
    diff = np.zeros((nx * ny, nz + 1), dtype=np.int32)
    np.add.at(diff, (column, cell), sign)
    return (np.cumsum(diff, axis=1)[:, :nz] > 0).reshape(nx, ny, nz)


def capsule_occupancy(
    start: np.ndarray, end: np.ndarray, radius: np.ndarray, origin: np.ndarray, step: float, shape: tuple[int, int, int]
) -> np.ndarray:
    """Voxel centres inside the union of capsules: (nx, ny, nz) bool."""
    axes = [origin[i] + step * np.arange(shape[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    occ = np.zeros(len(pts), dtype=bool)
    for a, b, r in zip(start, end, radius, strict=True):
        lo = np.minimum(a, b) - r
        hi = np.maximum(a, b) + r
        box = np.all((pts >= lo) & (pts <= hi), axis=1)
        sub = pts[box]
        ab = b - a
        denom = max(float(ab @ ab), 1e-12)
        t = np.clip((sub - a) @ ab / denom, 0.0, 1.0)
        d2 = np.sum((sub - a - t[:, None] * ab) ** 2, axis=1)
        occ[np.flatnonzero(box)[d2 <= r * r]] = True
    return occ.reshape(shape)


def capsule_mesh_iou(body, *, resolution: float = 0.01, capsules: Capsules | None = None) -> dict:
    """Volume IoU of the capsule union against the body's rest mesh (voxel estimate).

    Args:
        body: a Body (its rest mesh must be watertight).
        resolution: voxel edge, m.
        capsules: the capsules to score (default ``body.capsules``).

    Returns:
        ``{"iou", "mesh_volume", "capsule_volume", "intersection", "resolution"}`` (m^3).
    """
    if resolution <= 0:
        raise InvalidInputError(f"resolution: expected a positive voxel size in metres, got {resolution}")
    caps = body.capsules if capsules is None else capsules
    verts = np.asarray(body.rest_vertices)
    lo = np.minimum(verts.min(axis=0), (np.minimum(caps.start, caps.end) - caps.radius[:, None]).min(axis=0))
    hi = np.maximum(verts.max(axis=0), (np.maximum(caps.start, caps.end) + caps.radius[:, None]).max(axis=0))
    # an irrational offset keeps rays off mesh edges and vertices
    origin = lo - resolution + resolution * np.array([0.5 / np.sqrt(2), 0.5 / np.sqrt(3), 0.5])
    nx, ny, nz = (int(np.ceil((hi[i] - origin[i]) / resolution)) + 2 for i in range(3))
    shape = (nx, ny, nz)
    mesh_occ = mesh_occupancy(verts, body.faces, origin, resolution, shape)
    cap_occ = capsule_occupancy(caps.start, caps.end, caps.radius, origin, resolution, shape)
    cell = resolution**3
    inter = float(np.count_nonzero(mesh_occ & cap_occ)) * cell
    union = float(np.count_nonzero(mesh_occ | cap_occ)) * cell
    return {
        "iou": inter / union if union > 0 else 0.0,
        "mesh_volume": float(np.count_nonzero(mesh_occ)) * cell,
        "capsule_volume": float(np.count_nonzero(cap_occ)) * cell,
        "intersection": inter,
        "resolution": resolution,
    }


def capsule_skin(
    body, percentile: float = SKIN_PERCENTILE, max_skin: float = SKIN_MAX, hand_scale: float = SKIN_HAND_SCALE
) -> np.ndarray:
    """(J,) m: how far the body mesh reaches beyond each capsule.

    For the vertices bound mostly to bone j (largest skinning weight), the ``percentile``
    of their distance outside capsule j, clipped to [0, max_skin]. Added to the capsule
    radius for inter-body and environment contacts so the MESHES stay apart, not only the
    capsules. Zeros when the body has no mesh (``rest_vertices``/``weights``).

    The skin grows the capsule in every direction, while what reaches beyond a capsule is
    mostly one protrusion: the thumb and spread fingers beside a hand's capsule (2-4 cm on
    the MakeHuman bodies at the 90th percentile), a chest or a shoulder blade beside the
    upper trunk's (up to 4 cm). ``max_skin`` caps it, and the palm
    and finger bones (``left/right_wrist``, ``left/right_hand`` of a 24-joint skeleton)
    take ``hand_scale`` of their skin: a hand 3-4 cm thick had a contact sphere 12-14 cm
    across and stopped 3-5 cm short of a back it was pressed on (docs/lab-notes/correction-history.md,
    "Where concert D5's tracking goes").
    """
    if max_skin < 0 or hand_scale < 0:
        raise InvalidInputError(
            f"capsule_skin: expected max_skin >= 0 and hand_scale >= 0, got {max_skin!r}, {hand_scale!r}"
        )
    caps = body.capsules
    n_j = len(caps.radius)
    verts = getattr(body, "rest_vertices", None)
    weights = getattr(body, "weights", None)
    if verts is None or weights is None or percentile <= 0:
        return np.zeros(n_j)
    verts = np.asarray(verts, np.float64)
    # the vertices grouped by their dominant bone (for the shared template weights: once)
    order, bounds = _frozen(np.asarray(weights), "dominant", _dominant_groups)
    skin = np.zeros(n_j)
    for j in range(min(n_j, len(bounds) - 1)):
        if bounds[j] == bounds[j + 1]:
            continue
        v = verts[order[bounds[j] : bounds[j + 1]]]
        s, e = np.asarray(caps.start[j], np.float64), np.asarray(caps.end[j], np.float64)
        d = e - s
        t = np.clip((v - s) @ d / max(float(d @ d), 1e-12), 0.0, 1.0)
        excess = np.linalg.norm(v - (s + t[:, None] * d), axis=1) - caps.radius[j]
        skin[j] = np.clip(np.percentile(excess, percentile), 0.0, max_skin)
    if n_j == NUM_JOINTS:
        skin[list(HAND_BONES)] *= hand_scale
    return skin


def _dominant_groups(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ordered by their largest skinning weight's bone (stable: in index order
    within a bone) and each bone's slice bounds: bone j has ``order[bounds[j]:bounds[j + 1]]``."""
    dominant = weights.argmax(1)
    order = np.argsort(dominant, kind="stable")
    bounds = np.searchsorted(dominant[order], np.arange(weights.shape[1] + 1))
    return order, bounds

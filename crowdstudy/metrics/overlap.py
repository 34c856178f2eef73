"""Mean per-character volumetric overlap of a crowd animation.

For each measured frame and each character, the overlap is the volume of the character's
body that lies inside any *other* character's body (a point inside two neighbours counts
once). :func:`overlap_volume` averages it over characters and frames.

Geometry: ``"mesh"`` poses each character's skinned body mesh (``Body.pose``); ``"capsule"``
uses its 24 bone capsules (``Body.capsules``, placed by forward kinematics with the body's
``rest_joints``). Volumes are measured on vertical grid columns of side ``resolution``
(:mod:`crowdstudy.metrics.columns`): exact along z, a midpoint rule over (x, y).

Periodic scenes (``anim.meta["periodic"] = {"axis": 0, "length": L}``) wrap every character
into [0, L) along x and add ghost copies near both ends, which is the minimum-image
convention for bodies much shorter than L.

Speed: with Warp (the default ``device``), the skinning of all N meshes and the per-face
column crossings run as Warp kernels (:mod:`crowdstudy.metrics.kernels`, CPU or CUDA); the
interval arithmetic is sorting in numpy. ``device="numpy"`` is the pure-numpy reference
(same volumes). ``crowdstudy bench metrics`` reports the seconds per frame of both.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.metrics.columns import (
    Crossings,
    capsule_crossings,
    mesh_crossings,
    overlap_lengths,
    solid_intervals,
)

__all__ = [
    "OverlapResult",
    "overlap_volume",
    "frame_indices",
    "resolve_bodies",
    "capsules_world",
    "mesh_volume",
    "GEOMETRIES",
]

GEOMETRIES = ("mesh", "capsule")
_FRAME_CHUNK = 8


@dataclasses.dataclass(frozen=True)
class OverlapResult:
    """Volumetric overlap measured on some frames of an animation.

    Attributes:
        per_character: (F, N) float64 m^3, volume of character n inside any other
            character at measured frame f.
        frames: (F,) int64, the measured frame indices.
        resolution: column spacing in metres.
        geometry: ``"mesh"`` or ``"capsule"``.
        body_volume: (N,) float64 m^3, each body's rest-pose volume (mesh geometry; None
            for capsules).
        dropped_columns: (solid, column) pairs skipped because the surface did not close
            along them (0 for watertight meshes, apart from rare grazing round-off).
        seconds: wall time of the measurement.
    """

    per_character: np.ndarray
    frames: np.ndarray
    resolution: float
    geometry: str
    body_volume: np.ndarray | None = None
    dropped_columns: int = 0
    seconds: float = 0.0

    @property
    def mean(self) -> float:
        """Mean over characters and frames, m^3 per character."""
        return float(self.per_character.mean()) if self.per_character.size else 0.0

    @property
    def mean_litres(self) -> float:
        return 1000.0 * self.mean

    @property
    def per_frame(self) -> np.ndarray:
        """(F,) mean over characters, m^3."""
        return self.per_character.mean(axis=1)

    @property
    def fraction(self) -> float | None:
        """Mean overlap over mean body volume (mesh geometry), or None."""
        if self.body_volume is None or not np.any(self.body_volume > 0):
            return None
        return self.mean / float(np.mean(self.body_volume))

    def to_dict(self) -> dict:
        return {
            "geometry": self.geometry,
            "resolution_m": self.resolution,
            "mean_m3": self.mean,
            "mean_litres": self.mean_litres,
            "frames_measured": int(len(self.frames)),
            "fraction_of_body": self.fraction,
            "max_m3": float(self.per_character.max(initial=0.0)),
            "dropped_columns": self.dropped_columns,
            "seconds": self.seconds,
        }


def frame_indices(frames: Any, n_frames: int) -> np.ndarray:
    """Which frames to measure.

    ``frames``: None or ``"all"`` (every frame), ``"auto"`` (every 10th frame when there
    are more than 100, else all), ``"every:K"`` (every K-th from frame 0), a ``slice``, or a
    sequence of frame indices (negative ones count from the end).
    """
    if frames is None or (isinstance(frames, str) and frames == "all"):
        return np.arange(n_frames, dtype=np.int64)
    if isinstance(frames, str):
        if frames == "auto":
            return np.arange(0, n_frames, 10 if n_frames > 100 else 1, dtype=np.int64)
        if frames.startswith("every:"):
            try:
                step = int(frames.split(":", 1)[1])
            except ValueError:
                step = 0
            if step < 1:
                raise InvalidInputError(f"frames: expected 'every:K' with an integer K >= 1, got {frames!r}")
            return np.arange(0, n_frames, step, dtype=np.int64)
        raise InvalidInputError(f"frames: expected 'all', 'auto', 'every:K' or a list of indices, got {frames!r}")
    if isinstance(frames, slice):
        idx = np.arange(n_frames, dtype=np.int64)[frames]
    else:
        try:
            idx = np.asarray(frames, dtype=np.int64).reshape(-1)
        except (TypeError, ValueError):
            raise InvalidInputError(f"frames: expected frame indices, got {frames!r}") from None
        if np.any(idx < -n_frames) or np.any(idx >= n_frames):
            raise InvalidInputError(f"frames: indices must lie in [-{n_frames}, {n_frames}), got {idx.tolist()}")
        idx = np.where(idx < 0, idx + n_frames, idx)
    if len(idx) == 0:
        raise InvalidInputError(f"frames: selects no frame of {n_frames}")
    return idx


def resolve_bodies(anim, bodies: Sequence | None = None) -> list:
    """One body object per character: ``bodies`` when given (duck-typed, e.g. test
    fixtures), else ``crowdstudy.body.load_body(record)`` for each ``anim.bodies`` record."""
    n = anim.n_characters
    if bodies is not None:
        bodies = list(bodies)
        if len(bodies) != n:
            raise InvalidInputError(f"bodies: expected {n} bodies (one per character), got {len(bodies)}")
        return bodies
    from crowdstudy.body import load_body

    return [load_body(rec) for rec in anim.bodies]


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume (m^3) of a closed triangle mesh, by the divergence theorem."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    triple = (
        a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
        + a[:, 1] * (b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2])
        + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    )
    return float(abs(triple.sum()) / 6.0)


def capsules_world(
    body, joint_rotations: np.ndarray, root_translation: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space capsules of one character at some frames.

    Args:
        body: has ``rest_joints`` (J, 3) and ``capsules`` (``start``, ``end`` (J, 3) in the
            rest frame, ``radius`` (J,)).
        joint_rotations: (F, J, 3) axis-angle; root_translation: (F, 3) metres.

    Returns:
        ``(start (F, J, 3), end (F, J, 3), radius (J,))`` metres.
    """
    from crowdstudy.body.capsules import posed_capsules

    start, end = posed_capsules(body, joint_rotations, root_translation, parents=getattr(body, "parents", None))
    return start, end, np.asarray(body.capsules.radius, dtype=np.float64)


def _batch_poser(body_objs: list, backend: str = "numpy"):
    """A function posing all N bodies of one frame, ``(rot (N, J, 3), root (N, 3)) ->
    list of (V_i, 3)``: the Warp skinning kernel on a Warp backend when the bodies allow it
    (:class:`crowdstudy.metrics.kernels.WarpSkinner`), else
    ``crowdstudy.body.model.pose_bodies`` when every body is a
    :class:`crowdstudy.body.model.Body`, else None (each body's ``pose``)."""
    if backend != "numpy":
        from crowdstudy.metrics.kernels import WarpSkinner

        if WarpSkinner.supports(body_objs):
            skinner = WarpSkinner(body_objs, backend)
            return lambda bodies, rot, root: skinner(rot, root)
    from crowdstudy.body.model import Body, pose_bodies

    if not all(isinstance(b, Body) for b in body_objs):
        return None
    return lambda bodies, rot, root: pose_bodies(bodies, rot, root, dtype=np.float32)


def _backend(device: str | None) -> str:
    """``"numpy"`` or the Warp device that computes mesh crossings (see overlap_volume)."""
    if device == "numpy":
        return "numpy"
    if device is not None and not isinstance(device, str):
        raise InvalidInputError(f"device: expected None, 'auto', 'numpy', 'cpu' or 'cuda:N', got {device!r}")
    try:
        import warp  # noqa: F401
    except ImportError:
        if device in (None, "auto"):
            return "numpy"
        raise InvalidInputError(f"device: {device!r} needs Warp (pip install warp-lang); use 'numpy'") from None
    from crowdstudy.warp_runtime import resolve_device

    return resolve_device(device)


def _check_args(anim, resolution, geometry):
    try:
        h = float(resolution)
    except (TypeError, ValueError):
        raise InvalidInputError(f"resolution: expected a length in metres, got {resolution!r}") from None
    if not np.isfinite(h) or h <= 0 or h > 0.5:
        raise InvalidInputError(f"resolution: expected metres in (0, 0.5], got {resolution!r}")
    if geometry not in GEOMETRIES:
        raise InvalidInputError(f"geometry: expected one of {GEOMETRIES}, got {geometry!r}")
    if not hasattr(anim, "root_translation") or not hasattr(anim, "joint_rotations"):
        raise TypeError(f"anim: expected a CrowdAnimation, got {type(anim).__name__}")
    return h


def _periodic_images(lo: np.ndarray, hi: np.ndarray, length: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Shifts along x for each character (wrap into [0, L)) and the ghost copies to add.

    Args:
        lo, hi: (N, 3) AABB corners of the posed characters.

    Returns:
        ``(shift (N,), ghosts (G, 2))`` with rows (character, extra shift).
    """
    n = len(lo)
    if length is None:
        return np.zeros(n), np.zeros((0, 2))
    centre = 0.5 * (lo[:, 0] + hi[:, 0])
    shift = -np.floor(centre / length) * length
    reach = float(np.max(hi[:, 0] - lo[:, 0]))
    if 2.0 * reach >= length:
        raise InvalidInputError(f"anim.meta['periodic']: length {length} m is too short for bodies {reach:.2f} m wide")
    x_lo = lo[:, 0] + shift
    x_hi = hi[:, 0] + shift
    near_start = np.flatnonzero(x_lo < reach)
    near_end = np.flatnonzero(x_hi > length - reach)
    ghosts = np.concatenate(
        [
            np.stack([near_start, np.full(len(near_start), length)], 1),
            np.stack([near_end, np.full(len(near_end), -length)], 1),
        ]
    )
    return shift, ghosts


def _partner_rects(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    """For each solid, the (x, y) rectangles where its AABB meets another solid's AABB.

    Returns a list of (K_i, 4) arrays (x_lo, x_hi, y_lo, y_hi), empty when isolated.
    """
    meet = np.all((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :]), axis=2)
    np.fill_diagonal(meet, False)
    rects = []
    for i in range(len(lo)):
        js = np.flatnonzero(meet[i])
        r_lo = np.maximum(lo[i, :2], lo[js, :2])
        r_hi = np.minimum(hi[i, :2], hi[js, :2])
        rects.append(np.stack([r_lo[:, 0], r_hi[:, 0], r_lo[:, 1], r_hi[:, 1]], axis=1))
    return rects


def _min3(a: np.ndarray) -> np.ndarray:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])


def _max3(a: np.ndarray) -> np.ndarray:
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


def _frame_overlap_mesh(
    verts: list[np.ndarray],
    faces: list[np.ndarray],
    lo: np.ndarray,
    hi: np.ndarray,
    n_real: int,
    h: float,
    backend: str = "numpy",
) -> tuple[np.ndarray, int]:
    """Overlap volumes (n_real,) m^3 of one frame from posed meshes (real ones first, then
    ghosts, whose own overlap is not reported) with their AABBs ``lo``, ``hi`` (S, 3).

    ``backend``: ``"numpy"``, or a Warp device name for the crossing kernel."""
    rects = _partner_rects(lo, hi)
    if not any(len(r) for r in rects):
        return np.zeros(n_real), 0
    if backend != "numpy":
        from crowdstudy.metrics.kernels import mesh_crossings_warp

        sizes = np.array([len(v) for v in verts])
        base = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        all_faces = np.concatenate([f + b for f, b in zip(faces, base, strict=True)])
        face_solid = np.repeat(np.arange(len(faces)), [len(f) for f in faces])
        cr = mesh_crossings_warp(np.concatenate(verts), all_faces, face_solid, rects, h, backend)
        return _overlap_from_crossings(cr, len(verts), n_real, h)
    v_parts, f_parts, s_parts = [], [], []
    base = 0
    for s, (v, f, rect) in enumerate(zip(verts, faces, rects, strict=True)):
        if len(rect) == 0:
            continue
        # Column-index ranges of each face (ceil/floor are monotonic, so per vertex first),
        # kept when non-empty and meeting one of the partner rectangles' column ranges.
        fu = v[f, 0]
        fw = v[f, 1]
        x0 = np.ceil(_min3(fu) / h - 0.5)
        x1 = np.floor(_max3(fu) / h - 0.5)
        y0 = np.ceil(_min3(fw) / h - 0.5)
        y1 = np.floor(_max3(fw) / h - 0.5)
        hit = np.zeros(len(f), bool)
        for rx0, rx1, ry0, ry1 in rect:
            hit |= (
                (x0 <= np.floor(rx1 / h - 0.5))
                & (x1 >= np.ceil(rx0 / h - 0.5))
                & (y0 <= np.floor(ry1 / h - 0.5))
                & (y1 >= np.ceil(ry0 / h - 0.5))
            )
        hit &= (x0 <= x1) & (y0 <= y1)
        if not hit.any():
            continue
        v_parts.append(v)
        f_parts.append(f[hit] + base)
        s_parts.append(np.full(int(hit.sum()), s, np.int64))
        base += len(v)
    if not f_parts:
        return np.zeros(n_real), 0
    cr = mesh_crossings(np.concatenate(v_parts), np.concatenate(f_parts), np.concatenate(s_parts), h)
    return _overlap_from_crossings(_within_rects(cr, rects, h), len(verts), n_real, h)


def _within_rects(cr: Crossings, rects: list[np.ndarray], h: float) -> Crossings:
    """Keep the crossings whose column centre lies in one of its solid's partner
    rectangles: only there were all of the solid's faces kept, and only there can it
    overlap another solid."""
    k_max = max(len(r) for r in rects)
    table = np.full((len(rects), max(k_max, 1), 4), np.nan)
    for s, rect in enumerate(rects):
        table[s, : len(rect)] = rect
    t = table[cr.solid]  # (K, k_max, 4)
    px = ((cr.ix + 0.5) * h)[:, None]
    py = ((cr.iy + 0.5) * h)[:, None]
    inside = ((px >= t[..., 0]) & (px <= t[..., 1]) & (py >= t[..., 2]) & (py <= t[..., 3])).any(axis=1)
    return Crossings(cr.solid[inside], cr.ix[inside], cr.iy[inside], cr.z[inside], cr.sign[inside])


def _overlap_from_crossings(cr: Crossings, n_solids: int, n_real: int, h: float) -> tuple[np.ndarray, int]:
    solid, col, z0, z1, dropped = solid_intervals(cr)
    lengths = overlap_lengths(solid, col, z0, z1, n_solids)
    return lengths[:n_real] * h * h, dropped


def _frame_overlap_capsules(
    start: np.ndarray, end: np.ndarray, radius: np.ndarray, n_real: int, h: float
) -> tuple[np.ndarray, int]:
    """Overlap volumes (n_real,) m^3 of one frame from capsules (S, J, 3) x2, radius (S, J)."""
    r = radius[:, :, None]
    lo = np.minimum(start, end) - r
    hi = np.maximum(start, end) + r
    valid = radius > 0
    big = np.where(valid[:, :, None], lo, np.inf).min(axis=1)
    top = np.where(valid[:, :, None], hi, -np.inf).max(axis=1)
    rects = _partner_rects(big, top)
    keep = np.zeros(radius.shape, bool)
    for s, rect in enumerate(rects):
        for x0, x1, y0, y1 in rect:
            keep[s] |= valid[s] & (lo[s, :, 0] <= x1) & (hi[s, :, 0] >= x0) & (lo[s, :, 1] <= y1) & (hi[s, :, 1] >= y0)
    if not keep.any():
        return np.zeros(n_real), 0
    solid = np.broadcast_to(np.arange(len(radius))[:, None], radius.shape)
    cr = capsule_crossings(start[keep], end[keep], radius[keep], solid[keep].astype(np.int64), h)
    return _overlap_from_crossings(cr, len(radius), n_real, h)


def _mesh_frame(
    verts: list[np.ndarray], faces: list[np.ndarray], length: float | None, h: float, backend: str
) -> tuple[np.ndarray, int]:
    """Overlap volumes (N,) m^3 of one frame of posed meshes ``verts[i]`` (V_i, 3), with
    periodic wrapping and ghost copies when ``length`` is set."""
    n = len(verts)
    lo = np.array([v.min(axis=0) for v in verts])
    hi = np.array([v.max(axis=0) for v in verts])
    all_faces = list(faces)
    if length is not None:
        shift, ghosts = _periodic_images(lo, hi, length)
        verts = [v + np.array([s, 0.0, 0.0]) for v, s in zip(verts, shift, strict=True)]
        lo[:, 0] += shift
        hi[:, 0] += shift
        source = ghosts[:, 0].astype(np.int64)
        move = np.zeros((len(ghosts), 3))
        move[:, 0] = ghosts[:, 1]
        verts += [verts[i] + m for i, m in zip(source, move, strict=True)]
        all_faces += [faces[i] for i in source]
        lo = np.concatenate([lo, lo[source] + move])
        hi = np.concatenate([hi, hi[source] + move])
    return _frame_overlap_mesh(verts, all_faces, lo, hi, n, h, backend)


def _capsule_frame(
    caps: list[tuple[np.ndarray, np.ndarray, np.ndarray]], length: float | None, h: float
) -> tuple[np.ndarray, int]:
    """Overlap volumes (N,) m^3 of one frame of capsules, ``caps[i] = (start (J, 3),
    end (J, 3), radius (J,))`` of character i, with periodic ghosts when ``length`` is set."""
    n = len(caps)
    n_j = max(len(c[2]) for c in caps)
    start = np.zeros((n, n_j, 3))
    end = np.zeros((n, n_j, 3))
    radius = np.zeros((n, n_j))
    for i, (s, e, r) in enumerate(caps):
        start[i, : len(r)], end[i, : len(r)], radius[i, : len(r)] = s, e, r
    if length is not None:
        has = radius[:, :, None] > 0
        r3 = np.where(has, radius[:, :, None], 0.0)
        lo = np.where(has, np.minimum(start, end) - r3, np.inf).min(axis=1)
        hi = np.where(has, np.maximum(start, end) + r3, -np.inf).max(axis=1)
        shift, ghosts = _periodic_images(lo, hi, length)
        start[:, :, 0] += shift[:, None]
        end[:, :, 0] += shift[:, None]
        source = ghosts[:, 0].astype(np.int64)
        g_start = start[source].copy()
        g_end = end[source].copy()
        g_start[:, :, 0] += ghosts[:, 1][:, None]
        g_end[:, :, 0] += ghosts[:, 1][:, None]
        start = np.concatenate([start, g_start])
        end = np.concatenate([end, g_end])
        radius = np.concatenate([radius, radius[source]])
    return _frame_overlap_capsules(start, end, radius, n, h)


def overlap_volume(
    anim,
    *,
    resolution: float = 0.02,
    geometry: str = "mesh",
    frames: Any = None,
    device: str | None = None,
    progress: bool = False,
    bodies: Sequence | None = None,
) -> OverlapResult:
    """Mean per-character volumetric overlap between characters.

    Args:
        anim: a :class:`~crowdstudy.scene.CrowdAnimation` (T frames, N characters).
        resolution: grid column spacing in metres (0.02 = 2 cm). The z direction is exact;
            the error is that of a midpoint rule over (x, y). Measured against analytic
            lens volumes (tests/test_metrics.py): two balls (r 0.3 / 0.22 m) within 0.1 %
            at 2 cm; the worst case, a 15 cm wide lens prism between two vertical capsules,
            within 3.5 % at 2 cm, 1 % at 1 cm, 0.12 % at 5 mm.
        geometry: ``"mesh"`` (posed skinned body meshes, watertight) or ``"capsule"``.
        frames: which frames (see :func:`frame_indices`); None measures all of them.
        device: where the mesh crossings are computed: None or ``"auto"`` (Warp on CUDA
            when present, else Warp on the CPU; numpy when Warp is not installed),
            ``"cpu"`` / ``"cuda:0"`` (Warp on that device) or ``"numpy"`` (pure numpy,
            the reference implementation). Capsules always use numpy. All give the same
            volumes up to round-off.
        progress: show a progress bar over frames (stderr).
        bodies: optional per-character body objects overriding ``load_body(record)``.

    Returns:
        :class:`OverlapResult` with ``per_character`` (F, N) m^3 and ``mean`` m^3.
    """
    t_start = time.perf_counter()
    h = _check_args(anim, resolution, geometry)
    idx = frame_indices(frames, anim.n_frames)
    body_objs = resolve_bodies(anim, bodies)
    backend = _backend(device) if geometry == "mesh" else "numpy"
    n = anim.n_characters
    length = anim.periodic_length
    if length is not None and int(anim.meta["periodic"].get("axis", 0)) != 0:
        raise InvalidInputError(
            f"anim.meta['periodic']: only axis 0 (x) is supported, got axis {anim.meta['periodic'].get('axis')!r}"
        )
    out = np.zeros((len(idx), n))
    dropped = 0
    faces: list[np.ndarray] = []  # (F_i, 3) per body, mesh geometry only
    body_volume = None
    if geometry == "mesh":
        faces = [np.asarray(b.faces, dtype=np.int64) for b in body_objs]
        body_volume = np.array([mesh_volume(b.rest_vertices, f) for b, f in zip(body_objs, faces, strict=True)])
        batch_pose = _batch_poser(body_objs, backend)
    bar = None
    if progress:
        from crowdstudy.progress import progress_bar

        bar = progress_bar(total=len(idx), desc=f"overlap ({geometry})", unit="frame", leave=False)
    for c0 in range(0, len(idx), _FRAME_CHUNK):
        chunk = idx[c0 : c0 + _FRAME_CHUNK]
        rot = anim.joint_rotations[chunk]  # (C, N, J, 3)
        root = anim.root_translation[chunk]  # (C, N, 3)
        if geometry == "mesh":
            posed = (
                []
                if batch_pose is not None
                else [np.asarray(b.pose(rot[:, i], root[:, i])[0], dtype=np.float64) for i, b in enumerate(body_objs)]
            )
            for k in range(len(chunk)):
                if batch_pose is not None:
                    verts = [np.asarray(v, dtype=np.float64) for v in batch_pose(body_objs, rot[k], root[k])]
                else:
                    verts = [p[k] for p in posed]
                out[c0 + k], d = _mesh_frame(verts, faces, length, h, backend)
                dropped += d
                if bar is not None:
                    bar.update(1)
        else:
            caps = [capsules_world(b, rot[:, i], root[:, i]) for i, b in enumerate(body_objs)]
            for k in range(len(chunk)):
                out[c0 + k], d = _capsule_frame([(s[k], e[k], r) for s, e, r in caps], length, h)
                dropped += d
                if bar is not None:
                    bar.update(1)
    if bar is not None:
        bar.close()
    return OverlapResult(
        per_character=out,
        frames=idx,
        resolution=h,
        geometry=geometry,
        body_volume=body_volume,
        dropped_columns=dropped,
        seconds=time.perf_counter() - t_start,
    )

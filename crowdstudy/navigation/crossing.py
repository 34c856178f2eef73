"""The plaza where two flows cross (``kind = "crossing"``): an ORCA crowd with obstacles.

Geometry (the design's ``[floor]`` and ``[scenarios.NAME]`` of kind ``crossing``, see
:func:`crowdstudy.design.load_design`): the *crossing area* is the design's floor
(``width`` x ``depth`` m, centred on the origin), on a paved plaza ``plaza_width`` x
``plaza_depth`` m around it. Flow 1 walks towards +x, flow 2 at ``angle`` degrees from +x
towards +y. Each flow walks a *band* as wide as the crossing area seen across its
direction (the floor's depth for flow 1; ``width |sin a| + depth |cos a|`` for flow 2), so
both flows fill the whole crossing area, where they mix. ``obstacles`` (convex polygons and
circles, m) stand anywhere on the plaza.

Density: ``density`` characters per m^2 of free floor (an obstacle's footprint holds nobody)
in the crossing area, as for the other scenarios: flow 1 walks its band at ``share *
density``, flow 2 at ``(1 - share) * density``, so the crossing area, where both bands
overlap, holds the design's density.

Walkers keep coming, with no teleport: each band is long enough upstream that its walkers
still fill the crossing area at the end of the clip: ``h + 2.5 m + (v + sd) * (warm_up +
duration)`` upstream of the centre (``h`` half the crossing area's extent along the flow,
``v``/``sd`` the flow's preferred speed), and it reaches the plaza's edge downstream. The
animation therefore holds many more characters than the crossing area (about 150 at 2.2
per m^2 to 450 at 6.7 per m^2 with the example plaza); those outside the camera's view cost
the renderer nothing (frustum culling) and the physics little (no contacts). The clip loops
like the corridor's: D frames simulated past the video are cross-dissolved into its first
D frames (:data:`crowdstudy.motion.baseline.LOOP_DISSOLVE_SECONDS`). A periodic boundary per
flow would need two periodic axes that the physics, metrics and renderer do not have (they
wrap along x only), and a teleport would be a jump the physics' PD control follows.

Navigation: ORCA (:class:`~crowdstudy.navigation.orca.ORCASimulator`) with every obstacle's
edges as wall segments (a circle as the 16-gon around it), agents of radius
:func:`~crowdstudy.layout.discs.disc_radius` simulated 3 % larger, preferred speeds ``~
Normal(v * f(rho), sd * f(rho))`` clipped to ``[0.5, 1.5] v f(rho)`` with the corridor's
:func:`~crowdstudy.navigation.corridor.speed_factor`. ORCA is local: an agent walking
straight at a planter would stop against it, so the preferred velocity steers around an
obstacle ahead (towards the nearer side of its extent across the flow, within
:data:`LOOKAHEAD`), and pulls a walker pushed far out of its band back towards it.
Initial positions: uniform in each band, outside the obstacles, pushed apart until no two
simulated discs overlap; a warm-up (3 s) lets the flows settle before frame 0.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.layout.discs import disc_radius
from crowdstudy.navigation.corridor import SAFETY_MARGIN, smooth_headings, speed_factor
from crowdstudy.navigation.orca import ORCAParams, ORCASimulator
from crowdstudy.provenance import provenance
from crowdstudy.scene import Crowd

__all__ = [
    "crossing_crowd",
    "obstacle_polygons",
    "obstacle_segments",
    "obstacle_clearance",
    "LOOKAHEAD",
    "CIRCLE_SIDES",
]

#: Metres ahead within which a walker starts to steer around an obstacle.
LOOKAHEAD = 2.5
#: Sides of the polygon that stands for a circular obstacle (around the circle).
CIRCLE_SIDES = 16
_MAX_SUBSTEP = 1.0 / 60.0
_CLEAR = 0.12  # m kept between a disc and an obstacle's extent when steering around it
_STEER_GAIN = 1.2  # 1/s, lateral pull towards the side of the obstacle
_STEER_CLIP = 0.7  # largest lateral part of the preferred velocity (fraction of the speed)
_BAND_GAIN = 0.4  # 1/s, pull back into the band once outside it
_UPSTREAM_MARGIN = 2.5  # m of band upstream beyond what the clip needs


def obstacle_polygons(obstacles: list[dict]) -> list[np.ndarray]:
    """Each obstacle of a crossing scenario (the design's parsed ``obstacles``) as a
    counter-clockwise convex polygon (K, 2) m; a circle as the :data:`CIRCLE_SIDES`-gon
    whose edges touch it (the circle lies inside)."""
    out = []
    for ob in obstacles:
        if ob["shape"] == "circle":
            k = CIRCLE_SIDES
            rv = float(ob["radius"]) / math.cos(math.pi / k)
            ang = 2 * math.pi * (np.arange(k) + 0.5) / k
            out.append(np.asarray(ob["center"], np.float64) + rv * np.stack([np.cos(ang), np.sin(ang)], 1))
        else:
            out.append(np.asarray(ob["points"], np.float64))
    return out


def obstacle_segments(polygons: list[np.ndarray]) -> np.ndarray:
    """(M, 2, 2) m: the edges of every polygon, as ORCA and the physics' walls see them."""
    segs = [np.stack([p, np.roll(p, -1, axis=0)], 1) for p in polygons]
    return np.concatenate(segs) if segs else np.zeros((0, 2, 2))


def _signed_distance(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(...,) signed distance (m) of ``points`` (..., 2) to the convex counter-clockwise
    polygon ``poly`` (K, 2): negative inside."""
    a, b = poly, np.roll(poly, -1, axis=0)
    edge = b - a
    rel = points[..., None, :] - a  # (..., K, 2)
    t = np.clip(np.einsum("...kc,kc->...k", rel, edge) / np.einsum("kc,kc->k", edge, edge), 0.0, 1.0)
    dist = np.linalg.norm(rel - t[..., None] * edge, axis=-1).min(axis=-1)
    outward = np.stack([edge[:, 1], -edge[:, 0]], 1) / np.linalg.norm(edge, axis=1)[:, None]
    inside = np.all(np.einsum("...kc,kc->...k", rel, outward) < 0.0, axis=-1)
    return np.where(inside, -dist, dist)


def obstacle_clearance(crowd: Crowd, polygons: list[np.ndarray]) -> float:
    """Smallest gap (m) between a disc's edge and an obstacle over all frames and agents
    (negative: a disc reaches into an obstacle); inf without obstacles."""
    best = math.inf
    for poly in polygons:
        gap = _signed_distance(crowd.positions, poly) - crowd.radius[None, :]
        best = min(best, float(gap.min()))
    return best


@dataclasses.dataclass(frozen=True)
class _Flow:
    """One flow: unit ``direction`` (2,), its band's ``width`` (m, centred on the origin
    across the flow), the band's extent along the flow ``[s_min, s_max]`` m, its density
    (1/m^2) and preferred speed (m/s, mean and SD after the speed factor)."""

    direction: np.ndarray
    width: float
    s_min: float
    s_max: float
    density: float
    v_mean: float
    v_sd: float

    @property
    def across(self) -> np.ndarray:
        return np.array([-self.direction[1], self.direction[0]])


@dataclasses.dataclass(frozen=True)
class _Setup:
    """The checked settings of one crossing crowd (see :func:`crossing_crowd`)."""

    level: str
    density: float
    radius: float
    r_sim: float
    floor: tuple[float, float]
    plaza: tuple[float, float]
    angle: float
    flows: tuple[_Flow, _Flow]
    polygons: list[np.ndarray]
    shapes: list[dict]
    fps: float
    n_frames: int
    substeps: int
    warm_up: float
    orca: ORCAParams
    rng: np.random.Generator
    seed_value: int | None
    scenario: str


def _half_extent(direction: np.ndarray, width: float, depth: float) -> float:
    """Half the extent (m) of a centred width x depth rectangle along ``direction``."""
    return 0.5 * (width * abs(direction[0]) + depth * abs(direction[1]))


def _setup(design, level, seed, *, duration, fps, warm_up, params, scenario) -> _Setup:
    """The arguments of :func:`crossing_crowd` checked (InvalidInputError naming the
    argument) and resolved against the design's crossing scenario."""
    if level not in design.densities:
        raise InvalidInputError(
            f"level: unknown density level {level!r}; expected one of {', '.join(design.densities)}"
        )
    sc = design.scenario_of(scenario)
    if sc.kind != "crossing":
        raise InvalidInputError(f"scenario: {scenario!r} is a {sc.kind} scenario, not a crossing")
    duration = float(design.duration if duration is None else duration)
    fps = float(design.fps if fps is None else fps)
    for name, value in (("duration", duration), ("fps", fps)):
        if not math.isfinite(value) or value <= 0:
            raise InvalidInputError(f"{name}: expected a positive number, got {value!r}")
    if not isinstance(warm_up, numbers.Real) or not math.isfinite(warm_up) or warm_up < 0:
        raise InvalidInputError(f"warm_up: expected a non-negative number of seconds, got {warm_up!r}")
    if isinstance(seed, np.random.Generator):
        rng, seed_value = seed, None
    elif isinstance(seed, numbers.Integral) and not isinstance(seed, bool) and int(seed) >= 0:
        rng, seed_value = np.random.default_rng(int(seed)), int(seed)
    else:
        raise InvalidInputError(f"seed: expected a non-negative integer or numpy Generator, got {seed!r}")
    density = float(design.densities[level])
    n_frames = max(1, int(round(duration * fps)))
    factor = speed_factor(density)
    width, depth = float(design.floor_width), float(design.floor_depth)
    plaza = (float(sc["plaza_width"]), float(sc["plaza_depth"]))
    angle = math.radians(float(sc["angle"]))
    share = float(sc["share"])
    flows = []
    for k, direction in enumerate((np.array([1.0, 0.0]), np.array([math.cos(angle), math.sin(angle)]))):
        v_mean, v_sd = float(sc["preferred_speed"][k]) * factor, float(sc["preferred_speed_sd"][k]) * factor
        reach = _half_extent(direction, width, depth) + _UPSTREAM_MARGIN + (v_mean + v_sd) * (float(warm_up) + duration)
        flows.append(
            _Flow(
                direction=direction,
                width=_half_extent(np.array([-direction[1], direction[0]]), width, depth) * 2,
                s_min=-max(reach, _half_extent(direction, *plaza)),
                s_max=_half_extent(direction, *plaza) + 0.5,
                density=density * (share if k == 0 else 1.0 - share),
                v_mean=v_mean,
                v_sd=v_sd,
            )
        )
    substeps = max(1, int(math.ceil((1.0 / fps) / _MAX_SUBSTEP - 1e-9)))
    base = params or ORCAParams(neighbor_dist=1.5, max_neighbors=10, time_horizon=1.0, time_horizon_obst=0.5)
    radius = disc_radius(density)
    return _Setup(
        level=level,
        density=density,
        radius=radius,
        r_sim=SAFETY_MARGIN * radius,
        floor=(width, depth),
        plaza=plaza,
        angle=float(sc["angle"]),
        flows=(flows[0], flows[1]),
        polygons=obstacle_polygons(sc["obstacles"]),
        shapes=[dict(ob) for ob in sc["obstacles"]],
        fps=fps,
        n_frames=n_frames,
        substeps=substeps,
        warm_up=float(warm_up),
        orca=dataclasses.replace(base, time_step=1.0 / (fps * substeps)),
        rng=rng,
        seed_value=seed_value,
        scenario=sc.name,
    )


def _initial_agents(s: _Setup) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flow index (N,) 0/1, start positions (N, 2) m and preferred speeds (N,) m/s: each
    band filled uniformly at its density (points on an obstacle dropped), then separated."""
    pts, flow = [], []
    for k, f in enumerate(s.flows):
        count = int(round(f.density * f.width * (f.s_max - f.s_min)))
        along = s.rng.uniform(f.s_min, f.s_max, count)
        across = s.rng.uniform(-f.width / 2 + s.r_sim, f.width / 2 - s.r_sim, count)
        p = along[:, None] * f.direction + across[:, None] * f.across
        free = np.ones(count, bool)
        for poly in s.polygons:
            free &= _signed_distance(p, poly) > 0.0
        pts.append(p[free])
        flow.append(np.full(int(free.sum()), k))
    pos = _separate(np.concatenate(pts), 2 * s.r_sim, s.polygons)
    flow_idx = np.concatenate(flow)
    speeds = np.empty(len(pos))
    for k, f in enumerate(s.flows):
        m = flow_idx == k
        speeds[m] = np.clip(s.rng.normal(f.v_mean, f.v_sd, int(m.sum())), 0.5 * f.v_mean, 1.5 * f.v_mean)
    return flow_idx, pos, speeds


def _separate(points: np.ndarray, min_dist: float, polygons: list[np.ndarray], max_iter: int = 3000) -> np.ndarray:
    """Push discs apart until all centres are ``min_dist`` apart and at least ``min_dist /
    2`` outside every obstacle polygon. ``points``: (N, 2) metres."""
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  # missing from scipy stubs

    pts = points.copy()
    for _ in range(max_iter):
        moved = False
        pairs = cKDTree(pts).query_pairs(min_dist * (1 + 1e-6), output_type="ndarray")
        if len(pairs):
            delta = pts[pairs[:, 1]] - pts[pairs[:, 0]]
            d = np.linalg.norm(delta, axis=1)
            normal = delta / np.maximum(d, 1e-9)[:, None]
            push = 0.5 * (min_dist * (1 + 1e-3) - d)[:, None] * normal
            move = np.zeros_like(pts)
            np.add.at(move, pairs[:, 0], -push)
            np.add.at(move, pairs[:, 1], push)
            pts += move
            moved = True
        for poly in polygons:
            moved |= _push_out(pts, poly, min_dist / 2 * 1.001)
        if not moved:
            return pts
    raise InvalidInputError(
        f"level: could not separate the discs (min distance {min_dist:.3g} m) on the plaza; "
        "the density is too high for the disc radius"
    )


def _push_out(pts: np.ndarray, poly: np.ndarray, clearance: float) -> bool:
    """Move the points of ``pts`` (N, 2) m closer than ``clearance`` to the convex polygon
    ``poly`` to that distance outside it, away from the nearest boundary point (in place);
    whether any moved."""
    gap = _signed_distance(pts, poly)
    close = gap < clearance - 1e-9
    if not np.any(close):
        return False
    a, edge = poly, np.roll(poly, -1, axis=0) - poly
    rel = pts[close, None, :] - a  # (C, K, 2)
    t = np.clip(np.einsum("cki,ki->ck", rel, edge) / np.einsum("ki,ki->k", edge, edge), 0.0, 1.0)
    offset = rel - t[..., None] * edge  # from the nearest point of each edge
    k = np.argmin(np.linalg.norm(offset, axis=-1), axis=1)
    off = offset[np.arange(len(k)), k]
    outward = np.stack([edge[k, 1], -edge[k, 0]], 1) / np.linalg.norm(edge[k], axis=1)[:, None]
    dist = np.linalg.norm(off, axis=1)
    away = np.where((gap[close] > 1e-9)[:, None], off / np.maximum(dist, 1e-12)[:, None], outward)
    pts[close] += (clearance - gap[close])[:, None] * away
    return True


def _obstacle_boxes(s: _Setup) -> np.ndarray:
    """(2, M, 4) m: each obstacle's extent in each flow's frame, ``[s_lo, s_hi, t_lo,
    t_hi]`` along and across the flow (what a walker of that flow steers around)."""
    out = np.zeros((2, len(s.polygons), 4))
    for k, f in enumerate(s.flows):
        for m, poly in enumerate(s.polygons):
            along, across = poly @ f.direction, poly @ f.across
            out[k, m] = (along.min(), along.max(), across.min(), across.max())
    return out


def _merged_extent(
    lo: np.ndarray, hi: np.ndarray, first: np.ndarray, near: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(N,) lateral extent (m) to steer around: obstacle ``first`` (N,)'s ``[lo, hi]`` (M,)
    merged with every obstacle ``near`` (N, M) it overlaps across the flow, transitively (two
    planters side by side are passed as one, never through the gap between them)."""
    lo_c, hi_c = lo[first], hi[first]
    for _ in range(len(lo)):
        join = near & (lo[None, :] < hi_c[:, None]) & (hi[None, :] > lo_c[:, None])
        lo_n = np.minimum(lo_c, np.where(join, lo[None, :], np.inf).min(axis=1))
        hi_n = np.maximum(hi_c, np.where(join, hi[None, :], -np.inf).max(axis=1))
        if np.array_equal(lo_n, lo_c) and np.array_equal(hi_n, hi_c):
            break
        lo_c, hi_c = lo_n, hi_n
    return lo_c, hi_c


def _preferred_velocities(
    pos: np.ndarray, flow_idx: np.ndarray, speeds: np.ndarray, s: _Setup, boxes: np.ndarray
) -> np.ndarray:
    """(N, 2) m/s preferred velocities at ``pos`` (N, 2) m: each walker's speed along its
    flow, with a lateral part (at most ``_STEER_CLIP`` of the speed) towards the nearer side
    of the nearest obstacle ahead across its path, or back into its band once outside."""
    out = np.zeros_like(pos)
    for k, f in enumerate(s.flows):
        m = flow_idx == k
        along, across = pos[m] @ f.direction, pos[m] @ f.across
        v = speeds[m]
        target = np.clip(across, -f.width / 2, f.width / 2)  # back into the band
        gain = np.full(len(v), _BAND_GAIN)
        if len(s.polygons):
            b = boxes[k]  # (M, 4)
            c = s.r_sim + _CLEAR
            lo, hi = b[None, :, 2] - c, b[None, :, 3] + c
            ahead = b[None, :, 0] - along[:, None]
            blocked = (across[:, None] > lo) & (across[:, None] < hi) & (ahead < LOOKAHEAD)
            blocked &= along[:, None] < b[None, :, 1]
            dist = np.where(blocked, ahead, np.inf)
            first = np.argmin(dist, axis=1)
            hit = np.isfinite(dist[np.arange(len(v)), first])
            lo_f, hi_f = _merged_extent(lo[0], hi[0], first, (ahead < LOOKAHEAD + 1.0) & (along[:, None] < b[:, 1]))
            side = np.where(across - lo_f < hi_f - across, lo_f, hi_f)
            target = np.where(hit, side, target)
            gain = np.where(hit, _STEER_GAIN, gain)
        lateral = np.clip(gain * (target - across), -_STEER_CLIP * v, _STEER_CLIP * v)
        forward = np.sqrt(np.maximum(v**2 - lateral**2, 0.0))
        out[m] = forward[:, None] * f.direction + lateral[:, None] * f.across
    return out


def crossing_crowd(
    design,
    level: str,
    seed,
    *,
    duration: float | None = None,
    fps: float | None = None,
    warm_up: float = 3.0,
    params: ORCAParams | None = None,
    device: str | None = "cpu",
    progress: bool = False,
    scenario: str = "crossing",
) -> Crowd:
    """Trajectories of the crossing flows of one density level (see the module doc).

    Args:
        design: :class:`~crowdstudy.design.StudyDesign` with a scenario of kind ``crossing``.
        level: density level ("D1" .. "D5").
        seed: int (or numpy Generator): layout and preferred speeds.
        duration: seconds (default: the design's video duration).
        fps: frames per second of the output (default: the design's video fps).
        warm_up: seconds simulated before frame 0.
        params: ORCA parameters (the time step is replaced by the sub-step).
        device: Warp device for the simulation.
        progress: show a progress bar (stderr).
        scenario: the design's scenario (its name, or ``"crossing"``: the design's first).

    Returns:
        Crowd: positions (T, N, 2) m, velocities (T, N, 2) m/s, headings (T, N) rad, radius
        (N,) m, obstacles (M, 2, 2) the obstacles' edges, region (4, 2) the crossing area;
        meta with ``floor`` (the crossing area), ``plaza`` {width, depth, obstacles: the
        design's shapes with their heights}, ``obstacles`` (the edges, for the physics),
        ``flows`` (per flow: direction (rad), band width, density, preferred speed),
        ``flow`` (N,) each walker's flow (0, 1) and ``preferred_speeds``.
    """
    s = _setup(design, level, seed, duration=duration, fps=fps, warm_up=warm_up, params=params, scenario=scenario)
    flow_idx, pos, speeds = _initial_agents(s)
    n = len(pos)
    segments = obstacle_segments(s.polygons)
    boxes = _obstacle_boxes(s)
    sim = ORCASimulator(
        pos, s.r_sim, speeds + 0.3, params=s.orca, obstacles=segments if len(segments) else None, device=device
    )
    warm_frames = int(round(s.warm_up * s.fps))
    bar = None
    if progress:
        from crowdstudy.progress import progress_bar

        bar = progress_bar(total=warm_frames + s.n_frames, desc=f"crossing {level}", unit="frame", leave=False)
    positions = np.empty((s.n_frames + 1, n, 2))
    for t in range(warm_frames + s.n_frames):
        current = sim.positions
        if t >= warm_frames:
            positions[t - warm_frames] = current
        sim.set_preferred_velocities(_preferred_velocities(current, flow_idx, speeds, s, boxes))
        sim.step(s.substeps)
        if bar:
            bar.update(1)
    positions[-1] = sim.positions
    if bar:
        bar.close()
    return _result(s, positions, flow_idx, speeds, segments)


def _result(s: _Setup, positions: np.ndarray, flow_idx: np.ndarray, speeds: np.ndarray, segments) -> Crowd:
    """The :class:`Crowd` of the simulated ``positions`` (T + 1, N, 2) m (frame -1 first):
    mean velocities over each frame, smoothed headings and the meta of :func:`crossing_crowd`."""
    velocities = np.diff(positions, axis=0) * s.fps
    positions = positions[1:]
    start = np.array([math.atan2(*s.flows[k].direction[::-1]) for k in (0, 1)])[flow_idx]
    headings = smooth_headings(velocities, s.fps, initial=start)
    w, d = s.floor
    region = np.array([[-w / 2, -d / 2], [w / 2, -d / 2], [w / 2, d / 2], [-w / 2, d / 2]])
    n = len(flow_idx)
    meta = {
        "scenario": "crossing",
        "density_level": s.level,
        "density": s.density,
        "n_characters": n,
        "seed": s.seed_value,
        "radius": s.radius,
        "simulated_radius": s.r_sim,
        "flows": [
            {
                "direction": math.degrees(math.atan2(f.direction[1], f.direction[0])),
                "band_width": f.width,
                "band": [f.s_min, f.s_max],
                "density": f.density,
                "preferred_speed": f.v_mean,
                "preferred_speed_sd": f.v_sd,
            }
            for f in s.flows
        ],
        "flow": flow_idx.astype(int).tolist(),
        "preferred_speeds": speeds.tolist(),
        "speed_factor": speed_factor(s.density),
        "warm_up": s.warm_up,
        "substeps": s.substeps,
        "orca": dataclasses.asdict(s.orca),
        # the scene's static geometry, read by later stages instead of a design
        "floor": {"width": w, "depth": d},
        "plaza": {"width": s.plaza[0], "depth": s.plaza[1], "angle": s.angle, "obstacles": s.shapes},
        "obstacles": segments.tolist(),
        "provenance": provenance(s.seed_value, stage="navigation"),
    }
    return Crowd(
        positions=positions,
        radius=np.full(n, s.radius),
        fps=s.fps,
        velocities=velocities,
        headings=headings,
        obstacles=segments,
        region=region,
        meta=meta,
    )

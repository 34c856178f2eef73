"""The walking corridor of study stage 2: an ORCA crowd in a periodic corridor section.

Geometry: the visible section is ``length x width`` metres centred on the origin
(``design.scenarios["corridor"]``: 4.5 m x 2.0 m = 9 m^2), walls at ``y = +-width / 2``,
periodic along x with period ``length`` (what leaves at +x re-enters at -x, so the density
stays constant for the whole clip). Positions are stored *unwrapped* (continuous in time);
``meta["periodic"] = {"axis": 0, "length": L}`` tells consumers to use the minimum image.

Agents:

* ``n = design.n_characters(level)`` discs of radius
  :func:`~crowdstudy.layout.discs.disc_radius` (0.22 m shoulder half-width, smaller in the
  densest cells so the discs fit); ORCA simulates them with a 3 % safety margin on the
  radius so the discs themselves never overlap by more than 1 % of the radius.
* Preferred speeds ``~ Normal(v0 * f(rho), sd)`` with ``v0 = preferred_speed`` (1.2 m/s)
  and ``sd = preferred_speed_sd`` (0.1 m/s) of the design, clipped to
  ``[0.5, 1.5] * v0 * f(rho)``; ``f(rho) = max(0.2, 1 - rho / RHO_JAM)`` is a
  Greenshields-style linear speed-density relation with jam density ``RHO_JAM = 12`` per
  m^2 (f = 0.82 at D1 ... 0.45 at D5, so the densest cell still walks at about 0.5 m/s).
  Weidmann's (1993) empirical fundamental diagram would stop a real crowd at 5.4 per m^2;
  the study's characters keep walking through contact, which the physics layer resolves.
* Unidirectional (+x) by default; bidirectional sends the half of the agents nearer
  ``+y`` towards -x, starts each group in its own half of the corridor, and gives each
  agent's preferred velocity a gentle lateral pull (0.5 /s, at most 30 % of its speed)
  towards the centre line of its half (right-hand traffic lanes; with the groups mixed at
  the start, ORCA counter-flows at D3 and above lock up to about 0.1 m/s). Even so, an
  agent that ends up in the opposite lane can be swept along with that flow (a few of 40-60
  in some seeds at D4-D5).
* Initial positions: a Poisson-disk set in the section, then pushed apart (minimum image)
  until no two simulated discs overlap (the Poisson spacing bound, 0.25 m at D5, is below
  the disc diameter); a warm-up (3 s by default) lets the flow settle before frame 0.

The simulation runs at a sub-step of the frame period (at most 1/60 s) and is sampled at
the animation frame rate: positions (T, N, 2), velocities (T, N, 2) (mean velocity over
the frame), headings (T, N) from :func:`smooth_headings`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers

import numpy as np

from crowdstudy.errors import InvalidInputError
from crowdstudy.layout.discs import disc_radius
from crowdstudy.layout.poisson import poisson_disk
from crowdstudy.navigation.orca import ORCAParams, ORCASimulator
from crowdstudy.provenance import provenance
from crowdstudy.scene import Crowd

__all__ = [
    "corridor_crowd",
    "smooth_headings",
    "speed_factor",
    "trajectory_summary",
    "RHO_JAM",
    "MAX_TURN_RATE",
    "SAFETY_MARGIN",
]

RHO_JAM = 12.0  # agents / m^2 where the linear speed-density relation reaches 0
MAX_TURN_RATE = math.pi  # rad/s (180 deg/s) for a walking agent
SAFETY_MARGIN = 1.03  # simulated radius / disc radius
_MAX_SUBSTEP = 1.0 / 60.0
_LANE_GAIN = 0.5  # 1/s, lateral pull towards the lane centre (bidirectional)
_LANE_CLIP = 0.3  # largest lateral part of the preferred velocity (fraction of the speed)


def speed_factor(density: float) -> float:
    """Preferred-speed reduction with density: ``max(0.2, 1 - density / RHO_JAM)``."""
    return max(0.2, 1.0 - float(density) / RHO_JAM)


def _wrap_angle(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def smooth_headings(
    velocities,
    fps: float,
    initial=None,
    *,
    max_rate: float = MAX_TURN_RATE,
    time_constant: float = 0.25,
    min_speed: float = 0.15,
    walk_speed: float = 0.5,
) -> np.ndarray:
    """Facing directions that follow the walking direction smoothly.

    A first-order low-pass filter (``time_constant`` seconds) on the direction of motion,
    with the turn per frame clipped to ``max_rate / fps``. The filter gain fades linearly
    from full at ``walk_speed`` to zero at ``min_speed`` (m/s), so an agent shuffling in a
    jam does not spin with every jitter of its velocity, and one standing still keeps its
    heading. Angle differences are wrapped, so crossing +-pi is a small turn.

    Args:
        velocities: (T, N, 2) m/s.
        fps: frames per second.
        initial: (N,) radians, heading before frame 0 (default: direction of frame 0's
            velocity, or +x when it is too slow).
        max_rate: rad/s bound on the turn rate.

    Returns:
        (T, N) float64 radians in (-pi, pi], measured from +x towards +y.
    """
    vel = np.asarray(velocities, dtype=np.float64)
    if vel.ndim != 3 or vel.shape[2] != 2:
        raise InvalidInputError(f"velocities: expected shape (T, N, 2), got {vel.shape}")
    fps = float(fps)
    if not math.isfinite(fps) or fps <= 0:
        raise InvalidInputError(f"fps: expected a positive number, got {fps!r}")
    t_count, n = vel.shape[:2]
    speed = np.linalg.norm(vel, axis=2)
    target = np.arctan2(vel[..., 1], vel[..., 0])
    if initial is None:
        h = np.where(speed[0] >= min_speed, target[0], 0.0)
    else:
        h = np.broadcast_to(np.asarray(initial, dtype=np.float64), (n,)).copy()
    alpha = 1.0 - math.exp(-1.0 / (fps * time_constant))
    gain = alpha * np.clip((speed - min_speed) / max(walk_speed - min_speed, 1e-9), 0.0, 1.0)
    max_step = max_rate / fps
    out = np.empty((t_count, n))
    for t in range(t_count):
        turn = gain[t] * _wrap_angle(target[t] - h)
        h = _wrap_angle(h + np.clip(turn, -max_step, max_step))
        out[t] = h
    return out


def _separate(
    points: np.ndarray,
    min_dist: float,
    x0: float,
    length: float,
    y_lim: float,
    lanes: np.ndarray | None = None,
    max_iter: int = 2000,
) -> np.ndarray:
    """Push discs apart (minimum image along x) until all centres are ``min_dist`` apart
    and ``|y| <= y_lim``; with ``lanes`` (N,) = +-1, agent i also keeps to its own half
    (``lanes * y <= -min_dist / 2``: +1 below the centre line, -1 above it).
    ``points``: (N, 2) metres."""
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    lo = np.full(len(points), -y_lim)
    hi = np.full(len(points), y_lim)
    if lanes is not None:
        hi[lanes > 0] = -min_dist / 2
        lo[lanes < 0] = min_dist / 2
    pts = points.copy()
    pts[:, 1] = np.clip(pts[:, 1], lo, hi)
    for _ in range(max_iter):
        pts[:, 0] = x0 + np.mod(pts[:, 0] - x0, length)
        shifted = np.stack([np.mod(pts[:, 0] - x0, length), pts[:, 1] + 1e3], axis=1)
        shifted[shifted[:, 0] >= length, 0] = 0.0
        pairs = cKDTree(shifted, boxsize=(length, 4e3)).query_pairs(min_dist * (1 + 1e-6), output_type="ndarray")
        if len(pairs) == 0:
            return pts
        delta = pts[pairs[:, 1]] - pts[pairs[:, 0]]
        delta[:, 0] -= length * np.round(delta[:, 0] / length)
        d = np.linalg.norm(delta, axis=1)
        normal = delta / np.maximum(d, 1e-9)[:, None]
        push = 0.5 * (min_dist * (1 + 1e-3) - d)[:, None] * normal
        move = np.zeros_like(pts)
        np.add.at(move, pairs[:, 0], -push)
        np.add.at(move, pairs[:, 1], push)
        pts += move
        pts[:, 1] = np.clip(pts[:, 1], lo, hi)
    raise InvalidInputError(
        f"level: could not separate the discs (min distance {min_dist:.3g} m) in the corridor; "
        "the density is too high for the disc radius"
    )


def corridor_crowd(
    design,
    level: str,
    seed,
    *,
    duration: float | None = None,
    fps: float | None = None,
    direction: str | None = None,
    warm_up: float = 3.0,
    params: ORCAParams | None = None,
    device: str | None = "cpu",
    progress: bool = False,
    scenario: str = "corridor",
) -> Crowd:
    """Trajectories of the corridor crowd of one density level.

    Args:
        design: :class:`~crowdstudy.design.StudyDesign`.
        level: density level ("D1" .. "D5").
        seed: int (or numpy Generator): layout, preferred speeds.
        duration: seconds (default: the design's video duration).
        fps: frames per second of the output (default: the design's video fps).
        direction: "unidirectional" (+x) or "bidirectional" (default: the design's).
        warm_up: seconds simulated before frame 0.
        params: ORCA parameters (the time step is replaced by the sub-step).
        device: Warp device for the simulation.
        progress: show a progress bar (stderr).
        scenario: the design's scenario to walk (its name; default: the design's corridor).

    Returns:
        Crowd: positions (T, N, 2) unwrapped metres, velocities (T, N, 2) m/s, headings
        (T, N) radians, radius (N,) m, obstacles (2, 2, 2) the walls of the section,
        region (4, 2) the section, meta (see module doc) with ``periodic`` and the scene's
        static geometry: ``floor`` {width: length, depth: width} m (the section),
        ``corridor_width``, ``corridor_length`` (= the period) m, and ``obstacles`` the
        wall segments [[[x0, y0], [x1, y1]], ...] m exactly as ORCA saw them (the section's
        walls extended by one period on each side).
    """
    setup = _corridor_setup(
        design,
        level,
        seed,
        duration=duration,
        fps=fps,
        direction=direction,
        warm_up=warm_up,
        params=params,
        scenario=scenario,
    )
    n, fps, n_frames, substeps = setup.n, setup.fps, setup.n_frames, setup.substeps
    signs, pos, speeds = _initial_agents(setup)
    lane_y = -signs * setup.width / 4 if setup.direction == "bidirectional" else None
    preferred = functools.partial(_preferred_velocities, signs=signs, speeds=speeds, lane_y=lane_y)
    walls_section, walls_sim = _corridor_walls(setup.x0, setup.length, setup.half_w)
    sim = ORCASimulator(
        pos,
        setup.r_sim,
        speeds + 0.3,
        params=setup.orca,
        obstacles=walls_sim,
        periodic=(setup.x0, setup.length),
        device=device,
    )

    warm_frames = int(round(warm_up * fps))
    bar = None
    if progress:
        from crowdstudy.progress import progress_bar

        bar = progress_bar(total=warm_frames + n_frames, desc=f"corridor {level}", unit="frame", leave=False)
    for _ in range(warm_frames):
        sim.set_preferred_velocities(preferred(sim.positions))
        sim.step(substeps)
        if bar:
            bar.update(1)
    positions = np.empty((n_frames + 1, n, 2))
    positions[0] = sim.positions
    for t in range(n_frames):
        sim.set_preferred_velocities(preferred(positions[t]))
        sim.step(substeps)
        positions[t + 1] = sim.positions
        if bar:
            bar.update(1)
    if bar:
        bar.close()
    return _corridor_result(setup, positions, signs, speeds, walls_section, walls_sim)


@dataclasses.dataclass(frozen=True)
class _CorridorSetup:
    """The checked settings of one corridor crowd and what follows from them: ``n``
    agents of disc ``radius`` (m; ``r_sim`` as simulated) at ``density`` (1/m^2) in a
    ``length`` x ``width`` m section, ``n_frames`` frames at ``fps`` of ``substeps`` ORCA
    steps each, ``warm_up`` s before frame 0; preferred speeds about ``v_mean`` m/s (the
    design's ``v0`` times ``speed_factor``) with sd ``v_sd * speed_factor``; ``rng`` draws
    the layout and the speeds; ``seed_value`` the int seed (None for a Generator)."""

    level: str
    n: int
    density: float
    radius: float
    r_sim: float
    width: float
    length: float
    direction: str
    v0: float
    v_sd: float
    speed_factor: float
    v_mean: float
    fps: float
    n_frames: int
    substeps: int
    warm_up: float
    orca: ORCAParams
    rng: np.random.Generator
    seed_value: int | None

    @property
    def x0(self) -> float:
        """The section's -x end, m (it is centred on the origin)."""
        return -self.length / 2

    @property
    def half_w(self) -> float:
        """Half the corridor's width, m: the walls are at y = +-half_w."""
        return self.width / 2


def _corridor_setup(
    design,
    level: str,
    seed,
    *,
    duration: float | None,
    fps: float | None,
    direction: str | None,
    warm_up: float,
    params: ORCAParams | None,
    scenario: str = "corridor",
) -> _CorridorSetup:
    """The arguments of :func:`corridor_crowd` checked (InvalidInputError naming the
    argument) and resolved against the design's ``[scenarios.corridor]``."""
    if level not in design.densities:
        raise InvalidInputError(
            f"level: unknown density level {level!r}; expected one of {', '.join(design.densities)}"
        )
    sc = design.scenario_of(scenario)
    width, length = float(sc["width"]), float(sc["length"])
    v0, v_sd = float(sc["preferred_speed"]), float(sc["preferred_speed_sd"])
    direction = sc["direction"] if direction is None else direction
    if direction not in ("unidirectional", "bidirectional"):
        raise InvalidInputError(f"direction: expected 'unidirectional' or 'bidirectional', got {direction!r}")
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
    radius = disc_radius(density)
    substeps = max(1, int(math.ceil((1.0 / fps) / _MAX_SUBSTEP - 1e-9)))
    base = params or ORCAParams(
        neighbor_dist=min(1.5, 0.45 * length), max_neighbors=10, time_horizon=1.0, time_horizon_obst=0.5
    )
    factor = speed_factor(density)
    return _CorridorSetup(
        level=level,
        n=design.n_characters(level),
        density=density,
        radius=radius,
        r_sim=SAFETY_MARGIN * radius,
        width=width,
        length=length,
        direction=direction,
        v0=v0,
        v_sd=v_sd,
        speed_factor=factor,
        v_mean=v0 * factor,
        fps=fps,
        n_frames=max(1, int(round(duration * fps))),
        substeps=substeps,
        warm_up=warm_up,
        orca=dataclasses.replace(base, time_step=1.0 / (fps * substeps)),
        rng=rng,
        seed_value=seed_value,
    )


def _initial_agents(s: _CorridorSetup) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Walking directions (N,) +-1 along x, start positions (N, 2) m and preferred speeds
    (N,) m/s: a Poisson-disk set in the section (each direction in its own half when
    bidirectional, the +y half walking towards -x) separated until no two simulated discs
    overlap, then speeds ~ Normal(v_mean, v_sd * speed_factor) clipped to [0.5, 1.5] v_mean."""
    n, r_sim = s.n, s.r_sim
    layout = poisson_disk((s.length, s.width), n, seed=s.rng, margin=r_sim)
    signs = np.ones(n)
    if s.direction == "bidirectional":
        order = np.argsort(layout.points[:, 1], kind="stable")
        signs[order[n - n // 2 :]] = -1.0  # the +y half walks towards -x
    pos = _separate(
        layout.points,
        2 * r_sim,
        s.x0,
        s.length,
        s.half_w - r_sim * 1.001,
        lanes=signs if s.direction == "bidirectional" else None,
    )
    v_mean = s.v_mean
    speeds = np.clip(s.rng.normal(v_mean, s.v_sd * s.speed_factor, n), 0.5 * v_mean, 1.5 * v_mean)
    return signs, pos, speeds


def _preferred_velocities(
    current: np.ndarray, *, signs: np.ndarray, speeds: np.ndarray, lane_y: np.ndarray | None
) -> np.ndarray:
    """(N, 2) m/s preferred velocities at positions ``current`` (N, 2) m: ``speeds`` (N,)
    along ``signs`` (N,) +-x; with ``lane_y`` (N,) m, a gentle lateral pull towards that
    line (keep right), at most ``_LANE_CLIP`` of the speed."""
    vy = np.zeros(len(signs))
    if lane_y is not None:  # keep right: a gentle pull towards the own half's centre line
        vy = np.clip(_LANE_GAIN * (lane_y - current[:, 1]), -_LANE_CLIP * speeds, _LANE_CLIP * speeds)
    vx = signs * np.sqrt(np.maximum(speeds**2 - vy**2, 0.0))
    return np.stack([vx, vy], axis=1)


def _corridor_walls(x0: float, length: float, half_w: float) -> tuple[np.ndarray, np.ndarray]:
    """The walls (2, 2, 2) m of the section ``[x0, x0 + length]`` at y = +-half_w, and the
    same walls extended by one period on each side, as ORCA sees them."""
    walls_section = np.array([[[x0, -half_w], [x0 + length, -half_w]], [[x0, half_w], [x0 + length, half_w]]])
    walls_sim = walls_section.copy()
    walls_sim[:, 0, 0] -= length
    walls_sim[:, 1, 0] += length
    return walls_section, walls_sim


def _corridor_result(
    s: _CorridorSetup,
    positions: np.ndarray,
    signs: np.ndarray,
    speeds: np.ndarray,
    walls_section: np.ndarray,
    walls_sim: np.ndarray,
) -> Crowd:
    """The :class:`Crowd` of the simulated ``positions`` (T + 1, N, 2) m (frame -1 first):
    mean velocities over each frame, frame 0 shifted by whole periods into the section,
    smoothed headings and the meta of :func:`corridor_crowd`."""
    fps, length, width, x0, half_w = s.fps, s.length, s.width, s.x0, s.half_w
    velocities = np.diff(positions, axis=0) * fps  # mean velocity over each frame
    positions = positions[1:]
    # shift each agent by whole periods so frame 0 lies in the section (still unwrapped in time)
    positions[..., 0] -= length * np.floor((positions[0, :, 0] - x0) / length)[None]
    headings = smooth_headings(velocities, fps, initial=np.where(signs > 0, 0.0, np.pi))
    region = np.array([[x0, -half_w], [x0 + length, -half_w], [x0 + length, half_w], [x0, half_w]])
    meta = {
        "scenario": "corridor",
        "density_level": s.level,
        "density": s.density,
        "n_characters": s.n,
        "seed": s.seed_value,
        "width": width,
        "length": length,
        "direction": s.direction,
        "directions": signs.astype(int).tolist(),
        "radius": s.radius,
        "simulated_radius": s.r_sim,
        "preferred_speed": s.v_mean,
        "speed_factor": s.speed_factor,
        "preferred_speeds": speeds.tolist(),
        "warm_up": float(s.warm_up),
        "substeps": s.substeps,
        "orca": dataclasses.asdict(s.orca),
        "periodic": {"axis": 0, "length": length},
        # the scene's static geometry, read by later stages instead of a design
        "floor": {"width": length, "depth": width},
        "corridor_width": width,
        "corridor_length": length,
        "obstacles": walls_sim.tolist(),
        "provenance": provenance(s.seed_value, stage="navigation"),
    }
    return Crowd(
        positions=positions,
        radius=np.full(s.n, s.radius),
        fps=fps,
        velocities=velocities,
        headings=headings,
        obstacles=walls_section,
        region=region,
        meta=meta,
    )


def trajectory_summary(crowd: Crowd, tolerance: float = 0.01) -> dict:
    """Checks of a trajectory :class:`Crowd` against the navigation bars.

    Returns a dict: ``n_agents``, ``n_frames``, ``max_overlap`` (largest disc overlap depth
    over all frames and pairs, in units of the radius; minimum image when periodic; negative
    means a gap), ``overlapping_pairs`` (pair-frames overlapping by more than
    ``tolerance`` radius), ``wall_clearance`` (smallest distance from a disc's edge to a
    wall line ``y = const``, m; negative means crossing; None without walls),
    ``mean_speed`` (m/s), ``max_turn_rate`` (rad/s, from the headings).
    """
    pos = crowd.positions
    t_count, n = pos.shape[:2]
    length = crowd.periodic_length
    r = crowd.radius
    max_overlap, pairs = -math.inf, 0
    iu = np.triu_indices(n, k=1)
    for start in range(0, t_count, 64):
        chunk = pos[start : start + 64]
        rel = chunk[:, :, None, :] - chunk[:, None, :, :]
        if length:
            rel[..., 0] -= length * np.round(rel[..., 0] / length)
        dist = np.linalg.norm(rel, axis=-1)[:, iu[0], iu[1]]
        rsum = (r[:, None] + r[None, :])[iu]
        depth = (rsum - dist) / np.minimum(r[:, None], r[None, :])[iu]
        if depth.size:
            max_overlap = max(max_overlap, float(depth.max()))
            pairs += int(np.sum(depth > tolerance))
    clearance = None
    obst = crowd.obstacles
    if len(obst):
        horizontal = np.abs(obst[:, 0, 1] - obst[:, 1, 1]) < 1e-9
        if np.any(horizontal):
            ys = obst[horizontal, 0, 1]
            y = pos[..., 1]
            gaps = []
            for wy in ys:
                side = np.sign(np.median(y) - wy) or 1.0  # the side the crowd is on
                gaps.append(np.min(side * (y - wy) - r[None, :]))
            clearance = float(min(gaps))
    mean_speed = None if crowd.velocities is None else float(np.linalg.norm(crowd.velocities, axis=2).mean())
    turn = None
    if crowd.headings is not None and t_count > 1:
        dh = _wrap_angle(np.diff(crowd.headings, axis=0))
        turn = float(np.abs(dh).max() * crowd.fps)
    return {
        "n_agents": n,
        "n_frames": t_count,
        "max_overlap": max_overlap if n > 1 else None,
        "overlapping_pairs": pairs,
        "wall_clearance": clearance,
        "mean_speed": mean_speed,
        "max_turn_rate": turn,
    }

"""A closed-room scenario run identically through crowdstudy's ORCA and through pyrvo
(the RVO2 C++ library), for the side-by-side benchmark and the agreement tests.

N agents in a square room of side ``sqrt(N / density)`` bounded by four wall segments,
placed as a Poisson-disk set, each walking at its preferred speed towards a sequence of
random goals (a new goal when within 0.3 m of the current one). Both engines simulate discs
of ``radius * safety_margin``; overlaps are counted on ``radius``. The goal sequences, the
preferred speeds and the ORCA parameters are the same for both engines; each engine steers
from its own positions with the same rule.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from crowdstudy.errors import InvalidInputError, MissingDependencyError
from crowdstudy.layout.poisson import poisson_disk
from crowdstudy.navigation.orca import ORCAParams, ORCASimulator

__all__ = ["RoomScenario", "RoomRun", "run_room", "count_overlaps"]

_GOAL_RADIUS = 0.3


@dataclasses.dataclass(frozen=True)
class RoomScenario:
    """The room benchmark's set-up (metres, seconds)."""

    n_agents: int = 1000
    density: float = 1.5  # agents per m^2
    radius: float = 0.2
    preferred_speed: float = 1.2
    preferred_speed_sd: float = 0.1
    max_speed: float = 1.5
    safety_margin: float = 1.0  # simulated radius / disc radius (overlaps are counted on ``radius``)
    params: ORCAParams = ORCAParams()
    n_goals: int = 32
    seed: int = 0

    @property
    def simulated_radius(self) -> float:
        return self.radius * self.safety_margin

    @property
    def side(self) -> float:
        return math.sqrt(self.n_agents / self.density)

    def walls(self) -> np.ndarray:
        """(4, 2, 2) wall segments of the square room centred on the origin."""
        h = self.side / 2
        c = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
        return np.stack([c, np.roll(c, -1, axis=0)], axis=1)

    def initial_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """positions (N, 2) m, preferred speeds (N,) m/s, goals (N, G, 2) m."""
        if self.n_agents < 1:
            raise InvalidInputError(f"n_agents: expected >= 1, got {self.n_agents}")
        rng = np.random.default_rng(self.seed)
        layout = poisson_disk(
            (self.side, self.side),
            self.n_agents,
            seed=rng,
            margin=self.simulated_radius + 0.05,
            min_distance=2.1 * self.simulated_radius,
        )
        speeds = np.clip(
            rng.normal(self.preferred_speed, self.preferred_speed_sd, self.n_agents),
            0.5 * self.preferred_speed,
            self.max_speed,
        )
        h = self.side / 2 - self.simulated_radius - 0.2
        goals = rng.uniform(-h, h, size=(self.n_agents, self.n_goals, 2))
        return layout.points, speeds, goals


@dataclasses.dataclass
class RoomRun:
    """What one engine did: per-step times (s), mean speed (m/s), overlaps, final positions."""

    engine: str
    step_times: list[float]
    mean_speed: float
    overlaps: int  # pair-frames overlapping by more than 1 % of the radius
    max_overlap: float  # largest overlap depth / radius over the checked frames
    outside: int  # agent-frames outside the room
    positions: np.ndarray

    @property
    def ms_per_step(self) -> float:
        return 1000.0 * float(np.median(self.step_times))


def count_overlaps(points: np.ndarray, radius: float, tolerance: float = 0.01) -> tuple[int, float]:
    """Pairs of discs of ``radius`` overlapping by more than ``tolerance * radius`` and the
    largest overlap depth in units of the radius. ``points``: (N, 2) metres."""
    from scipy.spatial import cKDTree  # pyright: ignore[reportAttributeAccessIssue]  (compiled, not in the stubs)

    pairs = cKDTree(points).query_pairs(2 * radius, output_type="ndarray")
    if len(pairs) == 0:
        return 0, 0.0
    d = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    depth = (2 * radius - d) / radius
    return int(np.sum(depth > tolerance)), float(depth.max())


class _Steer:
    def __init__(self, goals: np.ndarray, speeds: np.ndarray):
        self.goals, self.speeds = goals, speeds
        self.current = np.zeros(len(speeds), dtype=np.int64)

    def __call__(self, pos: np.ndarray) -> np.ndarray:
        idx = np.arange(len(pos))
        d = self.goals[idx, self.current % self.goals.shape[1]] - pos
        dist = np.linalg.norm(d, axis=1)
        reached = dist < _GOAL_RADIUS
        if np.any(reached):
            self.current[reached] += 1
            d = self.goals[idx, self.current % self.goals.shape[1]] - pos
            dist = np.linalg.norm(d, axis=1)
        return d / np.maximum(dist, 1e-9)[:, None] * self.speeds[:, None]


_Engine = tuple[Callable[[np.ndarray], None], Callable[[], None], Callable[[], np.ndarray]]


def _crowdstudy_engine(scenario: RoomScenario, pos0: np.ndarray, walls, device: str | None) -> _Engine:
    """crowdstudy's ORCA as ``(set_pref, do_step, read)``: preferred velocities (N, 2) m/s in,
    positions (N, 2) m out."""
    sim = ORCASimulator(
        pos0, scenario.simulated_radius, scenario.max_speed, params=scenario.params, obstacles=walls, device=device
    )

    def set_pref(pref: np.ndarray) -> None:
        sim.set_preferred_velocities(pref)

    def do_step() -> None:
        sim.step()
        if sim.device != "cpu":
            sim.synchronize()

    def read() -> np.ndarray:
        return sim.positions

    return set_pref, do_step, read


def _pyrvo_engine(scenario: RoomScenario, pos0: np.ndarray, walls) -> _Engine:
    """pyrvo (RVO2) as ``(set_pref, do_step, read)``, same units and shapes as
    :func:`_crowdstudy_engine`."""
    try:
        import pyrvo
    except ImportError:
        raise MissingDependencyError("pyrvo is not installed: pip install 'crowdstudy[peers]' (or pyrvo)") from None
    p = scenario.params
    sim = pyrvo.RVOSimulator()  # pyright: ignore[reportAttributeAccessIssue]  # re-exported by a compiled module
    sim.set_time_step(float(p.time_step))
    sim.set_agent_defaults(
        float(p.neighbor_dist),
        int(p.max_neighbors),
        float(p.time_horizon),
        float(p.time_horizon_obst),
        float(scenario.simulated_radius),
        float(scenario.max_speed),
    )
    for q in pos0:
        sim.add_agent((float(q[0]), float(q[1])))
    for a, b in walls:
        sim.add_obstacle([(float(a[0]), float(a[1])), (float(b[0]), float(b[1]))])
    sim.process_obstacles()
    agents = range(scenario.n_agents)

    def set_pref(pref: np.ndarray) -> None:
        for i in agents:
            sim.set_agent_pref_velocity(i, (float(pref[i, 0]), float(pref[i, 1])))

    def read() -> np.ndarray:
        return np.array([sim.get_agent_position(i).to_tuple() for i in agents])

    return set_pref, sim.do_step, read


def run_room(
    scenario: RoomScenario,
    steps: int,
    *,
    engine: str = "crowdstudy",
    check_every: int = 10,
    device: str | None = "cpu",
    progress=None,
) -> RoomRun:
    """Run the room scenario for ``steps`` steps through ``engine`` ("crowdstudy" or "pyrvo").

    Only the engine's step is timed (for pyrvo ``do_step``; setting preferred velocities and
    reading positions through the Python binding are not counted).
    """
    pos0, speeds, goals = scenario.initial_state()
    steer = _Steer(goals, speeds)
    p = scenario.params
    walls = scenario.walls()
    if engine == "crowdstudy":
        set_pref, do_step, read = _crowdstudy_engine(scenario, pos0, walls, device)
    elif engine == "pyrvo":
        set_pref, do_step, read = _pyrvo_engine(scenario, pos0, walls)
    else:
        raise InvalidInputError(f"engine: expected 'crowdstudy' or 'pyrvo', got {engine!r}")

    pos = np.asarray(pos0, dtype=np.float64)
    times, speed_sum = [], 0.0
    overlaps, max_overlap, outside = 0, 0.0, 0
    half = scenario.side / 2
    for s in range(steps):
        set_pref(steer(pos))
        t0 = time.perf_counter()
        do_step()
        times.append(time.perf_counter() - t0)
        new = read()
        speed_sum += float(np.mean(np.linalg.norm(new - pos, axis=1))) / p.time_step
        pos = new
        if (s + 1) % check_every == 0 or s == steps - 1:
            c, m = count_overlaps(pos, scenario.radius)
            overlaps += c
            max_overlap = max(max_overlap, m)
            outside += int(np.sum(np.any(np.abs(pos) > half, axis=1)))
        if progress is not None:
            progress.update(1)
    return RoomRun(
        engine=engine,
        step_times=times,
        mean_speed=speed_sum / max(steps, 1),
        overlaps=overlaps,
        max_overlap=max_overlap,
        outside=outside,
        positions=pos,
    )

"""ORCA (optimal reciprocal collision avoidance) for disc agents and static wall segments.

:class:`ORCASimulator` runs the two-phase step of the RVO2 library on a Warp device (CPU:
compiled C++, CUDA: GPU), one thread per agent:

1. neighbour index: agents are binned in a uniform grid (cells at least
   ``neighbor_dist`` wide, radix-sorted by cell), so each agent scans 3 x 3 cells;
2. velocities: every agent computes its new velocity from a frozen snapshot of all
   positions and velocities (ORCA half-planes + 2D/3D linear programs, see
   :mod:`crowdstudy.navigation.orca_kernels`);
3. integration: ``v <- v_new``, ``p <- p + v dt`` for all agents at once.

Preferred velocities come from outside (a scenario sets them before each step).

Periodic domains: with ``periodic=(x0, L)`` the x axis wraps with period L. Neighbour
offsets use the minimum image; positions are stored *unwrapped* (they keep growing as the
agents walk), and the obstacles are given in the frame ``x0 <= x < x0 + L`` (walls that
should look endless must extend beyond that window by more than the obstacle range
``time_horizon_obst * max_speed + radius``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from crowdstudy.errors import InvalidInputError

__all__ = ["ORCAParams", "ORCASimulator", "segments_to_obstacle_vertices"]

_HOST_SORT_MAX = 2048  # on the CPU device, sort up to this many cell keys with numpy


@dataclasses.dataclass(frozen=True)
class ORCAParams:
    """Parameters shared by all agents (RVO2's agent defaults).

    Attributes:
        time_step: simulation step (s).
        neighbor_dist: agents farther than this (m, centre to centre) are ignored.
        max_neighbors: at most this many nearest agents are considered.
        time_horizon: look-ahead (s) against other agents.
        time_horizon_obst: look-ahead (s) against obstacles.
        max_obstacle_neighbors: at most this many nearest obstacle edges are considered.
    """

    time_step: float = 1.0 / 60.0
    neighbor_dist: float = 1.5
    max_neighbors: int = 10
    time_horizon: float = 1.0
    time_horizon_obst: float = 0.5
    max_obstacle_neighbors: int = 8

    def __post_init__(self) -> None:
        for name in ("time_step", "neighbor_dist", "time_horizon", "time_horizon_obst"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise InvalidInputError(f"ORCAParams.{name}: expected a positive finite number, got {value!r}")
        for name in ("max_neighbors", "max_obstacle_neighbors"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InvalidInputError(f"ORCAParams.{name}: expected a positive integer, got {value!r}")


def segments_to_obstacle_vertices(segments) -> dict[str, np.ndarray]:
    """RVO2's obstacle vertex lists for wall segments.

    Each segment (a, b) becomes a two-vertex obstacle, as RVO2 stores it: the directed edges
    a -> b and b -> a, each visible from its right side, both vertices convex.

    Args:
        segments: (M, 2, 2) float metres.

    Returns:
        dict with ``point`` (2M, 2) float32, ``next``/``prev`` (2M,) int32, ``direction``
        (2M, 2) float32 unit edge directions, ``convex`` (2M,) int32.
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
    if not np.all(np.isfinite(seg)):
        raise InvalidInputError("obstacles: segment end points must be finite")
    lengths = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    if np.any(lengths <= 1e-6):
        raise InvalidInputError(f"obstacles: segment {int(np.argmin(lengths))} has zero length")
    m = seg.shape[0]
    point = seg.reshape(2 * m, 2)
    idx = np.arange(2 * m)
    partner = idx ^ 1  # 2k <-> 2k + 1
    direction = point[partner] - point
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return {
        "point": point.astype(np.float32),
        "next": partner.astype(np.int32),
        "prev": partner.astype(np.int32),
        "direction": direction.astype(np.float32),
        "convex": np.ones(2 * m, dtype=np.int32),
    }


def _per_agent(value, n: int, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: expected a positive number or {n} positive numbers, got {value!r}") from None
    arr = np.full(n, float(arr)) if arr.ndim == 0 else arr
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise InvalidInputError(f"{name}: expected a positive number or {n} positive numbers, got shape {arr.shape}")
    return arr


class ORCASimulator:
    """ORCA crowd simulator (RVO2's algorithm) running as Warp kernels.

    Args:
        positions: (N, 2) float metres, initial agent centres.
        radius: float or (N,) metres, disc radii.
        max_speed: float or (N,) m/s, speed limit of each agent.
        params: :class:`ORCAParams`.
        obstacles: (M, 2, 2) float metres, static wall segments (or None).
        periodic: ``(x0, L)``: wrap x with period L (minimum image), or None.
        velocities: (N, 2) m/s initial velocities (default zero).
        device: Warp device, ``"cpu"`` (default, deterministic bytes), ``"cuda:0"``, or None
            / ``"auto"`` for CUDA when present.
    """

    def __init__(
        self,
        positions,
        radius,
        max_speed,
        *,
        params: ORCAParams | None = None,
        obstacles=None,
        periodic: tuple[float, float] | None = None,
        velocities=None,
        device: str | None = "cpu",
    ):
        from crowdstudy.warp_runtime import get_warp, resolve_device

        pos = np.asarray(positions, dtype=np.float64)
        if pos.ndim != 2 or pos.shape[1] != 2 or pos.shape[0] < 1:
            raise InvalidInputError(f"positions: expected shape (N, 2) with N >= 1, got {pos.shape}")
        if not np.all(np.isfinite(pos)):
            raise InvalidInputError("positions: expected finite values (found NaN or inf)")
        n = pos.shape[0]
        self.params = params or ORCAParams()
        if not isinstance(self.params, ORCAParams):
            raise InvalidInputError(f"params: expected ORCAParams, got {type(self.params).__name__}")
        self.radius = _per_agent(radius, n, "radius")
        self.max_speed = _per_agent(max_speed, n, "max_speed")
        self.periodic = None
        if periodic is not None:
            try:
                x0, length = (float(v) for v in periodic)
            except (TypeError, ValueError):
                raise InvalidInputError(f"periodic: expected (x0, length), got {periodic!r}") from None
            if not (math.isfinite(x0) and math.isfinite(length) and length > 0):
                raise InvalidInputError(f"periodic: expected a finite x0 and a positive length, got {periodic!r}")
            if self.params.neighbor_dist >= length / 2:
                raise InvalidInputError(
                    f"params.neighbor_dist: {self.params.neighbor_dist} m must be below half the "
                    f"period ({length / 2} m) for minimum-image neighbours"
                )
            self.periodic = (x0, length)
        vel = np.zeros_like(pos) if velocities is None else np.asarray(velocities, dtype=np.float64)
        if vel.shape != pos.shape or not np.all(np.isfinite(vel)):
            raise InvalidInputError(f"velocities: expected finite values of shape {pos.shape}, got {vel.shape}")
        self.n = n
        self.device = resolve_device(device)
        from crowdstudy.navigation import orca_kernels

        wp = get_warp()
        self._wp = wp
        dev = self.device
        wp.load_module(orca_kernels, device=dev)  # compile (or load from the cache) before the first step
        f32 = np.float32
        self._pos = wp.array(pos.astype(f32), dtype=wp.vec2, device=dev)
        self._vel = wp.array(vel.astype(f32), dtype=wp.vec2, device=dev)
        self._new_vel = wp.zeros(n, dtype=wp.vec2, device=dev)
        self._pref = wp.zeros(n, dtype=wp.vec2, device=dev)
        self._radius = wp.array(self.radius.astype(f32), dtype=float, device=dev)
        self._max_speed = wp.array(self.max_speed.astype(f32), dtype=float, device=dev)
        self._keys = wp.zeros(2 * n, dtype=int, device=dev)
        self._ids = wp.zeros(2 * n, dtype=int, device=dev)
        k = self.params.max_neighbors
        mo = self.params.max_obstacle_neighbors
        self._nb_idx = wp.zeros((n, k), dtype=int, device=dev)
        self._nb_d2 = wp.zeros((n, k), dtype=float, device=dev)
        self._ob_idx = wp.zeros((n, mo), dtype=int, device=dev)
        self._ob_d2 = wp.zeros((n, mo), dtype=float, device=dev)
        self._lp = wp.zeros((n, k + mo), dtype=wp.vec2, device=dev)
        self._ld = wp.zeros((n, k + mo), dtype=wp.vec2, device=dev)
        self._pp = wp.zeros((n, k + mo), dtype=wp.vec2, device=dev)
        self._pd = wp.zeros((n, k + mo), dtype=wp.vec2, device=dev)
        self._cell_start = wp.zeros(1, dtype=int, device=dev)
        self._cell_end = wp.zeros(1, dtype=int, device=dev)
        self._cmd_keys = None  # recorded launches, see _record_launches
        segs = np.zeros((0, 2, 2)) if obstacles is None else np.asarray(obstacles, dtype=np.float64)
        if segs.size and (segs.ndim != 3 or segs.shape[1:] != (2, 2)):
            raise InvalidInputError(f"obstacles: expected (M, 2, 2) wall segments, got shape {segs.shape}")
        self.obstacles = segs.reshape(-1, 2, 2)
        verts = segments_to_obstacle_vertices(self.obstacles) if len(self.obstacles) else None
        self._n_obs = 0 if verts is None else len(verts["point"])
        if verts is None:  # one dummy vertex keeps the kernel signature; n_obs = 0 skips it
            verts = {
                "point": np.zeros((1, 2), f32),
                "next": np.zeros(1, np.int32),
                "prev": np.zeros(1, np.int32),
                "direction": np.zeros((1, 2), f32),
                "convex": np.zeros(1, np.int32),
            }
        self._obs_point = wp.array(verts["point"], dtype=wp.vec2, device=dev)
        self._obs_next = wp.array(verts["next"], dtype=int, device=dev)
        self._obs_prev = wp.array(verts["prev"], dtype=int, device=dev)
        self._obs_dir = wp.array(verts["direction"], dtype=wp.vec2, device=dev)
        self._obs_convex = wp.array(verts["convex"], dtype=int, device=dev)
        self.time = 0.0

    # -- state ------------------------------------------------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """(N, 2) float64 metres (unwrapped in periodic domains), a copy."""
        return self._pos.numpy().astype(np.float64)

    @property
    def velocities(self) -> np.ndarray:
        """(N, 2) float64 m/s, the velocities of the last step, a copy."""
        return self._vel.numpy().astype(np.float64)

    def set_preferred_velocities(self, pref) -> None:
        """Set the (N, 2) m/s velocities the agents would take without neighbours."""
        arr = np.asarray(pref, dtype=np.float32)
        if arr.shape != (self.n, 2) or not np.all(np.isfinite(arr)):
            raise InvalidInputError(f"pref: expected finite values of shape ({self.n}, 2), got {arr.shape}")
        self._pref.assign(arr)

    # -- the step ---------------------------------------------------------------------------
    def _grid(self):
        """Grid geometry for the current positions: origin, inverse cell size, nx, ny."""
        nd = self.params.neighbor_dist
        pos = self._pos.numpy()
        if self.periodic is not None:
            x0, length = self.periodic
            nx = max(1, int(length // nd))
            lo_x, width_x = x0, length / nx
        else:  # bounds snapped to multiples of nd so the grid changes only now and then
            lo_x, hi_x = nd * math.floor(float(pos[:, 0].min()) / nd), float(pos[:, 0].max())
            nx = max(1, int((hi_x - lo_x) // nd) + 1)
            width_x = nd
        lo_y, hi_y = nd * math.floor(float(pos[:, 1].min()) / nd), float(pos[:, 1].max())
        ny = max(1, int((hi_y - lo_y) // nd) + 1)
        width_y = nd
        # Keep the table small when agents are sparse: larger cells stay correct (3x3 scan).
        while nx * ny > 4 * self.n + 16:
            if self.periodic is not None:
                nx = max(1, nx // 2)
                width_x = self.periodic[1] / nx
            else:
                width_x *= 2.0
                nx = int((hi_x - lo_x) // width_x) + 1
            width_y *= 2.0
            ny = int((hi_y - lo_y) // width_y) + 1
        return (lo_x, lo_y), (1.0 / width_x, 1.0 / width_y), nx, ny

    def _record_launches(self, origin_v, inv_v, nx: int, ny: int) -> None:
        """Record the three kernel launches once; later steps only update the grid values
        (replaying a recorded launch skips Warp's per-call argument packing)."""
        from crowdstudy.navigation import orca_kernels as k

        wp, p, dev = self._wp, self.params, self.device
        x0, length = self.periodic if self.periodic is not None else (0.0, 1.0)
        periodic = 0 if self.periodic is None else 1
        self._cmd_keys = wp.launch(
            k.cell_keys,
            dim=self.n,
            device=dev,
            record_cmd=True,
            inputs=[self._pos, origin_v, inv_v, nx, ny, periodic, x0, length, self._keys, self._ids],
        )
        self._cmd_ranges = wp.launch(
            k.cell_ranges,
            dim=self.n,
            device=dev,
            record_cmd=True,
            inputs=[self._keys, self.n, self._cell_start, self._cell_end],
        )
        self._cmd_velocities = wp.launch(
            k.compute_velocities,
            dim=self.n,
            device=dev,
            record_cmd=True,
            inputs=[
                self._pos,
                self._vel,
                self._pref,
                self._radius,
                self._max_speed,
                self._ids,
                self._cell_start,
                self._cell_end,
                origin_v,
                inv_v,
                nx,
                ny,
                periodic,
                x0,
                length,
                float(p.neighbor_dist),
                int(p.max_neighbors),
                float(p.time_horizon),
                float(p.time_horizon_obst),
                float(p.time_step),
                self._obs_point,
                self._obs_next,
                self._obs_prev,
                self._obs_dir,
                self._obs_convex,
                self._n_obs,
                int(p.max_obstacle_neighbors),
                self._nb_idx,
                self._nb_d2,
                self._ob_idx,
                self._ob_d2,
                self._lp,
                self._ld,
                self._pp,
                self._pd,
                self._new_vel,
            ],
        )
        self._cmd_integrate = wp.launch(
            k.integrate,
            dim=self.n,
            device=dev,
            record_cmd=True,
            inputs=[self._pos, self._vel, self._new_vel, float(p.time_step)],
        )
        self._recorded_grid = (origin_v, inv_v, nx, ny)

    def step(self, n_steps: int = 1) -> None:
        """Advance ``n_steps`` time steps with the current preferred velocities.

        Each step: (1) neighbour index (cell keys, radix sort, cell ranges), (2) all new
        velocities from the frozen positions and velocities, (3) integration.
        """
        wp, dev = self._wp, self.device
        for _ in range(int(n_steps)):
            origin, inv_cell, nx, ny = self._grid()
            ncell = nx * ny
            origin_v, inv_v = wp.vec2(*origin), wp.vec2(*inv_cell)
            if self._cell_start.shape[0] < ncell:
                self._cell_start = wp.zeros(max(ncell, 2 * self._cell_start.shape[0]), dtype=int, device=dev)
                self._cell_end = wp.zeros(self._cell_start.shape[0], dtype=int, device=dev)
                self._cmd_keys = None
            else:
                self._cell_start.zero_()
                self._cell_end.zero_()
            if self._cmd_keys is None:
                self._record_launches(origin_v, inv_v, nx, ny)
            elif self._recorded_grid != (origin_v, inv_v, nx, ny):
                for cmd in (self._cmd_keys, self._cmd_velocities):
                    cmd.set_param_by_name("origin", origin_v)
                    cmd.set_param_by_name("inv_cell", inv_v)
                    cmd.set_param_by_name("nx", nx)
                    cmd.set_param_by_name("ny", ny)
                self._recorded_grid = (origin_v, inv_v, nx, ny)
            self._cmd_keys.launch()  # pyright: ignore[reportOptionalMemberAccess]  (recorded: never None)
            if self.device == "cpu" and self.n <= _HOST_SORT_MAX:  # cheaper than a launch for small crowds
                keys = self._keys.numpy()[: self.n]
                order = np.argsort(keys, kind="stable")
                self._ids.numpy()[: self.n] = order
                keys[:] = keys[order]
            else:
                wp.utils.radix_sort_pairs(self._keys, self._ids, self.n)
            self._cmd_ranges.launch()
            self._cmd_velocities.launch()
            self._cmd_integrate.launch()
            self.time += self.params.time_step

    def synchronize(self) -> None:
        """Wait for queued device work (for timing on CUDA)."""
        self._wp.synchronize_device(self.device)

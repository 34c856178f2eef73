"""Warp kernels of the ORCA simulator.

:class:`~crowdstudy.navigation.orca.ORCASimulator` imports this module inside its methods,
so ``import crowdstudy.navigation`` does not load Warp; importing it configures Warp
(:func:`~crowdstudy.warp_runtime.get_warp`) before anything here can compile. Positions in
m, velocities in m/s, times in s, in the floor plane (x, y).

One thread per agent. The velocity kernel follows the RVO2 library's algorithm (van den
Berg, Guy, Snape, Lin, Manocha: "Reciprocal n-body collision avoidance", 2011): ORCA
half-planes of the static obstacle edges (with RVO2's convex-vertex, leg and cut-off
rules), then of the nearest agent neighbours, then the 2D linear program over the max-speed
disc; when it is infeasible, the 3D linear program that keeps the obstacle half-planes hard
and minimises the largest violation of the agent half-planes. Single-precision like RVO2.

Per-thread variable-length lists (neighbours, ORCA lines, projected lines) live in rows of
2D scratch arrays ``[agent, slot]`` so the same code runs on CPU and CUDA devices. An ORCA
line is a point ``lp`` (m/s) and a unit direction ``ld``; the permitted velocities lie to
its left.
"""

# pyright: reportInvalidTypeForm=false
# (Warp's parameter types, wp.array(dtype=...), are calls that a type checker rejects as types)
# pyright: reportOperatorIssue=false, reportArgumentType=false, reportCallIssue=false
# (inside a kernel, Warp's stubs type wp.tid() as int or a tuple, and overload wp.length, wp.dot
# and wp.normalize for quaternions only; Warp's code generator checks these bodies when it compiles)

from __future__ import annotations

import warp as wp

from crowdstudy.warp_runtime import get_warp

__all__ = ["cell_keys", "cell_ranges", "integrate", "compute_velocities"]

get_warp()  # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})  # forward only: halves the compile time

EPSILON = wp.constant(1.0e-5)  # RVO_EPSILON
BIG = wp.constant(1.0e30)


@wp.func
def det2(a: wp.vec2, b: wp.vec2):
    """The 2D cross product a x b (> 0 when b lies to the left of a)."""
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def wrap_coord(x: float, x0: float, length: float):
    """``x`` (m) wrapped into the periodic range [x0, x0 + length)."""
    s = (x - x0) / length
    return x - length * wp.floor(s)


@wp.func
def grid_cell(p: wp.vec2, origin: wp.vec2, inv_cell: wp.vec2, nx: int, ny: int):
    """The (ix, iy) cell of the nx x ny grid (lower corner ``origin`` m, ``inv_cell`` the
    inverse cell sizes, 1/m) that holds ``p`` (m), clamped to the grid."""
    ix = int(wp.floor((p[0] - origin[0]) * inv_cell[0]))
    iy = int(wp.floor((p[1] - origin[1]) * inv_cell[1]))
    ix = wp.clamp(ix, 0, nx - 1)
    iy = wp.clamp(iy, 0, ny - 1)
    return ix, iy


@wp.kernel
def cell_keys(
    pos: wp.array(dtype=wp.vec2),
    origin: wp.vec2,
    inv_cell: wp.vec2,
    nx: int,
    ny: int,
    periodic: int,
    x0: float,
    length: float,
    keys: wp.array(dtype=int),
    values: wp.array(dtype=int),
):
    """The grid cell of agent i (thread) as its sort key (``iy * nx + ix``) and i as its
    value (wrapped into the periodic range first when ``periodic``)."""
    i = wp.tid()
    p = pos[i]
    if periodic != 0:
        p = wp.vec2(wrap_coord(p[0], x0, length), p[1])
    ix, iy = grid_cell(p, origin, inv_cell, nx, ny)
    keys[i] = iy * nx + ix
    values[i] = i


@wp.kernel
def cell_ranges(keys: wp.array(dtype=int), n: int, cell_start: wp.array(dtype=int), cell_end: wp.array(dtype=int)):
    """From the ``n`` sorted keys, each cell's slice [cell_start, cell_end) of the sorted
    agents (cells without agents keep their zeroed range)."""
    i = wp.tid()
    k = keys[i]
    if i == 0:
        cell_start[k] = i
    elif keys[i - 1] != k:
        cell_start[k] = i
    if i == n - 1:
        cell_end[k] = i + 1
    elif keys[i + 1] != k:
        cell_end[k] = i + 1


@wp.kernel
def integrate(pos: wp.array(dtype=wp.vec2), vel: wp.array(dtype=wp.vec2), new_vel: wp.array(dtype=wp.vec2), dt: float):
    """Explicit Euler step of agent i (thread): v <- new_vel (m/s), p <- p + v dt (m, s)."""
    i = wp.tid()
    v = new_vel[i]
    vel[i] = v
    pos[i] = pos[i] + v * dt


# --- linear programs (RVO2's linearProgram1/2/3) -------------------------------------------


@wp.func
def lp1(
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
    row: int,
    line_no: int,
    radius: float,
    opt: wp.vec2,
    direction_opt: int,
    result: wp.vec2,
):
    """Optimum on line ``line_no`` subject to lines [0, line_no) and the speed disc."""
    p = lp[row, line_no]
    d = ld[row, line_no]
    dot_pd = wp.dot(p, d)
    disc = dot_pd * dot_pd + radius * radius - wp.dot(p, p)
    if disc < 0.0:
        return result, 0
    sq = wp.sqrt(disc)
    t_left = -dot_pd - sq
    t_right = -dot_pd + sq
    for k in range(line_no):
        dk = ld[row, k]
        denom = det2(d, dk)
        numer = det2(dk, p - lp[row, k])
        if wp.abs(denom) <= EPSILON:
            if numer < 0.0:
                return result, 0
            continue
        t = numer / denom
        if denom >= 0.0:
            t_right = wp.min(t_right, t)
        else:
            t_left = wp.max(t_left, t)
        if t_left > t_right:
            return result, 0
    if direction_opt != 0:
        if wp.dot(opt, d) > 0.0:
            return p + t_right * d, 1
        return p + t_left * d, 1
    t = wp.dot(d, opt - p)
    if t < t_left:
        return p + t_left * d, 1
    if t > t_right:
        return p + t_right * d, 1
    return p + t * d, 1


@wp.func
def lp2(
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
    row: int,
    n_lines: int,
    radius: float,
    opt: wp.vec2,
    direction_opt: int,
):
    """Closest feasible point to ``opt`` (or furthest along it); returns (result, first failing line or n_lines)."""
    result = opt
    if direction_opt != 0:
        result = opt * radius
    elif wp.dot(opt, opt) > radius * radius:
        result = wp.normalize(opt) * radius
    for k in range(n_lines):
        if det2(ld[row, k], lp[row, k] - result) > 0.0:
            previous = result
            candidate, ok = lp1(lp, ld, row, k, radius, opt, direction_opt, result)
            if ok == 0:
                return previous, k
            result = candidate
    return result, n_lines


@wp.func
def lp3(
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
    pp: wp.array2d(dtype=wp.vec2),
    pd: wp.array2d(dtype=wp.vec2),
    row: int,
    n_lines: int,
    n_obst: int,
    begin: int,
    radius: float,
    start: wp.vec2,
):
    """Minimise the largest violation of the agent lines, obstacle lines kept hard."""
    result = start
    distance = float(0.0)
    for i in range(begin, n_lines):
        di = ld[row, i]
        pi = lp[row, i]
        if det2(di, pi - result) > distance:
            for k in range(n_obst):
                pp[row, k] = lp[row, k]
                pd[row, k] = ld[row, k]
            m = n_obst
            for j in range(n_obst, i):
                dj = ld[row, j]
                pj = lp[row, j]
                determinant = det2(di, dj)
                point = pi
                if wp.abs(determinant) <= EPSILON:
                    if wp.dot(di, dj) > 0.0:
                        continue
                    point = 0.5 * (pi + pj)
                else:
                    point = pi + (det2(dj, pi - pj) / determinant) * di
                pp[row, m] = point
                pd[row, m] = wp.normalize(dj - di)
                m = m + 1
            candidate, fail = lp2(pp, pd, row, m, radius, wp.vec2(-di[1], di[0]), 1)
            if fail >= m:
                result = candidate
            distance = det2(di, pi - result)
    return result


# --- the velocity kernel -------------------------------------------------------------------


@wp.func
def leg_left(rel: wp.vec2, leg: float, r: float, dist_sq: float):
    """Direction of the left leg of the velocity obstacle of a disc of radius ``r`` (m) at
    ``rel`` (m), |rel|^2 = ``dist_sq``, ``leg`` = sqrt(dist_sq - r^2)."""
    return wp.vec2(rel[0] * leg - rel[1] * r, rel[0] * r + rel[1] * leg) / dist_sq


@wp.func
def leg_right(rel: wp.vec2, leg: float, r: float, dist_sq: float):
    """Direction of the right leg (see ``leg_left``)."""
    return wp.vec2(rel[0] * leg + rel[1] * r, -rel[0] * r + rel[1] * leg) / dist_sq


@wp.func
def obstacle_neighbours(
    i: int,
    pw: wp.vec2,
    r: float,
    vmax: float,
    time_horizon_obst: float,
    obs_point: wp.array(dtype=wp.vec2),
    obs_next: wp.array(dtype=int),
    n_obs: int,
    max_obst_neighbors: int,
    ob_idx: wp.array2d(dtype=int),
    ob_d2: wp.array2d(dtype=float),
):
    """The obstacle edges agent ``i`` (at ``pw``, the periodic frame) may reach within
    ``time_horizon_obst``: directed edges seen from their right side, the nearest
    ``max_obst_neighbors`` into row i of ``ob_idx`` / ``ob_d2`` (squared distance, m^2),
    nearest first. Returns their count."""
    n_ob = int(0)
    obst_range = time_horizon_obst * vmax + r
    obst_range_sq = obst_range * obst_range
    for e in range(n_obs):
        a = obs_point[e]
        b = obs_point[obs_next[e]]
        if det2(a - pw, b - a) < 0.0:
            ab = b - a
            s = wp.dot(pw - a, ab) / wp.dot(ab, ab)
            d2 = float(0.0)
            if s < 0.0:
                d2 = wp.length_sq(pw - a)
            elif s > 1.0:
                d2 = wp.length_sq(pw - b)
            else:
                d2 = wp.length_sq(pw - (a + s * ab))
            if d2 < obst_range_sq:
                slot = n_ob
                if n_ob < max_obst_neighbors:
                    n_ob = n_ob + 1
                else:
                    slot = max_obst_neighbors - 1
                    if d2 >= ob_d2[i, slot]:
                        continue
                while slot > 0:
                    if d2 >= ob_d2[i, slot - 1]:
                        break
                    ob_d2[i, slot] = ob_d2[i, slot - 1]
                    ob_idx[i, slot] = ob_idx[i, slot - 1]
                    slot = slot - 1
                ob_d2[i, slot] = d2
                ob_idx[i, slot] = e
    return n_ob


@wp.func
def agent_neighbours(
    i: int,
    p: wp.vec2,
    pw: wp.vec2,
    pos: wp.array(dtype=wp.vec2),
    sorted_ids: wp.array(dtype=int),
    cell_start: wp.array(dtype=int),
    cell_end: wp.array(dtype=int),
    origin: wp.vec2,
    inv_cell: wp.vec2,
    nx: int,
    ny: int,
    periodic: int,
    length: float,
    neighbor_dist: float,
    max_neighbors: int,
    nb_idx: wp.array2d(dtype=int),
    nb_d2: wp.array2d(dtype=float),
):
    """The ``max_neighbors`` agents nearest to agent ``i`` within ``neighbor_dist`` (m),
    from the grid cells around it (minimum image along x when ``periodic``), into row i of
    ``nb_idx`` / ``nb_d2``, nearest first; the search range shrinks to the farthest kept
    once the list is full (RVO2's rule). Returns their count."""
    n_nb = int(0)
    range_sq = neighbor_dist * neighbor_dist
    cx, cy = grid_cell(pw, origin, inv_cell, nx, ny)
    y_lo = wp.max(cy - 1, 0)
    y_hi = wp.min(cy + 1, ny - 1)
    x_lo = cx - 1
    x_hi = cx + 1
    if periodic != 0:
        if nx < 3:
            x_lo = 0
            x_hi = nx - 1
    else:
        x_lo = wp.max(x_lo, 0)
        x_hi = wp.min(x_hi, nx - 1)
    for gy in range(y_lo, y_hi + 1):
        for gx in range(x_lo, x_hi + 1):
            ix = gx
            if periodic != 0:
                ix = (gx + nx) % nx
            c = gy * nx + ix
            for k in range(cell_start[c], cell_end[c]):
                j = sorted_ids[k]
                if j == i:
                    continue
                rel = pos[j] - p
                if periodic != 0:
                    rel = wp.vec2(rel[0] - length * wp.round(rel[0] / length), rel[1])
                d2 = wp.length_sq(rel)
                if d2 < range_sq:
                    slot = n_nb
                    if n_nb < max_neighbors:
                        n_nb = n_nb + 1
                    else:
                        slot = max_neighbors - 1
                    while slot > 0:
                        if d2 >= nb_d2[i, slot - 1]:
                            break
                        nb_d2[i, slot] = nb_d2[i, slot - 1]
                        nb_idx[i, slot] = nb_idx[i, slot - 1]
                        slot = slot - 1
                    nb_d2[i, slot] = d2
                    nb_idx[i, slot] = j
                    if n_nb == max_neighbors:
                        range_sq = nb_d2[i, max_neighbors - 1]
    return n_nb


@wp.func
def already_covered(
    i: int,
    n_lines: int,
    rel1: wp.vec2,
    rel2: wp.vec2,
    inv_tho: float,
    r: float,
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
):
    """1 when both ends of an obstacle edge (``rel1``, ``rel2``: relative to the agent, m)
    lie beyond one of the agent's first ``n_lines`` ORCA lines: the edge adds nothing."""
    for m in range(n_lines):
        if det2(inv_tho * rel1 - lp[i, m], ld[i, m]) - inv_tho * r >= -EPSILON:
            if det2(inv_tho * rel2 - lp[i, m], ld[i, m]) - inv_tho * r >= -EPSILON:
                return 1
    return 0


@wp.func
def collision_line(
    o1: int,
    o2: int,
    rel1: wp.vec2,
    rel2: wp.vec2,
    s: float,
    dist_sq1: float,
    dist_sq2: float,
    dist_sq_line: float,
    radius_sq: float,
    obs_dir: wp.array(dtype=wp.vec2),
    obs_convex: wp.array(dtype=int),
):
    """An agent already colliding with the edge o1 -> o2 (s: its foot point's parameter on
    the edge, squared distances in m^2): (1, direction) when the collision adds the line
    through the origin along ``direction``, (2, _) when it adds none, (0, _) when there is
    no collision."""
    if s < 0.0 and dist_sq1 <= radius_sq:
        if obs_convex[o1] != 0:  # collision with the left vertex
            return 1, wp.normalize(wp.vec2(-rel1[1], rel1[0]))
        return 2, wp.vec2(0.0, 0.0)
    if s > 1.0 and dist_sq2 <= radius_sq:
        if obs_convex[o2] != 0 and det2(rel2, obs_dir[o2]) >= 0.0:  # collision with the right vertex
            return 1, wp.normalize(wp.vec2(-rel2[1], rel2[0]))
        return 2, wp.vec2(0.0, 0.0)
    if s >= 0.0 and s < 1.0 and dist_sq_line <= radius_sq:  # collision with the edge
        return 1, -obs_dir[o1]
    return 0, wp.vec2(0.0, 0.0)


@wp.func
def obstacle_legs(
    o1: int,
    o2: int,
    rel1: wp.vec2,
    rel2: wp.vec2,
    s: float,
    dist_sq1: float,
    dist_sq2: float,
    dist_sq_line: float,
    r: float,
    radius_sq: float,
    obs_dir: wp.array(dtype=wp.vec2),
    obs_convex: wp.array(dtype=int),
):
    """The legs of the truncated velocity obstacle of the edge o1 -> o2 when the agent does
    not collide with it. Seen obliquely, one vertex defines both legs and becomes both
    ends (o1 = o2). Returns (ok, o1, o2, left_leg, right_leg); ok = 0 when that vertex is
    not convex (the edge adds no line)."""
    left_leg = wp.vec2(0.0, 0.0)
    right_leg = wp.vec2(0.0, 0.0)
    if s < 0.0 and dist_sq_line <= radius_sq:  # seen obliquely: the left vertex defines it
        if obs_convex[o1] == 0:
            return 0, o1, o2, left_leg, right_leg
        leg1 = wp.sqrt(dist_sq1 - radius_sq)
        left_leg = leg_left(rel1, leg1, r, dist_sq1)
        right_leg = leg_right(rel1, leg1, r, dist_sq1)
        return 1, o1, o1, left_leg, right_leg
    if s > 1.0 and dist_sq_line <= radius_sq:  # seen obliquely: the right vertex defines it
        if obs_convex[o2] == 0:
            return 0, o1, o2, left_leg, right_leg
        leg2 = wp.sqrt(dist_sq2 - radius_sq)
        left_leg = leg_left(rel2, leg2, r, dist_sq2)
        right_leg = leg_right(rel2, leg2, r, dist_sq2)
        return 1, o2, o2, left_leg, right_leg
    if obs_convex[o1] != 0:
        left_leg = leg_left(rel1, wp.sqrt(dist_sq1 - radius_sq), r, dist_sq1)
    else:
        left_leg = -obs_dir[o1]
    if obs_convex[o2] != 0:
        right_leg = leg_right(rel2, wp.sqrt(dist_sq2 - radius_sq), r, dist_sq2)
    else:
        right_leg = obs_dir[o1]
    return 1, o1, o2, left_leg, right_leg


@wp.func
def obstacle_vo_line(
    v: wp.vec2,
    o1: int,
    o2: int,
    rel1: wp.vec2,
    rel2: wp.vec2,
    left_leg: wp.vec2,
    right_leg: wp.vec2,
    r: float,
    inv_tho: float,
    obs_prev: wp.array(dtype=int),
    obs_dir: wp.array(dtype=wp.vec2),
    obs_convex: wp.array(dtype=int),
):
    """The ORCA line of the truncated velocity obstacle of an edge (ends o1, o2 relative to
    the agent at ``rel1``, ``rel2``, m; legs from ``obstacle_legs``): the velocity ``v``
    (m/s) is projected on the nearest of the cut-off circles, the cut-off line and the
    legs. A leg that points into the neighbouring edge is that edge's ("foreign") and
    gives no line. Returns (emit, point, direction)."""
    left_neighbor = obs_prev[o1]
    left_foreign = int(0)
    right_foreign = int(0)
    ll = left_leg
    rl = right_leg
    if obs_convex[o1] != 0 and det2(ll, -obs_dir[left_neighbor]) >= 0.0:
        ll = -obs_dir[left_neighbor]
        left_foreign = 1
    if obs_convex[o2] != 0 and det2(rl, obs_dir[o2]) <= 0.0:
        rl = obs_dir[o2]
        right_foreign = 1
    left_cut = inv_tho * rel1
    right_cut = inv_tho * rel2
    cut_vec = right_cut - left_cut
    same = int(0)
    if o1 == o2:
        same = 1
    t = float(0.5)
    if same == 0:
        t = wp.dot(v - left_cut, cut_vec) / wp.length_sq(cut_vec)
    t_left = wp.dot(v - left_cut, ll)
    t_right = wp.dot(v - right_cut, rl)
    if (t < 0.0 and t_left < 0.0) or (same != 0 and t_left < 0.0 and t_right < 0.0):
        unit_w = wp.normalize(v - left_cut)  # project on the left cut-off circle
        return 1, left_cut + r * inv_tho * unit_w, wp.vec2(unit_w[1], -unit_w[0])
    if t > 1.0 and t_right < 0.0:
        unit_w = wp.normalize(v - right_cut)  # project on the right cut-off circle
        return 1, right_cut + r * inv_tho * unit_w, wp.vec2(unit_w[1], -unit_w[0])
    d_cut = BIG
    if t >= 0.0 and t <= 1.0 and same == 0:
        d_cut = wp.length_sq(v - (left_cut + t * cut_vec))
    d_left = BIG
    if t_left >= 0.0:
        d_left = wp.length_sq(v - (left_cut + t_left * ll))
    d_right = BIG
    if t_right >= 0.0:
        d_right = wp.length_sq(v - (right_cut + t_right * rl))
    if d_cut <= d_left and d_cut <= d_right:  # project on the cut-off line
        direction = -obs_dir[o1]
        return 1, left_cut + r * inv_tho * wp.vec2(-direction[1], direction[0]), direction
    if d_left <= d_right:  # project on the left leg
        if left_foreign == 0:
            return 1, left_cut + r * inv_tho * wp.vec2(-ll[1], ll[0]), ll
        return 0, wp.vec2(0.0, 0.0), wp.vec2(0.0, 0.0)
    if right_foreign == 0:  # project on the right leg
        direction = -rl
        return 1, right_cut + r * inv_tho * wp.vec2(-direction[1], direction[0]), direction
    return 0, wp.vec2(0.0, 0.0), wp.vec2(0.0, 0.0)


@wp.func
def obstacle_lines(
    i: int,
    pw: wp.vec2,
    v: wp.vec2,
    r: float,
    n_ob: int,
    time_horizon_obst: float,
    obs_point: wp.array(dtype=wp.vec2),
    obs_next: wp.array(dtype=int),
    obs_prev: wp.array(dtype=int),
    obs_dir: wp.array(dtype=wp.vec2),
    obs_convex: wp.array(dtype=int),
    ob_idx: wp.array2d(dtype=int),
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
):
    """The ORCA lines of agent ``i``'s ``n_ob`` obstacle neighbours (RVO2's rules), into
    row i of ``lp`` (points, m/s) and ``ld`` (unit directions) from slot 0. Returns their
    count."""
    n_lines = int(0)
    inv_tho = 1.0 / time_horizon_obst
    radius_sq = r * r
    for q in range(n_ob):
        o1 = ob_idx[i, q]
        o2 = obs_next[o1]
        rel1 = obs_point[o1] - pw
        rel2 = obs_point[o2] - pw
        if already_covered(i, n_lines, rel1, rel2, inv_tho, r, lp, ld) != 0:
            continue
        dist_sq1 = wp.length_sq(rel1)
        dist_sq2 = wp.length_sq(rel2)
        obstacle_vec = obs_point[o2] - obs_point[o1]
        s = wp.dot(-rel1, obstacle_vec) / wp.length_sq(obstacle_vec)
        dist_sq_line = wp.length_sq(-rel1 - s * obstacle_vec)
        hit, direction = collision_line(
            o1, o2, rel1, rel2, s, dist_sq1, dist_sq2, dist_sq_line, radius_sq, obs_dir, obs_convex
        )
        if hit != 0:
            if hit == 1:
                lp[i, n_lines] = wp.vec2(0.0, 0.0)
                ld[i, n_lines] = direction
                n_lines = n_lines + 1
            continue
        # no collision: legs of the truncated velocity obstacle
        ok, e1, e2, left_leg, right_leg = obstacle_legs(
            o1, o2, rel1, rel2, s, dist_sq1, dist_sq2, dist_sq_line, r, radius_sq, obs_dir, obs_convex
        )
        if ok == 0:
            continue
        emit, point, line_dir = obstacle_vo_line(
            v,
            e1,
            e2,
            obs_point[e1] - pw,
            obs_point[e2] - pw,
            left_leg,
            right_leg,
            r,
            inv_tho,
            obs_prev,
            obs_dir,
            obs_convex,
        )
        if emit != 0:
            lp[i, n_lines] = point
            ld[i, n_lines] = line_dir
            n_lines = n_lines + 1
    return n_lines


@wp.func
def agent_lines(
    i: int,
    p: wp.vec2,
    v: wp.vec2,
    r: float,
    n_nb: int,
    n_lines: int,
    pos: wp.array(dtype=wp.vec2),
    vel: wp.array(dtype=wp.vec2),
    radius: wp.array(dtype=float),
    periodic: int,
    length: float,
    time_horizon: float,
    time_step: float,
    nb_idx: wp.array2d(dtype=int),
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
):
    """The ORCA lines of agent ``i``'s ``n_nb`` agent neighbours (each takes half the
    avoidance), into row i of ``lp`` / ``ld`` after the first ``n_lines``. Returns the
    new line count."""
    count = n_lines
    inv_th = 1.0 / time_horizon
    inv_dt = 1.0 / time_step
    for q in range(n_nb):
        j = nb_idx[i, q]
        rel = pos[j] - p
        if periodic != 0:
            rel = wp.vec2(rel[0] - length * wp.round(rel[0] / length), rel[1])
        rel_v = v - vel[j]
        dist_sq = wp.length_sq(rel)
        comb = r + radius[j]
        comb_sq = comb * comb
        direction = wp.vec2(0.0, 0.0)
        u = wp.vec2(0.0, 0.0)
        if dist_sq > comb_sq:
            w = rel_v - inv_th * rel  # from the cut-off centre to the relative velocity
            w_len_sq = wp.length_sq(w)
            dot1 = wp.dot(w, rel)
            if dot1 < 0.0 and dot1 * dot1 > comb_sq * w_len_sq:
                w_len = wp.sqrt(w_len_sq)  # project on the cut-off circle
                unit_w = w / w_len
                direction = wp.vec2(unit_w[1], -unit_w[0])
                u = (comb * inv_th - w_len) * unit_w
            else:
                leg = wp.sqrt(dist_sq - comb_sq)  # project on a leg
                if det2(rel, w) > 0.0:
                    direction = leg_left(rel, leg, comb, dist_sq)
                else:
                    direction = -leg_right(rel, leg, comb, dist_sq)
                u = wp.dot(rel_v, direction) * direction - rel_v
        else:
            w = rel_v - inv_dt * rel  # overlapping: cut-off circle of one time step
            w_len = wp.length(w)
            unit_w = w / w_len
            direction = wp.vec2(unit_w[1], -unit_w[0])
            u = (comb * inv_dt - w_len) * unit_w
        lp[i, count] = v + 0.5 * u
        ld[i, count] = direction
        count = count + 1
    return count


@wp.kernel
def compute_velocities(
    pos: wp.array(dtype=wp.vec2),
    vel: wp.array(dtype=wp.vec2),
    pref: wp.array(dtype=wp.vec2),
    radius: wp.array(dtype=float),
    max_speed: wp.array(dtype=float),
    sorted_ids: wp.array(dtype=int),
    cell_start: wp.array(dtype=int),
    cell_end: wp.array(dtype=int),
    origin: wp.vec2,
    inv_cell: wp.vec2,
    nx: int,
    ny: int,
    periodic: int,
    x0: float,
    length: float,
    neighbor_dist: float,
    max_neighbors: int,
    time_horizon: float,
    time_horizon_obst: float,
    time_step: float,
    obs_point: wp.array(dtype=wp.vec2),
    obs_next: wp.array(dtype=int),
    obs_prev: wp.array(dtype=int),
    obs_dir: wp.array(dtype=wp.vec2),
    obs_convex: wp.array(dtype=int),
    n_obs: int,
    max_obst_neighbors: int,
    nb_idx: wp.array2d(dtype=int),
    nb_d2: wp.array2d(dtype=float),
    ob_idx: wp.array2d(dtype=int),
    ob_d2: wp.array2d(dtype=float),
    lp: wp.array2d(dtype=wp.vec2),
    ld: wp.array2d(dtype=wp.vec2),
    pp: wp.array2d(dtype=wp.vec2),
    pd: wp.array2d(dtype=wp.vec2),
    new_vel: wp.array(dtype=wp.vec2),
):
    """The new velocity (m/s) of agent i (thread): the obstacle and agent neighbours, their
    ORCA lines (obstacles first: kept hard by the 3D program), then the velocity closest to
    the preferred one ``pref[i]`` within ``max_speed[i]`` that satisfies them all (2D
    program), else the one that violates the agent lines least (3D program).

    The agents are found through the uniform grid (``cell_keys``, ``cell_ranges``:
    ``sorted_ids`` by cell); ``x0``, ``length`` the periodic x range when ``periodic``.
    Times in s, distances in m; the scratch rows (``nb_*``, ``ob_*``, ``lp``, ``ld``,
    ``pp``, ``pd``) are row i of (N, slots) arrays."""
    i = wp.tid()
    p = pos[i]
    v = vel[i]
    r = radius[i]
    vmax = max_speed[i]
    pw = p  # position in the periodic frame (obstacles, grid)
    if periodic != 0:
        pw = wp.vec2(wrap_coord(p[0], x0, length), p[1])
    n_ob = obstacle_neighbours(
        i, pw, r, vmax, time_horizon_obst, obs_point, obs_next, n_obs, max_obst_neighbors, ob_idx, ob_d2
    )
    n_nb = agent_neighbours(
        i,
        p,
        pw,
        pos,
        sorted_ids,
        cell_start,
        cell_end,
        origin,
        inv_cell,
        nx,
        ny,
        periodic,
        length,
        neighbor_dist,
        max_neighbors,
        nb_idx,
        nb_d2,
    )
    n_obst_lines = obstacle_lines(
        i, pw, v, r, n_ob, time_horizon_obst, obs_point, obs_next, obs_prev, obs_dir, obs_convex, ob_idx, lp, ld
    )
    n_lines = agent_lines(
        i, p, v, r, n_nb, n_obst_lines, pos, vel, radius, periodic, length, time_horizon, time_step, nb_idx, lp, ld
    )
    result, fail = lp2(lp, ld, i, n_lines, vmax, pref[i], 0)
    if fail < n_lines:
        result = lp3(lp, ld, pp, pd, i, n_lines, n_obst_lines, fail, vmax, result)
    new_vel[i] = result

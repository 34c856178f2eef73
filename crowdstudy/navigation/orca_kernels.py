"""Warp kernels of the ORCA simulator (imported by :class:`~crowdstudy.navigation.orca.ORCASimulator`
only, so ``import crowdstudy.navigation`` does not load Warp).

One thread per agent. The velocity kernel follows the RVO2 library's algorithm (van den
Berg, Guy, Snape, Lin, Manocha: "Reciprocal n-body collision avoidance", 2011): ORCA
half-planes of the static obstacle edges (with RVO2's convex-vertex, leg and cut-off
rules), then of the nearest agent neighbours, then the 2D linear program over the max-speed
disc; when it is infeasible, the 3D linear program that keeps the obstacle half-planes hard
and minimises the largest violation of the agent half-planes. Single-precision like RVO2.

Per-thread variable-length lists (neighbours, ORCA lines, projected lines) live in rows of
2D scratch arrays ``[agent, slot]`` so the same code runs on CPU and CUDA devices.
"""

from __future__ import annotations

import warp as wp

from crowdstudy.warp_runtime import get_warp

get_warp()      # the project's kernel cache and log level, set before this module can compile
wp.set_module_options({"enable_backward": False})     # forward only: halves the compile time

__all__ = ["cell_keys", "cell_ranges", "compute_velocities", "integrate"]

EPSILON = wp.constant(1.0e-5)      # RVO_EPSILON
BIG = wp.constant(1.0e30)


@wp.func
def det2(a: wp.vec2, b: wp.vec2):
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def wrap_coord(x: float, x0: float, length: float):
    s = (x - x0) / length
    return x - length * wp.floor(s)


@wp.func
def grid_cell(p: wp.vec2, origin: wp.vec2, inv_cell: wp.vec2, nx: int, ny: int):
    ix = int(wp.floor((p[0] - origin[0]) * inv_cell[0]))
    iy = int(wp.floor((p[1] - origin[1]) * inv_cell[1]))
    ix = wp.clamp(ix, 0, nx - 1)
    iy = wp.clamp(iy, 0, ny - 1)
    return ix, iy


@wp.kernel
def cell_keys(pos: wp.array(dtype=wp.vec2), origin: wp.vec2, inv_cell: wp.vec2, nx: int, ny: int,
              periodic: int, x0: float, length: float,
              keys: wp.array(dtype=int), values: wp.array(dtype=int)):
    i = wp.tid()
    p = pos[i]
    if periodic != 0:
        p = wp.vec2(wrap_coord(p[0], x0, length), p[1])
    ix, iy = grid_cell(p, origin, inv_cell, nx, ny)
    keys[i] = iy * nx + ix
    values[i] = i


@wp.kernel
def cell_ranges(keys: wp.array(dtype=int), n: int, cell_start: wp.array(dtype=int), cell_end: wp.array(dtype=int)):
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
def integrate(pos: wp.array(dtype=wp.vec2), vel: wp.array(dtype=wp.vec2), new_vel: wp.array(dtype=wp.vec2),
              dt: float):
    i = wp.tid()
    v = new_vel[i]
    vel[i] = v
    pos[i] = pos[i] + v * dt


# --- linear programs (RVO2's linearProgram1/2/3) -------------------------------------------

@wp.func
def lp1(lp: wp.array2d(dtype=wp.vec2), ld: wp.array2d(dtype=wp.vec2), row: int, line_no: int, radius: float,
        opt: wp.vec2, direction_opt: int, result: wp.vec2):
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
def lp2(lp: wp.array2d(dtype=wp.vec2), ld: wp.array2d(dtype=wp.vec2), row: int, n_lines: int, radius: float,
        opt: wp.vec2, direction_opt: int):
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
def lp3(lp: wp.array2d(dtype=wp.vec2), ld: wp.array2d(dtype=wp.vec2),
        pp: wp.array2d(dtype=wp.vec2), pd: wp.array2d(dtype=wp.vec2), row: int,
        n_lines: int, n_obst: int, begin: int, radius: float, start: wp.vec2):
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
    return wp.vec2(rel[0] * leg - rel[1] * r, rel[0] * r + rel[1] * leg) / dist_sq


@wp.func
def leg_right(rel: wp.vec2, leg: float, r: float, dist_sq: float):
    return wp.vec2(rel[0] * leg + rel[1] * r, -rel[0] * r + rel[1] * leg) / dist_sq


@wp.kernel
def compute_velocities(
        pos: wp.array(dtype=wp.vec2), vel: wp.array(dtype=wp.vec2), pref: wp.array(dtype=wp.vec2),
        radius: wp.array(dtype=float), max_speed: wp.array(dtype=float),
        sorted_ids: wp.array(dtype=int), cell_start: wp.array(dtype=int), cell_end: wp.array(dtype=int),
        origin: wp.vec2, inv_cell: wp.vec2, nx: int, ny: int, periodic: int, x0: float, length: float,
        neighbor_dist: float, max_neighbors: int, time_horizon: float, time_horizon_obst: float, time_step: float,
        obs_point: wp.array(dtype=wp.vec2), obs_next: wp.array(dtype=int), obs_prev: wp.array(dtype=int),
        obs_dir: wp.array(dtype=wp.vec2), obs_convex: wp.array(dtype=int), n_obs: int, max_obst_neighbors: int,
        nb_idx: wp.array2d(dtype=int), nb_d2: wp.array2d(dtype=float),
        ob_idx: wp.array2d(dtype=int), ob_d2: wp.array2d(dtype=float),
        lp: wp.array2d(dtype=wp.vec2), ld: wp.array2d(dtype=wp.vec2),
        pp: wp.array2d(dtype=wp.vec2), pd: wp.array2d(dtype=wp.vec2),
        new_vel: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    p = pos[i]
    v = vel[i]
    r = radius[i]
    vmax = max_speed[i]
    pw = p                                   # position in the periodic frame (obstacles, grid)
    if periodic != 0:
        pw = wp.vec2(wrap_coord(p[0], x0, length), p[1])

    # ---- obstacle neighbours: directed edges seen from their right side, nearest first
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

    # ---- agent neighbours: the max_neighbors nearest within neighbor_dist (RVO2's shrinking range)
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

    # ---- ORCA lines of the obstacles
    n_lines = int(0)
    inv_tho = 1.0 / time_horizon_obst
    radius_sq = r * r
    for q in range(n_ob):
        o1 = ob_idx[i, q]
        o2 = obs_next[o1]
        rel1 = obs_point[o1] - pw
        rel2 = obs_point[o2] - pw
        covered = int(0)
        for m in range(n_lines):
            if det2(inv_tho * rel1 - lp[i, m], ld[i, m]) - inv_tho * r >= -EPSILON:
                if det2(inv_tho * rel2 - lp[i, m], ld[i, m]) - inv_tho * r >= -EPSILON:
                    covered = 1
                    break
        if covered != 0:
            continue
        dist_sq1 = wp.length_sq(rel1)
        dist_sq2 = wp.length_sq(rel2)
        obstacle_vec = obs_point[o2] - obs_point[o1]
        s = wp.dot(-rel1, obstacle_vec) / wp.length_sq(obstacle_vec)
        dist_sq_line = wp.length_sq(-rel1 - s * obstacle_vec)
        if s < 0.0 and dist_sq1 <= radius_sq:
            if obs_convex[o1] != 0:                       # collision with the left vertex
                lp[i, n_lines] = wp.vec2(0.0, 0.0)
                ld[i, n_lines] = wp.normalize(wp.vec2(-rel1[1], rel1[0]))
                n_lines = n_lines + 1
            continue
        if s > 1.0 and dist_sq2 <= radius_sq:
            if obs_convex[o2] != 0 and det2(rel2, obs_dir[o2]) >= 0.0:   # collision with the right vertex
                lp[i, n_lines] = wp.vec2(0.0, 0.0)
                ld[i, n_lines] = wp.normalize(wp.vec2(-rel2[1], rel2[0]))
                n_lines = n_lines + 1
            continue
        if s >= 0.0 and s < 1.0 and dist_sq_line <= radius_sq:        # collision with the edge
            lp[i, n_lines] = wp.vec2(0.0, 0.0)
            ld[i, n_lines] = -obs_dir[o1]
            n_lines = n_lines + 1
            continue
        # no collision: legs of the truncated velocity obstacle
        left_leg = wp.vec2(0.0, 0.0)
        right_leg = wp.vec2(0.0, 0.0)
        if s < 0.0 and dist_sq_line <= radius_sq:        # seen obliquely: the left vertex defines it
            if obs_convex[o1] == 0:
                continue
            o2 = o1
            rel2 = rel1
            leg1 = wp.sqrt(dist_sq1 - radius_sq)
            left_leg = leg_left(rel1, leg1, r, dist_sq1)
            right_leg = leg_right(rel1, leg1, r, dist_sq1)
        elif s > 1.0 and dist_sq_line <= radius_sq:      # seen obliquely: the right vertex defines it
            if obs_convex[o2] == 0:
                continue
            o1 = o2
            rel1 = rel2
            leg2 = wp.sqrt(dist_sq2 - radius_sq)
            left_leg = leg_left(rel2, leg2, r, dist_sq2)
            right_leg = leg_right(rel2, leg2, r, dist_sq2)
        else:
            if obs_convex[o1] != 0:
                left_leg = leg_left(rel1, wp.sqrt(dist_sq1 - radius_sq), r, dist_sq1)
            else:
                left_leg = -obs_dir[o1]
            if obs_convex[o2] != 0:
                right_leg = leg_right(rel2, wp.sqrt(dist_sq2 - radius_sq), r, dist_sq2)
            else:
                right_leg = obs_dir[o1]
        left_neighbor = obs_prev[o1]
        left_foreign = int(0)
        right_foreign = int(0)
        if obs_convex[o1] != 0 and det2(left_leg, -obs_dir[left_neighbor]) >= 0.0:
            left_leg = -obs_dir[left_neighbor]
            left_foreign = 1
        if obs_convex[o2] != 0 and det2(right_leg, obs_dir[o2]) <= 0.0:
            right_leg = obs_dir[o2]
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
        t_left = wp.dot(v - left_cut, left_leg)
        t_right = wp.dot(v - right_cut, right_leg)
        if (t < 0.0 and t_left < 0.0) or (same != 0 and t_left < 0.0 and t_right < 0.0):
            unit_w = wp.normalize(v - left_cut)                  # project on the left cut-off circle
            ld[i, n_lines] = wp.vec2(unit_w[1], -unit_w[0])
            lp[i, n_lines] = left_cut + r * inv_tho * unit_w
            n_lines = n_lines + 1
            continue
        if t > 1.0 and t_right < 0.0:
            unit_w = wp.normalize(v - right_cut)                 # project on the right cut-off circle
            ld[i, n_lines] = wp.vec2(unit_w[1], -unit_w[0])
            lp[i, n_lines] = right_cut + r * inv_tho * unit_w
            n_lines = n_lines + 1
            continue
        d_cut = BIG
        if t >= 0.0 and t <= 1.0 and same == 0:
            d_cut = wp.length_sq(v - (left_cut + t * cut_vec))
        d_left = BIG
        if t_left >= 0.0:
            d_left = wp.length_sq(v - (left_cut + t_left * left_leg))
        d_right = BIG
        if t_right >= 0.0:
            d_right = wp.length_sq(v - (right_cut + t_right * right_leg))
        if d_cut <= d_left and d_cut <= d_right:                 # project on the cut-off line
            direction = -obs_dir[o1]
            ld[i, n_lines] = direction
            lp[i, n_lines] = left_cut + r * inv_tho * wp.vec2(-direction[1], direction[0])
            n_lines = n_lines + 1
        elif d_left <= d_right:                                  # project on the left leg
            if left_foreign == 0:
                ld[i, n_lines] = left_leg
                lp[i, n_lines] = left_cut + r * inv_tho * wp.vec2(-left_leg[1], left_leg[0])
                n_lines = n_lines + 1
        else:                                                    # project on the right leg
            if right_foreign == 0:
                direction = -right_leg
                ld[i, n_lines] = direction
                lp[i, n_lines] = right_cut + r * inv_tho * wp.vec2(-direction[1], direction[0])
                n_lines = n_lines + 1
    n_obst_lines = n_lines

    # ---- ORCA lines of the agent neighbours
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
            w = rel_v - inv_th * rel                # from the cut-off centre to the relative velocity
            w_len_sq = wp.length_sq(w)
            dot1 = wp.dot(w, rel)
            if dot1 < 0.0 and dot1 * dot1 > comb_sq * w_len_sq:
                w_len = wp.sqrt(w_len_sq)           # project on the cut-off circle
                unit_w = w / w_len
                direction = wp.vec2(unit_w[1], -unit_w[0])
                u = (comb * inv_th - w_len) * unit_w
            else:
                leg = wp.sqrt(dist_sq - comb_sq)    # project on a leg
                if det2(rel, w) > 0.0:
                    direction = leg_left(rel, leg, comb, dist_sq)
                else:
                    direction = -leg_right(rel, leg, comb, dist_sq)
                u = wp.dot(rel_v, direction) * direction - rel_v
        else:
            w = rel_v - inv_dt * rel                # overlapping: cut-off circle of one time step
            w_len = wp.length(w)
            unit_w = w / w_len
            direction = wp.vec2(unit_w[1], -unit_w[0])
            u = (comb * inv_dt - w_len) * unit_w
        lp[i, n_lines] = v + 0.5 * u
        ld[i, n_lines] = direction
        n_lines = n_lines + 1

    result, fail = lp2(lp, ld, i, n_lines, vmax, pref[i], 0)
    if fail < n_lines:
        result = lp3(lp, ld, pp, pd, i, n_lines, n_obst_lines, fail, vmax, result)
    new_vel[i] = result

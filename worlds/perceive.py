"""The compiled step of :mod:`worlds.perception`: one call turns the kernel's base observations
of a batch of robots into their frames (own map, subgoal, frame stack, geodesic reward).

Like :mod:`worlds.kernel`, the entry points take tuples of arrays (``world`` the bank's kernel
maps, ``robots`` the batch's state, ``finals`` its terminal results, ``mem`` the per-robot
memory of :class:`worlds.perception.Perception`, ``work`` the subgoal search's work arrays) and
are compiled without numba's reference-counted runtime: they allocate nothing, and per-robot
views and tuples then cost no atomic counting.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.geodesic import field_distance, start_field
from worlds.gridsearch import SOFT
from worlds.own_map import (
    CHANGED,
    ON_PLAN,
    PENALTY,
    UNKNOWN,
    centre,
    inflate,
    inflation_cells,
    level_radius,
    map_rays,
    plan_clear,
    plan_from_field,
    waypoint,
)

PATCH_VALUE = np.array([0.5, 0.0, 1.0], dtype=np.float32)
"""occupancy channel of the patch for UNKNOWN, FREE, SEEN_BLOCKED"""
SUB_NONE, SUB_OWN, SUB_KNOWN = 0, 1, 2
STAMP_WRAP = 2**31 - 2
"""a robot's plan-map version or search count at which its int32 stamps start again"""
REUSE_PARAM = 10
"""index in :attr:`worlds.perception.Perception.params` of the reuse switch: 1 keeps plans per cell
and pauses the geodesic field's Dijkstra, 0 is the straightforward program (a search at every
replan, the whole field per reset)"""
RATE_PARAM = 11
"""index in :attr:`worlds.perception.Perception.params` of the range rates' frame offset (-1: absent)"""
LENGTH_PARAM = 12
FRESH, STEPPED = np.bool_(True), np.bool_(False)
"""_robot's ``fresh``, numpy scalars: literal True / False would compile _robot (and what it calls)
once for each (a cold first compile's seconds, bench/first_run.py)"""
NO_ACTION = np.int64(-1)
"""_robot's ``action`` on a fresh episode, a numpy scalar for the same reason"""
"""index in :attr:`worlds.perception.Perception.params` of the plan length's frame offset (-1: absent)"""
CLEARANCE_PARAM = 13
"""index in :attr:`worlds.perception.Perception.params` of the subgoal's clearance (m; 0: off)"""
RADIUS_PARAM = 14
"""index in :attr:`worlds.perception.Perception.params` of the robot's radius (m), which the plan grid
is inflated by (:func:`worlds.own_map.inflation_cells`)"""
SEEN_PARAM = 15
"""index in :attr:`worlds.perception.Perception.params` of the own map's plan preferring seen cells (1:
unseen cells :data:`~worlds.gridsearch.SOFT` on the plan grid, :func:`worlds.own_map.plan_clear`)"""


@njit(cache=True, _nrt=False)
def _frame(out, base, x, y, theta, max_range, sub_at, wx, wy, act_at, n_actions, action, patch_at, patch, occ,
           visits, height, width, cell, value, rate_at, n_beams, len_at, length):  # fmt: skip
    """Write one frame into ``out`` (which holds the robot's previous frame, or anything when
    ``action`` < 0: a fresh episode): the base observation, then the optional parts."""
    if rate_at >= 0:  # before the readings are overwritten: out[:n_beams] are the previous ones
        for k in range(n_beams):
            rate = (base[k] - out[k]) * max_range if action >= 0 else 0.0
            out[rate_at + k] = min(max(rate, -1.0), 1.0)
    for k in range(base.shape[0]):
        out[k] = base[k]
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    if sub_at >= 0:
        ux, uy = wx - x, wy - y
        d = math.sqrt(ux * ux + uy * uy)
        out[sub_at] = d / (d + max_range)
        out[sub_at + 1] = (-ux * sin_t + uy * cos_t) / d if d > 0.0 else 0.0
        out[sub_at + 2] = (ux * cos_t + uy * sin_t) / d if d > 0.0 else 1.0
    if len_at >= 0:
        out[len_at] = length / (length + max_range)
    if act_at >= 0:
        for k in range(n_actions):
            out[act_at + k] = 1.0 if k == action else 0.0
    if patch_at >= 0:
        half = patch * 0.5
        for u in range(patch):  # u: back to front along the heading
            fwd = (u - half + 0.5) * cell
            for v in range(patch):  # v: right to left
                left = (v - half + 0.5) * cell
                px = (x + fwd * cos_t - left * sin_t) / cell
                py = (y + fwd * sin_t + left * cos_t) / cell
                at = patch_at + 2 * (u * patch + v)
                if px < 0.0 or py < 0.0 or px >= width or py >= height:
                    out[at], out[at + 1] = value[UNKNOWN], 0.0
                else:
                    c, r = int(px), int(py)
                    out[at] = value[occ[r, c]]
                    out[at + 1] = 1.0 - 1.0 / (1.0 + visits[r, c])


@njit(cache=True, _nrt=False)
def _subgoal(i, fresh, dirty, replan, x, y, gx, gy, gr, gc, height, width, cell, along, reuse, plans, work,
             clearance, unseen, wide, near, reach):  # fmt: skip
    """Robot ``i``'s waypoint into ``wpt[i]`` (``plans``). The plan depends on the map, the goal and
    the robot's cell only: it is searched again when one of them changed (``fresh``: a new episode;
    ``dirty``: a cell became blocked or free; ``replan``: one where the last search looked), else
    kept; with ``reuse``, from the plans kept per cell of this plan map, and kept on a new plan map
    when no change lies where the search that made it looked. ``wide``: robot ``i``'s inflated plan
    grid, empty when its map's cells need none (``near``, ``reach``: its levels' counts and reaches);
    ``unseen``: the penalty of the plan grid's unseen cells (:func:`worlds.own_map.waypoint`)."""
    plan, wpt, last, plan_node, stamp, version, exam, exam_id, searches, plan_length, path_length = plans[:11]
    rc, cc = int(y / cell), int(x / cell)
    moved = rc != last[i, 0] or cc != last[i, 1]
    if not (fresh or dirty or moved):
        return
    if fresh or dirty:  # a new plan map: the plans kept for the previous one are void
        if version[i] >= STAMP_WRAP:  # the stamps wrap: forget every kept plan once
            for r in range(stamp.shape[1]):
                _fill(stamp[i, r], -1)
            version[i] = 0
        version[i] += 1
    last[i, 0], last[i, 1] = rc, cc
    on_map = 0 <= rc < height and 0 <= cc < width
    if reuse and on_map and not (fresh or moved or replan):
        stamp[i, rc, cc] = version[i]  # the search would read the same cells: same plan, still valid
        return
    if reuse and on_map and stamp[i, rc, cc] == version[i]:
        # a cell already planned from on this plan map (same map, goal, cell: same plan)
        node, path_length[i] = plan_node[i, rc, cc], plan_length[i, rc, cc]
        exam_id[i] = -1  # where its search looked is not known
    else:
        if searches[i] >= STAMP_WRAP:
            _fill(exam[i], 0)
            searches[i] = 0
        searches[i] += 1
        node, searched, path_length[i] = waypoint(
            plan[i], wide, near, reach, height, width, cell, x, y, gr, gc, along, work, exam[i], searches[i],
            clearance, unseen,
        )  # fmt: skip
        exam_id[i] = searches[i] if searched else -1
        if on_map:
            plan_node[i, rc, cc], stamp[i, rc, cc] = node, version[i]
            plan_length[i, rc, cc] = path_length[i]
    wpt[i, 0], wpt[i, 1] = centre(node, width, cell, gx, gy)


@njit(cache=True)
def _fill(row, value):
    for k in range(row.shape[0]):
        row[k] = value


@njit(cache=True, _nrt=False)
def _robot(i, fresh, action, m, x, y, theta, gx, gy, gr, gc, base, rays, out, world, mem, work, params, ray_c,
           ray_s):  # fmt: skip
    """Robot ``i``'s frame at pose (x, y, theta) on map ``m`` with goal (gx, gy) in cell (gr, gc),
    its base observation and rays given, pushed onto its stack and written to ``out``. ``fresh``
    starts a new episode first (own map cleared, geodesic field started, stack filled); otherwise
    ``action`` led to this frame. Returns (shaped, the geodesic shaping term to add to the reward).
    ``params``: max_range, subgoal kind, subgoal distance, frame offsets of subgoal / action /
    patch (-1: absent), patch size, geodesic weight, number of actions, rays per sector, reuse of
    plans (1) or a search at every replan (0: the straightforward program the reuse must equal),
    frame offset of the range rates (-1: absent), of the plan length, the subgoal's clearance, the
    robot's radius (the plan grid's inflation on this map's cells: :mod:`worlds.own_map`), whether the
    own map's plan prefers seen cells (:data:`SEEN_PARAM`)."""
    max_range, sub_kind, along = params[0], int(params[1]), params[2]
    sub_at, act_at, patch_at = int(params[3]), int(params[4]), int(params[5])
    patch, w_geo, n_actions, per = int(params[6]), params[7], int(params[8]), int(params[9])
    reuse = params[REUSE_PARAM] > 0.0
    rate_at, n_beams = int(params[RATE_PARAM]), ray_c.shape[0] // per
    len_at, clearance = int(params[LENGTH_PARAM]), params[CLEARANCE_PARAM]
    field, moff, mh, mw, mcell = world
    occ, visits, plans, moves, geo, pgeo, stack = mem
    plan, wpt, exam, exam_id, path_length = plans[0], plans[1], plans[6], plans[7], plans[10]
    height, width, cell, at = mh[m], mw[m], mcell[m], moff[m]
    # the inflation levels on this map's cells, widest first (worlds.own_map.level_radius; worlds.perception
    # allocates the inflated grid when a map of the bank has cells fine enough for one)
    # (all of them when the widest inflates: a narrower one with no band blocks the blocked cells alone)
    reach, levels = plans[13][i], 0
    widest = level_radius(params[RADIUS_PARAM], clearance, 0)
    if sub_kind != SUB_NONE and inflation_cells(widest, cell) > 0:
        for level in range(plans[12].shape[1]):
            metres = level_radius(params[RADIUS_PARAM], clearance, level)
            if metres > 0.0:
                reach[levels] = metres / cell
                levels += 1
    wide = plans[11][i] if levels > 0 else plans[11][i, :0]
    near, reach = plans[12][i, :levels], reach[:levels]
    # the penalty of the own map's unseen cells: on maps of cells that need no inflation only (at finer
    # cells the sectors' traced rays leave most cells between them unseen: worlds.own_map's docstring)
    unseen = PENALTY if params[SEEN_PARAM] > 0.0 and levels == 0 else 0.0
    uses_map = occ.shape[1] > 0
    shaped, shaping = False, 0.0
    if fresh:
        if uses_map:
            for r in range(occ.shape[1]):
                for c in range(occ.shape[2]):
                    occ[i, r, c], visits[i, r, c] = UNKNOWN, 0
        if w_geo > 0.0:
            stride = width + 2
            start_field(moves, at, stride, (gr + 1) * stride + gc + 1, geo, i, reuse)
            pgeo[i] = field_distance(moves, at, height, width, geo, i, cell, x, y)
        if sub_kind == SUB_KNOWN:
            plan_from_field(field, at, plan[i], height, width)
        elif sub_kind == SUB_OWN:
            plan_clear(plan[i], height, width, SOFT if unseen > 0.0 else 0)
        if levels > 0:
            inflate(plan[i], wide, near, height, width, reach)
    elif w_geo > 0.0:
        now = field_distance(moves, at, height, width, geo, i, cell, x, y)
        if math.isfinite(now) and math.isfinite(pgeo[i]):
            shaped, shaping = True, w_geo * (pgeo[i] - now)
        pgeo[i] = now
    dirty, replan = fresh, fresh
    if uses_map:
        own = sub_kind == SUB_OWN  # the plan grid follows the own map
        tracked, seen_by = (plan[i], exam_id[i]) if own else (plan[i, :0], -1)
        mapped = wide if own else wide[:0]  # the inflated grid follows the own map only
        flags = map_rays(occ[i], visits[i], tracked, exam[i], seen_by, height, width, cell, x, y, theta,
                         ray_c, ray_s, rays, max_range, per, mapped, near, reach)  # fmt: skip
        dirty = dirty or (own and flags & CHANGED != 0)
        replan = replan or (own and flags & ON_PLAN != 0)
    wx, wy, length = gx, gy, 0.0
    if sub_kind != SUB_NONE:
        _subgoal(
            i,
            fresh,
            dirty,
            replan,
            x,
            y,
            gx,
            gy,
            gr,
            gc,
            height,
            width,
            cell,
            along,
            reuse,
            plans,
            work,
            clearance,
            unseen,
            wide,
            near,
            reach,
        )
        wx, wy, length = wpt[i, 0], wpt[i, 1], path_length[i]
        if length < 0.0:  # no path on the plan map: the straight line
            length = math.sqrt((gx - x) ** 2 + (gy - y) ** 2)
    k, d = stack.shape[1], stack.shape[2]
    if not fresh:
        for j in range(k - 1, 0, -1):
            for q in range(d):
                stack[i, j, q] = stack[i, j - 1, q]
    _frame(stack[i, 0], base, x, y, theta, max_range, sub_at, wx, wy, act_at, n_actions, action, patch_at,
           patch, occ[i], visits[i], height, width, cell, PATCH_VALUE, rate_at, n_beams, len_at,
           length)  # fmt: skip
    for j in range(k):
        for q in range(d):
            if fresh:
                stack[i, j, q] = stack[i, 0, q]
            out[j * d + q] = stack[i, j, q]
    return shaped, shaping


@njit(cache=True, _nrt=False)
def _first(i, robots, obs, world, mem, work, params, ray_c, ray_s):
    """The first frame of robot ``i``'s new episode (the batch's current state), into ``obs[i]``."""
    x, y, theta, gx, gy, goal_cell, map_index, base_obs, rays = robots
    _robot(i, FRESH, NO_ACTION, map_index[i], x[i], y[i], theta[i], gx[i], gy[i], goal_cell[i, 0],
           goal_cell[i, 1], base_obs[i], rays[i], obs[i], world, mem, work, params, ray_c, ray_s)  # fmt: skip


@njit(cache=True, _nrt=False)
def perceive_fresh(indices, world, robots, mem, work, params, ray_c, ray_s, obs):
    """The first frames of the episodes robots ``indices`` just started, into ``obs``."""
    for n in range(indices.shape[0]):
        _first(indices[n], robots, obs, world, mem, work, params, ray_c, ray_s)


@njit(cache=True, _nrt=False)
def perceive_step(actions, autoreset, world, emap, robots, finals, mem, work, params, ray_c, ray_s, obs,
                  final_obs, reward):  # fmt: skip
    """The frames after a step of every robot (``actions`` led to them), into ``obs``, adding the
    geodesic shaping to ``reward``. With ``autoreset``, a robot whose episode ended (``finals``'s
    done) gets its terminal frame from the ended episode's memory into ``final_obs`` (its shaping
    added), then the first frame of the episode the kernel started into ``obs``."""
    x, y, theta, gx, gy, goal_cell, map_index, base_obs, rays = robots
    f_pose, f_goal, f_entry, f_base, f_rays, done = finals
    mcell = world[4]
    for i in range(x.shape[0]):
        if autoreset and done[i]:
            m = emap[f_entry[i]]
            fr, fc = f_goal[i, 0], f_goal[i, 1]
            fx, fy = (fc + 0.5) * mcell[m], (fr + 0.5) * mcell[m]
            shaped, shaping = _robot(i, STEPPED, actions[i], m, f_pose[i, 0], f_pose[i, 1], f_pose[i, 2], fx,
                                     fy, fr, fc, f_base[i], f_rays[i], final_obs[i], world, mem, work, params,
                                     ray_c, ray_s)  # fmt: skip
        else:
            shaped, shaping = _robot(i, STEPPED, actions[i], map_index[i], x[i], y[i], theta[i], gx[i], gy[i],
                                     goal_cell[i, 0], goal_cell[i, 1], base_obs[i], rays[i], obs[i], world,
                                     mem, work, params, ray_c, ray_s)  # fmt: skip
        if shaped:
            reward[i] += shaping
        if autoreset and done[i]:
            _first(i, robots, obs, world, mem, work, params, ray_c, ray_s)

"""The robot's own map: a grid on the map's cells, per robot and episode, written only from the
robot's own rays and poses (see :mod:`worlds.perception`), and the subgoal planned on it.

The plan grid a subgoal search reads is *padded* (the layout of :mod:`worlds.gridsearch`): one
flat uint8 row per robot, :data:`~worlds.fields.BLOCKED` on seen-blocked cells (own map) or
blocked cells (known map) and on a ring around the map.
"""

from __future__ import annotations

import math

from numba import njit

from worlds.fields import BLOCKED
from worlds.gridsearch import GEN, search_run, search_start

UNKNOWN, FREE, SEEN_BLOCKED = 0, 1, 2
"""cell states of the robot's own map"""


@njit(cache=True, _nrt=False)
def map_rays(occ, visits, height, width, cell, x, y, theta, ray_c, ray_s, ranges, max_range, per) -> bool:
    """Write one step's rays and pose into a robot's own map: the cell past the end of every ray
    that hit something is blocked, the cells that the middle ray of each sector of ``per`` rays
    crosses before its end are free (rays of a sector cross nearly the same cells; tracing one
    keeps the map's cost near the sensor's). True when a cell became blocked or stopped being
    blocked (which changes the plan; unknown and free plan alike)."""
    changed = False
    px, py = x / cell, y / cell
    if px < 0.0 or py < 0.0 or px >= width or py >= height:
        return False
    c0, r0 = int(px), int(py)
    visits[r0, c0] += 1
    if occ[r0, c0] == SEEN_BLOCKED:
        changed = True
    occ[r0, c0] = FREE
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    for k in range(ray_c.shape[0]):
        dx = cos_t * ray_c[k] - sin_t * ray_s[k]
        dy = sin_t * ray_c[k] + cos_t * ray_s[k]
        length = ranges[k] / cell
        if ranges[k] < max_range:
            hx, hy = px + (length + 1e-6) * dx, py + (length + 1e-6) * dy
            if 0.0 <= hx < width and 0.0 <= hy < height:
                hc, hr = int(hx), int(hy)
                if occ[hr, hc] != SEEN_BLOCKED:
                    changed = True
                occ[hr, hc] = SEEN_BLOCKED
        if k % per != per // 2:
            continue
        # exact traversal of the cells the ray crosses before its end (Amanatides & Woo)
        c, r = c0, r0
        step_c, step_r = (1 if dx > 0.0 else -1), (1 if dy > 0.0 else -1)
        inv_dx = 1.0 / dx if dx != 0.0 else math.inf
        inv_dy = 1.0 / dy if dy != 0.0 else math.inf
        next_c = (c + (1.0 if dx > 0.0 else 0.0) - px) * inv_dx if dx != 0.0 else math.inf
        next_r = (r + (1.0 if dy > 0.0 else 0.0) - py) * inv_dy if dy != 0.0 else math.inf
        while True:
            if next_c < next_r:
                t = next_c
                c += step_c
                next_c += abs(inv_dx)
            else:
                t = next_r
                r += step_r
                next_r += abs(inv_dy)
            if t >= length or c < 0 or r < 0 or c >= width or r >= height:
                break
            if occ[r, c] == SEEN_BLOCKED:
                changed = True
            occ[r, c] = FREE
    return changed


@njit(cache=True, _nrt=False)
def plan_from_own_map(occ, plan, height, width):
    """Write the padded plan grid ``plan`` of a robot's own map ``occ``: seen-blocked cells blocked,
    unknown and free ones free."""
    stride = width + 2
    for k in range((height + 2) * stride):
        plan[k] = BLOCKED
    for r in range(height):
        for c in range(width):
            plan[(r + 1) * stride + c + 1] = BLOCKED if occ[r, c] == SEEN_BLOCKED else 0


@njit(cache=True, _nrt=False)
def plan_from_field(field, base, plan, height, width):
    """Copy the padded true map (the kernel's field of the map at ``base``) into ``plan``."""
    for k in range((height + 2) * (width + 2)):
        plan[k] = BLOCKED if field[base + k] == BLOCKED else 0


@njit(cache=True, _nrt=False)
def waypoint(plan, height, width, cell, x, y, gx, gy, goal_r, goal_c, along, work):
    """A* (8-connected, no corner cutting) on the padded grid ``plan`` from the robot's cell to the
    goal cell (counted free); the centre of the cell ``along`` metres down the path, or the goal
    itself when the path ends first, the robot is off the map or on a blocked cell, or no path
    exists. ``work``: the search's work arrays (:func:`worlds.gridsearch.new_work`)."""
    g, parent, seen, meta = work[0], work[1], work[3], work[7]
    stride = width + 2
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or c >= width or r >= height:
        return gx, gy
    start, goal = (r + 1) * stride + c + 1, (goal_r + 1) * stride + goal_c + 1
    if plan[start] == BLOCKED:
        return gx, gy
    was = plan[goal]
    plan[goal] = 0
    search_start(start, goal, stride, True, *work)
    search_run(plan, 0, stride, goal, True, *work)
    plan[goal] = was
    if seen[goal] != meta[GEN]:
        return gx, gy
    # parent links run goal -> start: the node at path length >= along is the last one walking back
    # from the goal whose g is still >= along (g grows along the path from the start)
    node = goal
    while parent[node] >= 0 and g[parent[node]] * cell >= along:
        node = parent[node]
    if node == goal:
        return gx, gy
    return (node % stride - 1 + 0.5) * cell, (node // stride - 1 + 0.5) * cell

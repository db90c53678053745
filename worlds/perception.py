"""What the robot perceives beyond one frame of range readings, and the geodesic reward.

The compiled kernel (:mod:`worlds.kernel`) writes each robot's *base* observation (range
readings, goal distance and bearing) and the noise-free range of every cast ray. This module
turns them into the observation of :class:`worlds.config.ObservationConfig`, one frame per
step, the last ``frame_stack`` frames observed newest first::

    frame = [readings (n_beams), goal (3), subgoal (3)?, range rates (n_beams)?,
             previous action one-hot (n_actions)?, own-map patch (2 * patch_size**2)?]

* **Range rates** (``range_rate``): each reading's change since the robot's previous step, in
  metres, clipped to [-1, 1] (0 at an episode's first step): negative when something comes
  closer, so one frame shows a moving disc's approach without a frame stack.

* **The robot's own map** (``own_map`` subgoal, patch): a grid on the map's cells, per robot and
  episode, written only from the robot's own rays and poses: every cell a ray crosses before
  its end is *seen free*, the cell just past a ray's end (a range below ``max_range``) *seen
  blocked*, the latest reading winning (so a moving disc's cell is free again once a ray crosses
  it), and the cell under the robot counts a visit each step. Nothing of the true map is read:
  a cell no ray reached stays unknown. The map's extent (its bounding box) is known, as the
  workspace boundary is to a real robot; its content is not.
* **The subgoal**: the shortest 8-connected grid path (:func:`worlds.gridsearch.grid_search`,
  the search behind the expert's A*) from the goal to every cell of the robot's own map,
  unknown cells counted free, so the robot cannot "see" unseen walls; the waypoint is the cell
  ``subgoal_distance`` metres along the path from the robot's cell (the goal itself when
  nearer); the frame gets its squashed distance and bearing. It is replanned whenever the map
  changed in a way that matters (a cell became blocked or stopped being blocked), which gives
  the same plan as replanning every step; the plan found from a cell is kept until the map
  changes, so coming back to that cell costs no search. ``known_map`` plans on the true map
  instead, for a user who has one.
* **The geodesic reward** (``rewards.geodesic_progress``): potential-based shaping by the true
  shortest-path distance from the robot's cell to the goal. It is a training signal; the policy
  never observes it. The Dijkstra from the goal is paused once the robot's cell is settled and
  resumed when the robot reaches a cell it has not settled yet (the same search, so the same
  distances, at the cost of the cells the episode needs).

Both envs go through :class:`worlds.batch.NavBatch`, which calls :class:`Perception` after every
kernel call, so the single env and the vector env stay the same program.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.config import NavConfig
from worlds.fields import BLOCKED
from worlds.geodesic import field_distance, start_field
from worlds.gridsearch import grid_search

UNKNOWN, FREE, SEEN_BLOCKED = 0, 1, 2
"""cell states of the robot's own map"""
PATCH_VALUE = np.array([0.5, 0.0, 1.0], dtype=np.float32)
"""occupancy channel of the patch for UNKNOWN, FREE, SEEN_BLOCKED"""
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)
SUB_NONE, SUB_OWN, SUB_KNOWN = 0, 1, 2
REUSE_PARAM = 10
"""index in :attr:`Perception.params` of the reuse switch: 1 keeps plans per cell and pauses the geodesic
field's Dijkstra, 0 is the straightforward program (a search at every replan, the whole field per reset)"""
RATE_PARAM = 11
"""index in :attr:`Perception.params` of the range rates' frame offset (-1: absent)"""


def frame_layout(config: NavConfig) -> dict[str, tuple[int, int]]:
    """Where each part sits in one frame: ``{name: (start, stop)}``, in frame order."""
    o, n = config.observation, config.sensors.n_beams
    parts = [("readings", n), ("goal", 3)]
    if o.subgoal != "none":
        parts.append(("subgoal", 3))
    if o.range_rate:
        parts.append(("range_rate", n))
    if o.previous_action:
        parts.append(("previous_action", config.robot.n_actions))
    if o.patch_size:
        parts.append(("patch", 2 * o.patch_size**2))
    layout, start = {}, 0
    for name, size in parts:
        layout[name] = (start, start + size)
        start += size
    return layout


def frame_dim(config: NavConfig) -> int:
    return max(stop for _, stop in frame_layout(config).values())


def observation_dim(config: NavConfig) -> int:
    """Length of the observation vector: frame_stack frames of :func:`frame_dim`."""
    return config.observation.frame_stack * frame_dim(config)


def observation_bounds(config: NavConfig) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the observation vector."""
    layout = frame_layout(config)
    low, high = np.zeros(frame_dim(config), np.float32), np.ones(frame_dim(config), np.float32)
    for part in ("goal", "subgoal"):
        if part in layout:
            a, _ = layout[part]
            low[a + 1 : a + 3] = -1.0
    if "range_rate" in layout:
        a, b = layout["range_rate"]
        low[a:b] = -1.0
    k = config.observation.frame_stack
    return np.tile(low, k), np.tile(high, k)


def needed(config: NavConfig) -> bool:
    """Does ``config`` need this module (anything beyond the kernel's observation and reward)?"""
    return not config.observation.plain or config.rewards.geodesic_progress > 0


# ----------------------------------------------------------------------------- compiled parts
@njit(cache=True)
def _true_blocked(field, off, height, width):
    """The true map of one kernel field entry as a (height, width) bool array."""
    out = np.empty((height, width), dtype=np.bool_)
    for r in range(height):
        for c in range(width):
            out[r, c] = field[off + (r + 1) * (width + 2) + c + 1] == BLOCKED
    return out


@njit(cache=True)
def _map_rays(occ, visits, height, width, cell, x, y, theta, ray_c, ray_s, ranges, max_range, per) -> bool:
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


@njit(cache=True)
def _waypoint(blocked, cell, x, y, gx, gy, goal_r, goal_c, along):
    """A* (8-connected, no corner cutting) on ``blocked`` from the robot's cell to the goal cell
    (counted free); the centre of the cell ``along`` metres down the path, or the goal itself when
    the path ends first, the robot is off the map or no path exists."""
    height, width = blocked.shape
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or c >= width or r >= height or blocked[r, c]:
        return gx, gy
    was = blocked[goal_r, goal_c]
    blocked[goal_r, goal_c] = False
    start, goal = r * width + c, goal_r * width + goal_c
    g, parent, _ = grid_search(blocked, start, goal, True)
    blocked[goal_r, goal_c] = was
    if not math.isfinite(g[goal]):
        return gx, gy
    # parent links run goal -> start: the node at path length >= along is the last one walking back
    # from the goal whose g is still >= along (g grows along the path from the start)
    node = goal
    while parent[node] >= 0 and g[parent[node]] * cell >= along:
        node = parent[node]
    if node == goal:
        return gx, gy
    return (node % width + 0.5) * cell, (node // width + 0.5) * cell


@njit(cache=True)
def _frame(out, base, x, y, theta, max_range, sub_at, wx, wy, act_at, n_actions, action, patch_at, patch, occ,
           visits, height, width, cell, value, rate_at, n_beams):  # fmt: skip
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


@njit(cache=True)
def perceive(indices, fresh, actions, field, moff, mh, mw, mcell, mp, pose, goal, goal_cell, base, rays,
             ray_c, ray_s, params, occ, visits, blocked, dirty, waypoint, last, plan_x, plan_y, stamp,
             version, truth_map, geo, geo_size, pgeo, stack, out, reward):  # fmt: skip
    """One frame for each robot in ``indices`` (its pose, goal, base observation and rays given),
    pushed onto its stack and written to ``out``. ``fresh[n]`` starts a new episode first (own
    map cleared, geodesic field made, stack filled); otherwise ``actions[n]`` led to
    this frame and the geodesic shaping term is added to ``reward[n]``. ``params``: max_range,
    subgoal kind, subgoal distance, frame offsets of subgoal / action / patch (-1: absent),
    patch size, geodesic weight, number of actions, rays per sector, reuse of plans (1) or a
    search at every replan (0: the straightforward program the reuse must equal)."""
    max_range, sub_kind, along = params[0], int(params[1]), params[2]
    sub_at, act_at, patch_at = int(params[3]), int(params[4]), int(params[5])
    patch, w_geo, n_actions, per = int(params[6]), params[7], int(params[8]), int(params[9])
    rate_at, n_beams = int(params[RATE_PARAM]), ray_c.shape[0] // per
    reuse = params[REUSE_PARAM] > 0.0
    uses_map = occ.shape[1] > 0
    for n in range(indices.shape[0]):
        i = indices[n]
        m = mp[n]
        height, width, cell = mh[m], mw[m], mcell[m]
        x, y, theta = pose[n, 0], pose[n, 1], pose[n, 2]
        gx, gy = goal[n, 0], goal[n, 1]
        gr, gc = goal_cell[n, 0], goal_cell[n, 1]
        if fresh[n]:
            if uses_map:
                occ[i, :, :] = UNKNOWN
                visits[i, :, :] = 0
            if w_geo > 0.0 or sub_kind == SUB_KNOWN:
                truth = _true_blocked(field, moff[m], height, width)
                if w_geo > 0.0:
                    truth_map[i, :height, :width] = truth
                    start_field(truth, gr, gc, geo, geo_size, i, reuse)
                    pgeo[i] = field_distance(truth_map[i, :height, :width], geo, geo_size, i, cell, x, y)
                if sub_kind == SUB_KNOWN:
                    blocked[i, :height, :width] = truth
            dirty[i] = sub_kind == SUB_OWN
        elif w_geo > 0.0:
            now = field_distance(truth_map[i, :height, :width], geo, geo_size, i, cell, x, y)
            if math.isfinite(now) and math.isfinite(pgeo[i]):
                reward[n] += w_geo * (pgeo[i] - now)
            pgeo[i] = now
        if uses_map:
            changed = _map_rays(occ[i], visits[i], height, width, cell, x, y, theta, ray_c, ray_s, rays[n],
                                max_range, per)  # fmt: skip
            dirty[i] = dirty[i] or (changed and sub_kind == SUB_OWN)
        wx, wy = gx, gy
        if sub_kind != SUB_NONE:
            # the plan depends on the map, the goal and the robot's cell only: search again when one changed
            rc, cc = int(y / cell), int(x / cell)
            if fresh[n] or dirty[i] or rc != last[i, 0] or cc != last[i, 1]:
                if fresh[n] or dirty[i]:
                    version[i] += 1  # a new plan map: the plans kept for the previous one are void
                if dirty[i]:
                    for r in range(height):
                        for c in range(width):
                            blocked[i, r, c] = occ[i, r, c] == SEEN_BLOCKED
                    dirty[i] = False
                on_map = 0 <= rc < height and 0 <= cc < width
                if reuse and on_map and stamp[i, rc, cc] == version[i]:
                    # a cell already planned from on this plan map (same map, goal, cell: same plan)
                    waypoint[i, 0], waypoint[i, 1] = plan_x[i, rc, cc], plan_y[i, rc, cc]
                else:
                    grid = blocked[i, :height, :width]
                    waypoint[i, 0], waypoint[i, 1] = _waypoint(grid, cell, x, y, gx, gy, gr, gc, along)
                    if on_map:
                        plan_x[i, rc, cc], plan_y[i, rc, cc] = waypoint[i, 0], waypoint[i, 1]
                        stamp[i, rc, cc] = version[i]
                last[i, 0], last[i, 1] = rc, cc
            wx, wy = waypoint[i, 0], waypoint[i, 1]
        k = stack.shape[1]
        if not fresh[n]:
            for j in range(k - 1, 0, -1):
                stack[i, j, :] = stack[i, j - 1, :]
        _frame(stack[i, 0], base[n], x, y, theta, max_range, sub_at, wx, wy, act_at, n_actions,
               -1 if fresh[n] else actions[n], patch_at, patch, occ[i], visits[i], height, width, cell,
               PATCH_VALUE, rate_at, n_beams)  # fmt: skip
        if fresh[n]:
            for j in range(1, k):
                stack[i, j, :] = stack[i, 0, :]
        d = stack.shape[2]
        for j in range(k):
            for q in range(d):
                out[n, j * d + q] = stack[i, j, q]


class Perception:
    """Per-robot memory (own map, plans, frame stack, geodesic field) of ``n`` robots, and the
    step that turns the kernel's base observations into observations (see the module docstring)."""

    def __init__(self, n: int, config: NavConfig, reuse: bool = True) -> None:
        o = config.observation
        self.n, self.config = n, config
        layout = frame_layout(config)
        self.frame_dim, self.obs_dim = frame_dim(config), observation_dim(config)
        angles = config.sensors.ray_angles
        self.ray_c, self.ray_s = np.cos(angles), np.sin(angles)
        kind = {"none": SUB_NONE, "own_map": SUB_OWN, "known_map": SUB_KNOWN}[o.subgoal]
        self.params = np.array(
            [
                config.sensors.max_range,
                kind,
                o.subgoal_distance,
                layout.get("subgoal", (-1,))[0],
                layout.get("previous_action", (-1,))[0],
                layout.get("patch", (-1,))[0],
                o.patch_size,
                config.rewards.geodesic_progress,
                config.robot.n_actions,
                config.sensors.rays_per_beam,
                reuse,
                layout.get("range_rate", (-1,))[0],
            ],
            dtype=np.float64,
        )
        self.uses_map, self.plans = o.needs_map, o.subgoal != "none"
        self.geodesic = config.rewards.geodesic_progress > 0
        self.stack = np.zeros((n, o.frame_stack, self.frame_dim), np.float32)
        self.dirty = np.zeros(n, np.bool_)
        self.waypoint = np.zeros((n, 2), np.float64)
        self.last = np.zeros((n, 2), np.int64)
        self.version = np.zeros(n, np.int64)
        self.pgeo = np.zeros(n, np.float64)
        self.geo_size = np.zeros(n, np.int64)
        self.shape = (0, 0)
        self._allocate((1, 1))

    def _allocate(self, shape: tuple[int, int]) -> None:
        """Grids of at least ``shape`` cells per robot, keeping what they hold."""
        h, w = max(shape[0], self.shape[0]), max(shape[1], self.shape[1])
        if (h, w) == self.shape:
            return

        def grow(old, dtype, used, fill=0):
            new = np.full((self.n, h, w) if used else (self.n, 0, 0), fill, dtype)
            if used and old is not None and old.size:
                new[:, : old.shape[1], : old.shape[2]] = old
            return new

        self.occ = grow(getattr(self, "occ", None), np.int8, self.uses_map)
        self.visits = grow(getattr(self, "visits", None), np.int32, self.uses_map)
        self.blocked = grow(getattr(self, "blocked", None), np.bool_, self.plans)
        self.plan_x = grow(getattr(self, "plan_x", None), np.float64, self.plans)
        self.plan_y = grow(getattr(self, "plan_y", None), np.float64, self.plans)
        self.stamp = grow(getattr(self, "stamp", None), np.int64, self.plans, -1)
        self.truth_map = grow(getattr(self, "truth_map", None), np.bool_, self.geodesic)
        # the geodesic field's Dijkstra, one per robot (flat work arrays of search_run, g first)
        flat = h * w if self.geodesic else 0
        old = getattr(self, "geo", None)
        dtypes = (np.float64, np.float64, np.int64, np.int64, np.bool_, np.int64)
        self.geo = tuple(np.zeros((self.n, flat), dtype) for dtype in dtypes)
        if old is not None:  # a search runs on the same flat indices (row * its map's width + col)
            for new, prev in zip(self.geo, old, strict=True):
                new[:, : prev.shape[1]] = prev[:, : new.shape[1]]
        self.shape = (h, w)

    def observe(
        self, indices, fresh, actions, maps, mp, pose, goal, goal_cell, base, rays, out, reward
    ) -> None:
        """Run :func:`perceive` for robots ``indices`` (arrays indexed like ``indices``)."""
        _, _, mh, mw, _ = maps
        self._allocate((int(mh.max()), int(mw.max())))
        perceive(
            np.asarray(indices, np.int64), np.asarray(fresh, np.bool_), np.asarray(actions, np.int64), *maps,
            np.asarray(mp, np.int64), pose, goal, np.asarray(goal_cell, np.int64), base, rays, self.ray_c,
            self.ray_s, self.params, self.occ, self.visits, self.blocked, self.dirty, self.waypoint,
            self.last, self.plan_x, self.plan_y, self.stamp, self.version, self.truth_map, self.geo,
            self.geo_size, self.pgeo, self.stack, out, reward,
        )  # fmt: skip

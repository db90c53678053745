"""Modified A* over the robot's own lattice (thesis ch. 3), compiled with numba.

Grid A* plans for a point that moves between cell centres; the robot is a
disc that can only *turn by one of its action angles, then drive one step*.
This planner searches what the robot can actually do, hybrid-A* style
(Dolgov et al. 2008):

* a node is a continuous pose ``(x, y, theta)``; successors apply each discrete
  action with the exact kinematics of ``worlds.robot`` (no noise);
* the closed set is discretised - position bins of ``position_resolution``
  metres times ``heading_bins`` heading sectors - and the cheapest pose
  reaching a bin is the one kept;
* a successor is dropped when the robot disc, swept along the step, touches a
  blocked cell or the border (the rule of ``worlds.robot.collides``, checked
  against it in the tests) or comes within a known moving disc;
* a step costs its length, times ``1 + clearance_weight * ((safe_gap - gap) /
  safe_gap)^2`` when the gap between the disc and the nearest obstacle is
  below ``safe_gap``, so paths keep away from walls, plus ``turn_weight`` per
  radian turned;
* the heuristic is the 8-connected grid distance to the goal
  (``agents.planning.astar.distance_field``) minus the goal tolerance.

The plan stops as soon as a pose is within the goal tolerance, so the action
sequence it returns ends where the environment would declare success.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from agents.planning.astar import distance_field
from worlds.maps import Cell, GridMap


@dataclass(frozen=True)
class LatticeConfig:
    """Knobs of the modified A*; the defaults suit the default ``worlds.config`` robot."""

    position_resolution: float = 0.25
    """side of a position bin of the closed set (m)"""
    heading_bins: int = 16
    """heading sectors of the closed set"""
    clearance_weight: float = 2.0
    """extra cost factor of a step that ends touching the safety gap (0 switches clearance cost off)"""
    safe_gap: float = 0.35
    """gap between robot disc and nearest obstacle below which steps cost extra (m)"""
    turn_weight: float = 0.05
    """cost per radian of heading change (m/rad), discourages zig-zags"""
    heuristic_weight: float = 1.0
    """weight of the grid-distance heuristic (> 1 trades optimality for speed)"""
    max_expansions: int = 200_000
    """give up (no plan) after this many expansions"""


@dataclass(frozen=True)
class LatticePlan:
    """An executable plan: ``actions[i]`` moves the robot from ``poses[i]`` to ``poses[i + 1]``."""

    actions: np.ndarray
    poses: np.ndarray
    cost: float
    found: bool
    expanded: int

    @property
    def length(self) -> float:
        """Path length in metres (sum of the step lengths)."""
        if len(self.poses) < 2:
            return 0.0
        return float(np.hypot(*np.diff(self.poses[:, :2], axis=0).T).sum())


@njit(cache=True)
def nearest_blocked_distance(blocked, cell_size, x, y, cap):
    """Distance from point ``(x, y)`` to the nearest blocked cell square or the map border,
    exact when below ``cap`` and at most ``cap`` otherwise (0 inside a blocked cell)."""
    height, width = blocked.shape
    best = min(cap, x, y, width * cell_size - x, height * cell_size - y)
    if best <= 0.0:
        return 0.0
    reach = math.ceil(best / cell_size) + 1
    r0 = math.floor(y / cell_size)
    c0 = math.floor(x / cell_size)
    for r in range(max(0, r0 - reach), min(height, r0 + reach + 1)):
        for c in range(max(0, c0 - reach), min(width, c0 + reach + 1)):
            if not blocked[r, c]:
                continue
            dx = max(c * cell_size - x, 0.0, x - (c + 1) * cell_size)
            dy = max(r * cell_size - y, 0.0, y - (r + 1) * cell_size)
            d = math.sqrt(dx * dx + dy * dy)
            if d < best:
                best = d
    return best


@njit(cache=True)
def _gap(blocked, cell_size, discs, radius, x, y, cap):
    """Free distance between the robot disc at ``(x, y)`` and the nearest obstacle, at most ``cap``."""
    gap = nearest_blocked_distance(blocked, cell_size, x, y, cap + radius) - radius
    for i in range(discs.shape[0]):
        d = math.hypot(x - discs[i, 0], y - discs[i, 1]) - discs[i, 2] - radius
        if d < gap:
            gap = d
    return gap


@njit(cache=True)
def _point_segment_sq(px, py, ax, ay, bx, by):
    vx, vy = bx - ax, by - ay
    length_sq = vx * vx + vy * vy
    t = 0.0 if length_sq == 0.0 else min(1.0, max(0.0, ((px - ax) * vx + (py - ay) * vy) / length_sq))
    dx, dy = ax + t * vx - px, ay + t * vy - py
    return dx * dx + dy * dy


@njit(cache=True)
def _point_box_sq(px, py, x0, y0, x1, y1):
    dx = max(x0 - px, 0.0, px - x1)
    dy = max(y0 - py, 0.0, py - y1)
    return dx * dx + dy * dy


@njit(cache=True)
def _segment_box_sq(ax, ay, bx, by, x0, y0, x1, y1):
    """Squared distance between segment a-b and the box [x0, x1] x [y0, y1]; 0 when they meet."""
    t_lo, t_hi = 0.0, 1.0
    meets = True
    for p, d, lo, hi in ((ax, bx - ax, x0, x1), (ay, by - ay, y0, y1)):  # slab test
        if d == 0.0:
            if p < lo or p > hi:
                meets = False
        else:
            t0, t1 = (lo - p) / d, (hi - p) / d
            t_lo, t_hi = max(t_lo, min(t0, t1)), min(t_hi, max(t0, t1))
    if meets and t_lo <= t_hi:
        return 0.0
    # disjoint convex shapes: the closest pair includes an end point or a box corner
    best = min(_point_box_sq(ax, ay, x0, y0, x1, y1), _point_box_sq(bx, by, x0, y0, x1, y1))
    for cx, cy in ((x0, y0), (x1, y0), (x0, y1), (x1, y1)):
        best = min(best, _point_segment_sq(cx, cy, ax, ay, bx, by))
    return best


@njit(cache=True)
def _sweep_hits(blocked, cell_size, discs, radius, x0, y0, x1, y1):
    """The env's collision rule for one step (``worlds.robot.collides``): the disc swept from
    (x0, y0) to (x1, y1) touches a blocked cell or leaves the map; or meets a known disc."""
    height, width = blocked.shape
    if min(x0, x1) - radius < 0.0 or min(y0, y1) - radius < 0.0:
        return True
    if max(x0, x1) + radius > width * cell_size or max(y0, y1) + radius > height * cell_size:
        return True
    r_sq = radius * radius
    for r in range(
        max(int((min(y0, y1) - radius) / cell_size), 0),
        min(int((max(y0, y1) + radius) / cell_size), height - 1) + 1,
    ):
        for c in range(
            max(int((min(x0, x1) - radius) / cell_size), 0),
            min(int((max(x0, x1) + radius) / cell_size), width - 1) + 1,
        ):
            if blocked[r, c]:
                box = (c * cell_size, r * cell_size, (c + 1) * cell_size, (r + 1) * cell_size)
                if _segment_box_sq(x0, y0, x1, y1, box[0], box[1], box[2], box[3]) < r_sq:
                    return True
    for i in range(discs.shape[0]):
        reach = discs[i, 2] + radius
        if _point_segment_sq(discs[i, 0], discs[i, 1], x0, y0, x1, y1) < reach * reach:
            return True
    return False


@njit(cache=True)
def _wrap(theta):
    return (theta + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def _heap_push(hf, hb, size, f, b):
    """Push (f, b); returns the heap arrays (grown when full) and the new size."""
    if size == hf.shape[0]:
        hf2, hb2 = np.empty(2 * size), np.empty(2 * size, dtype=np.int64)
        hf2[:size], hb2[:size] = hf, hb
        hf, hb = hf2, hb2
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if hf[p] <= f:
            break
        hf[i] = hf[p]
        hb[i] = hb[p]
        i = p
    hf[i] = f
    hb[i] = b
    return hf, hb, size + 1


@njit(cache=True)
def _heap_pop(hf, hb, size):
    b = hb[0]
    size -= 1
    f = hf[size]
    last = hb[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and hf[c + 1] < hf[c]:
            c += 1
        if hf[c] >= f:
            break
        hf[i] = hf[c]
        hb[i] = hb[c]
        i = c
    if size > 0:
        hf[i] = f
        hb[i] = last
    return b, size


@njit(cache=True)
def _slot(keys, key):
    """The slot of ``key`` in the open-addressing table ``keys`` (its own or the empty one, -1, where
    it would go; linear probing, the table a power of two at most half full)."""
    mask = keys.shape[0] - 1
    h = (key * 0x9E3779B97F4A7C15) & mask  # Fibonacci hashing spreads neighbouring bins
    while keys[h] != -1 and keys[h] != key:
        h = (h + 1) & mask
    return h


@njit(cache=True)
def _grown(nodes, keys, vals):
    """Node arrays and hash table of twice the capacity, the old entries kept."""
    g, closed, pose, parent, act = nodes
    n = g.shape[0]
    g2, closed2 = np.full(2 * n, np.inf), np.zeros(2 * n, dtype=np.bool_)
    pose2, parent2, act2 = np.zeros((2 * n, 3)), np.full(2 * n, -1, np.int64), np.full(2 * n, -1, np.int64)
    g2[:n], closed2[:n], pose2[:n], parent2[:n], act2[:n] = g, closed, pose, parent, act
    keys2, vals2 = np.full(2 * keys.shape[0], -1, np.int64), np.full(2 * keys.shape[0], -1, np.int64)
    for h in range(keys.shape[0]):
        if keys[h] != -1:
            at = _slot(keys2, keys[h])
            keys2[at], vals2[at] = keys[h], vals[h]
    return (g2, closed2, pose2, parent2, act2), keys2, vals2


INITIAL_NODES = 4096
"""node capacity a search starts with; doubled when full"""


@njit(cache=True)
def _search(blocked, cell_size, field, discs, sx, sy, sth, gx, gy, turns, step, radius, tol, params):
    """The modified A*. Its closed set is keyed by bins (position x heading) but stores only the
    bins the search reaches, in a hash table from bin to node: memory and set-up grow with the
    search, not with the map (a dense table over a 512 m map at 0.25 m x 16 headings is 67 M bins,
    gigabytes allocated per plan). Returns per-node ``parent``, ``act``, ``pose``, ``g`` (node
    indices, -1 for the start's parent), the goal node (-1: none) and the expansions."""
    res, n_head, w_clear, safe, w_turn, w_h, max_exp = params
    n_head = int(n_head)
    bw = math.ceil(blocked.shape[1] * cell_size / res)
    nodes = (
        np.full(INITIAL_NODES, np.inf),
        np.zeros(INITIAL_NODES, dtype=np.bool_),
        np.zeros((INITIAL_NODES, 3)),
        np.full(INITIAL_NODES, -1, np.int64),
        np.full(INITIAL_NODES, -1, np.int64),
    )
    keys, vals = np.full(2 * INITIAL_NODES, -1, np.int64), np.full(2 * INITIAL_NODES, -1, np.int64)
    hf, hb = np.empty(INITIAL_NODES), np.empty(INITIAL_NODES, dtype=np.int64)
    sector = 2.0 * math.pi / n_head

    def bin_of(x, y, th):
        hb_ = math.floor((_wrap(th) + math.pi) / sector + 0.5) % n_head
        return (int(y / res) * bw + int(x / res)) * n_head + hb_

    if _sweep_hits(blocked, cell_size, discs, radius, sx, sy, sx, sy):
        return nodes[3], nodes[4], nodes[2], -1, 0, nodes[0]
    count = 1
    at = _slot(keys, bin_of(sx, sy, sth))
    keys[at], vals[at] = bin_of(sx, sy, sth), 0
    g, closed, pose, parent, act = nodes
    g[0] = 0.0
    pose[0, 0], pose[0, 1], pose[0, 2] = sx, sy, sth
    hf, hb, size = _heap_push(hf, hb, 0, 0.0, 0)
    expanded = 0
    while size > 0 and expanded < max_exp:
        node, size = _heap_pop(hf, hb, size)
        if closed[node]:
            continue
        closed[node] = True
        expanded += 1
        x, y, th = pose[node, 0], pose[node, 1], pose[node, 2]
        if math.hypot(x - gx, y - gy) <= tol:
            return parent, act, pose, node, expanded, g
        for k in range(turns.shape[0]):
            nth = _wrap(th + turns[k])
            nx = x + step * math.cos(nth)
            ny = y + step * math.sin(nth)
            if _sweep_hits(blocked, cell_size, discs, radius, x, y, nx, ny):
                continue
            h_cell = field[int(ny / cell_size), int(nx / cell_size)]
            if not math.isfinite(h_cell):
                continue
            b = bin_of(nx, ny, nth)
            at = _slot(keys, b)
            nb = vals[at]
            if nb >= 0 and closed[nb]:
                continue
            gap = _gap(blocked, cell_size, discs, radius, nx, ny, safe)
            cost = step + w_turn * abs(turns[k])
            if gap < safe:
                short = (safe - gap) / safe
                cost += step * w_clear * short * short
            cand = g[node] + cost
            if nb >= 0 and not cand < g[nb]:
                continue
            if nb < 0:
                if 2 * (count + 1) > keys.shape[0]:
                    nodes, keys, vals = _grown(nodes, keys, vals)
                    g, closed, pose, parent, act = nodes
                    at = _slot(keys, b)
                nb = count
                count += 1
                keys[at], vals[at] = b, nb
            g[nb] = cand
            pose[nb, 0], pose[nb, 1], pose[nb, 2] = nx, ny, nth
            parent[nb] = node
            act[nb] = k
            hf, hb, size = _heap_push(hf, hb, size, cand + w_h * max(0.0, h_cell - tol), nb)
    return parent, act, pose, -1, expanded, g


def plan_lattice(
    grid: GridMap,
    start_pose: tuple[float, float, float],
    goal: Cell,
    turns: np.ndarray,
    step: float,
    radius: float,
    goal_tolerance: float,
    config: LatticeConfig | None = None,
    discs: np.ndarray | None = None,
    field: np.ndarray | None = None,
) -> LatticePlan:
    """Plan the robot's actions from ``start_pose`` to within ``goal_tolerance`` of the goal
    cell centre. ``discs`` are known moving obstacles as rows ``(x, y, radius)``, treated as
    static for this plan (inflate the radius for their motion). ``field`` is
    ``distance_field(grid, goal)``; pass it when planning many times to the same goal."""
    config = config or LatticeConfig()
    if field is None:
        field = distance_field(grid, goal)
    gx, gy = grid.cell_center(goal)
    discs = np.zeros((0, 3)) if discs is None else np.asarray(discs, dtype=np.float64).reshape(-1, 3)
    params = np.array(
        [
            config.position_resolution,
            config.heading_bins,
            config.clearance_weight,
            config.safe_gap,
            config.turn_weight,
            config.heuristic_weight,
            config.max_expansions,
        ],
        dtype=np.float64,
    )
    parent, act, pose, end, expanded, g = _search(
        grid.blocked,
        float(grid.cell_size),
        np.asarray(field, dtype=np.float64),
        discs,
        float(start_pose[0]),
        float(start_pose[1]),
        float(start_pose[2]),
        gx,
        gy,
        np.asarray(turns, dtype=np.float64),
        float(step),
        float(radius),
        float(goal_tolerance),
        params,
    )
    if end < 0:
        return LatticePlan(
            np.zeros(0, np.int64), np.asarray([start_pose], dtype=np.float64), math.inf, False, int(expanded)
        )
    actions, poses = [], [pose[end].copy()]
    node = end
    while parent[node] >= 0:
        actions.append(int(act[node]))
        node = int(parent[node])
        poses.append(pose[node].copy())
    poses[-1] = np.asarray(start_pose, dtype=np.float64)  # the exact start, not its bin's copy
    return LatticePlan(
        np.asarray(actions[::-1], dtype=np.int64), np.asarray(poses[::-1]), float(g[end]), True, int(expanded)
    )

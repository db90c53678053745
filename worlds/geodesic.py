"""The geodesic reward's distance field, one paused Dijkstra per robot.

The reward (``rewards.geodesic_progress``, :mod:`worlds.perception`) needs the true shortest-path
distance from the robot's cell to the goal at every step. The Dijkstra from the goal
(:func:`worlds.gridsearch.search_run`) is paused once the robot's cell is settled and resumed
when the robot reaches a cell not settled yet: the same search, so the same distances as the
whole field made at the reset, for the cells the episode needs. Its flat work arrays
``geo = (g, f, parent, pos, closed, heap)`` hold one row per robot.
"""

from __future__ import annotations

import math

from numba import njit

from worlds.gridsearch import search_run, search_start


@njit(cache=True)
def start_field(truth, goal_r, goal_c, geo, size, i, reuse):
    """Start robot ``i``'s distance field on its true map: a Dijkstra from the goal, for the geodesic
    reward. With ``reuse`` it is only started (:func:`field_distance` runs it on as far as each robot
    cell needs: the same search, paused), else run over the whole component at once."""
    height, width = truth.shape
    g, f, parent, pos, closed, heap = geo
    hw = height * width
    work = (g[i, :hw], f[i, :hw], parent[i, :hw], pos[i, :hw], closed[i, :hw], heap[i, :hw])
    size[i] = search_start(truth, goal_r * width + goal_c, -1, True, *work)
    if not reuse:
        size[i], _ = search_run(truth, -1, -1, True, *work, size[i])


@njit(cache=True)
def field_distance(truth, geo, size, i, cell, x, y):
    """Robot ``i``'s true shortest-path distance (m) from the cell under (x, y) to its goal (inf off
    the map or unreachable), searching on until that cell is settled."""
    height, width = truth.shape
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or r >= height or c >= width:
        return math.inf
    g, f, parent, pos, closed, heap = geo
    hw, node = height * width, r * width + c
    if not closed[i, node] and size[i] > 0:
        work = (g[i, :hw], f[i, :hw], parent[i, :hw], pos[i, :hw], closed[i, :hw], heap[i, :hw])
        size[i], _ = search_run(truth, -1, node, True, *work, size[i])
    return g[i, node] * cell

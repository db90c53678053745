"""The geodesic reward's distance field, one paused Dijkstra per robot.

The reward (``rewards.geodesic_progress``, :mod:`worlds.perception`) needs the true shortest-path
distance from the robot's cell to the goal at every step. The Dijkstra from the goal
(:func:`worlds.gridsearch.search_run`) runs on the kernel's map field in place (it has the padded
layout of :mod:`worlds.gridsearch`), is paused once the robot's cell is settled and resumed when
the robot reaches a cell not settled yet: the same distances as the whole field made at the reset,
for the cells the episode needs. A Dijkstra's settled distances do not depend on the order in which
equal keys leave its heap (each is the least of its settled neighbours' distance plus the step),
so pausing changes none.

``geo = (g, pos, seen, heap, meta)`` holds one row of work arrays per robot
(:func:`worlds.gridsearch.new_work`; f is g, and parents are written to a shared ``scratch`` row
no one reads).
"""

from __future__ import annotations

import math

from numba import njit

from worlds.gridsearch import CLOSED, GEN, SIZE, search_run, search_start


@njit(cache=True, _nrt=False)
def start_field(field, base, stride, goal, geo, scratch, i, reuse):
    """Start robot ``i``'s distance field on its true map (the padded field at ``base``): a Dijkstra
    from padded cell ``goal``. With ``reuse`` it is only started (:func:`field_distance` runs it on as
    far as each robot cell needs), else run over the whole component at once."""
    g, pos, seen, heap, meta = geo
    search_start(goal, -1, stride, True, g[i], g[i], scratch, pos[i], seen[i], heap[i], meta[i])
    if not reuse:
        search_run(field, base, stride, -1, -1, True, g[i], g[i], scratch, pos[i], seen[i], heap[i], meta[i])


@njit(cache=True, _nrt=False)
def field_distance(field, base, height, width, geo, scratch, i, cell, x, y):
    """Robot ``i``'s true shortest-path distance (m) from the cell under (x, y) to its goal (inf off
    the map or unreachable), searching on until that cell is settled."""
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or r >= height or c >= width:
        return math.inf
    g, pos, seen, heap, meta = geo
    stride = width + 2
    node = (r + 1) * stride + c + 1
    gen = meta[i, GEN]
    if not (seen[i, node] == gen and pos[i, node] == CLOSED) and meta[i, SIZE] > 0:
        search_run(
            field, base, stride, -1, node, True, g[i], g[i], scratch, pos[i], seen[i], heap[i], meta[i]
        )
    return g[i, node] * cell if seen[i, node] == gen else math.inf

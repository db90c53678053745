"""Grid shortest paths on a boolean occupancy array, compiled with numba: the one search the
expert's A* (:mod:`agents.planning.astar`) and the robot's own-map subgoal and the geodesic
reward (:mod:`worlds.perception`) share.

It lives in ``worlds`` because the world's observation needs it and ``worlds`` imports nothing
from ``agents`` (agents build on worlds, not the other way round); ``agents.planning.astar``
wraps it for maps and cells.

Move rules are MovingAI's: a straight move costs 1 cell, a diagonal sqrt(2), and a diagonal
move is allowed only when both cells it brushes past are free (it never cuts the corner of a
blocked cell). The search keeps everything in flat arrays indexed by ``row * width + col``:
g-costs, parents, a closed mask and an indexed binary heap with decrease-key (ordered by f,
ties broken towards the larger g), so there is no Python object per node.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SQRT2 = math.sqrt(2.0)

# Neighbour offsets: the 4 straight moves first, then the 4 diagonals.
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)


@njit(cache=True, inline="always")
def _before(f: np.ndarray, g: np.ndarray, a: int, b: int) -> bool:
    """Heap order: smaller f first; on equal f the deeper node (larger g)."""
    if f[a] != f[b]:
        return f[a] < f[b]
    return g[a] > g[b]


@njit(cache=True, inline="always")
def _sift_up(heap, pos, f, g, i):
    node = heap[i]
    while i > 0:
        parent = (i - 1) >> 1
        other = heap[parent]
        if not _before(f, g, node, other):
            break
        heap[i] = other
        pos[other] = i
        i = parent
    heap[i] = node
    pos[node] = i


@njit(cache=True, inline="always")
def _sift_down(heap, pos, f, g, i, size):
    node = heap[i]
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _before(f, g, heap[right], heap[child]):
            child = right
        if not _before(f, g, heap[child], node):
            break
        heap[i] = heap[child]
        pos[heap[i]] = i
        i = child
    heap[i] = node
    pos[node] = i


@njit(cache=True, inline="always")
def _octile(r0, c0, r1, c1, diagonal):
    dr = abs(r0 - r1)
    dc = abs(c0 - c1)
    if not diagonal:
        return float(dr + dc)
    return float(max(dr, dc)) + (SQRT2 - 1.0) * min(dr, dc)


@njit(cache=True)
def search_start(blocked, start, goal, diagonal, g, f, parent, pos, closed, heap):
    """Put a search from ``start`` into the flat work arrays (``height * width`` each); returns the
    heap's size. ``goal >= 0``: A* towards it, else Dijkstra."""
    width = blocked.shape[1]
    g[:] = np.inf
    f[:] = np.inf
    parent[:] = -1
    pos[:] = -1  # index in heap, -1 = not in heap
    closed[:] = False
    g[start] = 0.0
    if goal >= 0:
        f[start] = _octile(start // width, start % width, goal // width, goal % width, diagonal)
    else:
        f[start] = 0.0
    heap[0] = start
    pos[start] = 0
    return 1


@njit(cache=True)
def search_run(blocked, goal, stop, diagonal, g, f, parent, pos, closed, heap, size):
    """Run the search held in the work arrays (heap of ``size``) until it expands ``goal`` (A*; not
    expanded further) or has expanded ``stop`` and its neighbours (so that a later call goes on
    exactly where this one stopped), or the heap is empty. Returns (heap size, nodes expanded)."""
    height, width = blocked.shape
    n_moves = 8 if diagonal else 4
    gr = goal // width
    gc = goal % width
    expanded = 0
    while size > 0:
        node = heap[0]
        size -= 1
        pos[node] = -1
        if size > 0:
            heap[0] = heap[size]
            pos[heap[0]] = 0
            _sift_down(heap, pos, f, g, 0, size)
        closed[node] = True
        expanded += 1
        if node == goal:
            break
        r = node // width
        c = node % width
        for k in range(n_moves):
            nr = r + _DR[k]
            nc = c + _DC[k]
            if nr < 0 or nr >= height or nc < 0 or nc >= width or blocked[nr, nc]:
                continue
            if k >= 4:
                if blocked[r, nc] or blocked[nr, c]:
                    continue  # no corner cutting
                step = SQRT2
            else:
                step = 1.0
            nb = nr * width + nc
            if closed[nb]:
                continue
            cand = g[node] + step
            if cand < g[nb]:
                g[nb] = cand
                parent[nb] = node
                h = _octile(nr, nc, gr, gc, diagonal) if goal >= 0 else 0.0
                f[nb] = cand + h
                if pos[nb] < 0:
                    heap[size] = nb
                    pos[nb] = size
                    size += 1
                _sift_up(heap, pos, f, g, pos[nb])
        if node == stop:
            break
    return size, expanded


@njit(cache=True)
def grid_search(blocked, start, goal, diagonal):
    """Best-first search from ``start`` over the free cells of ``blocked``.

    With ``goal >= 0`` it is A* with the octile (or Manhattan) heuristic and
    stops when the goal is expanded; with ``goal < 0`` it is Dijkstra over the
    whole component. Returns (g, parent, expanded); unreached cells have g=inf.
    """
    n = blocked.shape[0] * blocked.shape[1]
    g, f = np.empty(n), np.empty(n)
    parent, pos = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    closed = np.empty(n, dtype=np.bool_)
    heap = np.empty(n, dtype=np.int64)
    size = search_start(blocked, start, goal, diagonal, g, f, parent, pos, closed, heap)
    _, expanded = search_run(blocked, goal, -1, diagonal, g, f, parent, pos, closed, heap, size)
    return g, parent, expanded

"""Grid shortest paths on a padded occupancy grid, compiled with numba: the one search the
expert's A* (:mod:`agents.planning.astar`) and the robot's own-map subgoal and the geodesic
reward (:mod:`worlds.perception`) share.

It lives in ``worlds`` because the world's observation needs it and ``worlds`` imports nothing
from ``agents`` (agents build on worlds, not the other way round); ``agents.planning.astar``
wraps it for maps and cells.

Move rules are MovingAI's: a straight move costs 1 cell, a diagonal sqrt(2), and a diagonal
move is allowed only when both cells it brushes past are free (it never cuts the corner of a
blocked cell). The open list is an indexed binary heap with decrease-key, ordered by f, ties
broken towards the larger g; the order in which equal keys leave it is the heap's own, so the
plans (which of several shortest paths) depend on exactly this heap and neighbour order.

**Layout.** A search reads a *padded* grid: a flat uint8 array of ``(height + 2) * stride``
cells, ``stride = width + 2``, :data:`~worlds.fields.BLOCKED` on blocked cells and on a ring
around the map, so the neighbour loop has no bounds tests; cell (r, c) is index
``(r + 1) * stride + c + 1``. It is the layout of the kernel's map field
(:func:`worlds.fields.kernel_field`), which the geodesic reward searches in place.

**Work arrays** (:func:`new_work`): ``(g, f, parent, pos, seen, heap, meta)``, one entry per
padded cell, reused from search to search. ``meta = (generation, heap size)``; a cell's entries
are valid only when ``seen[cell]`` equals the search's generation, so starting a search writes
one cell, not every cell. ``pos`` is the cell's place in the heap, :data:`CLOSED` once expanded.
A Dijkstra (``goal < 0``) may hand the same array as ``g`` and ``f`` (its f is its g).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.fields import BLOCKED

SQRT2 = math.sqrt(2.0)
CLOSED = -2
"""``pos`` of an expanded cell"""
GEN, SIZE = 0, 1
"""indices into a search's ``meta``: its generation stamp and its heap's size"""

# Neighbour offsets: the 4 straight moves first, then the 4 diagonals.
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)


def new_work(cells: int) -> tuple:
    """Work arrays ``(g, f, parent, pos, seen, heap, meta)`` for searches on grids of up to ``cells``
    padded cells."""
    i4 = np.int32
    return (np.zeros(cells), np.zeros(cells), np.full(cells, -1, i4), np.full(cells, -1, i4),
            np.zeros(cells, i4), np.zeros(cells, i4), np.zeros(2, i4))  # fmt: skip


@njit(cache=True, inline="always")
def _before(f, g, a, b):
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
def _octile(dr, dc, diagonal):
    dr, dc = abs(dr), abs(dc)
    if not diagonal:
        return float(dr + dc)
    return float(max(dr, dc)) + (SQRT2 - 1.0) * min(dr, dc)


@njit(cache=True, _nrt=False)
def search_start(start, goal, stride, diagonal, g, f, parent, pos, seen, heap, meta):
    """Begin a search from padded cell ``start`` in the work arrays: A* towards ``goal`` if
    ``goal >= 0``, else Dijkstra. Costs O(1): only ``start`` is written."""
    gen = meta[GEN] + 1
    if gen >= 2**31 - 1:  # the stamp wraps: forget every cell once
        for k in range(seen.shape[0]):
            seen[k] = 0
        gen = 1
    meta[GEN], meta[SIZE] = gen, 1
    seen[start], pos[start], parent[start], heap[0] = gen, 0, -1, start
    g[start] = 0.0
    f[start] = (
        _octile(start // stride - goal // stride, start % stride - goal % stride, diagonal)
        if goal >= 0
        else 0.0
    )


@njit(cache=True, _nrt=False)
def search_run(grid, base, stride, goal, stop, diagonal, g, f, parent, pos, seen, heap, meta):
    """Run the search held in the work arrays on the padded grid at ``grid[base:]`` until it
    expands ``goal`` (A*; not expanded further) or has expanded ``stop`` and its neighbours (so
    that a later call goes on exactly where this one stopped), or the heap is empty. Returns the
    number of nodes expanded."""
    gen, size = meta[GEN], meta[SIZE]
    n_moves = 8 if diagonal else 4
    gr, gc = goal // stride, goal % stride
    expanded = 0
    while size > 0:
        node = heap[0]
        size -= 1
        pos[node] = CLOSED
        if size > 0:
            heap[0] = heap[size]
            pos[heap[0]] = 0
            _sift_down(heap, pos, f, g, 0, size)
        expanded += 1
        if node == goal:
            break
        r, c = node // stride, node % stride
        g_node = g[node]
        for k in range(n_moves):
            dr, dc = _DR[k], _DC[k]
            nb = node + dr * stride + dc
            if grid[base + nb] == BLOCKED:
                continue
            if k >= 4:
                if grid[base + node + dc] == BLOCKED or grid[base + node + dr * stride] == BLOCKED:
                    continue  # no corner cutting
                cand = g_node + SQRT2
            else:
                cand = g_node + 1.0
            if seen[nb] == gen:
                if pos[nb] == CLOSED or not cand < g[nb]:
                    continue
            else:
                seen[nb] = gen
                heap[size] = nb
                pos[nb] = size
                size += 1
            g[nb] = cand
            parent[nb] = node
            f[nb] = cand + (_octile(r + dr - gr, c + dc - gc, diagonal) if goal >= 0 else 0.0)
            _sift_up(heap, pos, f, g, pos[nb])
        if node == stop:
            break
    meta[SIZE] = size
    return expanded


@njit(cache=True)
def grid_search(blocked, start, goal, diagonal):
    """Best-first search from ``start`` over the free cells of ``blocked`` (height, width), cells
    given as ``row * width + col``.

    With ``goal >= 0`` it is A* with the octile (or Manhattan) heuristic and
    stops when the goal is expanded; with ``goal < 0`` it is Dijkstra over the
    whole component. Returns (g, parent, expanded) over the unpadded cells; unreached cells
    have g=inf and parent -1.
    """
    height, width = blocked.shape
    stride = width + 2
    grid = np.full((height + 2) * stride, BLOCKED, np.uint8)
    for r in range(height):
        for c in range(width):
            if not blocked[r, c]:
                grid[(r + 1) * stride + c + 1] = 0
    cells = grid.shape[0]
    g, f = np.empty(cells), np.empty(cells)
    parent, pos = np.empty(cells, np.int32), np.empty(cells, np.int32)
    seen, heap, meta = np.zeros(cells, np.int32), np.empty(cells, np.int32), np.zeros(2, np.int32)
    padded = (start // width + 1) * stride + start % width + 1
    target = (goal // width + 1) * stride + goal % width + 1 if goal >= 0 else -1
    search_start(padded, target, stride, diagonal, g, f, parent, pos, seen, heap, meta)
    expanded = search_run(grid, 0, stride, target, -1, diagonal, g, f, parent, pos, seen, heap, meta)
    out_g, out_parent = np.full(height * width, np.inf), np.full(height * width, -1, np.int64)
    for r in range(height):
        for c in range(width):
            p = (r + 1) * stride + c + 1
            if seen[p] == meta[GEN]:
                out_g[r * width + c] = g[p]
                q = parent[p]
                if q >= 0:
                    out_parent[r * width + c] = (q // stride - 1) * width + q % stride - 1
    return out_g, out_parent, expanded

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

**Work arrays** (:func:`new_work`): ``(g, parent, pos, seen, heap, key_f, key_g, order, meta)``,
one entry per padded cell (``order``: the cells in the order the search expanded them), reused
from search to search. ``meta = (generation, heap size)``; a cell's ``g``, ``parent`` and ``pos``
are valid only when ``seen[cell]`` equals the search's generation, so starting a search writes
one cell, not every cell. ``pos`` is the cell's place in the heap,
:data:`CLOSED` once expanded. The heap holds its cells' keys beside them (``key_f``, ``key_g``,
indexed like ``heap``), so comparing two entries reads no other array; a Dijkstra (``goal < 0``)
may hand one array as both (its f is its g).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.fields import BLOCKED

SQRT2 = math.sqrt(2.0)
DIAGONAL = np.bool_(True)
"""``diagonal`` for the 8-connected searches of compiled callers, a numpy scalar: a literal True
would compile search_start and search_run a second time beside grid_search's ``bool``"""
CLOSED = -2
"""``pos`` of an expanded cell"""
GEN, SIZE = 0, 1
"""indices into a search's ``meta``: its generation stamp and its heap's size"""
SOFT = 1
"""a grid value a search with ``penalty`` > 0 enters at ``1 + penalty`` times the move's cost (the own
map's band of the subgoal's clearance, :mod:`worlds.own_map`); searches without a penalty (the
kernel's field, whose free cells hold gap values) read it as any free value"""


def new_work(cells: int) -> tuple:
    """Work arrays ``(g, parent, pos, seen, heap, key_f, key_g, order, meta)`` for searches on grids
    of up to ``cells`` padded cells."""
    i4 = np.int32
    return (np.zeros(cells), np.full(cells, -1, i4), np.full(cells, -1, i4), np.zeros(cells, i4),
            np.zeros(cells, i4), np.zeros(cells), np.zeros(cells), np.zeros(cells, i4),
            np.zeros(2, i4))  # fmt: skip


@njit(cache=True)
def _before(fa, ga, fb, gb):
    """Heap order: smaller f first; on equal f the deeper node (larger g). (Bitwise, not short-circuit:
    no branch to mispredict.)"""
    return (fa < fb) | ((fa == fb) & (ga > gb))


@njit(cache=True)
def _put(heap, key_f, key_g, pos, i, node, f, g):
    heap[i], key_f[i], key_g[i] = node, f, g
    pos[node] = i


@njit(cache=True)
def _sift_up(heap, key_f, key_g, pos, i):
    node, f, g = heap[i], key_f[i], key_g[i]
    while i > 0:
        parent = (i - 1) >> 1
        if not _before(f, g, key_f[parent], key_g[parent]):
            break
        _put(heap, key_f, key_g, pos, i, heap[parent], key_f[parent], key_g[parent])
        i = parent
    _put(heap, key_f, key_g, pos, i, node, f, g)


@njit(cache=True)
def _sift_down(heap, key_f, key_g, pos, i, size):
    node, f, g = heap[i], key_f[i], key_g[i]
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and _before(key_f[right], key_g[right], key_f[child], key_g[child]):
            child = right
        if not _before(key_f[child], key_g[child], f, g):
            break
        _put(heap, key_f, key_g, pos, i, heap[child], key_f[child], key_g[child])
        i = child
    _put(heap, key_f, key_g, pos, i, node, f, g)


@njit(cache=True)
def _octile(dr, dc, diagonal):
    dr, dc = abs(dr), abs(dc)
    if not diagonal:
        return float(dr + dc)
    return float(max(dr, dc)) + (SQRT2 - 1.0) * min(dr, dc)


@njit(cache=True, _nrt=False)
def search_start(start, goal, stride, diagonal, g, parent, pos, seen, heap, key_f, key_g, order, meta):
    """Begin a search from padded cell ``start`` in the work arrays: A* towards ``goal`` if
    ``goal >= 0``, else Dijkstra. Costs O(1): only ``start`` is written."""
    gen = meta[GEN] + 1
    if gen >= 2**31 - 1:  # the stamp wraps: forget every cell once
        for k in range(seen.shape[0]):
            seen[k] = 0
        gen = 1
    meta[GEN], meta[SIZE] = gen, 1
    seen[start], parent[start], g[start] = gen, -1, 0.0
    h = (
        _octile(start // stride - goal // stride, start % stride - goal % stride, diagonal)
        if goal >= 0
        else 0.0
    )
    _put(heap, key_f, key_g, pos, 0, start, h, 0.0)


@njit(cache=True)
def _relax(ctx, step, cand, hr, hc, size):
    """Offer the neighbour ``node + step`` the cost ``cand`` (via the expanded ``node`` of ``ctx``;
    ``hr``, ``hc``: its offset from the goal); returns the heap's size."""
    grid, at, node, goal, diagonal, gen, work, penalty = ctx
    g, parent, pos, seen, heap, key_f, key_g = work
    value = grid[at + step]
    if value == BLOCKED:
        return size
    if penalty > 0.0 and value == SOFT:
        cand = g[node] + (cand - g[node]) * (1.0 + penalty)
    nb = node + step
    if seen[nb] == gen:
        if pos[nb] == CLOSED or not cand < g[nb]:
            return size
        i = pos[nb]
    else:
        seen[nb] = gen
        i = size
        size += 1
    g[nb] = cand
    parent[nb] = node
    f = cand + (_octile(hr, hc, diagonal) if goal >= 0 else 0.0)
    _put(heap, key_f, key_g, pos, i, nb, f, cand)
    _sift_up(heap, key_f, key_g, pos, i)
    return size


@njit(cache=True, _nrt=False)
def search_run(grid, base, stride, goal, diagonal, g, parent, pos, seen, heap, key_f, key_g, order, meta,
               penalty=0.0):  # fmt: skip
    """Run the search held in the work arrays on the padded grid at ``grid[base:]`` until it
    expands ``goal`` (A*; not expanded further) or the heap is empty. Returns the number of nodes
    expanded. With ``penalty`` > 0, entering a :data:`SOFT` cell costs ``1 + penalty`` times the move
    (the octile heuristic stays a lower bound: no move costs less than before)."""
    gen, size = meta[GEN], meta[SIZE]
    gr, gc = goal // stride, goal % stride
    work = (g, parent, pos, seen, heap, key_f, key_g)
    expanded = 0
    while size > 0:
        node = heap[0]
        size -= 1
        pos[node] = CLOSED
        if size > 0:
            _put(heap, key_f, key_g, pos, 0, heap[size], key_f[size], key_g[size])
            _sift_down(heap, key_f, key_g, pos, 0, size)
        order[expanded] = node
        expanded += 1
        if node == goal:
            break
        r, c = node // stride, node % stride
        at, one, diag = base + node, g[node] + 1.0, g[node] + SQRT2
        hr, hc = r - gr, c - gc  # the heuristic's offsets (A* only)
        ctx = (grid, at, node, goal, diagonal, gen, work, penalty)
        size = _relax(ctx, -stride, one, hr - 1, hc, size)
        size = _relax(ctx, stride, one, hr + 1, hc, size)
        size = _relax(ctx, -1, one, hr, hc - 1, size)
        size = _relax(ctx, 1, one, hr, hc + 1, size)
        if diagonal:  # a diagonal move needs both cells it brushes past free (no corner cutting)
            up, down = grid[at - stride] != BLOCKED, grid[at + stride] != BLOCKED
            left, right = grid[at - 1] != BLOCKED, grid[at + 1] != BLOCKED
            if up and left:
                size = _relax(ctx, -stride - 1, diag, hr - 1, hc - 1, size)
            if up and right:
                size = _relax(ctx, -stride + 1, diag, hr - 1, hc + 1, size)
            if down and left:
                size = _relax(ctx, stride - 1, diag, hr + 1, hc - 1, size)
            if down and right:
                size = _relax(ctx, stride + 1, diag, hr + 1, hc + 1, size)
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
    g, parent, pos = np.empty(cells), np.empty(cells, np.int32), np.empty(cells, np.int32)
    seen, heap, meta = np.zeros(cells, np.int32), np.empty(cells, np.int32), np.zeros(2, np.int32)
    key_f, key_g, order = np.empty(cells), np.empty(cells), np.empty(cells, np.int32)
    work = (g, parent, pos, seen, heap, key_f, key_g, order, meta)
    padded = (start // width + 1) * stride + start % width + 1
    target = (goal // width + 1) * stride + goal % width + 1 if goal >= 0 else -1
    search_start(padded, target, stride, diagonal, *work)
    expanded = search_run(grid, 0, stride, target, diagonal, *work)
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

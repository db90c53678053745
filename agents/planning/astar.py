"""Grid A* (8- or 4-connected) and grid distance fields, compiled with numba.

Move rules are MovingAI's: a straight move costs 1 cell, a diagonal sqrt(2),
and a diagonal move is allowed only when both cells it brushes past are free
(it never cuts the corner of a blocked cell). Lengths are returned in metres
(cells times ``grid.cell_size``), so for ``cell_size=1`` they equal the
``optimal_length`` column of MovingAI ``.scen`` files.

The search keeps everything in flat arrays indexed by ``row * width + col``:
g-costs, parents, a closed mask and an indexed binary heap with decrease-key
(ordered by f, ties broken towards the larger g), so there is no Python object
per node and the hot loop runs compiled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from worlds.maps import Cell, GridMap

SQRT2 = math.sqrt(2.0)

# Neighbour offsets: the 4 straight moves first, then the 4 diagonals.
_DR = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DC = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)


@dataclass(frozen=True)
class PathResult:
    """Result of a grid search. ``path`` runs from start to goal inclusive;
    ``length`` is in metres (``inf`` and ``path=None`` when there is no path);
    ``expanded`` counts nodes taken off the open list."""

    path: list[Cell] | None
    length: float
    found: bool
    expanded: int


@njit(cache=True, inline="always")
def _before(f: np.ndarray, g: np.ndarray, a: int, b: int) -> bool:
    """Heap order: smaller f first; on equal f the deeper node (larger g)."""
    if f[a] != f[b]:
        return f[a] < f[b]
    return g[a] > g[b]


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def _octile(r0, c0, r1, c1, diagonal):
    dr = abs(r0 - r1)
    dc = abs(c0 - c1)
    if not diagonal:
        return float(dr + dc)
    return float(max(dr, dc)) + (SQRT2 - 1.0) * min(dr, dc)


@njit(cache=True)
def _search(blocked, start, goal, diagonal):
    """Best-first search from ``start`` over the free cells of ``blocked``.

    With ``goal >= 0`` it is A* with the octile (or Manhattan) heuristic and
    stops when the goal is expanded; with ``goal < 0`` it is Dijkstra over the
    whole component. Returns (g, parent, expanded); unreached cells have g=inf.
    """
    height, width = blocked.shape
    n = height * width
    g = np.full(n, np.inf)
    f = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    pos = np.full(n, -1, dtype=np.int64)  # index in heap, -1 = not in heap
    closed = np.zeros(n, dtype=np.bool_)
    heap = np.empty(n, dtype=np.int64)
    n_moves = 8 if diagonal else 4
    gr = goal // width
    gc = goal % width
    g[start] = 0.0
    f[start] = _octile(start // width, start % width, gr, gc, diagonal) if goal >= 0 else 0.0
    heap[0] = start
    pos[start] = 0
    size = 1
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
    return g, parent, expanded


def _blocked_array(grid: GridMap | np.ndarray) -> tuple[np.ndarray, float]:
    if isinstance(grid, GridMap):
        return grid.blocked, grid.cell_size
    blocked = np.ascontiguousarray(grid, dtype=bool)
    if blocked.ndim != 2:
        raise ValueError(f"grid must be a GridMap or a 2-D bool array, got shape {blocked.shape}")
    return blocked, 1.0


def _check_connectivity(connectivity: int) -> bool:
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    return connectivity == 8


def astar(grid: GridMap | np.ndarray, start: Cell, goal: Cell, connectivity: int = 8) -> PathResult:
    """Shortest grid path from ``start`` to ``goal`` (cells ``(row, col)``).

    A blocked or out-of-map start/goal, or a goal in another component, gives
    ``found=False`` and ``length=inf`` rather than an exception.
    """
    diagonal = _check_connectivity(connectivity)
    blocked, cell_size = _blocked_array(grid)
    height, width = blocked.shape

    def usable(cell: Cell) -> bool:
        r, c = int(cell[0]), int(cell[1])
        return 0 <= r < height and 0 <= c < width and not blocked[r, c]

    if not (usable(start) and usable(goal)):
        return PathResult(None, math.inf, False, 0)
    s = int(start[0]) * width + int(start[1])
    t = int(goal[0]) * width + int(goal[1])
    g, parent, expanded = _search(blocked, s, t, diagonal)
    if not np.isfinite(g[t]):
        return PathResult(None, math.inf, False, int(expanded))
    path: list[Cell] = []
    node = t
    while node >= 0:
        path.append((node // width, node % width))
        node = int(parent[node])
    path.reverse()
    return PathResult(path, float(g[t]) * cell_size, True, int(expanded))


def distance_field(grid: GridMap | np.ndarray, goal: Cell, connectivity: int = 8) -> np.ndarray:
    """Shortest grid-path length in metres from every cell to ``goal``
    (``inf`` where blocked or unreachable). Moves are symmetric, so one
    Dijkstra from the goal gives every cell's distance to it."""
    diagonal = _check_connectivity(connectivity)
    blocked, cell_size = _blocked_array(grid)
    out = np.full(blocked.shape, np.inf)
    r, c = int(goal[0]), int(goal[1])
    if not (0 <= r < blocked.shape[0] and 0 <= c < blocked.shape[1]) or blocked[r, c]:
        return out
    g, _, _ = _search(blocked, r * blocked.shape[1] + c, -1, diagonal)
    return g.reshape(blocked.shape) * cell_size


def path_length(path: list[Cell], cell_size: float = 1.0) -> float:
    """Length in metres of a cell path (straight steps 1, diagonal steps sqrt(2), times ``cell_size``)."""
    if len(path) < 2:
        return 0.0
    steps = np.diff(np.asarray(path, dtype=np.float64), axis=0)
    return float(np.hypot(steps[:, 0], steps[:, 1]).sum() * cell_size)

"""Grid A* (8- or 4-connected) and grid distance fields, compiled with numba.

Move rules are MovingAI's: a straight move costs 1 cell, a diagonal sqrt(2),
and a diagonal move is allowed only when both cells it brushes past are free
(it never cuts the corner of a blocked cell). Lengths are returned in metres
(cells times ``grid.cell_size``), so for ``cell_size=1`` they equal the
``optimal_length`` column of MovingAI ``.scen`` files.

The search itself is :func:`worlds.gridsearch.grid_search` (shared with the world's
own-map subgoal and geodesic reward); this module wraps it for maps and cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worlds.gridsearch import grid_search
from worlds.maps import Cell, GridMap


@dataclass(frozen=True)
class PathResult:
    """Result of a grid search. ``path`` runs from start to goal inclusive;
    ``length`` is in metres (``inf`` and ``path=None`` when there is no path);
    ``expanded`` counts nodes taken off the open list."""

    path: list[Cell] | None
    length: float
    found: bool
    expanded: int


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
    g, parent, expanded = grid_search(blocked, s, t, diagonal)
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
    g, _, _ = grid_search(blocked, r * blocked.shape[1] + c, -1, diagonal)
    return g.reshape(blocked.shape) * cell_size


def path_length(path: list[Cell], cell_size: float = 1.0) -> float:
    """Length in metres of a cell path (straight steps 1, diagonal steps sqrt(2), times ``cell_size``)."""
    if len(path) < 2:
        return 0.0
    steps = np.diff(np.asarray(path, dtype=np.float64), axis=0)
    return float(np.hypot(steps[:, 0], steps[:, 1]).sum() * cell_size)

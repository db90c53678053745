"""Start/goal pairs on any map, drawn by shortest-path distance the way MovingAI scenarios are.

A pair is usable when a robot of radius ``r`` can stand on both cells and drive between them:
:func:`robot_cells` keeps the cells whose centre is further than ``r`` from every blocked cell's
square and from the map border (the kernel's collision rule at rest), and the pair's two cells are
joined through such cells (8-connected without corner cutting, the moves of
:mod:`worlds.gridsearch`). Its distance is the shortest path through those cells, in metres.

:func:`draw_pairs` draws pairs seeded, at any map size, spread over distance buckets: the range
``[min_distance, max_distance]`` (``max_distance`` capped at the longest distance found) is cut
into ``buckets`` equal buckets and each pair's bucket is drawn uniformly, so short and long episodes come in
equal numbers, as in MovingAI's ``.scen`` files (which bucket by ``floor(length / 4)``). The
distances come from full Dijkstra searches from at most :data:`ANCHORS` start cells drawn uniformly
over the usable cells (a search over a 512x512 map takes tens of milliseconds, so a pool of 1024
pairs costs 16 searches, not 1024); each pair takes an anchor in turn and a goal drawn in its
bucket, and start and goal swap with probability one half.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import ndimage

from worlds.gridsearch import grid_search
from worlds.maps import GridMap, MapFormatError, Task

ANCHORS = 16
"""most Dijkstra searches one :func:`draw_pairs` call runs"""
BUCKETS = 10
"""distance buckets of :func:`draw_pairs` by default"""
_FOUR = ndimage.generate_binary_structure(2, 1)


def robot_cells(grid: GridMap, radius: float) -> np.ndarray:
    """Cells whose centre is more than ``radius`` metres from every blocked cell's square and from
    the map's border: where a robot disc of that radius may stand."""
    rho = radius / grid.cell_size
    reach = max(1, math.ceil(rho + 0.5))
    offsets = np.arange(-reach, reach + 1)
    dr, dc = np.meshgrid(offsets, offsets, indexing="ij")
    near = np.hypot(np.maximum(np.abs(dr) - 0.5, 0.0), np.maximum(np.abs(dc) - 0.5, 0.0)) <= rho
    padded = np.pad(grid.blocked, reach, constant_values=True)
    grown = ndimage.binary_dilation(padded, structure=near)
    return ~grown[reach:-reach, reach:-reach]


def check_usable(grid: GridMap, radius: float, source: str | Path, scale: float = 1.0) -> None:
    """A :class:`MapFormatError` naming ``source`` unless two cells a robot of ``radius`` fits on are
    4-connected through such cells (``scale``: world metres per metre of the file, which the message
    speaks in)."""
    labels, count = ndimage.label(robot_cells(grid, radius), structure=_FOUR)
    sizes = np.bincount(labels.ravel())[1:]
    if count == 0 or sizes.max() < 2:
        raise MapFormatError(
            source,
            None,
            f"no two connected free cells a robot of radius {radius / scale:g} m fits on ({grid.width}x"
            f"{grid.height} cells of {grid.cell_size / scale:g} m, {int((~grid.blocked).sum())} free): check "
            "the thresholds, negate, or give unknown=free",
        )


def draw_pairs(
    grid: GridMap,
    n: int,
    seed: int,
    radius: float,
    min_distance: float = 0.0,
    max_distance: float = math.inf,
    buckets: int = BUCKETS,
) -> list[tuple[Task, float]]:
    """``n`` start/goal tasks on ``grid`` with their path length (m) through cells a robot of
    ``radius`` fits on, between ``min_distance`` and ``max_distance`` metres, spread over
    ``buckets`` distance buckets (module docstring). Same arguments, same pairs. A ValueError names
    the map and the distances when no pair fits."""
    if n < 1:
        raise ValueError(f"need at least one pair, got {n}")
    if not (min_distance >= 0 and max_distance > min_distance):
        raise ValueError(f"distances must satisfy 0 <= min ({min_distance}) < max ({max_distance})")
    ok = robot_cells(grid, radius)
    cells = np.argwhere(ok)
    if len(cells) < 2:
        raise ValueError(f"map {grid.name!r}: fewer than two cells a robot of radius {radius:g} m fits on")
    rng = np.random.default_rng([seed, 104729])
    blocked = ~ok
    width = grid.width
    anchors = cells[rng.choice(len(cells), size=min(ANCHORS, n, len(cells)), replace=False)]
    fields = []
    longest = 0.0
    for a in anchors:
        g, _, _ = grid_search(blocked, int(a[0]) * width + int(a[1]), -1, True)
        dist = g * grid.cell_size
        finite = dist[np.isfinite(dist)]
        longest = max(longest, float(finite.max()) if len(finite) else 0.0)
        fields.append(dist)
    hi = min(max_distance, longest)
    if hi <= min_distance:
        raise ValueError(
            f"map {grid.name!r}: no pair at least {min_distance:g} m apart (the longest path found is "
            f"{longest:.1f} m); lower min_distance"
        )
    edges = np.linspace(min_distance, hi, buckets + 1)
    per_anchor = []
    for dist in fields:
        index = np.flatnonzero((dist >= min_distance) & (dist <= hi) & (dist > 0))
        which = np.clip(np.searchsorted(edges, dist[index], side="right") - 1, 0, buckets - 1)
        per_anchor.append([index[which == b] for b in range(buckets)])
    usable = [k for k in range(len(anchors)) if any(len(b) for b in per_anchor[k])]
    if not usable:
        raise ValueError(f"map {grid.name!r}: no pair between {min_distance:g} and {hi:g} m")
    tasks: list[tuple[Task, float]] = []
    for k in range(n):
        a = usable[k % len(usable)]
        filled = [b for b in range(buckets) if len(per_anchor[a][b])]
        bucket = per_anchor[a][filled[int(rng.integers(len(filled)))]]
        goal_index = int(bucket[rng.integers(len(bucket))])
        start = (int(anchors[a][0]), int(anchors[a][1]))
        goal = (goal_index // width, goal_index % width)
        if rng.random() < 0.5:
            start, goal = goal, start
        tasks.append((Task(grid, start, goal, grid.name), float(fields[a].ravel()[goal_index])))
    return tasks

"""Range sensors: exact grid ray casting (Amanatides & Woo 1987) vectorised over robots
and beams, plus moving discs.

A beam starts at the robot centre and returns the distance to the first point where
it enters a blocked cell or leaves the map, capped at ``max_range``. The traversal is
exact: it visits every cell the ray crosses, in order, and the hit distance is the
ray parameter at the boundary of the first blocked cell.

Empty space is skipped with the *gap field*: for a free cell ``c`` it holds
``min over blocked b of hypot(max(0,|dr|-1), max(0,|dc|-1)) * cell``, the exact
distance between the squares of ``c`` and ``b``, so no blocked point lies within it
of any point of ``c``. The ray may jump that far (sphere tracing) without crossing a
blocked cell, and the exact traversal resumes where it lands, so distances stay exact.
(It equals the centre distance from ``c`` to the blocked set grown by one cell: moving
each ``b`` one cell towards ``c`` along both axes gives a grown cell at that distance,
and every grown cell is within one cell per axis of a blocked one.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.maps import GridMap
from worlds.robot import gap_field

JUMP_MIN = 1.5
"""sphere-trace only where the gap is at least this many cells; below it one exact step is as cheap"""


@njit(cache=True)
def cast_ray(blocked, off, height, width, cell, gap, x, y, dx, dy, max_range) -> float:
    """Distance (m) from (x, y) along the unit vector (dx, dy) to the first blocked cell or the
    map border, at most ``max_range``. 0 when the origin is blocked or outside."""
    px, py = x / cell, y / cell  # cell units from here on
    limit = max_range / cell
    c, r = math.floor(px), math.floor(py)
    if r < 0 or c < 0 or r >= height or c >= width or blocked[off + r * width + c]:
        return 0.0
    step_c = 1 if dx > 0.0 else -1
    step_r = 1 if dy > 0.0 else -1
    delta_c = abs(1.0 / dx) if dx != 0.0 else math.inf
    delta_r = abs(1.0 / dy) if dy != 0.0 else math.inf
    t = 0.0
    while True:
        skip = gap[off + r * width + c] / cell
        if skip >= JUMP_MIN:
            t += skip - 1e-9
            if t >= limit:
                return max_range
            c, r = math.floor(px + t * dx), math.floor(py + t * dy)
        # parameters of the next vertical and horizontal cell boundary crossings
        next_c = ((c + 1 - px) / dx if dx > 0.0 else (c - px) / dx) if dx != 0.0 else math.inf
        next_r = ((r + 1 - py) / dy if dy > 0.0 else (r - py) / dy) if dy != 0.0 else math.inf
        while True:
            if next_c < next_r:
                t = next_c
                c += step_c
                next_c += delta_c
            else:
                t = next_r
                r += step_r
                next_r += delta_r
            if t >= limit:
                return max_range
            if r < 0 or c < 0 or r >= height or c >= width or blocked[off + r * width + c]:
                return t * cell
            if gap[off + r * width + c] / cell >= JUMP_MIN:
                break


@njit(cache=True, inline="always")
def ray_disc(x, y, dx, dy, ox, oy, radius) -> float:
    """Distance along the unit ray from (x, y) to the disc's edge; inf when missed, 0 inside."""
    fx, fy = x - ox, y - oy
    c = fx * fx + fy * fy - radius * radius
    if c <= 0.0:
        return 0.0
    b = fx * dx + fy * dy
    if b >= 0.0:
        return math.inf
    disc = b * b - c
    if disc < 0.0:
        return math.inf
    return -b - math.sqrt(disc)


@njit(cache=True)
def _cast_batch(blocked, gap, height, width, cell, x, y, theta, angles, max_range, discs, out):
    for i in range(x.shape[0]):
        for k in range(angles.shape[0]):
            dx, dy = math.cos(theta[i] + angles[k]), math.sin(theta[i] + angles[k])
            d = cast_ray(blocked, 0, height, width, cell, gap, x[i], y[i], dx, dy, max_range)
            for j in range(discs.shape[0]):
                d = min(d, ray_disc(x[i], y[i], dx, dy, discs[j, 0], discs[j, 1], discs[j, 2]))
            out[i, k] = d


def cast_rays(
    grid: GridMap,
    x: np.ndarray,
    y: np.ndarray,
    theta: np.ndarray,
    angles: np.ndarray,
    max_range: float,
    discs: np.ndarray | None = None,
) -> np.ndarray:
    """Exact ranges (m), shape ``(n_robots, n_beams)``, for robots at (x, y, theta) with beams at
    ``angles`` relative to the heading. ``discs`` is an optional ``(k, 3)`` array of moving
    discs (x, y, radius) the beams also see. No noise here; the environment adds it."""
    x, y, theta = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (x, y, theta))
    angles = np.atleast_1d(np.asarray(angles, dtype=np.float64))
    discs = np.zeros((0, 3)) if discs is None else np.asarray(discs, dtype=np.float64).reshape(-1, 3)
    out = np.empty((x.shape[0], angles.shape[0]), dtype=np.float64)
    blocked = grid.blocked.ravel().astype(np.uint8)
    gap = gap_field(grid).ravel()
    _cast_batch(
        blocked, gap, grid.height, grid.width, grid.cell_size, x, y, theta, angles, max_range, discs, out
    )
    return out


@njit(cache=True)
def _cast_exact_reference(blocked, height, width, cell, x, y, dx, dy, max_range) -> float:
    """Plain traversal without skipping, kept to check :func:`cast_ray` in the tests."""
    zero_gap = np.zeros(height * width)
    return cast_ray(blocked, 0, height, width, cell, zero_gap, x, y, dx, dy, max_range)

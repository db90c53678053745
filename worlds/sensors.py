"""Range sensors: exact grid ray casting (Amanatides & Woo 1987) vectorised over robots
and beams, plus moving discs.

A beam starts at the robot centre and returns the distance to the first point where
it enters a blocked cell or leaves the map, capped at ``max_range``. The traversal is
exact: it visits every cell the ray crosses, in order, and the hit distance is the
ray parameter at the boundary of the first blocked cell.

Empty space is skipped with the gap field (:mod:`worlds.fields`): from a cell whose gap
is ``g`` the ray may jump ``g`` without crossing a blocked cell (sphere tracing), and the
exact traversal resumes where it lands, so distances stay exact.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.fields import BLOCKED, GAP_UNIT, cached_kernel_field, kernel_field
from worlds.maps import GridMap

JUMP_MIN = 6
"""sphere-trace only where the gap is at least this many GAP_UNITs (1.5 cells); below it one exact
step is as cheap"""


@njit(cache=True, inline="always")
def cast_ray(field, off, height, width, cell, x, y, dx, dy, max_range) -> float:
    """Distance (m) from (x, y) along the unit vector (dx, dy) to the first blocked cell or the
    map border, at most ``max_range``; 0 when the origin is blocked or outside the map.
    ``field`` and ``off`` locate the map as :func:`worlds.fields.kernel_field` lays it out;
    the blocked ring around it stops every ray, so the traversal needs no bounds checks."""
    px, py = x / cell, y / cell  # cell units from here on
    limit = max_range / cell
    c, r = math.floor(px), math.floor(py)
    if r < 0 or c < 0 or r >= height or c >= width:
        return 0.0
    pw = width + 2
    idx = off + (r + 1) * pw + c + 1
    value = field[idx]
    if value == BLOCKED:
        return 0.0
    # per axis: index step, distance between boundary crossings, parameter of the next crossing
    step_c, step_r = (1 if dx > 0.0 else -1), (pw if dy > 0.0 else -pw)
    inv_dx = 1.0 / dx if dx != 0.0 else math.inf
    inv_dy = 1.0 / dy if dy != 0.0 else math.inf
    delta_c, delta_r = abs(inv_dx), abs(inv_dy)
    side_c, side_r = (1.0 if dx > 0.0 else 0.0), (1.0 if dy > 0.0 else 0.0)
    next_c = (c + side_c - px) * inv_dx if dx != 0.0 else math.inf
    next_r = (r + side_r - py) * inv_dy if dy != 0.0 else math.inf
    t = 0.0
    while True:
        if value >= JUMP_MIN:  # skip empty space, then resume the exact traversal where we land
            t += value * GAP_UNIT - 1e-9
            if t >= limit:
                return max_range
            c, r = math.floor(px + t * dx), math.floor(py + t * dy)
            idx = off + (r + 1) * pw + c + 1
            next_c = (c + side_c - px) * inv_dx if dx != 0.0 else math.inf
            next_r = (r + side_r - py) * inv_dy if dy != 0.0 else math.inf
            # rounding may put a landing point on a boundary into the cell behind it: step over
            # boundaries the ray has already crossed, so t never goes back
            while next_c < t:
                idx += step_c
                next_c += delta_c
            while next_r < t:
                idx += step_r
                next_r += delta_r
        if next_c < next_r:
            t = next_c
            idx += step_c
            next_c += delta_c
        else:
            t = next_r
            idx += step_r
            next_r += delta_r
        if t >= limit:
            return max_range
        value = field[idx]
        if value == BLOCKED:
            return t * cell


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
def _cast_batch(field, height, width, cell, x, y, theta, angles, max_range, discs, out):
    for i in range(x.shape[0]):
        for k in range(angles.shape[0]):
            dx, dy = math.cos(theta[i] + angles[k]), math.sin(theta[i] + angles[k])
            d = cast_ray(field, 0, height, width, cell, x[i], y[i], dx, dy, max_range)
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
    field = cached_kernel_field(grid)
    _cast_batch(field, *grid.shape, grid.cell_size, x, y, theta, angles, max_range, discs, out)
    return out


def cast_rays_without_skipping(grid: GridMap, x, y, theta, angles, max_range: float) -> np.ndarray:
    """:func:`cast_rays` with a zero gap field: the plain cell-by-cell traversal (for tests)."""
    x, y, theta = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (x, y, theta))
    angles = np.atleast_1d(np.asarray(angles, dtype=np.float64))
    out = np.empty((x.shape[0], angles.shape[0]), dtype=np.float64)
    field = kernel_field(grid)
    field = np.where(field == BLOCKED, BLOCKED, 0).astype(np.uint8).ravel()
    _cast_batch(field, *grid.shape, grid.cell_size, x, y, theta, angles, max_range, np.zeros((0, 3)), out)
    return out

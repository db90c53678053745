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

JUMP_MIN = 10
"""sphere-trace only where the gap is at least this many GAP_UNITs (2.5 cells): with 6 m beams on
small maps shorter jumps cost more than the exact steps they replace (measured)"""


@njit(cache=True)
def ray_origin(field, off, height, width, cell, x, y):
    """Where rays from (x, y) start: (field index of the origin cell, its column and row, the origin
    in cell units), or index -1 when the origin is outside the map or blocked."""
    px, py = x / cell, y / cell
    if px < 0.0 or py < 0.0 or px >= width or py >= height:
        return -1, 0, 0, px, py
    c, r = int(px), int(py)
    idx = off + (r + 1) * (width + 2) + c + 1
    if field[idx] == BLOCKED:
        return -1, c, r, px, py
    return idx, c, r, px, py


@njit(cache=True)
def reciprocal(d: float) -> float:
    """``1 / d`` of a direction component, inf for 0 (of either sign): the traversal's spacing of
    boundary crossings. (No division by zero is ever evaluated, so no branch raises.)"""
    q = 1.0 / (d if d != 0.0 else 1.0)
    return q if d != 0.0 else math.inf


@njit(cache=True)
def cast_from(field, off, width, idx, c, r, px, py, dx, dy, limit) -> float:
    """Distance in cells along the unit vector (dx, dy) from an origin found by :func:`ray_origin`
    to the first blocked cell (the blocked ring around the map stops every ray, so the traversal
    needs no bounds checks), at most ``limit``."""
    return cast_along(field, off, width, idx, c, r, px, py, dx, dy, reciprocal(dx), reciprocal(dy), limit)


@njit(cache=True)
def cast_along(field, off, width, idx, c, r, px, py, dx, dy, inv_dx, inv_dy, limit) -> float:
    """:func:`cast_from` given the direction's :func:`reciprocal` components ``inv_dx``, ``inv_dy``
    (a caller casting many rays computes them side by side)."""
    pw = width + 2
    # per axis: index step, distance between boundary crossings, parameter of the next crossing
    step_c, step_r = (1 if dx > 0.0 else -1), (pw if dy > 0.0 else -pw)
    delta_c, delta_r = abs(inv_dx), abs(inv_dy)
    side_c, side_r = (1.0 if dx > 0.0 else 0.0), (1.0 if dy > 0.0 else 0.0)
    next_c = (c + side_c - px) * inv_dx if dx != 0.0 else math.inf
    next_r = (r + side_r - py) * inv_dy if dy != 0.0 else math.inf
    value = field[idx]
    t = 0.0
    while True:
        if value >= JUMP_MIN:  # skip empty space, then resume the exact traversal where we land
            t += value * GAP_UNIT - 1e-9
            if t >= limit:
                return limit
            c, r = int(px + t * dx), int(py + t * dy)
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
        on_c = next_c < next_r  # selects, not branches: which boundary comes next is a coin toss
        t = next_c if on_c else next_r
        idx += step_c if on_c else step_r
        next_c = next_c + delta_c if on_c else next_c  # (not += 0.0, which would turn -0.0 into 0.0)
        next_r = next_r if on_c else next_r + delta_r
        if t >= limit:
            return limit
        value = field[idx]
        if value == BLOCKED:
            return t


@njit(cache=True)
def cast_ray(field, off, height, width, cell, x, y, dx, dy, max_range) -> float:
    """Distance (m) from (x, y) along the unit vector (dx, dy) to the first blocked cell or the
    map border, at most ``max_range``; 0 when the origin is blocked or outside the map.
    ``field`` and ``off`` locate the map as :func:`worlds.fields.kernel_field` lays it out."""
    idx, c, r, px, py = ray_origin(field, off, height, width, cell, x, y)
    if idx < 0:
        return 0.0
    return min(cast_from(field, off, width, idx, c, r, px, py, dx, dy, max_range / cell) * cell, max_range)


@njit(cache=True)
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

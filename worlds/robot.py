"""Unicycle kinematics and collision geometry (thesis ch. 2.5).

An action turns the robot in place by ``turn`` then drives it ``step`` metres
straight ahead, so one action sweeps the robot disc along a segment (a capsule);
the turn-around (``RobotConfig.turn_around``, taken only by the reading shield)
turns half a turn in place and sweeps nothing.
The compiled helpers here are shared by the environment kernel; the numpy
functions are the same maths for callers outside it (planners, tests).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.fields import BLOCKED, GAP_UNIT, cached_kernel_field
from worlds.maps import GridMap


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Angle(s) wrapped to ``[-pi, pi)``."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


@njit(cache=True)
def held(theta: float, headings: float) -> float:
    """``theta`` turned to the nearest of ``headings`` compass headings (multiples of ``2 pi /
    headings``), the heading a robot that holds them (``RobotConfig.held_headings``) starts its next
    action from; ``theta`` itself where ``headings`` is 0 (not held)."""
    if headings <= 0.0:
        return theta
    quantum = 2.0 * math.pi / headings
    return round(theta / quantum) * quantum


def move(
    x: np.ndarray,
    y: np.ndarray,
    theta: np.ndarray,
    turn: np.ndarray,
    step: float | np.ndarray,
    trans_noise: float = 0.0,
    rot_noise: float = 0.0,
    rng: np.random.Generator | None = None,
    held_headings: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Apply one action to a batch of robots: ``theta += turn (+ noise)``, then move
    ``step (+ noise)`` metres along the new heading (never backwards); with ``held_headings``,
    ``theta`` is first turned to the nearest of that many compass headings (:func:`held`). Arrays
    in, arrays out."""
    x, y, theta, turn = (np.asarray(a, dtype=np.float64) for a in (x, y, theta, turn))
    shape = np.broadcast_shapes(x.shape, y.shape, theta.shape, turn.shape)
    if held_headings > 0:
        theta = np.vectorize(held, otypes=[np.float64])(theta, float(held_headings))
    heading = theta + turn
    distance = np.broadcast_to(np.asarray(step, dtype=np.float64), shape)
    if rot_noise > 0 or trans_noise > 0:
        if rng is None:
            raise ValueError("motion noise needs an rng")
        heading = heading + rot_noise * rng.standard_normal(shape)
        distance = np.maximum(distance + trans_noise * rng.standard_normal(shape), 0.0)
    heading = wrap_angle(heading)
    return x + distance * np.cos(heading), y + distance * np.sin(heading), heading


@njit(cache=True)
def _point_box_sq(px: float, py: float, x0: float, y0: float, x1: float, y1: float) -> float:
    dx = max(x0 - px, 0.0, px - x1)
    dy = max(y0 - py, 0.0, py - y1)
    return dx * dx + dy * dy


@njit(cache=True)
def _point_segment_sq(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    vx, vy = bx - ax, by - ay
    length_sq = vx * vx + vy * vy
    t = 0.0
    if length_sq > 0.0:
        t = min(1.0, max(0.0, ((px - ax) * vx + (py - ay) * vy) / length_sq))
    dx, dy = ax + t * vx - px, ay + t * vy - py
    return dx * dx + dy * dy


@njit(cache=True)
def _segment_hits_box(ax: float, ay: float, bx: float, by: float, x0: float, y0: float, x1: float, y1: float):
    """Slab test: does segment a->b meet the closed box [x0, x1] x [y0, y1]?"""
    t_lo, t_hi = 0.0, 1.0
    for p, d, lo, hi in ((ax, bx - ax, x0, x1), (ay, by - ay, y0, y1)):
        if d == 0.0:
            if p < lo or p > hi:
                return False
        else:
            t0, t1 = (lo - p) / d, (hi - p) / d
            if t0 > t1:
                t0, t1 = t1, t0
            t_lo, t_hi = max(t_lo, t0), min(t_hi, t1)
            if t_lo > t_hi:
                return False
    return True


@njit(cache=True)
def segment_box_distance_sq(ax, ay, bx, by, x0, y0, x1, y1) -> float:
    """Squared distance between segment a->b and the box; 0 when they meet. For two disjoint
    convex polygons the closest pair includes a vertex, so endpoints and corners suffice."""
    if _segment_hits_box(ax, ay, bx, by, x0, y0, x1, y1):
        return 0.0
    best = min(_point_box_sq(ax, ay, x0, y0, x1, y1), _point_box_sq(bx, by, x0, y0, x1, y1))
    best = min(best, _point_segment_sq(x0, y0, ax, ay, bx, by), _point_segment_sq(x1, y0, ax, ay, bx, by))
    return min(best, _point_segment_sq(x0, y1, ax, ay, bx, by), _point_segment_sq(x1, y1, ax, ay, bx, by))


@njit(cache=True)
def capsule_hits_grid(field, off, height, width, cell, x0, y0, x1, y1, radius) -> bool:
    """Does a disc of ``radius`` swept from (x0, y0) to (x1, y1) touch a blocked cell or leave
    the map? ``field``/``off`` locate the map in a bank (see :func:`worlds.fields.kernel_field`)."""
    if min(x0, x1) - radius < 0.0 or min(y0, y1) - radius < 0.0:
        return True
    if max(x0, x1) + radius > width * cell or max(y0, y1) + radius > height * cell:
        return True
    pw = width + 2
    gap = field[off + (int(y0 / cell) + 1) * pw + int(x0 / cell) + 1]
    if (
        gap != BLOCKED and gap * (GAP_UNIT * cell) > math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2) + radius
    ):  # nothing within reach
        return False
    r_lo = max(int((min(y0, y1) - radius) / cell), 0)
    r_hi = min(int((max(y0, y1) + radius) / cell), height - 1)
    c_lo = max(int((min(x0, x1) - radius) / cell), 0)
    c_hi = min(int((max(x0, x1) + radius) / cell), width - 1)
    r_sq = radius * radius
    for r in range(r_lo, r_hi + 1):
        for c in range(c_lo, c_hi + 1):
            if field[off + (r + 1) * pw + c + 1] == BLOCKED:
                d_sq = segment_box_distance_sq(
                    x0, y0, x1, y1, c * cell, r * cell, (c + 1) * cell, (r + 1) * cell
                )
                if d_sq < r_sq:
                    return True
    return False


@njit(cache=True)
def _collides_batch(field, height, width, cell, x0, y0, x1, y1, radius, out):
    for i in range(x0.shape[0]):
        out[i] = capsule_hits_grid(field, 0, height, width, cell, x0[i], y0[i], x1[i], y1[i], radius)


def collides(grid: GridMap, x0, y0, x1, y1, radius: float) -> np.ndarray:
    """Per robot: does its disc, swept from (x0, y0) to (x1, y1), touch a blocked cell or the border?"""
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x0, y0, x1, y1)))
    flat = [np.ascontiguousarray(a).ravel() for a in arrays]
    out = np.empty(flat[0].shape, dtype=bool)
    field = cached_kernel_field(grid)
    _collides_batch(field, grid.height, grid.width, grid.cell_size, *flat, float(radius), out)
    return out.reshape(arrays[0].shape)

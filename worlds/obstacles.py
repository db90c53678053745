"""Moving disc obstacles: constant velocity bouncing off walls, or patrolling back and
forth between two waypoints. Range beams see them; touching one ends the episode.

Discs move once per step, before the collision test, along a straight segment; they
pass through each other. A bouncing disc whose next position along one axis would
touch a wall or the border reverses that velocity component and stays put on that
axis for the step. A patrolling disc reverses when it reaches a waypoint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from worlds.rng import randint, uniform
from worlds.robot import _point_segment_sq, capsule_hits_grid


@dataclass
class DiscObstacles:
    """The moving discs of one episode, for ``reset(options={"obstacles": ...})``.

    ``position`` and ``velocity`` are ``(k, 2)`` arrays of (x, y) in m and m/step,
    ``radius`` a scalar or ``(k,)``. With ``waypoints`` (``(k, 2, 2)``: the two ends
    of each disc's patrol segment) the discs patrol, otherwise they bounce."""

    position: np.ndarray
    velocity: np.ndarray
    radius: np.ndarray | float
    waypoints: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.position = np.asarray(self.position, dtype=np.float64).reshape(-1, 2)
        self.velocity = np.asarray(self.velocity, dtype=np.float64).reshape(-1, 2)
        k = len(self.position)
        self.radius = np.broadcast_to(np.asarray(self.radius, dtype=np.float64), (k,)).copy()
        if self.velocity.shape != (k, 2):
            raise ValueError(f"velocity must be ({k}, 2), got {self.velocity.shape}")
        if self.waypoints is not None:
            self.waypoints = np.asarray(self.waypoints, dtype=np.float64).reshape(k, 2, 2)
        if not (np.all(np.isfinite(self.position)) and np.all(np.isfinite(self.velocity))):
            raise ValueError("obstacle positions and velocities must be finite")
        if np.any(self.radius <= 0):
            raise ValueError("obstacle radii must be positive")

    def __len__(self) -> int:
        return len(self.position)


@njit(cache=True)
def move_disc(field, off, height, width, cell, x, y, vx, vy, radius, patrol, ax, ay, bx, by):
    """One step of one disc; returns the new (x, y, vx, vy)."""
    if patrol:
        nx, ny = x + vx, y + vy
        # heading to b when the velocity points from a to b, else to a
        tx, ty = (bx, by) if vx * (bx - ax) + vy * (by - ay) > 0.0 else (ax, ay)
        if (tx - nx) * vx + (ty - ny) * vy <= 0.0:
            return tx, ty, -vx, -vy
        return nx, ny, vx, vy
    nx = x + vx
    if capsule_hits_grid(field, off, height, width, cell, nx, y, nx, y, radius):
        nx, vx = x, -vx
    ny = y + vy
    if capsule_hits_grid(field, off, height, width, cell, nx, ny, nx, ny, radius):
        ny, vy = y, -vy
    return nx, ny, vx, vy


@njit(cache=True)
def swept_contact(rx0, ry0, rx1, ry1, ox0, oy0, ox1, oy1, reach) -> bool:
    """Do the robot (r0 -> r1) and a disc (o0 -> o1), both moving linearly over the step, come
    closer than ``reach`` (sum of radii)? Their relative position is linear in time."""
    d_sq = _point_segment_sq(0.0, 0.0, rx0 - ox0, ry0 - oy0, rx1 - ox1, ry1 - oy1)
    return d_sq < reach * reach


@njit(cache=True)
def place_discs(
    i, rng, field, off, height, width, cell, cand, cand_off, cand_n, sx, sy, keep_out, spec, discs
):
    """Place robot ``i``'s discs at random candidate cell centres (flat indices ``cand[cand_off:
    cand_off + cand_n]``) at least ``keep_out`` from the start (sx, sy), with random directions.
    ``spec`` = (count, radius, speed, patrol, patrol_length); ``discs`` the kernel's disc arrays.
    Returns how many were placed (32 tries each)."""
    count, radius, speed, patrol, patrol_length = spec
    ox, oy, ovx, ovy, orad, opat, oax, oay, obx, oby = discs[:10]
    placed = 0
    for _ in range(count):
        for _try in range(32):
            cell_index = cand[cand_off + randint(rng, i, cand_n)]
            x = (cell_index % width + 0.5) * cell
            y = (cell_index // width + 0.5) * cell
            angle = 2.0 * math.pi * uniform(rng, i)
            if math.hypot(x - sx, y - sy) < keep_out:
                continue
            if capsule_hits_grid(field, off, height, width, cell, x, y, x, y, radius):
                continue
            dx, dy = math.cos(angle), math.sin(angle)
            k = placed
            ox[i, k], oy[i, k], orad[i, k] = x, y, radius
            ovx[i, k], ovy[i, k] = speed * dx, speed * dy
            opat[i, k] = patrol
            oax[i, k], oay[i, k], obx[i, k], oby[i, k] = x, y, x, y
            if patrol:  # the longest of 8 random directions' free segments, in quarter-metre steps
                best = 0.0
                for _turn in range(8):
                    length = 0.0
                    while length + 0.25 <= patrol_length:
                        ex, ey = x + (length + 0.25) * dx, y + (length + 0.25) * dy
                        if capsule_hits_grid(field, off, height, width, cell, x, y, ex, ey, radius):
                            break
                        length += 0.25
                    if length > best:
                        best = length
                        ovx[i, k], ovy[i, k] = speed * dx, speed * dy
                        obx[i, k], oby[i, k] = x + length * dx, y + length * dy
                    if best >= patrol_length:
                        break
                    angle = 2.0 * math.pi * uniform(rng, i)
                    dx, dy = math.cos(angle), math.sin(angle)
                if best < speed:  # boxed in: it stands still
                    ovx[i, k], ovy[i, k] = 0.0, 0.0
            placed += 1
            break
    return placed

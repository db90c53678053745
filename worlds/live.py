"""The world's observation for a robot outside the world: measured rays and poses in, the
policy's observation out, built by the same code as in the world.

A real robot (``navlearn drive``, :mod:`services.drive`) has no map of its surroundings, only
range readings and odometry. :class:`LiveObserver` turns them into exactly what a policy saw in
training: the kernel's base observation (sector minima of the rays over ``max_range``, the
goal's squashed distance and bearing; the same arithmetic as :func:`worlds.kernel._observe`,
without noise) and then everything :class:`worlds.perception.Perception` adds (own map,
subgoal, frame stack, previous action), by calling :class:`~worlds.perception.Perception`
itself on a :class:`Workspace`: an empty grid, in the odometry frame, around the robot and its
goal. The own map's extent is that workspace (as the world's is the map's bounding box), its
content only what the robot's rays saw; the goal sits at a cell centre, as in the world.

``tests/test_drive_observation.py`` proves that it is one builder: fed the world's own rays and
poses on the world's grid, the observations equal the world's, step by step.

Measured rays need one more step (``snap_hits``). The world's rays are exact: each ends on the
face of the blocked cell it hits, so the own map marks that cell blocked and the cells before it
free. A measured range is off by the sensor's noise and by resampling: a little short, and the map
marks the free cell in front of the wall as blocked; a little long, and the free trace of the ray
runs into the wall cell and clears it. With ``snap_hits`` the own map gets, for every return, the
range at which the ray enters the cell its measured end point lies in (a hair less): that cell is
marked blocked and no trace clears it, as with the world's rays. The readings (sector minima) keep
the measured ranges. The caller moves returns a little past the measurement first
(``services.drive.scan.pad_returns``), so that a short reading of a wall still ends inside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worlds.config import NavConfig
from worlds.fields import BLOCKED
from worlds.perception import Perception, needed, observation_dim

MAX_CELLS = 1024
"""the largest workspace side (cells): a goal further away than this is refused"""


@dataclass(frozen=True)
class Workspace:
    """An axis-aligned grid in the robot's odometry frame: cell (r, c) spans
    ``origin + [c, c + 1) x [r, r + 1) * cell`` (x along columns, y along rows, as in the world)."""

    origin_x: float
    origin_y: float
    height: int
    width: int
    cell: float

    @classmethod
    def around(cls, pose: tuple[float, float], goal: tuple[float, float], margin: float, cell: float):
        """The grid covering ``pose`` and ``goal`` with ``margin`` metres on every side, shifted so
        that the goal lies at a cell centre (the world's goals are cell centres). Raises ValueError
        when it would exceed :data:`MAX_CELLS` cells a side."""
        if not (cell > 0 and margin >= 0):
            raise ValueError(f"workspace cell must be > 0 and margin >= 0, got {cell}, {margin}")
        sides = []
        for p, g in zip(pose, goal, strict=True):
            low = min(p, g) - margin
            k = math.floor((g - low) / cell)  # the goal's cell index
            origin = g - (k + 0.5) * cell
            size = math.ceil((max(p, g) + margin - origin) / cell)
            if size > MAX_CELLS:
                raise ValueError(
                    f"the goal is {abs(g - p):.1f} m away: a workspace of {size} cells of {cell} m a side "
                    f"exceeds {MAX_CELLS}; give a nearer goal or a larger cell"
                )
            sides.append((origin, size))
        (ox, w), (oy, h) = sides
        return cls(ox, oy, h, w, cell)

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(row, column) of point (x, y) of the odometry frame."""
        return math.floor((y - self.origin_y) / self.cell), math.floor((x - self.origin_x) / self.cell)

    def kernel_maps(self) -> tuple:
        """The workspace as the world's compiled code reads a bank of one map: (field, offsets,
        heights, widths, cells). The field holds no obstacle (only the blocked ring): nothing but
        the own map, written from the rays, is known."""
        field = np.zeros((self.height + 2, self.width + 2), np.uint8)
        field[0, :] = field[-1, :] = field[:, 0] = field[:, -1] = BLOCKED
        i8 = np.int64
        return (field.ravel(), np.zeros(1, i8), np.array([self.height], i8), np.array([self.width], i8),
                np.array([self.cell], np.float64))  # fmt: skip


def base_observation(
    rays: np.ndarray, per: int, max_range: float, x: float, y: float, theta: float, gx: float, gy: float
) -> np.ndarray:
    """The kernel's base observation without noise (:func:`worlds.kernel._observe`, the same
    operations): per sector the minimum of its ``per`` rays and ``max_range``, over ``max_range``;
    the goal's distance d squashed as d / (d + max_range); sine and cosine of its bearing from the
    heading."""
    n_beams = rays.shape[0] // per
    out = np.empty(n_beams + 3, np.float32)
    sectors = np.minimum(rays.reshape(n_beams, per).min(axis=1), max_range)
    out[:n_beams] = sectors / max_range
    c, s = math.cos(theta), math.sin(theta)
    ux, uy = gx - x, gy - y
    dist = math.sqrt(ux * ux + uy * uy)
    out[n_beams] = dist / (dist + max_range)
    out[n_beams + 1] = (-ux * s + uy * c) / dist if dist > 0.0 else 0.0
    out[n_beams + 2] = (ux * c + uy * s) / dist if dist > 0.0 else 1.0
    return out


class LiveObserver:
    """The observation of one robot from its rays and poses (see the module docstring).

    ``start(workspace, goal)`` begins an episode (own map cleared); ``observe(rays, pose)`` gives
    the first frame after it and, with ``action`` (the action that led here), every later one.
    ``rays`` are ranges in metres along ``config.sensors.ray_angles`` from the heading, clipped to
    ``[0, max_range]`` (``max_range``: nothing seen); poses are odometry-frame (x, y, theta).
    """

    def __init__(self, config: NavConfig, snap_hits: bool = False) -> None:
        self.config, self.snap_hits = config, snap_hits
        self.n_rays = len(config.sensors.ray_angles)
        self.ray_c, self.ray_s = np.cos(config.sensors.ray_angles), np.sin(config.sensors.ray_angles)
        self.per = config.sensors.rays_per_beam
        self.max_range = float(config.sensors.max_range)
        self.obs_dim = observation_dim(config)
        self.perception = Perception(1, config) if needed(config) else None
        self.workspace: Workspace | None = None
        self._fresh = True

    def start(self, workspace: Workspace, goal: tuple[float, float]) -> None:
        """A new episode towards ``goal`` (odometry frame) on ``workspace``: the next observation
        is a first frame (own map and frame stack cleared)."""
        self.workspace, self.goal = workspace, (float(goal[0]), float(goal[1]))
        self.maps = workspace.kernel_maps()
        self.emap = np.zeros(1, np.int64)
        self.goal_cell = np.array([workspace.cell_of(*self.goal)], np.int64)
        self._fresh = True

    def observe(self, rays: np.ndarray, pose: tuple[float, float, float], action: int = -1) -> np.ndarray:
        """The observation (obs_dim,) float32 at ``pose`` seeing ``rays``, after ``action`` (ignored
        on the first frame of an episode)."""
        if self.workspace is None:
            raise RuntimeError("LiveObserver.observe before start(): no goal yet")
        rays = np.clip(np.asarray(rays, np.float64).reshape(self.n_rays), 0.0, self.max_range)
        ws = self.workspace
        x, y, theta = pose[0] - ws.origin_x, pose[1] - ws.origin_y, float(pose[2])
        gx, gy = self.goal[0] - ws.origin_x, self.goal[1] - ws.origin_y
        base = base_observation(rays, self.per, self.max_range, x, y, theta, gx, gy)
        if self.perception is None:
            self._fresh = False
            return base
        f8 = np.float64
        map_rays = self._snapped(rays, x, y, theta) if self.snap_hits else rays
        robots = (np.array([x], f8), np.array([y], f8), np.array([theta], f8), np.array([gx], f8),
                  np.array([gy], f8), self.goal_cell, np.zeros(1, np.int64), base[None, :].copy(),
                  map_rays[None, :].copy())  # fmt: skip
        obs = np.zeros((1, self.obs_dim), np.float32)
        if self._fresh:
            self.perception.observe_fresh(np.zeros(1, np.int64), self.maps, robots, obs)
            self._fresh = False
        else:
            if action < 0:
                raise ValueError(
                    "observe: a frame after the first of an episode needs the action that led to it"
                )
            finals = (np.zeros((1, 3)), np.zeros((1, 2), np.int64), np.zeros(1, np.int64),
                      np.zeros_like(robots[7]), np.zeros_like(robots[8]), np.zeros(1, bool))  # fmt: skip
            self.perception.observe_step(
                np.array([int(action)], np.int64),
                False,
                self.maps,
                self.emap,
                robots,
                finals,
                obs,
                np.zeros_like(obs),
                np.zeros(1),
            )
        return obs[0]

    def _snapped(self, rays: np.ndarray, x: float, y: float, theta: float) -> np.ndarray:
        """The rays as the own map should take them (``snap_hits``, see the module docstring): each
        return ends just short of where it enters the cell its end point lies in (1e-9 cell, so
        that :func:`worlds.own_map.map_rays` marks that cell blocked and its trace stops before it)."""
        cell = self.workspace.cell
        c, s = math.cos(theta), math.sin(theta)
        dx, dy = c * self.ray_c - s * self.ray_s, s * self.ray_c + c * self.ray_s  # as map_rays turns them
        px, py, length = x / cell, y / cell, rays / cell
        ex, ey = px + length * dx, py + length * dy  # the end points, in cells
        with np.errstate(divide="ignore", invalid="ignore"):  # where each ray enters its end's cell
            entry_x = np.where(dx != 0, (np.floor(ex) + (dx < 0) - px) / np.where(dx != 0, dx, 1.0), -np.inf)
            entry_y = np.where(dy != 0, (np.floor(ey) + (dy < 0) - py) / np.where(dy != 0, dy, 1.0), -np.inf)
        entry = np.maximum(entry_x, entry_y)
        snap = (rays < self.max_range) & (entry > 0) & (entry <= length)
        return np.where(snap, (entry - 1e-9) * cell, rays)

"""What the robot perceives beyond one frame of range readings, and the geodesic reward.

The compiled kernel (:mod:`worlds.kernel`) writes each robot's *base* observation (range
readings, goal distance and bearing) and the noise-free range of every cast ray. This module
turns them into the observation of :class:`worlds.config.ObservationConfig`, one frame per
step, the last ``frame_stack`` frames observed newest first::

    frame = [readings (n_beams), goal (3), subgoal (3)?, plan length (1)?, range rates (n_beams)?,
             previous action one-hot (n_actions)?, own-map patch (2 * patch_size**2)?]

* **Range rates** (``range_rate``): each reading's change since the robot's previous step, in
  metres, clipped to [-1, 1] (0 at an episode's first step): negative when something comes
  closer, so one frame shows a moving disc's approach without a frame stack.

* **The robot's own map** (``own_map`` subgoal, patch): a grid on the map's cells, per robot and
  episode, written only from the robot's own rays and poses: every cell a ray crosses before
  its end is *seen free*, the cell just past a ray's end (a range below ``max_range``) *seen
  blocked*, the latest reading winning (so a moving disc's cell is free again once a ray crosses
  it), and the cell under the robot counts a visit each step. Nothing of the true map is read:
  a cell no ray reached stays unknown. The map's extent (its bounding box) is known, as the
  workspace boundary is to a real robot; its content is not.
* **The subgoal**: the shortest 8-connected grid path (:func:`worlds.gridsearch.grid_search`,
  the search behind the expert's A*) from the goal to every cell of the robot's own map,
  unknown cells counted free, so the robot cannot "see" unseen walls, in the robot's configuration
  space: on cells finer than the robot the grid is inflated, cells within the robot's radius of a
  wall blocked and those within the subgoal's clearance dearer to cross (:mod:`worlds.own_map`;
  nothing is inflated at 1 m cells and the default radius and clearance); the waypoint is the cell
  ``subgoal_distance`` metres along the path from the robot's cell (the goal itself when
  nearer); the frame gets its squashed distance and bearing. It is replanned whenever the map
  changed in a way that matters (a cell became blocked or stopped being blocked next to a cell
  the last search expanded: a search reads nothing else), which gives the same plan as
  replanning every step; the plan found from a cell is kept until the map changes, so coming
  back to that cell costs no search. ``known_map`` plans on the true map instead, for a user who
  has one. ``plan_length`` adds that path's length from the robot's cell to the goal, squashed
  like the goal distance (the straight line when no path exists).
* **The geodesic reward** (``rewards.geodesic_progress``): potential-based shaping by the true
  shortest-path distance from the robot's cell to the goal. It is a training signal; the policy
  never observes it. The Dijkstra from the goal (a bucket queue, :mod:`worlds.geodesic`) is paused
  once the robot's cell is settled and resumed when the robot reaches a cell it has not settled
  yet (the same distances, at the cost of the cells the episode needs).

Both envs go through :class:`worlds.batch.NavBatch`, which calls :class:`Perception` after every
kernel call, so the single env and the vector env stay the same program. The compiled step is
:mod:`worlds.perceive`, the own map and its planner :mod:`worlds.own_map`.
"""

from __future__ import annotations

import numpy as np

from worlds.config import NavConfig
from worlds.geodesic import move_masks, new_fields
from worlds.gridsearch import new_work
from worlds.own_map import FREE, LEVELS, SEEN_BLOCKED, UNKNOWN, inflation_cells, level_radius
from worlds.perceive import (
    PATCH_VALUE,
    REUSE_PARAM,
    SUB_KNOWN,
    SUB_NONE,
    SUB_OWN,
    perceive_fresh,
    perceive_step,
)

__all__ = [
    "FREE",
    "PATCH_VALUE",
    "REUSE_PARAM",
    "SEEN_BLOCKED",
    "UNKNOWN",
    "Perception",
    "frame_dim",
    "frame_layout",
    "needed",
    "observation_bounds",
    "observation_dim",
]


def frame_layout(config: NavConfig) -> dict[str, tuple[int, int]]:
    """Where each part sits in one frame: ``{name: (start, stop)}``, in frame order."""
    o, n = config.observation, config.sensors.n_beams
    parts = [("readings", n), ("goal", 3)]
    if o.subgoal != "none":
        parts.append(("subgoal", 3))
    if o.plan_length:
        parts.append(("plan_length", 1))
    if o.range_rate:
        parts.append(("range_rate", n))
    if o.previous_action:
        parts.append(("previous_action", config.robot.n_actions))
    if o.patch_size:
        parts.append(("patch", 2 * o.patch_size**2))
    layout, start = {}, 0
    for name, size in parts:
        layout[name] = (start, start + size)
        start += size
    return layout


def frame_dim(config: NavConfig) -> int:
    return max(stop for _, stop in frame_layout(config).values())


def observation_dim(config: NavConfig) -> int:
    """Length of the observation vector: frame_stack frames of :func:`frame_dim`."""
    return config.observation.frame_stack * frame_dim(config)


def observation_bounds(config: NavConfig) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the observation vector."""
    layout = frame_layout(config)
    low, high = np.zeros(frame_dim(config), np.float32), np.ones(frame_dim(config), np.float32)
    for part in ("goal", "subgoal"):
        if part in layout:
            a, _ = layout[part]
            low[a + 1 : a + 3] = -1.0
    if "range_rate" in layout:
        a, b = layout["range_rate"]
        low[a:b] = -1.0
    k = config.observation.frame_stack
    return np.tile(low, k), np.tile(high, k)


def needed(config: NavConfig) -> bool:
    """Does ``config`` need this module (anything beyond the kernel's observation and reward)?"""
    return not config.observation.plain or config.rewards.geodesic_progress > 0


class Perception:
    """Per-robot memory (own map, plans, frame stack, geodesic field) of ``n`` robots, and the
    step that turns the kernel's base observations into observations (see the module docstring;
    the compiled step is :mod:`worlds.perceive`)."""

    def __init__(self, n: int, config: NavConfig, reuse: bool = True) -> None:
        o = config.observation
        self.n, self.config = n, config
        layout = frame_layout(config)
        self.frame_dim, self.obs_dim = frame_dim(config), observation_dim(config)
        angles = config.sensors.ray_angles
        self.ray_c, self.ray_s = np.cos(angles), np.sin(angles)
        kind = {"none": SUB_NONE, "own_map": SUB_OWN, "known_map": SUB_KNOWN}[o.subgoal]
        self.params = np.array(
            [
                config.sensors.max_range,
                kind,
                o.subgoal_distance,
                layout.get("subgoal", (-1,))[0],
                layout.get("previous_action", (-1,))[0],
                layout.get("patch", (-1,))[0],
                o.patch_size,
                config.rewards.geodesic_progress,
                config.robot.n_actions,
                config.sensors.rays_per_beam,
                reuse,
                layout.get("range_rate", (-1,))[0],  # worlds.perceive.RATE_PARAM
                layout.get("plan_length", (-1,))[0],  # worlds.perceive.LENGTH_PARAM
                o.subgoal_clearance,  # worlds.perceive.CLEARANCE_PARAM
                config.robot.radius,  # worlds.perceive.RADIUS_PARAM
                o.subgoal_prefers_seen,  # worlds.perceive.SEEN_PARAM
            ],
            dtype=np.float64,
        )
        self.uses_map, self.plans = o.needs_map, o.subgoal != "none"
        self.geodesic = config.rewards.geodesic_progress > 0
        self.stack = np.zeros((n, o.frame_stack, self.frame_dim), np.float32)
        self.waypoint = np.zeros((n, 2), np.float64)
        self.path_length = np.zeros(n, np.float64)  # the plan's length to the goal (m; -1: no path)
        self.last = np.zeros((n, 2), np.int64)
        self.version, self.searches = np.zeros(n, np.int32), np.zeros(n, np.int32)
        self.exam_id = np.full(n, -1, np.int32)
        self.pgeo = np.zeros(n, np.float64)
        self.shape, self._sized_for = (0, 0), None
        self.inflates = False  # does a map of the bank have cells the plan grid is inflated on?
        radius, clearance = config.robot.radius, o.subgoal_clearance
        self.levels = sum(level_radius(radius, clearance, k) > 0.0 for k in range(LEVELS))
        self.moves, self._moves_for = np.zeros(0, np.uint8), None  # the geodesic field's move table
        self._allocate((1, 1), False)

    def _allocate(self, shape: tuple[int, int], inflates: bool) -> None:
        """Grids of at least ``shape`` cells per robot, keeping what they hold (padded grids and search
        rows are indexed with each map's own stride, so their first cells carry over as they are), and
        the inflated plan grids once a map needs them (``inflates``)."""
        h, w = max(shape[0], self.shape[0]), max(shape[1], self.shape[1])
        inflates = inflates or self.inflates
        if (h, w) == self.shape and inflates == self.inflates:
            return
        cells = (h + 2) * (w + 2)

        def grow(old, dtype, used, fill=0, flat=False):
            size = (cells,) if flat else (h, w)
            new = np.full((self.n, *size) if used else (self.n,) + (0,) * len(size), fill, dtype)
            if used and old is not None and old.size:
                new[(slice(None), *(slice(0, k) for k in old.shape[1:]))] = old
            return new

        self.occ = grow(getattr(self, "occ", None), np.int8, self.uses_map)
        self.visits = grow(getattr(self, "visits", None), np.int32, self.uses_map)
        self.plan = grow(getattr(self, "plan", None), np.uint8, self.plans, flat=True)
        # the inflated plan grid and its levels' counts (worlds.own_map.inflate), on maps of fine cells
        # only; the levels' reaches on the robot's map (cells)
        levels = self.levels if self.plans and inflates else 0
        self.wide = grow(getattr(self, "wide", None), np.uint8, levels > 0, flat=True)
        old = getattr(self, "near", None)
        self.near = np.zeros((self.n, levels, cells if levels else 0), np.int32)
        if levels and old is not None and old.size:
            self.near[:, :, : old.shape[2]] = old
        self.reach = np.zeros((self.n, LEVELS), np.float64)
        # per cell: the waypoint cell planned from it (-1: the goal), valid on plan-map version ``stamp``
        self.plan_node = grow(getattr(self, "plan_node", None), np.int32, self.plans)
        self.plan_length = grow(getattr(self, "plan_length", None), np.float64, self.plans)  # and its length
        self.stamp = grow(getattr(self, "stamp", None), np.int32, self.plans, -1)
        self.exam = grow(getattr(self, "exam", None), np.int32, self.plans, flat=True)  # searches' cells
        # the geodesic field's Dijkstra, one row of work arrays per robot (worlds.geodesic)
        old = getattr(self, "geo", None)  # the geodesic field's Dijkstra, one row per robot
        self.geo = new_fields(self.n, cells if self.geodesic else 0)
        if old is not None and self.geodesic:
            for new, prev in zip(self.geo, old, strict=True):
                new[(slice(None), *(slice(0, k) for k in prev.shape[1:]))] = prev
        self.work = new_work(cells)  # the subgoal's A*, one search at a time
        self.shape, self.inflates = (h, w), inflates

    def _memory(self, maps) -> tuple:
        field, moff, mh, mw, mcell = maps[:5]
        if mh is not self._sized_for:  # the bank's maps changed: grids big enough for its largest
            widest = level_radius(self.config.robot.radius, self.config.observation.subgoal_clearance, 0)
            inflates = any(inflation_cells(widest, float(cell)) > 0 for cell in mcell)
            self._allocate((int(mh.max()), int(mw.max())), inflates)
            self._sized_for = mh
        if self.geodesic and field is not self._moves_for:
            self.moves, self._moves_for = move_masks(field, moff, mh, mw), field
        plans = (self.plan, self.waypoint, self.last, self.plan_node, self.stamp, self.version, self.exam,
                 self.exam_id, self.searches, self.plan_length, self.path_length, self.wide,
                 self.near, self.reach)  # fmt: skip
        return self.occ, self.visits, plans, self.moves, self.geo, self.pgeo, self.stack

    def _state(self, maps) -> tuple:
        """What both compiled calls take after the batch's arrays: memory, the subgoal search's work
        arrays, parameters, ray directions."""
        return self._memory(maps), self.work, self.params, self.ray_c, self.ray_s

    def observe_fresh(self, indices: np.ndarray, maps: tuple, robots: tuple, obs: np.ndarray) -> None:
        """First frames of the episodes robots ``indices`` just started (see
        :func:`worlds.perceive.perceive_fresh`)."""
        perceive_fresh(np.asarray(indices, np.int64), maps, robots, *self._state(maps), obs)

    def observe_step(self, actions, autoreset, maps, emap, robots, finals, obs, final_obs, reward) -> None:
        """Frames after a step of every robot (see :func:`worlds.perceive.perceive_step`)."""
        state = self._state(maps)
        perceive_step(actions, bool(autoreset), maps, emap, robots, finals, *state, obs, final_obs, reward)

"""MAP refinement with a hindsight prior: a planner on the map the demonstration's own beams drew.

The thesis' refinement (``losses.map_posterior``) asks which action the demonstrator meant, ``a*``,
given the recorded one: with probability ``noise`` the recorded action is a random one. Its answer
is only as good as its prior ``P(a* | s)``. A prior taken from the learner's own policy has to be
learned from the same noisy steps it should judge, and spreads their noise over every action, so it
relabels few injected steps once the clean ones must be kept. A demonstration holds more than its
actions, though: the robot's poses and, at every pose, its range readings. Offline, after the
episode, they show the part of the map the demonstrator drove through - the same hindsight that
experience replay's relabelling uses (Andrychowicz et al. 2017) - and on that map a planner can say
how much each action would have cost.

Here:

1. ``seen_map``: an occupancy grid filled only from the demonstration's poses and sector-minimum
   readings. Each reading ``r`` of sector ``k`` says the rays of that sector crossed free space up
   to ``r`` (cells traced to ``r - margin`` count free) and one of them stopped at ``r`` (the cell
   just past ``r`` on each ray of the sector counts a hit, unless it is the maximum range). A cell
   is blocked when more rays ended in it than crossed it; cells no ray reached are free (unknown
   counted free, as the own-map subgoal does). Nothing is read from the true map.
2. ``action_costs``: for each action, one noiseless step of the robot (``worlds.robot.move``), then
   the project's lattice A* (``agents.planning.lattice``, the thesis' modified A*) from there to the
   goal on the seen map: ``Q(s, a) = step + cost-to-go``; an action whose step hits a seen wall costs
   infinity. The demonstrator is assumed to drive a short, safe path to the goal - the assumption
   NIRL's progress potential already makes (``agents.nirl.progress``: the expert's unit cost per step).
3. The prior is Boltzmann-rational in that cost, ``P(a* | s) = softmax(-(Q(s, .) - min Q) / T)``
   (``temperature`` in metres); ``losses.map_posterior`` gives the posterior over ``a*`` and
   ``losses.refine_steps(..., judge_recorded=True)`` replaces a recorded action by the MAP one
   when the recorded action was noise with posterior >= ``threshold``. The test is on the
   recorded action rather than on one alternative because the planner's prior splits its mass
   over near-equal actions (two turns of about the same cost often lead around an obstacle),
   so no single alternative reaches a high posterior even when the recorded action surely
   cost the demonstrator a detour.

The prior does not learn, so it is computed once per demonstration, when it is added
(``NIRLLearner.add_demos`` with ``NIRLConfig.refine_prior = "hindsight"``). It needs the
demonstration's poses and the map's size (``agents.demos.Demo``); demonstrations that arrive over
the wire carry neither, so the distributed learner keeps the learned prior.

Limits: a human demonstrator whose costs differ from the lattice planner's (clearance, turning)
would be judged by the planner's; the expert's own choice among near-equal actions is one of
several (the planner's cheapest action is the expert's on about 3 of 4 clean steps), so a random
action that is about as good as the expert's is kept, as it should be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from agents.nirl.losses import Refinement, kept_as_recorded, map_posterior, refine_steps
from agents.planning.astar import distance_field
from agents.planning.lattice import plan_lattice
from worlds.config import NavConfig
from worlds.maps import Cell, GridMap
from worlds.robot import collides, move

STORED = ("hindsight_label", "hindsight_weight", "hindsight_decision")
"""the demonstration buffer's fields holding each step's refinement (``Refinement``'s three, in order)"""
TRACE_STEP = 0.05
"""spacing of the points traced along a ray (m): a 1 m cell is crossed by about 20 of them"""
RANGE_MARGIN = 0.1
"""a reading ``r`` marks its rays' cells free only up to ``r - RANGE_MARGIN`` (m), a margin for range noise"""


@dataclass(frozen=True)
class HindsightSettings:
    """Knobs of the hindsight refinement (chosen by results/nirl/scripts/nirl_hindsight.py
    --tune on a noisy set no reported run uses)."""

    temperature: float = 0.2
    """Boltzmann temperature of the prior over the actions' cost-to-go (m)"""
    threshold: float = 0.7
    """relabel (to the MAP action) when the recorded action was noise with at least this posterior"""
    margin: float = RANGE_MARGIN
    """a reading ``r`` marks its rays' cells free only up to ``r - margin`` (m)"""

    def __post_init__(self) -> None:
        if not self.temperature > 0:
            raise ValueError(f"HindsightSettings.temperature must be > 0, got {self.temperature}")
        if not 0 < self.threshold <= 1:
            raise ValueError(f"HindsightSettings.threshold must be in (0, 1], got {self.threshold}")
        if self.margin < 0:
            raise ValueError(f"HindsightSettings.margin must be >= 0, got {self.margin}")


def seen_map(
    observations: np.ndarray,
    poses: np.ndarray,
    nav: NavConfig,
    shape: tuple[int, int],
    cell_size: float,
    margin: float = RANGE_MARGIN,
) -> tuple[np.ndarray, np.ndarray]:
    """The occupancy grid the readings of ``observations`` (T, obs_dim) taken at ``poses`` (T, 3)
    show (module docstring, step 1) -> (blocked, reached) boolean (H, W) arrays; ``reached`` marks
    the cells a ray crossed or ended in (every blocked cell is one)."""
    sensors = nav.sensors
    height, width = shape
    n_cells = height * width
    per = sensors.rays_per_beam
    angles = sensors.ray_angles  # (n_beams * per,), sector by sector
    samples = np.arange(0.0, sensors.max_range, TRACE_STEP)
    free = np.zeros(n_cells, dtype=np.int64)
    hits = np.zeros(n_cells, dtype=np.int64)
    n_rays = len(angles)
    ray_ids = np.arange(n_rays)[:, None]
    for obs, (x, y, theta) in zip(observations, poses, strict=True):
        ranges = np.repeat(np.asarray(obs[: sensors.n_beams], dtype=np.float64) * sensors.max_range, per)
        cos, sin = np.cos(theta + angles)[:, None], np.sin(theta + angles)[:, None]
        px, py = x + samples[None, :] * cos, y + samples[None, :] * sin
        rows, cols = np.floor(py / cell_size).astype(np.int64), np.floor(px / cell_size).astype(np.int64)
        inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
        crossed = inside & (samples[None, :] < (ranges - margin)[:, None])
        keys = np.unique((ray_ids * n_cells + rows * width + cols)[crossed])  # once per ray and cell
        np.add.at(free, keys % n_cells, 1)
        ended = ranges < sensors.max_range - TRACE_STEP
        reach = ranges[ended] + TRACE_STEP
        ex, ey = x + reach * cos[ended, 0], y + reach * sin[ended, 0]
        er, ec = np.floor(ey / cell_size).astype(np.int64), np.floor(ex / cell_size).astype(np.int64)
        ok = (er >= 0) & (er < height) & (ec >= 0) & (ec < width)
        np.add.at(hits, er[ok] * width + ec[ok], 1)
    blocked = (hits > free).reshape(shape)
    reached = ((hits > 0) | (free > 0)).reshape(shape)
    return blocked, reached


def action_costs(
    grid: GridMap, pose, goal: Cell, nav: NavConfig, field: np.ndarray | None = None
) -> np.ndarray:
    """(A,) cost of each action from ``pose`` on ``grid``: one noiseless step, then the lattice A*'s
    cost to within the goal tolerance (inf when the step hits the map or no plan exists)."""
    robot = nav.robot
    turns = robot.turns
    field = distance_field(grid, goal) if field is None else field
    x, y, theta = (np.full(len(turns), float(v)) for v in pose)
    nx, ny, ntheta = move(x, y, theta, turns, robot.step)
    hit = collides(grid, x, y, nx, ny, robot.radius)
    gx, gy = grid.cell_center(goal)
    costs = np.full(len(turns), np.inf)
    for a in np.flatnonzero(~hit):
        if np.hypot(nx[a] - gx, ny[a] - gy) <= nav.goal_tolerance:
            costs[a] = robot.step
            continue
        start = (float(nx[a]), float(ny[a]), float(ntheta[a]))
        plan = plan_lattice(
            grid, start, goal, turns, robot.step, robot.radius, nav.goal_tolerance, field=field
        )
        if plan.found:
            costs[a] = robot.step + plan.cost
    return costs


def hindsight_prior(costs: np.ndarray, temperature: float) -> np.ndarray:
    """(T, A) prior softmax(-(Q - min Q) / temperature) over actions of finite cost (uniform over all
    actions at a step where none is finite)."""
    costs = np.asarray(costs, dtype=np.float64)
    finite = np.isfinite(costs)
    best = np.where(finite, costs, np.inf).min(axis=1, keepdims=True)
    logits = np.where(finite, -(costs - np.where(np.isfinite(best), best, 0.0)) / temperature, -np.inf)
    logits[~finite.any(axis=1)] = 0.0
    weights = np.exp(logits - logits.max(axis=1, keepdims=True))
    return weights / weights.sum(axis=1, keepdims=True)


def demo_costs(demo, nav: NavConfig, margin: float = RANGE_MARGIN) -> np.ndarray:
    """(T, A) action costs at every demonstrated step of ``demo`` (an ``agents.demos.Demo``: its
    observations, poses, goal and the map's size; not the map's cells) on its seen map."""
    if demo.grid is None or "goal" not in demo.metadata:
        raise ValueError(
            "hindsight refinement needs the demonstration's map size and goal (Demo.grid, .metadata)"
        )
    cell = float(demo.grid.cell_size)
    blocked, _ = seen_map(demo.observations, demo.poses, nav, demo.grid.shape, cell, margin)
    return costs_along(demo, GridMap(blocked, cell), nav)


def costs_along(demo, grid: GridMap, nav: NavConfig) -> np.ndarray:
    """(T, A) ``action_costs`` on ``grid`` at every demonstrated pose of ``demo``, towards its goal."""
    goal = tuple(int(v) for v in demo.metadata["goal"])
    field = distance_field(grid, goal)
    return np.stack([action_costs(grid, demo.poses[t], goal, nav, field) for t in range(len(demo.actions))])


def refine_demo(demo, nav: NavConfig, noise: float, settings: HindsightSettings | None = None) -> Refinement:
    """MAP refinement of every step of ``demo`` under the hindsight prior (module docstring). With
    ``noise`` 0 (a clean expert) every step is kept with weight 1 - what the posterior gives - without
    planning."""
    settings = settings or HindsightSettings()
    recorded = torch.as_tensor(np.asarray(demo.actions), dtype=torch.int64)
    if noise == 0:
        return kept_as_recorded(recorded)
    prior = hindsight_prior(demo_costs(demo, nav, settings.margin), settings.temperature)
    posterior = map_posterior(torch.as_tensor(prior, dtype=torch.float32), recorded, noise)
    return refine_steps(posterior, recorded, settings.threshold, judge_recorded=True)

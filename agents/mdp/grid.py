"""Grid-map MDPs: the :mod:`worlds.gridworld` dynamics as a sparse
:class:`~agents.mdp.model.FiniteMDP` (thesis ch. 2.2 applied to the robot's grid)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from agents.mdp.model import FiniteMDP
from agents.planning import distance_field
from worlds.gridworld import GridDynamics, GridWorldConfig
from worlds.maps import Cell, GridMap, components


def dynamics_to_mdp(dynamics: GridDynamics, gamma: float) -> FiniteMDP:
    """Sparse ``P[a][s, successor[s, b]] += outcome_prob[a, b]`` and ``R = E[reward]``."""
    n_states, n_outcomes = dynamics.successor.shape
    rows = np.repeat(np.arange(n_states), n_outcomes)
    cols = dynamics.successor.ravel()
    matrices = []
    for a in range(dynamics.n_actions):
        data = np.tile(dynamics.outcome_prob[a], n_states)
        coo = sp.coo_array((data, (rows, cols)), shape=(n_states, n_states))
        matrices.append(coo.tocsr())  # duplicates (several moves to one cell) are summed
    return FiniteMDP(matrices, dynamics.expected_reward(), gamma)


def grid_mdp(
    grid: GridMap, goal: Cell, config: GridWorldConfig | None = None, gamma: float = 0.99
) -> tuple[GridDynamics, FiniteMDP]:
    """Build the dynamics arrays and the sparse MDP of a grid navigation task."""
    dynamics = GridDynamics.build(grid, goal, config)
    return dynamics, dynamics_to_mdp(dynamics, gamma)


def default_start_goal(grid: GridMap, connectivity: int = 8) -> tuple[Cell, Cell]:
    """A deterministic, far-apart start and goal in the largest free region:
    the goal is the region's cell nearest the top-left corner's opposite
    (bottom-right), the start the cell farthest from it by shortest path."""
    labels = components(grid)
    if labels.max() == 0:
        raise ValueError(f"map {grid.name!r} has no free cell")
    largest = int(np.argmax(np.bincount(labels.ravel())[1:])) + 1
    cells = np.argwhere(labels == largest)
    goal_idx = int(np.argmax(cells[:, 0] + cells[:, 1]))
    goal = (int(cells[goal_idx, 0]), int(cells[goal_idx, 1]))
    dist = distance_field(grid, goal, connectivity)
    dist[~np.isfinite(dist)] = -1.0
    start = np.unravel_index(int(np.argmax(dist)), dist.shape)
    return (int(start[0]), int(start[1])), goal

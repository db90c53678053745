"""Tabular grid world (thesis ch. 2.2-2.4): a robot hopping between the free
cells of a :class:`~worlds.maps.GridMap`, with slip.

The dynamics live in :class:`GridDynamics`, a handful of arrays shared by the
gymnasium env here, the MDP builder (``agents.mdp.grid``) and the compiled
tabular learners (``agents.tabular``), so all three describe the same MDP:

* actions are the moves N, S, W, E (4-connected) and NW, NE, SW, SE (8);
* the intended move happens with probability ``1 - slip``; otherwise one of
  the other moves happens, each with probability ``slip / (A - 1)``;
* a move off the map, into a blocked cell, or diagonally past a blocked corner
  (the MovingAI rule: both cells the diagonal brushes must be free) leaves the
  robot where it is and costs ``collision_cost``;
* a legal move costs ``step_cost`` times its length (1, or sqrt(2) diagonally)
  and earns ``goal_reward`` when it enters the goal;
* the goal is absorbing: every move stays there with reward 0.

The states are the free cells from which the goal is reachable (its
4-connected component: with the corner rule, 8-connected moves reach exactly
these), numbered row-major. Other free cells are not part of the MDP.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from worlds.maps import Cell, GridMap, components, parse_ascii

# Move offsets (d_row, d_col): the 4 straight moves, then the 4 diagonals
# (the order agents.planning.astar uses too).
MOVES = np.array([(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)], dtype=np.int64)
MOVE_NAMES = ("N", "S", "W", "E", "NW", "NE", "SW", "SE")

DEFAULT_MAP = """\
##########
#S.......#
#.##.###.#
#.#.....##
#.#.###..#
#...#G#..#
##......##
##########
"""


@dataclass(frozen=True)
class GridWorldConfig:
    """Grid-world dynamics and rewards (see the module docstring)."""

    connectivity: int = 8
    """4 (straight moves only) or 8 (straight and diagonal moves)."""
    slip: float = 0.1
    """Probability that another move than the intended one happens (shared evenly)."""
    step_cost: float = 1.0
    """Cost per cell of distance moved (a diagonal move costs sqrt(2) times this)."""
    collision_cost: float = 5.0
    """Cost of a move that is blocked (the robot stays where it is)."""
    goal_reward: float = 0.0
    """Reward for the move that enters the goal (on top of its step cost)."""

    def __post_init__(self) -> None:
        if self.connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 4 or 8, got {self.connectivity}")
        if not 0.0 <= self.slip <= 1.0:
            raise ValueError(f"slip must be in [0, 1], got {self.slip}")
        for name in ("step_cost", "collision_cost", "goal_reward"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")


@dataclass(frozen=True, eq=False)
class GridDynamics:
    """The grid MDP as arrays. ``B`` outcomes (moves) equal the ``A`` actions.

    Action ``a`` in state ``s`` yields outcome ``b`` with ``outcome_prob[a, b]``;
    the outcome leads to ``successor[s, b]`` with ``reward[s, b]``
    (``collision[s, b]`` when the move was blocked)."""

    grid: GridMap
    goal: Cell
    config: GridWorldConfig
    cells: np.ndarray  # (S, 2) int64, (row, col) of each state
    state_index: np.ndarray  # (H, W) int64, state of each cell or -1
    successor: np.ndarray  # (S, B) int64
    reward: np.ndarray  # (S, B) float64
    collision: np.ndarray  # (S, B) bool
    outcome_prob: np.ndarray  # (A, B) float64, rows sum to 1
    goal_state: int

    @classmethod
    def build(cls, grid: GridMap, goal: Cell, config: GridWorldConfig | None = None) -> GridDynamics:
        config = config or GridWorldConfig()
        goal = (int(goal[0]), int(goal[1]))
        if not grid.is_free(goal):
            raise ValueError(f"goal {goal} is blocked or outside the {grid.shape} map")
        labels = components(grid)
        reachable = labels == labels[goal]
        cells = np.argwhere(reachable)
        state_index = np.full(grid.shape, -1, dtype=np.int64)
        state_index[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
        n_moves = config.connectivity
        moves = MOVES[:n_moves]

        padded = np.pad(grid.blocked, 1, constant_values=True)  # off-map counts as blocked
        rows, cols = cells[:, 0] + 1, cells[:, 1] + 1
        target_r = rows[:, None] + moves[None, :, 0]
        target_c = cols[:, None] + moves[None, :, 1]
        legal = ~padded[target_r, target_c]
        diagonal = (moves[:, 0] != 0) & (moves[:, 1] != 0)
        corner_free = ~padded[target_r, cols[:, None]] & ~padded[rows[:, None], target_c]
        legal &= ~diagonal[None, :] | corner_free

        here = np.arange(len(cells))[:, None]
        inside_r = np.clip(target_r - 1, 0, grid.height - 1)
        inside_c = np.clip(target_c - 1, 0, grid.width - 1)
        successor = np.where(legal, state_index[inside_r, inside_c], here)
        length = np.where(diagonal, math.sqrt(2.0), 1.0)
        reward = np.where(legal, -config.step_cost * length[None, :], -config.collision_cost)
        goal_state = int(state_index[goal])
        reward = reward + np.where(legal & (successor == goal_state), config.goal_reward, 0.0)
        successor[goal_state] = goal_state
        reward[goal_state] = 0.0
        collision = ~legal
        collision[goal_state] = False

        outcome_prob = np.full((n_moves, n_moves), config.slip / (n_moves - 1))
        np.fill_diagonal(outcome_prob, 1.0 - config.slip)
        return cls(
            grid,
            goal,
            config,
            cells,
            state_index,
            successor.astype(np.int64),
            reward,
            collision,
            outcome_prob,
            goal_state,
        )

    @property
    def n_states(self) -> int:
        return len(self.cells)

    @property
    def n_actions(self) -> int:
        return int(self.outcome_prob.shape[0])

    def state(self, cell: Cell) -> int:
        """State number of ``cell``; ValueError if it is not a state."""
        r, c = int(cell[0]), int(cell[1])
        if not self.grid.in_bounds((r, c)) or self.state_index[r, c] < 0:
            raise ValueError(
                f"cell {(r, c)} is blocked, outside the map or cannot reach the goal {self.goal}"
            )
        return int(self.state_index[r, c])

    def cell(self, state: int) -> Cell:
        r, c = self.cells[state]
        return (int(r), int(c))

    def expected_reward(self) -> np.ndarray:
        """``(S, A)`` expected immediate reward of each action."""
        return self.reward @ self.outcome_prob.T

    def intended_path(self, policy: np.ndarray, start: Cell, max_steps: int | None = None) -> list[Cell]:
        """Cells visited from ``start`` when each state's action in ``policy``
        always does its intended move (no slip); stops at the goal, on a
        repeated state or after ``max_steps`` (default: the number of states)."""
        s = self.state(start)
        path = [self.cell(s)]
        seen = {s}
        for _ in range(self.n_states if max_steps is None else max_steps):
            if s == self.goal_state:
                break
            s = int(self.successor[s, int(policy[s])])
            path.append(self.cell(s))
            if s in seen:
                break
            seen.add(s)
        return path


class GridWorldEnv(gym.Env):
    """Tabular grid-world navigation.

    ## Description
    A robot moves between the free cells of a grid map towards a goal cell,
    with the slip, collision and step costs of :class:`GridDynamics`.

    ## Action space
    ``Discrete(A)``: the moves ``MOVE_NAMES[:A]``, ``A`` = 8 or 4.

    ## Observation space
    ``Discrete(S)``: the state number of the robot's cell (row-major over the
    cells from which the goal is reachable; ``env.dynamics.cell(s)`` maps back).

    ## Rewards
    ``-step_cost`` per cell moved, ``-collision_cost`` for a blocked move,
    ``+goal_reward`` on entering the goal.

    ## Episode end
    Terminated on reaching the goal; truncated after ``max_steps`` steps.

    ## Arguments
    ``grid`` (default: a small built-in map with its own start and goal),
    ``goal`` (required with ``grid``), ``start`` (``None``: a uniformly random
    non-goal state each episode, i.e. exploring starts), ``config``
    (:class:`GridWorldConfig`), ``max_steps``, ``render_mode`` (``"ansi"``).
    ``reset(options={"start": cell})`` overrides the start for one episode.
    ``info`` holds ``"cell"`` and, after a step, ``"collision"``.

    ## Example
    >>> env = gymnasium.make("navlearn/GridWorld-v0")
    >>> obs, info = env.reset(seed=0)
    """

    metadata: ClassVar[dict] = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(
        self,
        grid: GridMap | None = None,
        goal: Cell | None = None,
        start: Cell | None = None,
        config: GridWorldConfig | None = None,
        max_steps: int = 200,
        render_mode: str | None = None,
    ) -> None:
        if grid is None:
            grid, markers = parse_ascii(DEFAULT_MAP, "gridworld-default")
            goal = markers["G"] if goal is None else goal
            start = markers["S"] if start is None else start
        if goal is None:
            raise ValueError("goal is required when a grid is given")
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}"
            )
        self.dynamics = GridDynamics.build(grid, goal, config)
        self.start_state = None if start is None else self.dynamics.state(start)
        self.max_steps = int(max_steps)
        self.render_mode = render_mode
        self.observation_space = spaces.Discrete(self.dynamics.n_states)
        self.action_space = spaces.Discrete(self.dynamics.n_actions)
        self._cumulative = np.cumsum(self.dynamics.outcome_prob, axis=1)
        self._state = 0
        self._steps = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[int, dict]:
        super().reset(seed=seed)
        start = (options or {}).get("start")
        if start is not None:
            self._state = self.dynamics.state(start)
        elif self.start_state is not None:
            self._state = self.start_state
        else:
            draw = int(self.np_random.integers(self.dynamics.n_states - 1))
            self._state = draw + (draw >= self.dynamics.goal_state)  # any state but the goal
        self._steps = 0
        return self._state, {"cell": self.dynamics.cell(self._state)}

    def step(self, action: int) -> tuple[int, float, bool, bool, dict]:
        if not self.action_space.contains(action):
            raise ValueError(f"action must be in 0..{self.action_space.n - 1}, got {action!r}")
        dyn = self.dynamics
        outcome = int(np.searchsorted(self._cumulative[int(action)], self.np_random.random(), side="right"))
        outcome = min(outcome, dyn.n_actions - 1)
        s = self._state
        reward = float(dyn.reward[s, outcome])
        collision = bool(dyn.collision[s, outcome])
        self._state = int(dyn.successor[s, outcome])
        self._steps += 1
        terminated = self._state == dyn.goal_state
        truncated = not terminated and self._steps >= self.max_steps
        return (
            self._state,
            reward,
            terminated,
            truncated,
            {"cell": dyn.cell(self._state), "collision": collision},
        )

    def render(self) -> str | None:
        if self.render_mode != "ansi":
            return None
        chars = np.where(self.dynamics.grid.blocked, "#", ".")
        chars[self.dynamics.goal] = "G"
        chars[self.dynamics.cell(self._state)] = "R"
        return "\n".join("".join(row) for row in chars) + "\n"


ENV_ID = "navlearn/GridWorld-v0"
"""Registered with gymnasium by ``worlds/__init__.py`` (importing this module imports that first)."""

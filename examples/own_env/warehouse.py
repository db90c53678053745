"""A complete example of bringing your own environment to navlearn (docs/own-env.md).

``WarehouseAisle`` is a small Gymnasium env: a robot in a warehouse aisle of ``length`` cells must reach
the picking station at the far end while a forklift crosses the aisle; it runs with

    navlearn up --env examples.own_env.warehouse:WarehouseAisle --env-kwargs '{"length": 8}'

(from the repository root, or with this directory's parent on PYTHONPATH), or, once registered (the
``register`` call at the bottom runs when the module is imported),

    navlearn up --env-module examples.own_env.warehouse --env navlearn-example/WarehouseAisle-v0

## Description
The robot moves one cell per step along the aisle. A forklift crosses at cell ``length // 2``: it blocks
that cell on the steps where ``(t // 3) % 2 == 1``. Driving into the forklift ends the episode.

## Action space
``Discrete(3)``: 0 wait, 1 forward, 2 back. navlearn's NNQL needs discrete actions.

## Observation space
``Dict``: ``"position"`` ``Box(0, 1, (1,))`` (the cell over the aisle's length), ``"forklift"``
``MultiBinary(2)`` (blocking now, blocking on the next step), ``"time"`` ``Box(0, 1, (1,))``. navlearn
flattens it with ``gymnasium.wrappers.FlattenObservation`` to 4 inputs; any Box shape, Dict or Tuple
works the same way.

## Rewards
+1 at the station, -1 for a collision with the forklift, -0.01 per step otherwise.

## Episode end
Terminated at the station (``info["is_success"] = True``) or at a collision (``False``); truncated after
``4 * length`` steps (``False``). ``is_success`` is the gymnasium-robotics / SB3 convention navlearn's
evaluator reads for its success rate.

## Arguments
``length`` (default 8): cells in the aisle.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class WarehouseAisle(gym.Env):
    """A robot drives along an aisle to the picking station past a crossing forklift."""

    metadata = {"render_modes": []}  # noqa: RUF012 - gymnasium's class attribute

    def __init__(self, length: int = 8) -> None:
        if length < 4:
            raise ValueError(f"length={length}: the aisle needs at least 4 cells")
        self.length = int(length)
        self.limit = 4 * self.length
        self.action_space = spaces.Discrete(3)
        self.observation_space = spaces.Dict(
            {
                "position": spaces.Box(0.0, 1.0, (1,), np.float32),
                "forklift": spaces.MultiBinary(2),
                "time": spaces.Box(0.0, 1.0, (1,), np.float32),
            }
        )

    def _blocked(self, t: int) -> bool:
        return (t // 3) % 2 == 1

    def _observe(self) -> dict:
        return {
            "position": np.array([self.cell / (self.length - 1)], np.float32),
            "forklift": np.array([self._blocked(self.t), self._blocked(self.t + 1)], np.int8),
            "time": np.array([self.t / self.limit], np.float32),
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.cell = int(self.np_random.integers(0, self.length // 2 - 1))  # somewhere before the crossing
        self.t = 0
        return self._observe(), {}

    def step(self, action):
        move = (0, 1, -1)[int(action)]
        self.cell = min(max(self.cell + move, 0), self.length - 1)
        self.t += 1
        arrived = self.cell == self.length - 1
        hit = self.cell == self.length // 2 and self._blocked(self.t)
        reward = 1.0 if arrived else -1.0 if hit else -0.01
        terminated = arrived or hit
        truncated = not terminated and self.t >= self.limit
        info = {"is_success": arrived} if terminated or truncated else {}
        return self._observe(), reward, terminated, truncated, info


gym.register("navlearn-example/WarehouseAisle-v0", entry_point=WarehouseAisle, kwargs={"length": 8})

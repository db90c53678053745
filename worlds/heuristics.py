"""Hand-written policies that read only the observation (like a learned policy): baselines.

- :func:`goal_seeking_policy`, the robot of `navlearn world show`: among the actions whose new
  heading has enough free range in front and to both sides (judged from the nearest beam and its
  two neighbours), it takes the one closest to the goal bearing. It is not a planner: it gets
  stuck behind walls that face the goal.
- :func:`subgoal_scores`: the classical mapless planner's choice, turn towards the subgoal of the
  robot's own map (:mod:`worlds.own_map`: A* on what the readings have shown so far, unknown cells
  free, re-planned as the map grows). It needs an observation with a subgoal, and something that
  keeps it off walls (``bench/map_sizes.py`` runs it through the reading shield, as the learned
  policy acts); it says how much of a policy's result its own map's plan already gives.
"""

from __future__ import annotations

import numpy as np

from worlds.config import NavConfig
from worlds.perception import frame_layout


def misalignment(bearing: np.ndarray, turns: np.ndarray) -> np.ndarray:
    """``(N, n_actions)``: how far (rad, in [0, pi]) each action's turn leaves the robot from
    ``bearing`` (N,), a direction relative to its heading."""
    return np.abs(np.angle(np.exp(1j * (bearing[:, None] - turns[None, :]))))


def goal_seeking_policy(config: NavConfig | None = None, margin: float = 0.3):
    """A policy ``obs (N, n_beams + 3) -> actions (N,)`` for ``config``'s robot and sensors;
    an action is blocked when the beam nearest its heading reads less than
    ``step + radius + margin`` metres, or a neighbouring beam less than twice ``radius + margin``
    (which keeps the robot's sides off corners)."""
    config = config or NavConfig()
    sensors, robot = config.sensors, config.robot
    turns = robot.turns
    beam_angles = sensors.beam_angles
    gap = np.angle(np.exp(1j * (turns[:, None] - beam_angles[None, :])))  # action x beam
    nearest_beam = np.abs(gap).argmin(axis=1)
    n = sensors.n_beams
    sides = np.stack([(nearest_beam - 1) % n, (nearest_beam + 1) % n], axis=1)
    needed = (robot.step + robot.radius + margin) / sensors.max_range
    needed_side = 2 * (robot.radius + margin) / sensors.max_range

    def policy(obs: np.ndarray) -> np.ndarray:
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        bearing = np.arctan2(obs[:, n + 1], obs[:, n + 2])  # goal direction relative to the heading
        free = (obs[:, nearest_beam] >= needed) & (obs[:, sides].min(axis=2) >= needed_side)
        score = np.where(free, -misalignment(bearing, turns), -np.inf)
        stuck = ~free.any(axis=1)
        score[stuck] = obs[stuck][:, nearest_beam]  # nothing free: head for the most open side
        return score.argmax(axis=1).astype(np.int64)

    return policy


def subgoal_scores(config: NavConfig):
    """``scores(obs (N, obs_dim)) -> (N, n_actions)``: minus each action's turn away from the
    bearing of the own map's subgoal (highest: the action heading closest to it), for ``config``'s
    observation, which must have a subgoal."""
    layout = frame_layout(config)
    if "subgoal" not in layout:
        raise ValueError("subgoal_scores: the observation has no subgoal (observation.subgoal is 'none')")
    at, turns = layout["subgoal"][0], config.robot.turns

    def scores(obs: np.ndarray) -> np.ndarray:
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        bearing = np.arctan2(obs[:, at + 1], obs[:, at + 2])  # (sin, cos) of the subgoal's bearing
        return -misalignment(bearing, turns)

    return scores

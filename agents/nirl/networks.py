"""NIRL's reward network over state-action features.

The features of taking action ``a`` in the state seen as observation ``s`` are the
observation itself, a one-hot code of ``a`` and three quantities the action changes:
the free range straight ahead *after* the turn of ``a`` (the beam readings interpolated
at the turn angle) and the sine and cosine of the goal bearing relative to that new
heading. They need no transition model - only the robot's own geometry (beam and turn
angles) - and they are what lets a reward learned from a few demonstrations transfer to
maps it never saw. Two output forms: ``cost`` (the max-margin core's
``R(s, a) = -scale * sigmoid(f(phi))``: costs below zero, as in maximum margin planning's cost
maps, so that reaching the goal is always worth it) and ``linear`` (``R(s, a) = f(phi)``, the
IQ-Learn and SQIL cores' explicit model of the reward their Q-function implies).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn
from torchrl.modules import MLP

from agents.nnql.networks import activation_class
from worlds.perception import observation_dim

REWARD_OUTPUTS = ("cost", "linear")
N_ACTION_FEATURES = 3
"""range along the new heading, sin and cos of the goal bearing from the new heading"""


def direction_weights(beam_angles: np.ndarray, directions: np.ndarray, full_circle: bool) -> np.ndarray:
    """Matrix ``W`` (n_beams, n_directions) such that ``ranges @ W`` interpolates the beam ranges
    linearly at each direction (radians from the heading); around the circle when the beams
    cover 360 degrees, clamped to the outermost beams otherwise."""
    beams = np.asarray(beam_angles, dtype=np.float64)
    n = len(beams)
    weights = np.zeros((n, len(directions)))
    if n == 1:
        weights[0, :] = 1.0
        return weights
    order = np.argsort(beams)
    sorted_angles = beams[order]
    for j, direction in enumerate(np.asarray(directions, dtype=np.float64)):
        if full_circle:
            # position of the direction in "beam steps" from the first sorted beam, wrapped
            step = 2 * math.pi / n
            pos = ((direction - sorted_angles[0]) % (2 * math.pi)) / step
            lo = math.floor(pos) % n
            frac = pos - math.floor(pos)
            weights[order[lo], j] += 1.0 - frac
            weights[order[(lo + 1) % n], j] += frac
        else:
            pos = float(np.interp(direction, sorted_angles, np.arange(n)))
            lo = min(math.floor(pos), n - 2)
            frac = pos - lo
            weights[order[lo], j] += 1.0 - frac
            weights[order[lo + 1], j] += frac
    return weights


def state_action_features(
    obs: torch.Tensor, turns: torch.Tensor, range_weights: torch.Tensor, n_beams: int
) -> torch.Tensor:
    """Features ``phi(s, a)`` of every action, ``(N, A, obs_dim + A + 3)``.

    ``obs`` (N, obs_dim) is the navigation observation (ranges / max_range, squashed goal
    distance, sin and cos of the goal bearing); ``turns`` (A,) the heading change of each
    action; ``range_weights`` (n_beams, A) from :func:`direction_weights`.
    """
    n, n_actions = obs.shape[0], turns.shape[0]
    ahead = obs[:, :n_beams] @ range_weights  # (N, A)
    sin_b, cos_b = obs[:, n_beams + 1 : n_beams + 2], obs[:, n_beams + 2 : n_beams + 3]
    cos_t, sin_t = torch.cos(turns)[None, :], torch.sin(turns)[None, :]
    bearing_cos = cos_b * cos_t + sin_b * sin_t  # cos(bearing - turn)
    bearing_sin = sin_b * cos_t - cos_b * sin_t  # sin(bearing - turn)
    one_hot = torch.eye(n_actions, dtype=obs.dtype).expand(n, n_actions, n_actions)
    state = obs[:, None, :].expand(n, n_actions, obs.shape[1])
    per_action = torch.stack([ahead, bearing_sin, bearing_cos], dim=-1)
    return torch.cat([state, one_hot, per_action], dim=-1)


def goal_reached(
    next_obs: torch.Tensor, n_beams: int, goal_tolerance: float, max_range: float
) -> torch.Tensor:
    """(N,) bool: the observation after a step puts the goal within ``goal_tolerance`` - read
    from the squashed goal distance ``d / (d + max_range)``, so terminations can be told apart
    (goal or collision) from observations alone."""
    squashed = goal_tolerance / (goal_tolerance + max_range)
    return next_obs[:, n_beams] <= squashed + 1e-6


class RewardNetwork(nn.Module):
    """``R(s, .)``: the learned cost of every action in a batch of states, ``(N, A)``.

    ``architecture`` (JSON-able) rebuilds it: obs_dim, n_actions, hidden_sizes,
    activation, scale, n_beams, turns, beam_angles, full_circle, output (``cost`` or ``linear``;
    files written before ``linear`` existed lack it and are ``cost``).
    """

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        hidden_sizes: tuple[int, ...] | list[int],
        activation: str,
        scale: float,
        n_beams: int,
        turns: np.ndarray | list[float],
        beam_angles: np.ndarray | list[float],
        full_circle: bool,
        output: str = "cost",
    ):
        super().__init__()
        if output not in REWARD_OUTPUTS:
            raise ValueError(f"reward output {output!r}: expected one of {REWARD_OUTPUTS}")
        activation_class(activation)  # ValueError for an unknown one, before anything is built
        turns = np.asarray(turns, dtype=np.float64)
        if len(turns) != n_actions or obs_dim < n_beams + 3:
            raise ValueError(
                f"need {n_actions} turns and obs_dim >= n_beams + 3, got {len(turns)}, {obs_dim}"
            )
        self.architecture: dict[str, Any] = {
            "obs_dim": int(obs_dim),
            "n_actions": int(n_actions),
            "hidden_sizes": [int(h) for h in hidden_sizes],
            "activation": activation,
            "scale": float(scale),
            "n_beams": int(n_beams),
            "turns": [float(t) for t in turns],
            "beam_angles": [float(b) for b in beam_angles],
            "full_circle": bool(full_circle),
            "output": output,
        }
        self.output = output
        self.scale = float(scale)
        self.n_beams = int(n_beams)
        self.register_buffer("turns", torch.as_tensor(turns, dtype=torch.float32), persistent=False)
        weights = direction_weights(np.asarray(beam_angles), turns, full_circle)
        self.register_buffer("range_weights", torch.as_tensor(weights, dtype=torch.float32), persistent=False)
        self.mlp = MLP(
            in_features=obs_dim + n_actions + N_ACTION_FEATURES,
            out_features=1,
            num_cells=[int(h) for h in hidden_sizes],
            activation_class=activation_class(activation),
        )

    @classmethod
    def for_navigation(
        cls, nav: Any, hidden_sizes, activation: str, scale: float, output: str = "cost"
    ) -> RewardNetwork:
        """The reward network for a ``worlds.config.NavConfig``'s robot, sensors and observation
        (its structured features read the newest frame's readings and goal, which lead every frame)."""
        sensors = nav.sensors
        return cls(
            obs_dim=observation_dim(nav),
            n_actions=nav.robot.n_actions,
            hidden_sizes=hidden_sizes,
            activation=activation,
            scale=scale,
            n_beams=sensors.n_beams,
            turns=nav.robot.turns,
            beam_angles=sensors.beam_angles,
            full_circle=math.isclose(sensors.fov, 2 * math.pi),
            output=output,
        )

    @classmethod
    def from_architecture(cls, architecture: dict[str, Any]) -> RewardNetwork:
        return cls(**architecture)

    def features(self, obs: torch.Tensor) -> torch.Tensor:
        return state_action_features(obs, self.turns, self.range_weights, self.n_beams)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        out = self.mlp(self.features(obs)).squeeze(-1)
        return out if self.output == "linear" else -self.scale * torch.sigmoid(out)

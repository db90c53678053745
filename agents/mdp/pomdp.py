"""Partially observable grid robot (thesis ch. 2.2, POMDPs): a discrete Bayes
filter over the MDP's states and the QMDP policy on top of the solved MDP.

The robot does not see its cell. It senses, in each of ``k`` directions (the
first ``k`` moves of ``worlds.gridworld.MOVES``: N, S, W, E, then diagonals),
whether the neighbouring cell is blocked (off the map counts as blocked); each
reading is wrong, independently, with probability ``flip_prob``. An
observation is the integer whose bit ``j`` is reading ``j``.

Belief update after action ``a`` and observation ``o``:
``b'(s') = O(s', o) * sum_s P_a(s, s') b(s) / normaliser``.
QMDP (Littman, Cassandra & Kaelbling 1995) acts as if the state became known
after one step: ``argmax_a sum_s b(s) Q*(s, a)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.mdp.model import FiniteMDP
from worlds.gridworld import MOVES, GridDynamics


def wall_readings(dynamics: GridDynamics, directions: int = 4) -> np.ndarray:
    """``(S,)`` noise-free observation code of every state."""
    if not 1 <= directions <= len(MOVES):
        raise ValueError(f"directions must be in 1..{len(MOVES)}, got {directions}")
    padded = np.pad(dynamics.grid.blocked, 1, constant_values=True)
    rows, cols = dynamics.cells[:, 0] + 1, dynamics.cells[:, 1] + 1
    code = np.zeros(dynamics.n_states, dtype=np.int64)
    for j, (dr, dc) in enumerate(MOVES[:directions]):
        code |= padded[rows + dr, cols + dc].astype(np.int64) << j
    return code


def wall_sensor_model(dynamics: GridDynamics, flip_prob: float = 0.1, directions: int = 4) -> np.ndarray:
    """``(S, 2**directions)`` observation probabilities ``O[s, o]``; rows sum to 1."""
    if not 0.0 <= flip_prob <= 0.5:
        raise ValueError(f"flip_prob must be in [0, 0.5], got {flip_prob}")
    true = wall_readings(dynamics, directions)
    codes = np.arange(2**directions)
    wrong = np.bitwise_xor(true[:, None], codes[None, :])
    n_wrong = np.zeros(wrong.shape, dtype=np.int64)
    for j in range(directions):
        n_wrong += (wrong >> j) & 1
    return flip_prob**n_wrong * (1.0 - flip_prob) ** (directions - n_wrong)


@dataclass(frozen=True, eq=False)
class BeliefFilter:
    """Discrete Bayes filter: ``mdp`` gives the motion model, ``observation``
    the ``(S, n_obs)`` sensor model."""

    mdp: FiniteMDP
    observation: np.ndarray

    def __post_init__(self) -> None:
        if self.observation.ndim != 2 or self.observation.shape[0] != self.mdp.n_states:
            raise ValueError(
                f"observation must be (S, n_obs) with S={self.mdp.n_states}, got {self.observation.shape}"
            )
        if (self.observation < 0).any() or not np.allclose(self.observation.sum(axis=1), 1.0):
            raise ValueError("observation rows must be probability distributions over observations")

    def uniform(self) -> np.ndarray:
        return np.full(self.mdp.n_states, 1.0 / self.mdp.n_states)

    def predict(self, belief: np.ndarray, action: int) -> np.ndarray:
        """Motion update: ``sum_s P_a(s, .) b(s)``."""
        return self.mdp.transitions[int(action)].T @ belief

    def correct(self, belief: np.ndarray, observation: int) -> np.ndarray:
        """Measurement update; ValueError if the observation is impossible under ``belief``."""
        posterior = belief * self.observation[:, int(observation)]
        total = posterior.sum()
        if not total > 0:
            raise ValueError(f"observation {observation} has probability 0 under the current belief")
        return posterior / total

    def update(self, belief: np.ndarray, action: int, observation: int) -> np.ndarray:
        return self.correct(self.predict(belief, action), observation)

    def sample_observation(self, rng: np.random.Generator, state: int) -> int:
        return int(rng.choice(self.observation.shape[1], p=self.observation[state]))


def qmdp_action(belief: np.ndarray, q: np.ndarray) -> int:
    """QMDP: the action with the best belief-weighted ``Q*(s, a)``."""
    return int(np.argmax(belief @ q))

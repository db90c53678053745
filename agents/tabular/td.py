"""TD(0) policy evaluation (Sutton 1988; thesis ch. 2.4):
``V(s) += alpha * (r + gamma * V(s') - V(s))`` while following a fixed policy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from agents.tabular.common import Progress, grid_dynamics, run_episodes, sample_index, start_state, step_size
from agents.tabular.config import TDConfig
from worlds.gridworld import GridWorldEnv


@dataclass(frozen=True)
class PredictionResult:
    values: np.ndarray
    """``(S,)`` estimated state values of the policy."""
    returns: np.ndarray
    """Undiscounted return of each episode."""
    lengths: np.ndarray
    """Steps of each episode."""


@njit(cache=True)
def _episodes(
    values,
    visits,
    successor,
    reward,
    cum_prob,
    goal,
    start,
    max_steps,
    gamma,
    alpha,
    by_visits,
    power,
    cum_policy,
    n_episodes,
    returns,
    lengths,
    first,
):
    for i in range(n_episodes):
        s = start_state(start, successor.shape[0], goal)
        total = 0.0
        t = 0
        while t < max_steps and s != goal:
            a = sample_index(cum_policy[s])
            b = sample_index(cum_prob[a])
            nxt = successor[s, b]
            r = reward[s, b]
            visits[s] += 1
            target = r if nxt == goal else r + gamma * values[nxt]
            values[s] += step_size(alpha, by_visits, power, visits[s]) * (target - values[s])
            total += r
            s = nxt
            t += 1
        returns[first + i] = total
        lengths[first + i] = t


def td0_prediction(
    env: GridWorldEnv, policy: np.ndarray, config: TDConfig | None = None, progress: Progress | None = None
) -> PredictionResult:
    """Estimate ``V_pi`` of a deterministic ``(S,)`` or stochastic ``(S, A)`` policy by TD(0)."""
    config = config or TDConfig()
    grid = grid_dynamics(env)
    dyn = grid[0]
    policy = np.asarray(policy)
    if policy.shape == (dyn.n_states,):
        policy = np.eye(dyn.n_actions)[policy]
    if policy.shape != (dyn.n_states, dyn.n_actions) or (policy < 0).any():
        raise ValueError(f"policy must be (S,) actions or (S, A) probabilities, got shape {policy.shape}")
    cum_policy = np.cumsum(policy, axis=1)
    values = np.zeros(dyn.n_states)
    returns, lengths = run_episodes(
        _episodes, grid, values, config, progress, lambda first, last: (cum_policy, last - first)
    )
    return PredictionResult(values, returns, lengths)

"""TD(0) policy evaluation (Sutton 1988; thesis ch. 2.4):
``V(s) += alpha * (r + gamma * V(s') - V(s))`` while following a fixed policy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from agents.tabular.common import (
    Progress,
    grid_dynamics,
    run_in_chunks,
    sample_index,
    seed_numba,
    start_state,
    step_size,
)
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
    cum_policy,
    goal,
    start,
    max_steps,
    gamma,
    alpha,
    by_visits,
    power,
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
    dyn, start, max_steps = grid_dynamics(env)
    policy = np.asarray(policy)
    if policy.shape == (dyn.n_states,):
        policy = np.eye(dyn.n_actions)[policy]
    if policy.shape != (dyn.n_states, dyn.n_actions) or (policy < 0).any():
        raise ValueError(f"policy must be (S,) actions or (S, A) probabilities, got shape {policy.shape}")
    cum_policy = np.cumsum(policy, axis=1)
    values = np.zeros(dyn.n_states)
    visits = np.zeros(dyn.n_states, dtype=np.int64)
    cum_prob = np.cumsum(dyn.outcome_prob, axis=1)
    returns = np.zeros(config.episodes)
    lengths = np.zeros(config.episodes, dtype=np.int64)
    seed_numba(config.seed)

    def run(first: int, last: int) -> None:
        _episodes(
            values,
            visits,
            dyn.successor,
            dyn.reward,
            cum_prob,
            cum_policy,
            dyn.goal_state,
            start,
            max_steps,
            config.gamma,
            config.alpha,
            config.alpha_schedule == "visits",
            config.alpha_power,
            last - first,
            returns,
            lengths,
            first,
        )

    run_in_chunks(run, config.episodes, progress)
    return PredictionResult(values, returns, lengths)

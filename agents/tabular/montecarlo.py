"""Monte Carlo control with epsilon-soft policies (Sutton & Barto 2018, sec. 5.4;
thesis ch. 2.4): play a whole episode with the exploring policy, then move
``Q(s, a)`` towards the observed return ``G_t`` of each first (or every) visit.
With ``alpha_schedule="visits"`` and ``alpha_power=1`` this is the sample average
of the returns; the default 0.6 forgets the returns of the early, exploring
policies faster."""

from __future__ import annotations

import numpy as np
from numba import njit

from agents.tabular.common import (
    Progress,
    TabularResult,
    explore,
    run_control,
    sample_index,
    start_state,
    step_size,
)
from agents.tabular.config import MonteCarloConfig
from worlds.gridworld import GridWorldEnv


@njit(cache=True)
def _episodes(
    q,
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
    boltzmann,
    explore_params,
    first_visit,
    returns,
    lengths,
    first,
):
    n_states, n_actions = q.shape
    states = np.empty(max_steps, dtype=np.int64)
    actions = np.empty(max_steps, dtype=np.int64)
    rewards = np.empty(max_steps)
    counted = np.empty(max_steps, dtype=np.bool_)
    stamp = np.full((n_states, n_actions), -1, dtype=np.int64)
    for i in range(explore_params.shape[0]):
        s = start_state(start, n_states, goal)
        t = 0
        while t < max_steps and s != goal:
            a = explore(q[s], boltzmann, explore_params[i])
            b = sample_index(cum_prob[a])
            states[t], actions[t], rewards[t] = s, a, reward[s, b]
            counted[t] = not first_visit or stamp[s, a] != i
            stamp[s, a] = i
            s = successor[s, b]
            t += 1
        g = 0.0
        for k in range(t - 1, -1, -1):
            g = rewards[k] + gamma * g
            if counted[k]:
                s, a = states[k], actions[k]
                visits[s, a] += 1
                q[s, a] += step_size(alpha, by_visits, power, visits[s, a]) * (g - q[s, a])
        returns[first + i] = rewards[:t].sum()
        lengths[first + i] = t


def monte_carlo_control(
    env: GridWorldEnv, config: MonteCarloConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn the action values of a grid-world env by on-policy Monte Carlo control.
    Episodes cut by the env's ``max_steps`` give truncated returns."""
    config = config or MonteCarloConfig()
    # the kernel runs once per chunk; its visit stamps are episode numbers within a call,
    # so each call starts a fresh stamp table
    return run_control(_episodes, env, config, progress, config.first_visit)

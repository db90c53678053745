"""Q-learning (Watkins 1989; thesis ch. 2.4): off-policy TD control,
``Q(s, a) += alpha * (r + gamma * max_a' Q(s', a') - Q(s, a))``."""

from __future__ import annotations

from numba import njit

from agents.tabular.common import (
    Progress,
    TabularConfig,
    TabularResult,
    explore,
    run_control,
    sample_index,
    start_state,
    step_size,
)
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
    returns,
    lengths,
    first,
):
    for i in range(explore_params.shape[0]):
        s = start_state(start, successor.shape[0], goal)
        total = 0.0
        t = 0
        while t < max_steps and s != goal:
            a = explore(q[s], boltzmann, explore_params[i])
            b = sample_index(cum_prob[a])
            nxt = successor[s, b]
            r = reward[s, b]
            visits[s, a] += 1
            target = r if nxt == goal else r + gamma * q[nxt].max()
            q[s, a] += step_size(alpha, by_visits, power, visits[s, a]) * (target - q[s, a])
            total += r
            s = nxt
            t += 1
        returns[first + i] = total
        lengths[first + i] = t


def q_learning(
    env: GridWorldEnv, config: TabularConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn ``Q*`` of a grid-world env by Q-learning."""
    return run_control(_episodes, env, config or TabularConfig(), progress)

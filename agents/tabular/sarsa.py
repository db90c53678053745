"""SARSA (Rummery & Niranjan 1994; thesis ch. 2.4): on-policy TD control,
``Q(s, a) += alpha * (r + gamma * Q(s', a') - Q(s, a))`` with ``a'`` drawn from
the same exploring policy. With exploration decaying towards greedy (GLIE) it
converges to ``Q*``. Its targets change as the policy improves, so with
epsilon-greedy exploration a constant step size (``alpha_schedule="constant"``)
tracks them better than the visit-count schedule, whose steps shrink on the
pairs it visits most (tests/test_tabular_learners.py uses alpha 0.1)."""

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
        param = explore_params[i]
        s = start_state(start, successor.shape[0], goal)
        a = explore(q[s], boltzmann, param)
        total = 0.0
        t = 0
        while t < max_steps and s != goal:
            b = sample_index(cum_prob[a])
            nxt = successor[s, b]
            r = reward[s, b]
            nxt_a = explore(q[nxt], boltzmann, param)
            visits[s, a] += 1
            target = r if nxt == goal else r + gamma * q[nxt, nxt_a]
            q[s, a] += step_size(alpha, by_visits, power, visits[s, a]) * (target - q[s, a])
            total += r
            s, a = nxt, nxt_a
            t += 1
        returns[first + i] = total
        lengths[first + i] = t


def sarsa(
    env: GridWorldEnv, config: TabularConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn the action values of a grid-world env by SARSA."""
    return run_control(_episodes, env, config or TabularConfig(), progress)

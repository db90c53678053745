"""TD control (thesis ch. 2.4): Q-learning and SARSA, one compiled episode kernel for both.

Q-learning (Watkins 1989) is off-policy TD control,
``Q(s, a) += alpha * (r + gamma * max_a' Q(s', a') - Q(s, a))``.

SARSA (Rummery & Niranjan 1994) is on-policy TD control,
``Q(s, a) += alpha * (r + gamma * Q(s', a') - Q(s, a))`` with ``a'`` drawn from
the same exploring policy. With exploration decaying towards greedy (GLIE) it
converges to ``Q*``. Its targets change as the policy improves, so with
epsilon-greedy exploration a constant step size (``alpha_schedule="constant"``)
tracks them better than the visit-count schedule, whose steps shrink on the
pairs it visits most (tests/test_tabular_learners.py uses alpha 0.1).
"""

from __future__ import annotations

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
from agents.tabular.config import TabularConfig
from worlds.gridworld import GridWorldEnv


@njit(cache=True)
def td_control_episodes(
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
    on_policy,
    returns,
    lengths,
    first,
):
    """The TD control kernel (run_control's signature, ``on_policy`` as its extra argument): Q-learning
    bootstraps on ``max_a' Q(s', a')`` and draws each action when it acts; SARSA (``on_policy``) draws
    the next action ``a'`` first and bootstraps on ``Q(s', a')``, then takes it."""
    for i in range(explore_params.shape[0]):
        param = explore_params[i]
        s = start_state(start, successor.shape[0], goal)
        total = 0.0
        t = 0
        a = explore(q[s], boltzmann, param) if on_policy else 0
        while t < max_steps and s != goal:
            if not on_policy:
                a = explore(q[s], boltzmann, param)
            b = sample_index(cum_prob[a])
            nxt = successor[s, b]
            r = reward[s, b]
            visits[s, a] += 1
            if on_policy:
                nxt_a = explore(q[nxt], boltzmann, param)
                bootstrap = q[nxt, nxt_a]
            else:
                nxt_a = 0
                bootstrap = q[nxt].max()
            target = r if nxt == goal else r + gamma * bootstrap
            q[s, a] += step_size(alpha, by_visits, power, visits[s, a]) * (target - q[s, a])
            total += r
            s, a = nxt, nxt_a
            t += 1
        returns[first + i] = total
        lengths[first + i] = t


def q_learning(
    env: GridWorldEnv, config: TabularConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn ``Q*`` of a grid-world env by Q-learning."""
    return run_control(td_control_episodes, env, config or TabularConfig(), progress, False)


def sarsa(
    env: GridWorldEnv, config: TabularConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn the action values of a grid-world env by SARSA."""
    return run_control(td_control_episodes, env, config or TabularConfig(), progress, True)

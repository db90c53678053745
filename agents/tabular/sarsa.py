"""SARSA (Rummery & Niranjan 1994; thesis ch. 2.4): on-policy TD control,
``Q(s, a) += alpha * (r + gamma * Q(s', a') - Q(s, a))`` with ``a'`` drawn from
the same exploring policy. With exploration decaying towards greedy (GLIE) it
converges to ``Q*``. Its targets change as the policy improves, so with
epsilon-greedy exploration a constant step size (``alpha_schedule="constant"``)
tracks them better than the visit-count schedule, whose steps shrink on the
pairs it visits most (tests/test_tabular_learners.py uses alpha 0.1)."""

from __future__ import annotations

from agents.tabular.common import Progress, TabularConfig, TabularResult, run_control, td_control_episodes
from worlds.gridworld import GridWorldEnv


def sarsa(
    env: GridWorldEnv, config: TabularConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn the action values of a grid-world env by SARSA."""
    return run_control(td_control_episodes, env, config or TabularConfig(), progress, True)

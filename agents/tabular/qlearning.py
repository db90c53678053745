"""Q-learning (Watkins 1989; thesis ch. 2.4): off-policy TD control,
``Q(s, a) += alpha * (r + gamma * max_a' Q(s', a') - Q(s, a))``."""

from __future__ import annotations

from agents.tabular.common import Progress, TabularConfig, TabularResult, run_control, td_control_episodes
from worlds.gridworld import GridWorldEnv


def q_learning(
    env: GridWorldEnv, config: TabularConfig | None = None, progress: Progress | None = None
) -> TabularResult:
    """Learn ``Q*`` of a grid-world env by Q-learning."""
    return run_control(td_control_episodes, env, config or TabularConfig(), progress, False)

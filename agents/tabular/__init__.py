"""Model-free tabular learning (thesis ch. 2.4): Monte Carlo control (first- and
every-visit, epsilon-soft), TD(0) prediction, SARSA and Q-learning, with
epsilon-greedy or Boltzmann exploration and step-size schedules, on the
``worlds.gridworld`` env. Compiled with numba; seeded."""

from agents.tabular.common import TabularConfig, TabularResult, exploration_schedule
from agents.tabular.montecarlo import MonteCarloConfig, monte_carlo_control
from agents.tabular.qlearning import q_learning
from agents.tabular.sarsa import sarsa
from agents.tabular.td import PredictionResult, TDConfig, td0_prediction

__all__ = [
    "MonteCarloConfig",
    "PredictionResult",
    "TDConfig",
    "TabularConfig",
    "TabularResult",
    "exploration_schedule",
    "monte_carlo_control",
    "q_learning",
    "sarsa",
    "td0_prediction",
]

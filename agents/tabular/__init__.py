"""Model-free tabular learning (thesis ch. 2.4): Monte Carlo control (first- and
every-visit, epsilon-soft), TD(0) prediction, SARSA and Q-learning, with
epsilon-greedy or Boltzmann exploration and step-size schedules, on the
``worlds.gridworld`` env. Compiled with numba; seeded.

The configs (agents.tabular.config) import nothing heavy; the learners and their numba kernels are
imported when first named here, so reading a config (the command line does) loads no numba."""

from __future__ import annotations

import importlib

from agents.tabular.config import MonteCarloConfig, TabularConfig, TDConfig

_LEARNERS = {
    "TabularResult": "agents.tabular.common",
    "exploration_schedule": "agents.tabular.common",
    "monte_carlo_control": "agents.tabular.montecarlo",
    "q_learning": "agents.tabular.td_control",
    "sarsa": "agents.tabular.td_control",
    "PredictionResult": "agents.tabular.td",
    "td0_prediction": "agents.tabular.td",
}


def __getattr__(name: str) -> object:
    if name in _LEARNERS:
        return getattr(importlib.import_module(_LEARNERS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["MonteCarloConfig", "TDConfig", "TabularConfig", *_LEARNERS]

"""Neural-network Q-learning (thesis ch. 4): a library, no transport.

config (NNQLConfig) - networks (QNetwork) - losses (DQNLoss wiring, SarsaLoss,
td_target) - learner (NNQLLearner: TorchRL replay + updates + checkpoints) - policy
(NNQLPolicy: numpy Boltzmann / epsilon / greedy policy built from weights).
Import the learner from ``agents.nnql.learner`` (it pulls in torch); the policy
module is numpy-only so actors start fast.
"""

from agents.nnql.config import NNQLConfig

__all__ = ["NNQLConfig"]

"""What NIRLLearner hands the core it trains with (``agents.nirl.soft_q.SoftQFit`` or
``agents.nirl.max_margin.MaxMarginFit``): one declaration of the parts both cores use."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.data import TensorDictReplayBuffer

from agents.nirl.config import NIRLConfig
from agents.nirl.losses import Refinement
from agents.nirl.networks import RewardNetwork
from agents.nnql.learner import NNQLLearner

ClipStep = Callable[[torch.Tensor, Any, torch.optim.Optimizer], float]
"""(loss, parameters, optimiser) -> gradient norm: backward, clip, step."""
Refine = Callable[[TensorDictBase], Refinement]
"""demonstrated steps (observation, action, recorded noise, ...) -> MAP refinement."""


@dataclass(eq=False)
class FitParts:
    """The reward network and its optimiser, NNQL's learner, both buffers, the refinement function,
    the goal test's constants, the clipped optimiser step and what runs after each Q update."""

    config: NIRLConfig
    reward: RewardNetwork
    reward_optimizer: torch.optim.Optimizer
    q: NNQLLearner
    demos: TensorDictReplayBuffer
    experience: TensorDictReplayBuffer
    refine: Refine
    goal_tolerance: float
    max_range: float
    clip_step: ClipStep
    after_update: Callable[[], None]

"""Does NIRL's learned reward generalise? Its figures on demonstrated episodes it never trained on.

For a list of expert episodes (``agents.demos.Demo``) this measures, under a trained
``NIRLLearner`` of the soft-Q cores: the greedy policy's agreement with the expert's actions, the
implicit reward ``Q(s, a) - gamma V(s')`` per expert step (with the learner's own absorbing end
states, ``soft_q.absorbing_next``) and the rank correlation of the soft value ``V(s)`` with the
expert's remaining steps to the goal (a reward that transfers orders states by progress: the
correlation with the steps still to go is negative). Run on the training demonstrations and on
held-out ones (other maps), the gap says how much of the reward is memorised.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from agents.nirl.losses import implicit_reward, soft_value
from agents.nirl.networks import goal_reached
from agents.nirl.soft_q import absorbing_next


def rank_correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation (ties broken by order; NaN when either side is constant)."""
    if len(x) < 2 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan")
    rx, ry = np.argsort(np.argsort(x)), np.argsort(np.argsort(y))
    return float(np.corrcoef(rx, ry)[0, 1])


def demo_figures(learner: Any, demos: Sequence[Any]) -> dict[str, float]:
    """Greedy agreement, implicit reward per step and value/steps-to-go correlation over ``demos``."""
    cfg = learner.config
    obs = torch.as_tensor(np.concatenate([d.observations[:-1] for d in demos]), dtype=torch.float32)
    nxt = torch.as_tensor(np.concatenate([d.observations[1:] for d in demos]), dtype=torch.float32)
    actions = torch.as_tensor(np.concatenate([d.actions for d in demos]), dtype=torch.int64)
    terminated = torch.as_tensor(np.concatenate([d.terminations for d in demos]), dtype=torch.bool)
    to_go = np.concatenate([np.arange(len(d.actions), 0, -1) for d in demos]).astype(np.float64)
    obs, nxt = obs.to(learner.device), nxt.to(learner.device)
    actions, terminated = actions.to(learner.device), terminated.to(learner.device)
    with torch.no_grad():
        q_all = learner.q.network(obs)
        next_value = soft_value(learner.fit.target_q(nxt), cfg.alpha)
        at_goal = goal_reached(nxt, learner.reward.n_beams, learner.goal_tolerance, learner.max_range)
        next_value, term = absorbing_next(cfg, next_value, terminated, at_goal)
        q_taken = q_all.gather(1, actions[:, None]).squeeze(1)
        reward = implicit_reward(q_taken, next_value, term, cfg.gamma)
        value = soft_value(q_all, cfg.alpha)
    return {
        "steps": len(actions),
        "greedy_agreement": float((q_all.argmax(dim=1) == actions).float().mean()),
        "implicit_reward": float(reward.mean()),
        "value": float(value.mean()),
        "value_vs_steps_to_go": rank_correlation(value.cpu().numpy(), to_go),
    }

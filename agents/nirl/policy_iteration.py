"""NIRL's policy iteration at NNQL's speed: NNQL's own local trainer on the fixed learned reward.

Once IQ-Learn's rounds have fixed the reward (``NIRLConfig.fix_reward_after``), what is left is
plain reinforcement learning on a known reward: the unit step cost shaped by the progress
potential learned from the demonstrations (``agents.nirl.progress``), the collision's absorbing
state valued as never arriving. NNQL's local trainer (``agents.nnql.train_local``: many robots, its
update-to-data ratio, dueling head, the 0..6 moving-disc mix, keep-best on the validation seed)
does that fastest, so NIRL hands it the reward (``NIRLConfig.policy_steps`` robot-steps) instead
of running soft Q-learning inside its own slow rounds. ``FixedReward`` is the reward the
transitions carry: computed where they are made, from the observations alone, with
``progress.shaped_progress_reward`` (its one definition); the environment's reward is overwritten
before anything stores it.

The Q-learner discounts with NIRL's gamma: potential-based shaping leaves the optimal policy
unchanged only under the discount it was built with (Ng, Harada & Russell, ICML 1999).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import torch

from agents.nirl.config import NIRLConfig, NIRLRun
from agents.nirl.learner import NIRLLearner
from agents.nirl.networks import goal_reached
from agents.nirl.progress import ProgressPotential, shaped_progress_reward
from agents.nnql.config import NNQLConfig
from agents.nnql.networks import output_layer
from agents.nnql.train_local import LocalTrainConfig, TrainResult, train_local
from worlds.config import NavConfig

POLICY_DIR = "policy_iteration"
"""subdirectory of a NIRL run's output where the policy of this phase is written (NNQL's files)"""


class FixedReward:
    """The fixed learned reward of a transition batch: ``(1 - gamma) (-1 + gamma Phi(s') - Phi(s))``,
    the goal's potential 0, a collision's ``-1 / (1 - gamma)`` (``progress.shaped_progress_reward``).

    The factor ``1 - gamma`` (the same optimal policy) puts it in the units of NNQL's own rewards - a
    step costs 0.01, a collision about 1 - which NNQL's Huber loss and Boltzmann temperatures (0.2 to
    0.01) are tuned for: unscaled (a collision about -90) those temperatures make exploration all but
    greedy and validation success falls."""

    def __init__(self, potential: ProgressPotential, gamma: float, n_beams: int, goal_tolerance: float,
                 max_range: float):  # fmt: skip
        self.potential = copy.deepcopy(potential).cpu().requires_grad_(False).eval()
        self.gamma = float(gamma)
        self.scale = 1.0 - self.gamma
        self.n_beams, self.goal_tolerance = int(n_beams), float(goal_tolerance)
        self.max_range = float(max_range)

    @classmethod
    def of(cls, learner: NIRLLearner) -> FixedReward:
        """The reward a NIRL learner holds once its reward is fixed (its progress potential)."""
        potential = learner.potential
        if potential is None:
            raise ValueError("policy iteration at NNQL's speed needs fixed_reward='progress' (a potential)")
        return cls(potential, learner.config.gamma, learner.reward.n_beams, learner.goal_tolerance,
                   learner.max_range)  # fmt: skip

    def __call__(self, batch: dict[str, np.ndarray]) -> np.ndarray:
        obs = torch.as_tensor(np.asarray(batch["obs"], dtype=np.float32))
        next_obs = torch.as_tensor(np.asarray(batch["next_obs"], dtype=np.float32))
        terminated = torch.as_tensor(np.asarray(batch["terminated"], dtype=bool))
        at_goal = goal_reached(next_obs, self.n_beams, self.goal_tolerance, self.max_range)
        reward = shaped_progress_reward(self.potential, obs, next_obs, terminated, at_goal, self.gamma)
        return (self.scale * reward).numpy().astype(np.float32)


def nnql_config(config: NIRLConfig) -> NNQLConfig:
    """NNQL's defaults (dueling head, utd, batch, exploration) on the MLP alone, with NIRL's gamma and
    seed, ``policy_utd``
    when set, and with ``policy_warm_start`` NIRL's Q-network's layers and a constant
    ``policy_temperature``."""
    options: dict = {"utd_ratio": config.policy_utd} if config.policy_utd > 0 else {}
    if config.policy_warm_start:
        options |= {
            "hidden_sizes": config.hidden_sizes,
            "activation": config.activation,
            "temperature_start": config.policy_temperature,
            "temperature_end": config.policy_temperature,
        }
    # the MLP alone: the warm start's layout, and the phase's recorded runs
    return NNQLConfig(gamma=config.gamma, seed=config.seed, network="mlp", **options)


def warm_weights(learner: NIRLLearner, config: NIRLConfig) -> dict[str, np.ndarray]:
    """NIRL's Q-network in NNQL's plain layout with its output layer times ``1 - gamma``: the same greedy
    policy, its values in the units of :class:`FixedReward` (a step 0.01, not 1)."""
    weights = {name: value.copy() for name, value in learner.get_weights().items()}
    last = output_layer(config.hidden_sizes)
    for name in (f"{last}.weight", f"{last}.bias"):
        weights[name] *= np.float32(1.0 - config.gamma)
    return weights


def policy_iteration(learner: NIRLLearner, config: NIRLConfig, run: NIRLRun, nav: NavConfig) -> TrainResult:
    """``config.policy_steps`` robot-steps of NNQL's local trainer on ``learner``'s fixed reward
    (``run.envs`` robots on ``run.maps``, NNQL's disc mix, keep-best on ``run.eval_episodes`` validation
    episodes every ``run.policy_eval_every`` robot-steps, ``run.policy_eval_dynamic_episodes`` with 4
    moving discs beside) -> TrainResult (its ``policy`` is the kept one)."""
    out = str(Path(run.out) / POLICY_DIR) if run.out else ""
    local = LocalTrainConfig(
        steps=config.policy_steps, envs=run.envs, maps=run.maps, seed=config.seed, out=out,
        eval_every=run.policy_eval_every, eval_episodes=run.eval_episodes, eval_sizes=(16,),
        eval_dynamic_episodes=run.policy_eval_dynamic_episodes, keep_best=run.policy_eval_every > 0,
        final_eval_episodes=0, progress=run.progress, device=run.device,
    )  # fmt: skip
    initial = warm_weights(learner, config) if config.policy_warm_start else None
    return train_local(
        local, nnql_config(config), nav, reward=FixedReward.of(learner), initial_weights=initial
    )

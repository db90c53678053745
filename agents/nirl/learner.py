"""The NIRL learner: reward network + NNQL's Q-learning machinery + a demonstration buffer.

Transport-free, like ``agents.nnql.learner``: the local trainer and the learner service
feed it experience and demonstrations and ask for updates. Policy evaluation *is*
``NNQLLearner``'s - its QNetwork, TorchRL replay, DQNLoss (TD(0), target network,
double Q) and soft target updates - only the reward of every sampled transition is
replaced by the learned one. Buffers come in through the constructor, so the learner
service can share its NNQL replay (actor experience) and its demonstration buffer.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.data import TensorDictReplayBuffer

from agents.nirl.buffers import demo_buffer, demo_steps, sample
from agents.nirl.config import NIRLConfig
from agents.nirl.losses import (
    KEEP,
    RELABEL,
    REWEIGHT,
    Refinement,
    absorbing_rewards,
    map_posterior,
    margin_violations,
    max_margin_loss,
    ranking_margin_loss,
    refine_steps,
    structured_margins,
)
from agents.nirl.networks import RewardNetwork, goal_reached
from agents.nnql.learner import NNQLLearner, transitions_to_tensordict
from agents.nnql.policy import NNQLPolicy
from worlds.config import NavConfig, observation_settings
from worlds.perception import observation_dim

Q_KEYS = (
    "observation",
    "action",
    ("next", "observation"),
    ("next", "reward"),
    ("next", "terminated"),
    ("next", "truncated"),
    ("next", "done"),
)


class NIRLLearner:
    """Neural inverse RL: MAP-refined demonstrations, max-margin reward fit, Q-learning under it.

    ``add_demos`` / ``add_experience`` fill the buffers; ``warm_start()`` fits both networks
    to the demonstrations; ``iterate()`` is one policy-iteration round (reward updates, then
    Q-learning updates); ``update()`` is one Q update with the reward updates the configured
    ratio asks for (the learner service's fine-grained step). ``version`` counts Q updates.
    """

    def __init__(
        self,
        config: NIRLConfig,
        nav: Any = None,
        *,
        experience: TensorDictReplayBuffer | None = None,
        demos: TensorDictReplayBuffer | None = None,
    ):
        self.config = config
        nav = nav or NavConfig()
        obs_dim, n_actions = observation_dim(nav), nav.robot.n_actions
        observation = observation_settings(nav)
        self.q = NNQLLearner(config.nnql_config(), obs_dim, n_actions, observation=observation)  # seeds torch
        self.reward = RewardNetwork.for_navigation(
            nav, config.reward_hidden_sizes, config.activation, config.reward_scale
        )
        self.reward_optimizer = torch.optim.Adam(
            self.reward.parameters(), lr=config.reward_lr, weight_decay=config.reward_weight_decay
        )
        self.goal_tolerance = float(nav.goal_tolerance)
        self.max_range = float(nav.sensors.max_range)
        self.margins = structured_margins(torch.as_tensor(nav.robot.turns), config.margin)
        self.experience = experience if experience is not None else self.q.replay
        self.owns_demos = demos is None
        self.demos = demos if demos is not None else demo_buffer(config.demo_capacity, config.seed + 1)
        self.demo_episodes = 0
        self.iteration = 0
        self.reward_steps = 0
        self.warm_updates = 0
        self.reward_credit = 0.0
        self.metrics: dict[str, float] = {}

    # ------------------------------------------------------------ data in

    @property
    def obs_dim(self) -> int:
        return int(self.q.architecture["obs_dim"])

    @property
    def version(self) -> int:
        """Policy version: Q-network updates so far (warm start included)."""
        return self.q.updates

    def add_demos(self, demos: Iterable[Any]) -> int:
        """Add demonstrated episodes: ``agents.demos.Demo`` objects, or (meta, arrays) pairs from
        ``protocols.messages.DemoBatch.split()``. Returns the number of steps added."""
        steps = 0
        for item in demos:
            if isinstance(item, tuple):
                arrays = item[1]
                flat = demo_steps(
                    arrays["observations"], arrays["actions"], arrays["terminations"], arrays["truncations"]
                )
            else:
                flat = demo_steps(item.observations, item.actions, item.terminations, item.truncations)
            td = transitions_to_tensordict(flat, self.obs_dim)
            td.set("episode", torch.full((td.batch_size[0],), self.demo_episodes, dtype=torch.int64))
            self.demos.extend(td)
            self.demo_episodes += 1
            steps += td.batch_size[0]
        return steps

    def add_experience(self, batch: Any) -> int:
        """Insert environment transitions (any form ``NNQLLearner.add`` takes) into the experience replay."""
        if self.experience is self.q.replay:
            return self.q.add(batch)
        td = transitions_to_tensordict(batch, self.obs_dim)
        self.experience.extend(td)
        return td.batch_size[0]

    # ------------------------------------------------------------ MAP refinement

    def prior(self, obs: torch.Tensor) -> torch.Tensor:
        """The current stochastic policy as a prior over intended actions: softmax(Q / T)."""
        with torch.no_grad():
            return torch.softmax(self.q.network(obs) / self.config.prior_temperature, dim=1)

    def refine(self, obs: torch.Tensor, actions: torch.Tensor) -> Refinement:
        """MAP refinement of demonstrated steps under the current policy prior (see losses.refine_steps)."""
        actions = actions.long().reshape(-1)
        if not self.config.refine:
            ones = torch.ones(len(actions))
            return Refinement(actions, ones, torch.full_like(actions, KEEP))
        posterior = map_posterior(self.prior(obs), actions, self.config.demo_noise)
        return refine_steps(posterior, actions, self.config.relabel_threshold)

    def refine_all(self) -> tuple[TensorDict, Refinement]:
        """Every stored demonstration step and its refinement (for reports and tests)."""
        steps = self.demos.storage.get(torch.arange(len(self.demos)))
        return steps, self.refine(steps["observation"], steps["action"])

    # ------------------------------------------------------------ updates

    def _clip_step(self, loss: torch.Tensor, params, optimizer) -> float:
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        max_norm = self.config.grad_clip if self.config.grad_clip > 0 else float("inf")
        norm = torch.nn.utils.clip_grad_norm_(params, max_norm)
        optimizer.step()
        return float(norm)

    def reward_step(self, myopic: bool = False) -> dict[str, float]:
        """One maximum-margin update of the reward network on a batch of refined demonstration steps.

        Model-free: ``Q_theta(s, a) = R_theta(s, a) + C(s, a)`` where the continuation
        ``C = Q - R`` (the discounted value after the step) comes from the Q-network learned on
        sampled experience and is held fixed; the gradient reaches the reward through the
        immediate term. ``myopic`` (the warm start, before any Q exists) uses ``C = 0``.
        """
        batch = sample(self.demos, self.config.demo_batch_size)
        obs = batch["observation"]
        refined = self.refine(obs, batch["action"])
        reward = self.reward(obs)
        if myopic:
            q_hat = reward
        else:
            with torch.no_grad():
                continuation = self.q.network(obs) - reward
            q_hat = reward + continuation
        loss = margin = max_margin_loss(q_hat, refined.labels, self.margins, refined.weights)
        rank = torch.zeros(())
        if not myopic and self.config.rank_coef > 0 and len(self.experience):
            own = sample(self.experience, self.config.demo_batch_size)
            own_reward = self.reward(own["observation"]).gather(1, own["action"].long()[:, None])
            demo_reward = reward.gather(1, refined.labels[:, None])
            rank = ranking_margin_loss(demo_reward, own_reward, self.config.margin, refined.weights)
            loss = loss + self.config.rank_coef * rank
        norm = self._clip_step(loss, self.reward.parameters(), self.reward_optimizer)
        self.reward_steps += 1
        decisions = refined.decisions
        return {
            "losses/reward_margin": float(margin.detach()),
            "losses/reward_rank": float(rank.detach()),
            "losses/reward_grad_norm": norm,
            "charts/reward_violations": float(
                margin_violations(q_hat.detach(), refined.labels, self.margins)
            ),
            "charts/demo_reward": float(reward.detach().gather(1, refined.labels[:, None]).mean()),
            "charts/refine_keep": float((decisions == KEEP).float().mean()),
            "charts/refine_reweight": float((decisions == REWEIGHT).float().mean()),
            "charts/refine_relabel": float((decisions == RELABEL).float().mean()),
            "charts/demo_weight": float(refined.weights.mean()),
        }

    def _q_batch(self) -> TensorDict:
        """A Q-learning batch: experience plus a share of demonstration steps, rewards relabelled."""
        cfg = self.config
        n_demo = round(cfg.batch_size * cfg.demo_fraction) if len(self.demos) else 0
        if len(self.experience) == 0:
            n_demo = cfg.batch_size
        parts = []
        if cfg.batch_size - n_demo > 0:
            parts.append(sample(self.experience, cfg.batch_size - n_demo).select(*Q_KEYS))
        if n_demo > 0:
            parts.append(sample(self.demos, n_demo).select(*Q_KEYS))
        batch = torch.cat(parts) if len(parts) > 1 else parts[0]
        with torch.no_grad():
            learned = self.reward(batch["observation"]).gather(1, batch["action"].long()[:, None]).squeeze(1)
        terminated = batch[("next", "terminated")].reshape(-1)
        at_goal = goal_reached(
            batch[("next", "observation")], self.reward.n_beams, self.goal_tolerance, self.max_range
        )
        cfg = self.config
        target_reward = absorbing_rewards(learned, terminated, at_goal, cfg.reward_scale, cfg.gamma)
        batch.set(("next", "reward"), target_reward[:, None])
        return batch

    def q_step(self, margin_coef: float | None = None) -> dict[str, float]:
        """One policy-evaluation update: NNQL's DQNLoss on relabelled transitions, plus (weight
        ``margin_coef``) the large-margin term on the Q-network's values at refined demo steps."""
        coef = self.config.q_margin_coef if margin_coef is None else margin_coef
        q = self.q
        batch = self._q_batch()
        loss = td_loss = q.loss(batch)["loss"]
        margin = torch.zeros(())
        if coef > 0 and len(self.demos):
            demo = sample(self.demos, self.config.demo_batch_size)
            refined = self.refine(demo["observation"], demo["action"])
            margin = max_margin_loss(
                q.network(demo["observation"]), refined.labels, self.margins, refined.weights
            )
            loss = loss + coef * margin
        norm = self._clip_step(loss, q.loss.parameters(), q.optimizer)
        q.target_updater.step()
        q.updates += 1
        return {
            "losses/td_loss": float(td_loss.detach()),
            "losses/q_margin": float(margin.detach()),
            "losses/grad_norm": norm,
            "charts/learned_reward": float(batch[("next", "reward")].mean()),
            "charts/version": float(q.updates),
        }

    def warm_start(self, updates: int | None = None) -> dict[str, float]:
        """Fit both networks to the demonstrations alone: the reward by the myopic margin (no
        continuation yet), the Q-network by the large margin plus TD on relabelled demo steps.
        Runs ``updates`` steps, by default those of ``warmstart_updates`` not run yet."""
        if not len(self.demos):
            raise RuntimeError("warm_start needs demonstrations; call add_demos first")
        if updates is None:
            updates = max(self.config.warmstart_updates - self.warm_updates, 0)
        metrics: dict[str, float] = {}
        for _ in range(updates):
            metrics = self._warm_step()
        return metrics

    def _warm_step(self) -> dict[str, float]:
        metrics = {**self.reward_step(myopic=True), **self.q_step(margin_coef=1.0)}
        self.warm_updates += 1
        self.metrics.update(metrics)
        return metrics

    def iterate(self) -> dict[str, float]:
        """One round of neural policy iteration's learning: ``reward_updates`` max-margin steps,
        then ``q_updates`` Q-learning steps under the new reward. The improved policy is the
        softmax over the new Q (``policy()``)."""
        metrics: dict[str, float] = {}
        for _ in range(self.config.reward_updates):
            metrics.update(self.reward_step())
        for _ in range(self.config.q_updates):
            metrics.update(self.q_step())
        self.iteration += 1
        metrics["charts/iteration"] = float(self.iteration)
        self.metrics.update(metrics)
        return metrics

    def update(self) -> dict[str, float]:
        """The learner service's step: a warm-start update while fewer than ``warmstart_updates``
        ran, else one Q update preceded by the reward updates due at reward_updates per q_updates
        (an iteration ends every q_updates Q updates)."""
        cfg = self.config
        if self.warm_updates < cfg.warmstart_updates:
            return self._warm_step()
        metrics: dict[str, float] = {}
        self.reward_credit += cfg.reward_updates / max(cfg.q_updates, 1)
        while self.reward_credit >= 1.0:
            metrics.update(self.reward_step())
            self.reward_credit -= 1.0
        metrics.update(self.q_step())
        if cfg.q_updates and self.q.updates % cfg.q_updates == 0:
            self.iteration += 1
        metrics["charts/iteration"] = float(self.iteration)
        self.metrics.update(metrics)
        return metrics

    def ready(self) -> bool:
        """Updates need demonstrations (experience is optional: demos alone train it)."""
        return len(self.demos) >= 1

    def exploration_schedule(self) -> dict[str, Any]:
        """The behaviour policy's schedule in NNQLConfig's terms (what actors read from a
        WeightsUpdate's architecture): Boltzmann, temperature decaying over Q updates."""
        cfg = self.config
        return {
            "exploration": "boltzmann",
            "temperature_start": cfg.temperature_start,
            "temperature_end": cfg.temperature_end,
            "temperature_decay_updates": cfg.warmstart_updates
            + cfg.temperature_decay_iterations * cfg.q_updates,
        }

    # ------------------------------------------------------------ weights and files

    def get_weights(self) -> dict[str, np.ndarray]:
        """The policy's (Q-network's) weights, the payload of a WeightsUpdate on weights/nirl."""
        return self.q.get_weights()

    def reward_weights(self) -> dict[str, np.ndarray]:
        return {name: t.detach().cpu().numpy().copy() for name, t in self.reward.mlp.state_dict().items()}

    def policy(self, **kwargs: Any) -> NNQLPolicy:
        """The stochastic (Boltzmann) or greedy numpy policy of the current Q-network."""
        return self.q.policy(**kwargs)

    def save_policy(self, path: str | Path, **metadata: Any) -> Path:
        """model.safetensors + config.json (model "nirl", kind "q_network") and reward.safetensors."""
        from agents.nirl.persistence import save_policy_files

        return save_policy_files(self, path, **metadata)

    def state_dict(self) -> dict[str, Any]:
        """Reward network, its optimiser and NIRL's counters (the Q side is NNQLLearner's)."""
        return {
            "config": self.config.to_dict(),
            "reward_architecture": self.reward.architecture,
            "reward": self.reward.state_dict(),
            "reward_optimizer": self.reward_optimizer.state_dict(),
            "counters": {
                "iteration": self.iteration,
                "reward_steps": self.reward_steps,
                "warm_updates": self.warm_updates,
                "reward_credit": self.reward_credit,
                "demo_episodes": self.demo_episodes,
            },
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        if state["reward_architecture"] != self.reward.architecture:
            raise ValueError("checkpoint reward architecture differs from this learner's")
        self.reward.load_state_dict(state["reward"])
        self.reward_optimizer.load_state_dict(state["reward_optimizer"])
        counters = state["counters"]
        self.iteration = int(counters["iteration"])
        self.reward_steps = int(counters["reward_steps"])
        self.warm_updates = int(counters["warm_updates"])
        self.reward_credit = float(counters["reward_credit"])
        self.demo_episodes = int(counters["demo_episodes"])

    def save_checkpoint(self, path: str | Path) -> Path:
        """Directory with q/ (NNQLLearner checkpoint), nirl.pt and demos/ (if this learner owns them)."""
        from agents.nirl.persistence import save_checkpoint

        return save_checkpoint(self, path)

    def load_checkpoint(self, path: str | Path) -> None:
        from agents.nirl.persistence import load_checkpoint

        load_checkpoint(self, path)

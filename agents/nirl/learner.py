"""The NIRL learner: NNQL's Q-network and machinery, a demonstration buffer, a reward network.

Transport-free, like ``agents.nnql.learner``: the local trainer and the learner service
feed it experience and demonstrations and ask for updates. The Q-network, its Adam
optimiser, its target network (TorchRL ``SoftUpdate`` over ``DQNLoss``'s target
parameters) and the experience replay are ``NNQLLearner``'s. Buffers come in through the
constructor, so the learner service can share its NNQL replay (actor experience) and its
demonstration buffer.

The default core (``iq``) trains the Q-network by inverse soft-Q learning on 50/50 batches
of refined demonstration steps and own experience; the reward it holds,
``r = Q(s, a) - gamma V(s')``, is logged (``nirl/learned_reward``) and distilled into the
reward network, which `navlearn nirl reward` draws. ``sqil`` is the SQIL baseline on the same
machinery; ``max_margin`` the thesis-era fit (``agents.nirl.max_margin``).
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.data import TensorDictReplayBuffer

from agents.nirl.buffers import demo_buffer, demo_steps, sample
from agents.nirl.config import FORMAT_VERSION, NIRLConfig
from agents.nirl.losses import (
    KEEP,
    RELABEL,
    REWEIGHT,
    Refinement,
    crash_absorbing_value,
    implicit_reward,
    iq_loss,
    map_posterior,
    refine_steps,
    soft_td_loss,
    soft_value,
    sqil_rewards,
    structured_margins,
)
from agents.nirl.max_margin import MaxMarginFit
from agents.nirl.networks import RewardNetwork, goal_reached
from agents.nnql.learner import NNQLLearner, transitions_to_tensordict
from agents.nnql.policy import NNQLPolicy
from worlds.config import NavConfig, observation_settings
from worlds.perception import observation_dim


class NIRLLearner:
    """Neural inverse RL: MAP-refined demonstrations, a soft Q-function that holds reward and policy.

    ``add_demos`` / ``add_experience`` fill the buffers; ``warm_start()`` runs the offline updates
    on the demonstrations alone; ``iterate()`` is one policy-iteration round (``q_updates`` Q
    updates, each a soft policy evaluation step under the current implicit reward whose
    improvement is the softmax over the new Q, then ``reward_updates`` reward-network updates);
    ``update()`` is one Q update with the reward updates due (the learner service's step).
    ``version`` counts Q updates.
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
        output = "cost" if config.core == "max_margin" else "linear"
        self.reward = RewardNetwork.for_navigation(
            nav, config.reward_hidden_sizes, config.activation, config.reward_scale, output
        )
        self.reward_optimizer = torch.optim.Adam(
            self.reward.parameters(), lr=config.reward_lr, weight_decay=config.reward_weight_decay
        )
        self.goal_tolerance = float(nav.goal_tolerance)
        self.max_range = float(nav.sensors.max_range)
        self.experience = experience if experience is not None else self.q.replay
        self.owns_demos = demos is None
        self.demos = demos if demos is not None else demo_buffer(config.demo_capacity, config.seed + 1)
        self.margin_fit = MaxMarginFit(
            config,
            self.reward,
            self.reward_optimizer,
            self.q,
            self.demos,
            self.experience,
            self.refine,
            structured_margins(torch.as_tensor(nav.robot.turns), config.margin),
            self.goal_tolerance,
            self.max_range,
            self._clip_step,
            self._freeze_prior,
        )
        self.prior_network: torch.nn.Module | None = None
        self.demo_episodes = 0
        self.demo_path_steps = 0
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
    def n_actions(self) -> int:
        return int(self.q.architecture["n_actions"])

    @property
    def version(self) -> int:
        """Policy version: Q-network updates so far (warm start included)."""
        return self.q.updates

    def add_demos(self, demos: Iterable[Any]) -> int:
        """Add demonstrated episodes: ``agents.demos.Demo`` objects, or (meta, arrays) pairs from
        ``protocols.messages.DemoBatch.split()``. Returns the number of steps added. An episode
        whose observation width or actions do not fit this learner is refused (ValueError naming it)."""
        steps = 0
        for index, item in enumerate(demos):
            if isinstance(item, tuple):
                meta, arrays = item
                keys = ("observations", "actions", "terminations", "truncations")
                fields = tuple(arrays[key] for key in keys)
            else:
                meta = getattr(item, "metadata", None)
                fields = (item.observations, item.actions, item.terminations, item.truncations)
            self._check_episode(index, fields[0], fields[1])
            td = transitions_to_tensordict(demo_steps(*fields), self.obs_dim)
            n = td.batch_size[0]
            td.set("episode", torch.full((n,), self.demo_episodes, dtype=torch.int64))
            noise = meta.get("noise") if isinstance(meta, Mapping) else None
            td.set("noise", torch.full((n,), self.config.demo_noise if noise is None else float(noise)))
            self.demos.extend(td)
            self.demo_episodes += 1
            self.demo_path_steps += td.batch_size[0]
            steps += td.batch_size[0]
        return steps

    def _check_episode(self, index: int, observations: Any, actions: Any) -> None:
        obs, acts = np.asarray(observations), np.asarray(actions)
        if acts.ndim != 1 or len(acts) == 0:
            raise ValueError(f"demonstration {index}: no actions (shape {acts.shape})")
        if obs.ndim != 2 or obs.shape != (len(acts) + 1, self.obs_dim):
            raise ValueError(
                f"demonstration {index}: observations of shape {obs.shape}, this learner needs "
                f"({len(acts) + 1}, {self.obs_dim}) - recorded with another observation setting?"
            )
        if acts.min() < 0 or acts.max() >= self.n_actions:
            raise ValueError(f"demonstration {index}: actions outside 0..{self.n_actions - 1}")

    def add_experience(self, batch: Any) -> int:
        """Insert environment transitions (any form ``NNQLLearner.add`` takes) into the experience replay."""
        if self.experience is self.q.replay:
            return self.q.add(batch)
        td = transitions_to_tensordict(batch, self.obs_dim)
        self.experience.extend(td)
        return td.batch_size[0]

    # ------------------------------------------------------------ MAP refinement

    def prior(self, obs: torch.Tensor) -> torch.Tensor:
        """The prior over intended actions, softmax(Q / T) of the policy as it was after ``refine_start``
        updates on the recorded actions (frozen then: a prior that kept learning from its own relabels
        would confirm them - measured: 25% of clean steps changed on the 20 noisy demonstrations)."""
        network = self.q.network if self.prior_network is None else self.prior_network
        with torch.no_grad():
            return torch.softmax(network(obs) / self.config.prior_temperature, dim=1)

    def _freeze_prior(self) -> None:
        if self.prior_network is None and self.config.refine and self.q.updates >= self.config.refine_start:
            self.prior_network = copy.deepcopy(self.q.network).requires_grad_(False)

    def refine(
        self, obs: torch.Tensor, actions: torch.Tensor, noise: torch.Tensor | None = None
    ) -> Refinement:
        """MAP refinement of demonstrated steps under the current policy prior (see losses.refine_steps);
        ``noise`` (N,) is each step's random-action probability as its dataset recorded it (None:
        ``demo_noise``). Every step is kept with weight 1 while refinement is off or before
        ``refine_start`` Q updates."""
        actions = actions.long().reshape(-1)
        if not self.config.refine or self.q.updates < self.config.refine_start:
            ones = torch.ones(len(actions))
            return Refinement(actions, ones, torch.full_like(actions, KEEP))
        noise = self.config.demo_noise if noise is None else noise
        posterior = map_posterior(self.prior(obs), actions, noise)
        return refine_steps(posterior, actions, self.config.relabel_threshold)

    def refine_all(self) -> tuple[TensorDict, Refinement]:
        """Every stored demonstration step and its refinement (for reports and tests)."""
        steps = self.demos.storage.get(torch.arange(len(self.demos)))
        return steps, self.refine(steps["observation"], steps["action"], steps.get("noise", None))

    # ------------------------------------------------------------ updates

    def _clip_step(self, loss: torch.Tensor, params, optimizer) -> float:
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        max_norm = self.config.grad_clip if self.config.grad_clip > 0 else float("inf")
        norm = torch.nn.utils.clip_grad_norm_(params, max_norm)
        optimizer.step()
        return float(norm)

    def _mixed_batch(self, offline: bool) -> tuple[TensorDict, torch.Tensor]:
        """Demonstration steps and own experience, ``demo_fraction`` of the batch demonstrated
        (all of it offline or while no experience exists); returns the batch and its expert mask."""
        cfg = self.config
        n_demo = cfg.batch_size
        if not offline and len(self.experience):
            n_demo = max(1, round(cfg.batch_size * cfg.demo_fraction))
        keys = ("observation", "action", ("next", "observation"), ("next", "terminated"))
        demos = sample(self.demos, n_demo)
        noise = demos.get("noise", torch.full((n_demo,), cfg.demo_noise))
        parts = [demos.select(*keys)]
        if cfg.batch_size > n_demo:
            parts.append(sample(self.experience, cfg.batch_size - n_demo).select(*keys))
        batch = torch.cat(parts) if len(parts) > 1 else parts[0]
        batch.set("noise", torch.cat([noise, torch.zeros(cfg.batch_size - n_demo)]))
        is_expert = torch.zeros(cfg.batch_size, dtype=torch.bool)
        is_expert[:n_demo] = True
        return batch, is_expert

    def target_q(self, obs: torch.Tensor) -> torch.Tensor:
        """Q-values of the target network (DQNLoss's target parameters, Polyak-averaged)."""
        loss = self.q.loss
        with torch.no_grad(), loss.target_value_network_params.to_module(loss.value_network):
            return self.q.network(obs)

    def q_step(self, offline: bool = False) -> dict[str, float]:
        """One Q-network update of the configured core (iq or sqil) on a mixed batch."""
        cfg = self.config
        batch, is_expert = self._mixed_batch(offline)
        obs, next_obs = batch["observation"], batch[("next", "observation")]
        terminated = batch[("next", "terminated")].reshape(-1)
        labels = batch["action"].long().reshape(-1).clone()
        weights = torch.ones(len(labels))
        refined = self.refine(obs[is_expert], labels[is_expert], batch["noise"][is_expert])
        labels[is_expert], weights[is_expert] = refined.labels, refined.weights
        q_all = self.q.network(obs)
        q_taken = q_all.gather(1, labels[:, None]).squeeze(1)
        next_value = soft_value(self.target_q(next_obs), cfg.alpha)
        metrics: dict[str, float] = {}
        at_goal = goal_reached(next_obs, self.reward.n_beams, self.goal_tolerance, self.max_range)
        if cfg.core == "iq" and cfg.crash_absorbing:
            # a collision leads to an absorbing state (Kostrikov et al. 2019, DAC) told apart from the
            # goal by the observation; its value is IQ-Learn's optimum there (losses.crash_absorbing_value)
            crashed = terminated.bool() & ~at_goal
            next_value = torch.where(crashed, crash_absorbing_value(cfg.chi2_alpha, cfg.gamma), next_value)
            terminated = terminated.bool() & at_goal
        if cfg.core == "sqil" and cfg.crash_absorbing:
            # DAC's absorbing states for SQIL: the goal where demonstrations end is an expert absorbing
            # state (reward 1 forever, 1 / (1 - gamma)); a collision ends with reward 0. Without it, ending
            # at the goal is worth less than wandering on at reward 1, and the policy avoids the goal
            reached = terminated.bool() & at_goal
            forever = torch.full_like(next_value, 1.0 / (1.0 - cfg.gamma))
            next_value = torch.where(reached, forever, next_value)
            terminated = terminated.bool() & ~at_goal
        if cfg.core == "iq":
            terms = iq_loss(
                q_taken, soft_value(q_all, cfg.alpha), next_value, terminated, is_expert, cfg.gamma,
                cfg.chi2_alpha, weights,
            )  # fmt: skip
            loss, reward = terms.loss, terms.reward
            metrics.update({
                "losses/iq_loss": float(terms.loss.detach()),
                "losses/iq_expert": float(terms.expert_term),
                "losses/iq_value": float(terms.value_term),
                "losses/iq_chi2": float(terms.chi2_term),
            })  # fmt: skip
        else:  # sqil
            loss = soft_td_loss(q_taken, sqil_rewards(is_expert), next_value, terminated, cfg.gamma)
            reward = implicit_reward(q_taken.detach(), next_value, terminated, cfg.gamma)
            metrics["losses/td_loss"] = float(loss.detach())
        norm = self._clip_step(loss, self.q.loss.parameters(), self.q.optimizer)
        self.q.target_updater.step()
        self.q.updates += 1
        self._freeze_prior()
        metrics.update(self._reward_scale(reward, q_taken.detach(), q_all.detach(), batch, is_expert))
        decisions = refined.decisions
        metrics.update({
            "losses/grad_norm": norm,
            "charts/refine_keep": float((decisions == KEEP).float().mean()),
            "charts/refine_reweight": float((decisions == REWEIGHT).float().mean()),
            "charts/refine_relabel": float((decisions == RELABEL).float().mean()),
            "charts/demo_weight": float(refined.weights.mean()),
            "charts/version": float(self.q.updates),
        })  # fmt: skip
        return metrics

    def _reward_scale(self, reward, q_taken, q_all, batch, is_expert) -> dict[str, float]:
        """The learned reward beside what it must value: per demonstrated step, what a demonstrated
        path earns at that rate, the path length, and the value of a crash (Q of a collision step)."""
        cfg = self.config
        per_step = float(reward[is_expert].mean())
        length = self.demo_path_steps / max(self.demo_episodes, 1)
        out = {
            "nirl/learned_reward": per_step,
            "nirl/path_length": length,
            "nirl/path_return": per_step * (1 - cfg.gamma**length) / (1 - cfg.gamma),
            "nirl/expert_value": float(soft_value(q_all[is_expert], cfg.alpha).mean()),
        }
        own = ~is_expert
        if own.any():
            out["nirl/learned_reward_own"] = float(reward[own].mean())
            terminated = batch[("next", "terminated")].reshape(-1).bool()
            at_goal = goal_reached(
                batch[("next", "observation")], self.reward.n_beams, self.goal_tolerance, self.max_range
            )
            crashed = own & terminated & ~at_goal
            if crashed.any():
                out["nirl/collision_value"] = float(q_taken[crashed].mean())
        return out

    def reward_step(self, myopic: bool = False) -> dict[str, float]:
        """One reward-network update. iq/sqil: regression of ``R(s, a)`` on the Q-function's implicit
        reward ``Q(s, a) - gamma V(s')`` over a mixed batch; max_margin: its margin fit."""
        if self.config.core == "max_margin":
            metrics = self.margin_fit.reward_step(myopic)
        else:
            cfg = self.config
            batch, _ = self._mixed_batch(offline=False)
            obs, actions = batch["observation"], batch["action"].long().reshape(-1)
            with torch.no_grad():
                q_taken = self.q.network(obs).gather(1, actions[:, None]).squeeze(1)
                next_value = soft_value(self.target_q(batch[("next", "observation")]), cfg.alpha)
                target = implicit_reward(
                    q_taken, next_value, batch[("next", "terminated")].reshape(-1), cfg.gamma
                )
            predicted = self.reward(obs).gather(1, actions[:, None]).squeeze(1)
            loss = torch.nn.functional.mse_loss(predicted, target)
            norm = self._clip_step(loss, self.reward.parameters(), self.reward_optimizer)
            metrics = {"losses/reward_fit": float(loss.detach()), "losses/reward_grad_norm": norm}
        self.reward_steps += 1
        return metrics

    def warm_start(self, updates: int | None = None) -> dict[str, float]:
        """Updates on the demonstrations alone (offline IQ-Learn; for max_margin, the myopic margin
        fit and the large margin), ``updates`` of them or those of ``warmstart_updates`` not run yet."""
        if not len(self.demos):
            raise RuntimeError("warm_start needs demonstrations; call add_demos first")
        if updates is None:
            updates = max(self.config.warmstart_updates - self.warm_updates, 0)
        metrics: dict[str, float] = {}
        for _ in range(updates):
            metrics = self._warm_step()
        return metrics

    def _warm_step(self) -> dict[str, float]:
        if self.config.core == "max_margin":
            metrics = self.margin_fit.warm_step()
            self.reward_steps += 1
        else:
            metrics = self.q_step(offline=True)
        self.warm_updates += 1
        self.metrics.update(metrics)
        return metrics

    def _q_update(self) -> dict[str, float]:
        return self.margin_fit.q_step() if self.config.core == "max_margin" else self.q_step()

    def iterate(self) -> dict[str, float]:
        """One round of neural policy iteration's learning. iq/sqil: ``q_updates`` soft policy
        evaluation steps (the improved policy is the softmax over the new Q), then ``reward_updates``
        reward-network fits; max_margin: the reward first, then Q-learning under it."""
        cfg = self.config
        metrics: dict[str, float] = {}
        if cfg.core == "max_margin":
            for _ in range(cfg.reward_updates):
                metrics.update(self.reward_step())
        for _ in range(cfg.q_updates):
            metrics.update(self._q_update())
        if cfg.core != "max_margin":
            for _ in range(cfg.reward_updates):
                metrics.update(self.reward_step())
        self.iteration += 1
        metrics["charts/iteration"] = float(self.iteration)
        self.metrics.update(metrics)
        return metrics

    def update(self) -> dict[str, float]:
        """The learner service's step: a warm-start update while fewer than ``warmstart_updates``
        ran, else one Q update and the reward updates due at reward_updates per q_updates
        (an iteration ends every q_updates Q updates)."""
        cfg = self.config
        if self.warm_updates < cfg.warmstart_updates:
            return self._warm_step()
        metrics: dict[str, float] = {}
        self.reward_credit += cfg.reward_updates / max(cfg.q_updates, 1)
        while self.reward_credit >= 1.0:
            metrics.update(self.reward_step())
            self.reward_credit -= 1.0
        metrics.update(self._q_update())
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
            "format": FORMAT_VERSION,
            "config": self.config.to_dict(),
            "reward_architecture": self.reward.architecture,
            "reward": self.reward.state_dict(),
            "reward_optimizer": self.reward_optimizer.state_dict(),
            "prior_network": None if self.prior_network is None else self.prior_network.state_dict(),
            "counters": {
                "iteration": self.iteration,
                "reward_steps": self.reward_steps,
                "warm_updates": self.warm_updates,
                "reward_credit": self.reward_credit,
                "demo_episodes": self.demo_episodes,
                "demo_path_steps": self.demo_path_steps,
            },
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Inverse of state_dict. A state saved before cores existed (format 1) was the max-margin
        learner's: it loads into a learner with ``core="max_margin"`` and is refused, with the fix
        named, by the others."""
        version = int(state.get("format", 1))
        saved_core = state["config"].get("core", "max_margin")
        if version > FORMAT_VERSION:
            raise ValueError(
                f"NIRL state format {version} is newer than this version reads ({FORMAT_VERSION})"
            )
        if saved_core != self.config.core:
            raise ValueError(
                f"NIRL state was saved by the {saved_core!r} core (format {version}); this learner runs "
                f"{self.config.core!r}: load it with NIRLConfig(core={saved_core!r}) or start a fresh run"
            )
        saved = RewardNetwork.from_architecture(state["reward_architecture"]).architecture
        if saved != self.reward.architecture:
            raise ValueError(
                f"NIRL state's reward network {saved} differs from this learner's {self.reward.architecture}"
            )
        self.reward.load_state_dict(state["reward"])
        self.reward_optimizer.load_state_dict(state["reward_optimizer"])
        if state.get("prior_network") is not None:
            self.prior_network = copy.deepcopy(self.q.network).requires_grad_(False)
            self.prior_network.load_state_dict(state["prior_network"])
        counters = state["counters"]
        self.iteration = int(counters["iteration"])
        self.reward_steps = int(counters["reward_steps"])
        self.warm_updates = int(counters["warm_updates"])
        self.reward_credit = float(counters["reward_credit"])
        self.demo_episodes = int(counters["demo_episodes"])
        self.demo_path_steps = int(counters.get("demo_path_steps", 0))

    def save_checkpoint(self, path: str | Path) -> Path:
        """Directory with q/ (NNQLLearner checkpoint), nirl.pt and demos/ (if this learner owns them)."""
        from agents.nirl.persistence import save_checkpoint

        return save_checkpoint(self, path)

    def load_checkpoint(self, path: str | Path) -> None:
        from agents.nirl.persistence import load_checkpoint

        load_checkpoint(self, path)

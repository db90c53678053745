"""The NIRL learner: NNQL's Q-network and machinery, a demonstration buffer, a reward network.

Transport-free, like ``agents.nnql.learner``: the local trainer and the learner service
feed it experience and demonstrations and ask for updates. The Q-network, its Adam
optimiser, its target network (TorchRL ``SoftUpdate`` over ``DQNLoss``'s target
parameters, stepped and read through NNQL's lean path, ``agents/nnql/lean.py``: the same lerp
in one foreach call, the same parameters without a ``to_module`` swap) and the experience
replay are ``NNQLLearner``'s. Buffers come in through the
constructor, so the learner service can share its NNQL replay (actor experience) and its
demonstration buffer.

The default core (``iq``) trains the Q-network by inverse soft-Q learning on 50/50 batches
of refined demonstration steps and own experience; the reward it holds,
``r = Q(s, a) - gamma V(s')``, is logged (``nirl/learned_reward``) and distilled into the
reward network, which `navlearn nirl reward` draws. ``sqil`` is the SQIL baseline on the same
machinery (both in ``agents.nirl.soft_q``); ``max_margin`` the thesis-era fit
(``agents.nirl.max_margin``). Networks and optimisers live on ``device``
(``agents.device.resolve_device``), sampled batches are moved to it, the buffers stay in host
memory and weights come back as numpy arrays on the CPU.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import TensorDictReplayBuffer

from agents.nirl import persistence
from agents.nirl.buffers import demo_buffer, demo_steps
from agents.nirl.config import NIRLConfig
from agents.nirl.hindsight import STORED, refine_demo
from agents.nirl.losses import Refinement, kept_as_recorded, map_posterior, refine_steps, structured_margins
from agents.nirl.max_margin import MaxMarginFit
from agents.nirl.networks import RewardNetwork
from agents.nirl.progress import ProgressPotential, steps_to_go
from agents.nirl.refine_progress import refined_to_go
from agents.nirl.soft_q import SoftQFit
from agents.nnql.learner import NNQLLearner
from agents.nnql.policy import NNQLPolicy
from agents.nnql.transitions import transitions_to_tensordict
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
        device: str = "cpu",
    ):
        self.config = config
        nav = nav or NavConfig()
        self.nav: NavConfig = nav
        obs_dim, n_actions = observation_dim(nav), nav.robot.n_actions
        observation = observation_settings(nav)
        self.q = NNQLLearner(
            config.nnql_config(), obs_dim, n_actions, device=device, observation=observation
        )  # seeds torch
        self.device = self.q.device
        output = "cost" if config.core == "max_margin" else "linear"
        self.reward = RewardNetwork.for_navigation(
            nav, config.reward_hidden_sizes, config.activation, config.reward_scale, output
        ).to(self.device)
        self.reward_optimizer = torch.optim.Adam(
            self.reward.parameters(), lr=config.reward_lr, weight_decay=config.reward_weight_decay
        )
        self.goal_tolerance = float(nav.goal_tolerance)
        self.max_range = float(nav.sensors.max_range)
        self.experience = experience if experience is not None else self.q.replay
        self.owns_demos = demos is None
        self.demos = demos if demos is not None else demo_buffer(config.demo_capacity, config.seed + 1)
        common = {
            "config": config,
            "reward": self.reward,
            "reward_optimizer": self.reward_optimizer,
            "q": self.q,
            "demos": self.demos,
            "experience": self.experience,
            "refine": self.refine,
            "goal_tolerance": self.goal_tolerance,
            "max_range": self.max_range,
            "clip_step": self._clip_step,
            "after_update": self._freeze_prior,
        }
        self.fit: MaxMarginFit | SoftQFit
        """the core this learner trains with (``config.core``), handed the parts both cores use"""
        if config.core == "max_margin":
            margins = structured_margins(torch.as_tensor(nav.robot.turns), config.margin).to(self.device)
            self.fit = MaxMarginFit(**common, margins=margins)
        else:
            self.fit = SoftQFit(**common, path_length=self._demo_path_length)
            if config.fixed_reward == "progress":
                first = goal_features_from(nav) if config.potential_inputs == "goal" else 0
                self.fit.potential = ProgressPotential(
                    obs_dim, config.reward_hidden_sizes, config.activation, config.gamma, first
                ).to(self.device)
                self.fit.potential_optimizer = torch.optim.Adam(
                    self.fit.potential.parameters(), lr=config.reward_lr
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
            episode = torch.full((n,), self.demo_episodes, dtype=torch.int64)
            td.set("episode", episode)
            noise = meta.get("noise") if isinstance(meta, Mapping) else None
            noise = self.config.demo_noise if noise is None else float(noise)
            td.set("noise", torch.full((n,), noise))
            reached = bool(np.asarray(fields[2])[-1]) if len(fields[2]) else False  # ended by termination
            to_go = torch.as_tensor(steps_to_go(n, reached))
            if self.config.refine and self.config.refine_prior == "hindsight":
                refined = self._hindsight(index, item, noise)
                for key, value in zip(STORED, refined, strict=True):
                    td.set(key, value)
                to_go = refined_to_go(episode, to_go, refined.decisions)  # steps judged noise do not count
            td.set("to_go", to_go)
            self.demos.extend(td)
            self.demo_episodes += 1
            self.demo_path_steps += td.batch_size[0]
            steps += td.batch_size[0]
        return steps

    def _hindsight(self, index: int, item: Any, noise: float) -> Refinement:
        """The hindsight refinement of one added episode (agents.nirl.hindsight)."""
        if getattr(item, "poses", None) is None or getattr(item, "grid", None) is None:
            raise ValueError(
                f"demonstration {index}: NIRLConfig.refine_prior='hindsight' needs the episode's poses, goal "
                "and map size (an agents.demos.Demo); demonstrations sent over the wire carry none - use "
                "refine_prior='policy'"
            )
        return refine_demo(item, self.nav, noise)

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

    def refine(self, steps: TensorDictBase) -> Refinement:
        """MAP refinement of demonstrated ``steps`` (their observation, action and recorded noise): the
        hindsight refinement stored with them when ``refine_prior`` is hindsight, else under the current
        policy prior (see losses.refine_steps). With the policy prior every step is kept with weight 1
        while refinement is off or before ``refine_start`` Q updates."""
        actions = steps["action"].long().reshape(-1)
        if not self.config.refine or (
            self.config.refine_prior == "policy" and self.q.updates < self.config.refine_start
        ):
            return kept_as_recorded(actions)
        if self.config.refine_prior == "hindsight":
            return Refinement(*(steps[key].reshape(-1) for key in STORED))
        posterior = map_posterior(self.prior(steps["observation"]), actions, steps["noise"])
        return refine_steps(posterior, actions, self.config.relabel_threshold)

    def refine_all(self) -> tuple[TensorDict, Refinement]:
        """Every stored demonstration step and its refinement (for reports and tests)."""
        steps = self.demos.storage.get(torch.arange(len(self.demos))).to(self.device)
        return steps, self.refine(steps)

    # ------------------------------------------------------------ updates

    def _clip_step(self, loss: torch.Tensor, params, optimizer) -> float:
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        max_norm = self.config.grad_clip if self.config.grad_clip > 0 else float("inf")
        norm = torch.nn.utils.clip_grad_norm_(params, max_norm)
        optimizer.step()
        return float(norm)

    def reward_step(self, myopic: bool = False) -> dict[str, float]:
        """One reward-network update. iq/sqil: regression of ``R(s, a)`` on the Q-function's implicit
        reward ``Q(s, a) - gamma V(s')`` over a mixed batch; max_margin: its margin fit."""
        fit = self.fit
        metrics = fit.reward_step(myopic) if isinstance(fit, MaxMarginFit) else fit.reward_step()
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
        if isinstance(self.fit, MaxMarginFit):
            metrics = self.fit.warm_step()
            self.reward_steps += 1
        else:
            metrics = self.fit.q_step(offline=True)
            metrics.update(self.fit.potential_step())
        self.warm_updates += 1
        self.metrics.update(metrics)
        return metrics

    def _q_update(self) -> dict[str, float]:
        return self.fit.q_step()

    def _demo_path_length(self) -> float:
        """Mean steps of the demonstrated paths so far (SoftQFit logs the reward's scale beside it)."""
        return self.demo_path_steps / max(self.demo_episodes, 1)

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
        if cfg.core != "max_margin" and not self.reward_fixed:
            for _ in range(cfg.reward_updates):
                metrics.update(self.reward_step())
                metrics.update(self.fit.potential_step())
        self.iteration += 1
        self._fix_reward_when_due()
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
        if not self.reward_fixed:
            self.reward_credit += cfg.reward_updates / max(cfg.q_updates, 1)
        while self.reward_credit >= 1.0:
            metrics.update(self.reward_step())
            if isinstance(self.fit, SoftQFit):
                metrics.update(self.fit.potential_step())
            self.reward_credit -= 1.0
        metrics.update(self._q_update())
        if cfg.q_updates and self.q.updates % cfg.q_updates == 0:
            self.iteration += 1
            self._fix_reward_when_due()
        metrics["charts/iteration"] = float(self.iteration)
        self.metrics.update(metrics)
        return metrics

    @property
    def reward_fixed(self) -> bool:
        """Whether the learned reward is fixed (soft-Q core, :meth:`fix_reward`): only Q learns."""
        return isinstance(self.fit, SoftQFit) and self.fit.reward_fixed

    def fix_reward(self) -> None:
        """Freeze the reward network: from then on the Q-network does NNQL-style policy iteration
        (soft Q-learning) on the learned reward (soft-Q cores only)."""
        if not isinstance(self.fit, SoftQFit):
            raise ValueError(f"NIRLConfig.core={self.config.core!r}: only the soft-Q cores fix their reward")
        self.fit.reward_fixed = True
        self.reward.requires_grad_(False)

    def _fix_reward_when_due(self) -> None:
        """After ``fix_reward_after`` iterations (iq core), :meth:`fix_reward`."""
        after = self.config.fix_reward_after
        if self.config.core == "iq" and after and self.iteration >= after and not self.reward_fixed:
            self.fix_reward()

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

    @property
    def potential(self) -> ProgressPotential | None:
        """The progress potential of the fixed reward (soft-Q core with ``fixed_reward = "progress"``),
        else None."""
        return self.fit.potential if isinstance(self.fit, SoftQFit) else None

    def policy(self, **kwargs: Any) -> NNQLPolicy:
        """The stochastic (Boltzmann) or greedy numpy policy of the current Q-network."""
        return self.q.policy(**kwargs)

    def save_policy(self, path: str | Path, **metadata: Any) -> Path:
        """model.safetensors + config.json (model "nirl", kind "q_network") and reward.safetensors."""
        return persistence.save_policy_files(self, path, **metadata)

    def state_dict(self) -> dict[str, Any]:
        """Reward network, its optimiser and NIRL's counters (the Q side is NNQLLearner's)."""
        return persistence.nirl_state(self)

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Inverse of state_dict (format 1 states are the max-margin core's: persistence.load_nirl_state)."""
        persistence.load_nirl_state(self, state)

    def save_checkpoint(self, path: str | Path) -> Path:
        """Directory with q/ (NNQLLearner checkpoint), nirl.pt and demos/ (if this learner owns them)."""
        return persistence.save_checkpoint(self, path)

    def load_checkpoint(self, path: str | Path) -> None:
        """Inverse of save_checkpoint, onto this learner's device whichever device saved it."""
        persistence.load_checkpoint(self, path)


def goal_features_from(nav: NavConfig) -> int:
    """Index of the first feature after the range readings of a one-frame, patch-free observation (the
    progress potential's ``potential_inputs = "goal"``)."""
    if nav.observation.frame_stack > 1 or nav.observation.patch_size > 0:
        raise ValueError(
            "NIRLConfig.potential_inputs='goal' reads the features after the range readings of one frame: "
            f"observation.frame_stack={nav.observation.frame_stack}, "
            f"patch_size={nav.observation.patch_size}; "
            "use potential_inputs='observation'"
        )
    return nav.sensors.n_beams

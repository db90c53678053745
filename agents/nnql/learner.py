"""The NNQL learner: TorchRL replay buffer + loss + optimiser + target updates.

Transport-free (Acme's learner role): the learner service feeds it transitions it
received over the wire and ships ``get_weights()`` to actors; ``train --local`` feeds
it from an in-process vector env. One update (``train_step``) is sample -> loss ->
backward -> clip -> Adam step -> target update -> priority update.

Transitions come as a TensorDict in TorchRL's layout (``observation``, ``action``,
``("next", "observation"|"reward"|"done"|"terminated"|"truncated")``), as a flat
dict of arrays (see ``TRANSITION_FIELDS``) or as any object with those attributes (a
protocols TransitionBatch), N transitions per call.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import LazyTensorStorage, PrioritizedSampler, RandomSampler, TensorDictReplayBuffer
from torchrl.objectives import HardUpdate, SoftUpdate

from agents.nnql.config import NNQLConfig
from agents.nnql.losses import PRIORITY_KEY, make_loss
from agents.nnql.networks import QNetwork, make_q_actor
from agents.nnql.policy import NNQLPolicy, save_policy_dir
from agents.replay_files import load_replay, save_replay

TRANSITION_FIELDS = ("obs", "action", "reward", "next_obs", "terminated", "truncated")
"""Flat transition batch (the field names of protocols' TransitionBatch): float32 (N, obs_dim), int (N,),
float (N,), float32 (N, obs_dim) - the true next observation, terminal one at episode ends -, bool (N,),
bool (N,); plus ``next_action`` int (N,) for the SARSA variant."""
CHECKPOINT_STATE = "learner.pt"
CHECKPOINT_REPLAY = "replay"
CHECKPOINT_POLICY = "policy"


def _flat_fields(batch: Any) -> dict[str, Any]:
    """The flat fields of a TorchRL-layout TensorDict, a mapping, or an object with those attributes."""
    if isinstance(batch, TensorDictBase):
        flat = {
            "obs": batch.get("observation"),
            "action": batch.get("action"),
            "reward": batch.get(("next", "reward")),
            "next_obs": batch.get(("next", "observation")),
            "terminated": batch.get(("next", "terminated")),
            "truncated": batch.get(("next", "truncated"), torch.zeros(batch.batch_size[0], dtype=torch.bool)),
        }
        if ("next", "action") in batch.keys(include_nested=True):
            flat["next_action"] = batch.get(("next", "action"))
        return flat
    if not isinstance(batch, Mapping):  # e.g. a protocols.messages.TransitionBatch
        batch = {
            name: getattr(batch, name) for name in (*TRANSITION_FIELDS, "next_action") if hasattr(batch, name)
        }
    missing = [name for name in TRANSITION_FIELDS if name not in batch]
    if missing:
        raise KeyError(f"transition batch lacks {missing}")
    return dict(batch)


def transitions_to_tensordict(batch: Any, obs_dim: int) -> TensorDict:
    """A transition batch (see ``_flat_fields``) as a replay-ready TensorDict in TorchRL's layout."""
    flat = _flat_fields(batch)
    n = len(flat["action"])
    obs = torch.as_tensor(np.asarray(flat["obs"], dtype=np.float32))
    next_obs = torch.as_tensor(np.asarray(flat["next_obs"], dtype=np.float32))
    if obs.shape != (n, obs_dim) or next_obs.shape != (n, obs_dim):
        raise ValueError(
            f"observations must be ({n}, {obs_dim}); got {tuple(obs.shape)}, {tuple(next_obs.shape)}"
        )
    terminated = torch.as_tensor(np.asarray(flat["terminated"], dtype=bool)).reshape(n, 1)
    truncated = torch.as_tensor(np.asarray(flat["truncated"], dtype=bool)).reshape(n, 1)
    following = {
        "observation": next_obs,
        "reward": torch.as_tensor(np.asarray(flat["reward"], dtype=np.float32)).reshape(n, 1),
        "terminated": terminated,
        "truncated": truncated,
        "done": terminated | truncated,
    }
    if "next_action" in flat:
        following["action"] = torch.as_tensor(np.asarray(flat["next_action"], dtype=np.int64)).reshape(n)
    return TensorDict(
        {
            "observation": obs,
            "action": torch.as_tensor(np.asarray(flat["action"], dtype=np.int64)).reshape(n),
            "next": TensorDict(following, batch_size=[n]),
        },
        batch_size=[n],
    )


class NNQLLearner:
    """Q-learning (or SARSA) over a TorchRL replay buffer.

    ``add(batch)`` inserts transitions; ``updates_due()`` says how many updates the
    update-to-data ratio allows; ``update()`` runs one; ``version`` counts updates.
    """

    def __init__(self, config: NNQLConfig, obs_dim: int, n_actions: int):
        self.config = config
        torch.set_num_threads(config.torch_threads)
        torch.manual_seed(config.seed)
        self.network = QNetwork.from_config(config, obs_dim, n_actions)
        self.loss = make_loss(config, make_q_actor(self.network))
        if config.target_update == "soft":
            self.target_updater = SoftUpdate(self.loss, tau=config.target_tau)
        else:
            self.target_updater = HardUpdate(self.loss, value_network_update_interval=config.target_period)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=config.lr)
        self.replay = self._make_replay()
        self.updates = 0
        self.transitions_added = 0
        self.update_credit = 0.0

    def _make_replay(self) -> TensorDictReplayBuffer:
        cfg = self.config
        if cfg.prioritized:
            sampler = PrioritizedSampler(
                cfg.replay_capacity, alpha=cfg.priority_alpha, beta=cfg.priority_beta, eps=cfg.priority_eps
            )
        else:
            sampler = RandomSampler()
        return TensorDictReplayBuffer(
            storage=LazyTensorStorage(cfg.replay_capacity),
            sampler=sampler,
            batch_size=cfg.batch_size,
            priority_key=PRIORITY_KEY,
            generator=torch.Generator().manual_seed(cfg.seed),
        )

    # ------------------------------------------------------------ data in

    @property
    def architecture(self) -> dict[str, Any]:
        return dict(self.network.architecture)

    @property
    def version(self) -> int:
        """Policy version: the number of gradient updates so far."""
        return self.updates

    def add(self, batch: Any) -> int:
        """Insert a batch of transitions; returns how many were added."""
        td = transitions_to_tensordict(batch, self.architecture["obs_dim"])
        if self.config.sarsa and ("next", "action") not in td.keys(include_nested=True):
            raise KeyError("the SARSA variant needs next_action in every transition batch")
        n = td.batch_size[0]
        if n == 0:
            return 0
        self.replay.extend(td)
        self.transitions_added += n
        if len(self.replay) >= self.config.learning_starts:
            self.update_credit += n * self.config.utd_ratio
        return n

    def ready(self) -> bool:
        return len(self.replay) >= max(self.config.learning_starts, self.config.batch_size)

    def updates_due(self) -> int:
        """Updates the update-to-data ratio allows now (0 before learning_starts)."""
        return int(self.update_credit) if self.ready() else 0

    # ------------------------------------------------------------ learning

    def update(self) -> dict[str, float]:
        """Sample a batch and run one update; returns its metrics."""
        if not self.ready():
            raise RuntimeError(
                f"replay holds {len(self.replay)} transitions; need {self.config.learning_starts}"
            )
        metrics = self.train_step(self.replay.sample())
        self.update_credit = max(self.update_credit - 1.0, 0.0)
        return metrics

    def train_due(self) -> dict[str, float] | None:
        """Run every update that is due; metrics of the last one (None if none ran)."""
        metrics = None
        for _ in range(self.updates_due()):
            metrics = self.update()
        return metrics

    def train_step(self, batch: TensorDictBase) -> dict[str, float]:
        """One gradient update on a sampled batch (the step the overhead benchmark times)."""
        loss = self.loss(batch)["loss"]
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        max_norm = self.config.grad_clip if self.config.grad_clip > 0 else float("inf")
        grad_norm = torch.nn.utils.clip_grad_norm_(self.loss.parameters(), max_norm)
        self.optimizer.step()
        self.target_updater.step()
        if self.config.prioritized:
            self.replay.update_tensordict_priority(batch)
        self.updates += 1
        squared_td = batch.get(PRIORITY_KEY)
        return {
            "losses/td_loss": float(loss.detach()),
            "losses/td_error": float(squared_td.sqrt().mean()),
            "losses/grad_norm": float(grad_norm),
            "charts/version": float(self.updates),
        }

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """Online-network Q-values of a batch of observations."""
        with torch.no_grad():
            return self.network(torch.as_tensor(np.asarray(obs, dtype=np.float32))).numpy()

    # ------------------------------------------------------------ weights

    def get_weights(self) -> dict[str, np.ndarray]:
        """Online-network weights as float32 arrays (the payload of a WeightsUpdate)."""
        return {name: t.detach().cpu().numpy().copy() for name, t in self.network.state_dict().items()}

    def set_weights(self, weights: Mapping[str, np.ndarray], sync_target: bool = True) -> None:
        """Load online weights (e.g. a warm start); by default the target network copies them too."""
        state = {name: torch.as_tensor(np.asarray(value)) for name, value in weights.items()}
        self.network.load_state_dict(state)
        if sync_target:
            self.loss.target_value_network_params.data.update_(self.loss.value_network_params.data)

    def policy(self, **kwargs: Any) -> NNQLPolicy:
        """A numpy policy holding a copy of the current weights (greedy unless told)."""
        return NNQLPolicy(self.get_weights(), self.architecture, version=self.version, **kwargs)

    def save_policy(self, path: str | Path, **metadata: Any) -> Path:
        """model.safetensors + config.json (loadable by NNQLPolicy.load and `navlearn evaluate`)."""
        metadata.setdefault("nnql_config", self.config.to_dict())
        return save_policy_dir(path, self.get_weights(), self.architecture, self.version, **metadata)

    # ------------------------------------------------------------ checkpoints

    def state_dict(self) -> dict[str, Any]:
        """Everything but the replay contents: networks (online + target), optimiser, counters."""
        return {
            "config": self.config.to_dict(),
            "architecture": self.architecture,
            "loss": self.loss.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "target_updater": self.target_updater.state_dict(),
            "counters": {
                "updates": self.updates,
                "transitions_added": self.transitions_added,
                "update_credit": self.update_credit,
            },
            "torch_rng": torch.get_rng_state(),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        if state["architecture"] != self.architecture:
            raise ValueError(f"checkpoint architecture {state['architecture']} != {self.architecture}")
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.target_updater.load_state_dict(state["target_updater"])
        counters = state["counters"]
        self.updates = int(counters["updates"])
        self.transitions_added = int(counters["transitions_added"])
        self.update_credit = float(counters["update_credit"])
        torch.set_rng_state(state["torch_rng"])

    def save_replay(self, path: str | Path) -> None:
        """The replay buffer (storage, sampler priorities, writer, rng), nothing pickled
        (agents.replay_files)."""
        if len(self.replay):
            save_replay(self.replay, path)

    def load_replay(self, path: str | Path) -> None:
        """Inverse of save_replay; a missing directory means an empty buffer."""
        if Path(path).exists():
            load_replay(self.replay, path)

    def save_checkpoint(self, path: str | Path) -> Path:
        """A directory with learner.pt, replay/ and policy/, replaced atomically."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        torch.save(self.state_dict(), tmp / CHECKPOINT_STATE)
        self.save_replay(tmp / CHECKPOINT_REPLAY)
        self.save_policy(tmp / CHECKPOINT_POLICY)
        old = path.with_name(f".{path.name}.old{os.getpid()}")
        if path.exists():
            os.replace(path, old)
        os.replace(tmp, path)
        shutil.rmtree(old, ignore_errors=True)
        return path

    def load_checkpoint(self, path: str | Path) -> None:
        path = Path(path)
        self.load_state_dict(torch.load(path / CHECKPOINT_STATE, weights_only=True))
        self.load_replay(path / CHECKPOINT_REPLAY)

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> NNQLLearner:
        """A learner rebuilt from a checkpoint directory (its config and architecture included)."""
        state = torch.load(Path(path) / CHECKPOINT_STATE, weights_only=True)
        arch = state["architecture"]
        learner = cls(NNQLConfig.from_dict(state["config"]), arch["obs_dim"], arch["n_actions"])
        learner.load_checkpoint(path)
        return learner

"""The NNQL learner: TorchRL replay buffer + loss + optimiser + target updates.

Transport-free (Acme's learner role): the learner service feeds it transitions it
received over the wire and ships ``get_weights()`` to actors; ``train --local`` feeds
it from an in-process vector env. One update is sample -> loss -> backward -> clip -> Adam
step -> target update -> priority update: ``update(n)`` runs n of them on plain tensors
(agents/nnql/lean.py, the hot loop), ``train_step(td)`` runs one through TorchRL's loss module
and updater on a sampled TensorDict (the reference the lean path is tested against).

Networks, loss and sampled batches live on ``device`` (``agents.device.resolve_device``); the
replay stays in host memory, where inserting is cheapest: in RAM, or in memory-mapped files
under ``replay_dir`` (agents/nnql/replay_storage.py: capacities beyond RAM, checkpoints that
do not copy the buffer).

Transitions come as a TensorDict in TorchRL's layout (``observation``, ``action``,
``("next", "observation"|"reward"|"done"|"terminated"|"truncated")``), as a flat
dict of arrays (see ``agents.nnql.transitions``) or as any object with those attributes (a
protocols TransitionBatch), N transitions per call.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import PrioritizedSampler, RandomSampler, TensorDictReplayBuffer
from torchrl.objectives import HardUpdate, SoftUpdate

from agents.device import resolve_device
from agents.nnql.config import NNQLConfig
from agents.nnql.image_network import architecture_image
from agents.nnql.lean import Batch, LeanUpdate, Step
from agents.nnql.losses import PRIORITY_KEY, make_loss
from agents.nnql.networks import export_weights, import_weights, make_q_actor
from agents.nnql.nstep import NStepAccumulator
from agents.nnql.persistence import (
    CHECKPOINT_STATE,
    LearnerOutputs,
    check_checkpoint_env,
    check_checkpoint_observation,
)
from agents.nnql.policy import NNQLPolicy
from agents.nnql.q_networks import build_q_network
from agents.nnql.replay_storage import (
    columns,
    has_memmap_state,
    is_memmap,
    load_memmap,
    make_storage,
    save_memmap,
)
from agents.nnql.transitions import flat_fields, transitions_to_tensordict
from agents.replay_files import load_replay, save_replay


class NNQLLearner(LearnerOutputs):
    """Q-learning (or SARSA) over a TorchRL replay buffer.

    ``add(batch)`` inserts transitions; ``update(n)`` runs n updates (how many, the caller's
    agents.nnql.ratelimit.RateLimiter says); ``version`` counts updates. ``device``:
    cpu, cuda or auto (see ``agents.device``); ``replay_dir``: keep the replay in memory-mapped
    files there instead of RAM (uniform sampling only). ``observation``: navlearn's observation settings
    (None for a Gymnasium env); ``image``: a Gymnasium env's image observation
    (``worlds.own_env.image_description``), which network "auto" learns with a CNN.
    """

    def __init__(
        self,
        config: NNQLConfig,
        obs_dim: int,
        n_actions: int,
        *,
        device: str = "cpu",
        replay_dir: str | Path | None = None,
        observation: Mapping[str, Any] | None = None,
        image: Mapping[str, Any] | None = None,
    ):
        if replay_dir is not None and config.prioritized:
            raise ValueError(
                "a memory-mapped replay samples uniformly: prioritized replay keeps its trees in RAM and "
                "would write them whole at every checkpoint; drop --prioritized or keep the replay in memory"
            )
        self.observation = None if observation is None else dict(observation)
        """what the network observes (``worlds.config.observation_settings``), recorded in saved policies"""
        self.image = None if image is None else dict(image)
        """a Gymnasium env's image observation (``worlds.own_env.image_description``), None if not one"""
        self.config = config.resolved(self.observation, self.image)
        """the config with ``network`` the variant built ("auto" resolved), as checkpoints and policies
        record it"""
        config = self.config
        self.device = resolve_device(device)
        torch.set_num_threads(config.torch_threads)
        torch.manual_seed(config.seed)
        self.network = build_q_network(config, obs_dim, n_actions, self.observation, self.image).to(
            self.device
        )
        self.loss = make_loss(config, make_q_actor(self.network))
        if config.target_update == "soft":
            self.target_updater = SoftUpdate(self.loss, tau=config.target_tau)
        else:
            self.target_updater = HardUpdate(self.loss, value_network_update_interval=config.target_period)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=config.lr, **self._optimizer_options())
        self.lean = LeanUpdate(config, self.network, self.loss, self.optimizer, self.target_updater)
        self.replay_rng = torch.Generator().manual_seed(config.seed)
        self.replay = self._make_replay(replay_dir)
        self._stored: Batch | None = None
        self.nstep = NStepAccumulator(config.n_step, config.gamma) if config.n_step > 1 else None
        """builds n-step transitions per (actor, env_id) stream when ``config.n_step > 1``"""
        self.updates = 0
        self.transitions_added = 0

    def _make_replay(self, replay_dir: str | Path | None) -> TensorDictReplayBuffer:
        cfg = self.config
        if cfg.prioritized:
            sampler = PrioritizedSampler(
                cfg.replay_capacity, alpha=cfg.priority_alpha, beta=cfg.priority_beta, eps=cfg.priority_eps
            )
        else:
            sampler = RandomSampler()
        return TensorDictReplayBuffer(
            storage=make_storage(cfg.replay_capacity, replay_dir),
            sampler=sampler,
            batch_size=cfg.batch_size,
            priority_key=PRIORITY_KEY,
            generator=self.replay_rng,
        )

    @staticmethod
    def _optimizer_options() -> dict[str, bool]:
        """Adam's fused kernel (CPU and CUDA): a step costs about 0.4 of the per-tensor loop's here."""
        return {"fused": True, "foreach": False}

    # ------------------------------------------------------------ data in

    def add(self, batch: Any) -> int:
        """Insert a batch of transitions; returns how many were added.

        With ``n_step > 1`` the batch needs ``env_ids`` (and an ``actor`` name when several actors
        feed the learner: a TransitionBatch has both); what is added are the n-step transitions
        that became complete, which lag the one-step ones by up to n - 1 per stream."""
        if self.nstep is not None:
            flat = flat_fields(batch)
            if "env_ids" not in flat:
                raise KeyError("n-step returns need env_ids in every transition batch")
            actor = batch.get("actor", "") if isinstance(batch, Mapping) else getattr(batch, "actor", "")
            batch = self.nstep(flat, str(actor))
        td = transitions_to_tensordict(batch, self.architecture["obs_dim"])
        if self.config.sarsa and ("next", "action") not in td.keys(include_nested=True):
            raise KeyError("the SARSA variant needs next_action in every transition batch")
        n = td.batch_size[0]
        if n == 0:
            return 0
        self.replay.extend(td)
        self.transitions_added += n
        return n

    def ready(self) -> bool:
        return len(self.replay) >= max(self.config.learning_starts, self.config.batch_size)

    # ------------------------------------------------------------ learning

    def update(self, n: int = 1) -> dict[str, float]:
        """Run ``n`` updates on freshly sampled batches (the lean path); metrics of the last one.

        Uniform replay draws the indices of all ``n`` batches in one sampler call and gathers
        them in one storage read; prioritized replay samples each batch after the previous
        one's priorities were written back, as one update at a time would.
        """
        if not self.ready():
            raise RuntimeError(
                f"replay holds {len(self.replay)} transitions; need {self.config.learning_starts}"
            )
        if n < 1:
            raise ValueError(f"update(n={n}): n must be >= 1")
        size = self.config.batch_size
        if self.config.prioritized:
            for _ in range(n):
                index, batch = self._sample(size)
                step = self.lean(batch)
                self.replay.update_priority(index, step.priority.to(index.device))
        else:
            _, batches = self._sample(n * size)
            for i in range(n):
                step = self.lean(batches.slice(i * size, (i + 1) * size))
        self.updates += n
        return self._metrics(step)

    def _sample(self, size: int) -> tuple[torch.Tensor, Batch]:
        """Indices drawn by the replay's sampler and their transitions, on the learner's device.

        The transitions are read from the storage's columns one at a time: ``storage.get``
        would slice and index the whole nested TensorDict, 0.18 ms of the ~1.4 ms an update
        takes here. The indices come from the sampler, so they are always below ``len``.
        """
        index, info = self.replay.sampler.sample(self.replay.storage, size)
        batch = Batch(*(None if column is None else column[index] for column in self._columns()))
        batch = batch._replace(weight=info.get("priority_weight"))
        return index, batch if self.device.type == "cpu" else batch.to(self.device)

    def _columns(self) -> Batch:
        """The storage's columns as full-capacity views (weight: None), looked up again whenever the
        storage holds other tensors (its first insert, a resume)."""
        stored = columns(self.replay)
        if self._stored is None or self._stored.obs is not stored.get("observation"):
            self._stored = Batch.from_tensordict(stored)
        return self._stored

    def _metrics(self, step: Step) -> dict[str, float]:
        return {
            "losses/td_loss": float(step.loss),
            "losses/td_error": float(step.priority.sqrt().mean()),
            "losses/grad_norm": float(step.grad_norm),
            "charts/version": float(self.updates),
        }

    def train_step(self, batch: TensorDictBase) -> dict[str, float]:
        """One update on a sampled TensorDict through TorchRL's loss module and target updater.

        The reference path: ``update`` runs the same arithmetic on plain tensors, and
        tests/test_nnql_lean.py holds the two to the same parameters on the same batches.
        """
        if self.config.n_step > 1:
            raise ValueError(
                "train_step is the TD(0) reference (TorchRL's DQNLoss); n-step targets are update()'s"
            )
        batch = batch.to(self.device)
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
            obs = torch.as_tensor(np.asarray(obs, dtype=np.float32), device=self.device)
            return self.network(obs).cpu().numpy()

    # ------------------------------------------------------------ weights

    def get_weights(self) -> dict[str, np.ndarray]:
        """Online-network weights as float32 arrays (the payload of a WeightsUpdate)."""
        return export_weights(self.network)

    def set_weights(self, weights: Mapping[str, np.ndarray], sync_target: bool = True) -> None:
        """Load online weights (e.g. a warm start); by default the target network copies them too."""
        import_weights(self.network, weights)
        if sync_target:
            self.loss.target_value_network_params.data.update_(self.loss.value_network_params.data)

    def policy(self, **kwargs: Any) -> NNQLPolicy:
        """A numpy policy holding a copy of the current weights (greedy unless told)."""
        kwargs.setdefault("observation", self.observation)
        return NNQLPolicy(self.get_weights(), self.architecture, version=self.version, **kwargs)

    # ------------------------------------------------------------ checkpoints

    def state_dict(self) -> dict[str, Any]:
        """Everything but the replay contents: networks (online + target), optimiser, counters."""
        return {
            "config": self.config.to_dict(),
            "architecture": self.architecture,
            "observation": self.observation,
            "env": self.env,
            "loss": self.loss.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "target_updater": self.target_updater.state_dict(),
            "counters": {
                "updates": self.updates,
                "transitions_added": self.transitions_added,
            },
            "torch_rng": torch.get_rng_state(),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        check_checkpoint_env(state.get("env"), self.env)
        check_checkpoint_observation(state.get("observation"), self.observation)
        if state["architecture"] != self.architecture:
            raise ValueError(f"checkpoint architecture {state['architecture']} != {self.architecture}")
        self.loss.load_state_dict(state["loss"])
        self.optimizer.load_state_dict(state["optimizer"])
        for group in self.optimizer.param_groups:  # this device's kernels, not the saving one's
            group.update(self._optimizer_options())
        self.target_updater.load_state_dict(state["target_updater"])
        counters = state["counters"]
        self.updates = int(counters["updates"])
        self.transitions_added = int(counters["transitions_added"])
        torch.set_rng_state(state["torch_rng"])

    def save_replay(self, path: str | Path) -> None:
        """The replay buffer: in RAM, every stored row, the writer, sampler and rng, nothing pickled
        (agents.replay_files); memory-mapped, its files flushed in place and their state (see
        agents/nnql/replay_storage.py)."""
        if is_memmap(self.replay):
            save_memmap(self.replay, self.replay_rng, Path(path))
        elif len(self.replay):
            save_replay(self.replay, path)

    def load_replay(self, path: str | Path) -> None:
        """Inverse of save_replay; a missing directory means an empty buffer."""
        path = Path(path)
        if is_memmap(self.replay):
            if has_memmap_state(path):
                load_memmap(self.replay, self.replay_rng, path)
        elif has_memmap_state(path):
            raise ValueError(
                f"{path} holds a memory-mapped replay's state; build the learner with replay_dir"
            )
        elif path.exists():
            load_replay(self.replay, path)

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, device: str = "cpu", replay_dir: str | Path | None = None
    ) -> NNQLLearner:
        """A learner rebuilt from a checkpoint directory (its config and architecture included);
        ``replay_dir``: where its memory-mapped replay is, if it has one."""
        state = torch.load(Path(path) / CHECKPOINT_STATE, map_location="cpu", weights_only=True)
        arch = state["architecture"]
        config = NNQLConfig.from_dict(state["config"], state.get("observation"))
        learner = cls(config, arch["obs_dim"], arch["n_actions"], device=device, replay_dir=replay_dir,
                      observation=state.get("observation"), image=architecture_image(arch))  # fmt: skip
        learner.load_checkpoint(path)
        return learner

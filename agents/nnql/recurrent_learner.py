"""Recurrent NNQL (R2D2-style): an LSTM Q-network trained on replayed sequences.

The same role and interface as :class:`agents.nnql.learner.NNQLLearner` (``add``, ``ready``,
``update(n)``, weights, policies, checkpoints), so ``train --local`` and the learner service
drive either. What differs:

* transitions carry ``episode``, ``step`` and the acting policy's LSTM state ``state_h`` /
  ``state_c`` before the step (agents.nnql.sequence_replay.SEQUENCE_FIELDS);
* an update samples ``sequences`` slices of ``burn_in + seq_len`` steps of one episode each
  (SliceSampler), starts the online and the target network from the state stored at each
  slice's first step, unrolls the first ``burn_in`` steps without loss - and without gradient
  into the start state, unless the slice starts at its episode's first step, whose stored
  state is the exact zero state: then every step is trained on - and takes a double-Q TD(0)
  loss on the remaining real steps (padding masked out): online argmax at s', target value;
* target network: Polyak (soft) or periodic copies (hard), as ``NNQLConfig`` says.

The unroll runs over ``obs_0, next_obs_0, ..., next_obs_{L-1}``: inside an episode
``next_obs_t`` is ``obs_{t+1}``, and the last step's true next observation (terminal at an
episode end) is there too, so every step's s' has its Q-values from the same unroll.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from agents.device import resolve_device
from agents.nnql.config import NNQLConfig
from agents.nnql.losses import td_target
from agents.nnql.persistence import LearnerOutputs, check_checkpoint_env, check_checkpoint_observation
from agents.nnql.recurrent_net import RecurrentQNetwork, State
from agents.nnql.recurrent_policy import RecurrentNNQLPolicy
from agents.nnql.sequence_replay import (
    SEQUENCE_FIELDS,
    SequenceReplay,
    Sequences,
    StreamEpisodes,
    sequence_tensordict,
)
from agents.nnql.transitions import flat_fields
from agents.replay_files import load_replay, save_replay

LOSSES = {"l2": F.mse_loss, "smooth_l1": F.smooth_l1_loss, "l1": F.l1_loss}


class RecurrentNNQLLearner(LearnerOutputs):
    """Double Q-learning of the recurrent Q-network over a sequence replay (see the module docstring)."""

    def __init__(
        self,
        config: NNQLConfig,
        obs_dim: int,
        n_actions: int,
        *,
        device: str = "cpu",
        observation: Mapping[str, Any] | None = None,
    ):
        if not config.recurrent:
            raise ValueError("RecurrentNNQLLearner needs NNQLConfig.recurrent=True")
        self.config = config
        self.observation = None if observation is None else dict(observation)
        self.device = resolve_device(device)
        torch.set_num_threads(config.torch_threads)
        torch.manual_seed(config.seed)
        self.network = RecurrentQNetwork.from_config(config, obs_dim, n_actions).to(self.device)
        self.target = copy.deepcopy(self.network).requires_grad_(False)
        self.optimizer = torch.optim.Adam(self.network.parameters(), lr=config.lr)
        self.replay_rng = torch.Generator().manual_seed(config.seed)
        self.replay = SequenceReplay(config.replay_capacity, config.burn_in + config.seq_len, self.replay_rng)
        self.streams = StreamEpisodes()
        """(actor, robot) streams and their episode numbers -> the replay's trajectory ids"""
        self.updates = 0
        self.transitions_added = 0

    # ------------------------------------------------------------ data in

    def add(self, batch: Any) -> int:
        """Insert N transitions with their sequence fields (a mapping or an object with those attributes,
        such as a protocols SequenceBatch); ``actor`` (attribute or key, "" if absent) names the stream."""
        flat = flat_fields(batch)
        for name in (*SEQUENCE_FIELDS, "actor"):
            if name not in flat:
                flat[name] = getattr(batch, name, "" if name == "actor" else None)
            if flat[name] is None:
                raise KeyError(f"a recurrent learner needs {name!r} in every transition batch")
        n = len(flat["action"])
        if n == 0:
            return 0
        robots = np.asarray(flat["env_ids"]).tolist()
        flat["episode"] = self.streams.ids([(flat["actor"], r) for r in robots], flat["episode"])
        arch = self.architecture
        self.replay.extend(sequence_tensordict(flat, arch["obs_dim"], arch["lstm_size"]))
        self.transitions_added += n
        return n

    def ready(self) -> bool:
        return len(self.replay) >= max(self.config.learning_starts, self.config.sequences)

    # ------------------------------------------------------------ learning

    def update(self, n: int = 1) -> dict[str, float]:
        """Run ``n`` updates, each on freshly sampled sequences; metrics of the last one."""
        if not self.ready():
            raise RuntimeError(f"replay holds {len(self.replay)}, needs {self.config.learning_starts}")
        if n < 1:
            raise ValueError(f"update(n={n}): n must be >= 1")
        for _ in range(n):
            metrics = self.train_on(self.replay.sample_sequences(self.config.sequences))
        return metrics

    def train_on(self, seq: Sequences) -> dict[str, float]:
        """One gradient step on a batch of sequences (see the module docstring)."""
        cfg = self.config
        seq = Sequences(*(t.to(self.device) for t in seq))
        inputs = torch.cat([seq.obs[:, :1], seq.next_obs], dim=1)  # (B, L + 1): s_0, s'_0, ..., s'_{L-1}
        start: State = (seq.state_h, seq.state_c)
        fresh = seq.step[:, 0] == 0  # slices starting at their episode's first step: zero state, all trained
        b = cfg.burn_in
        with torch.no_grad():
            q_target, _ = self.target.unroll(inputs, start)
        if b > 0:
            q_burn, (h, c) = self.network.unroll(inputs[:, :b], start)
            keep = fresh[:, None]
            h, c = torch.where(keep, h, h.detach()), torch.where(keep, c, c.detach())
            q_rest, _ = self.network.unroll(inputs[:, b:], (h, c))
            q_online = torch.cat([q_burn, q_rest], dim=1)
        else:
            q_online, _ = self.network.unroll(inputs, start)
        trained = seq.mask.clone()
        trained[:, :b] &= fresh[:, None]
        taken = q_online[:, :-1].gather(-1, seq.action.unsqueeze(-1)).squeeze(-1)
        with torch.no_grad():
            next_q = q_online[:, 1:]
            if cfg.double_q:
                next_value = q_target[:, 1:].gather(-1, next_q.argmax(-1, keepdim=True)).squeeze(-1)
            else:
                next_value = q_target[:, 1:].max(-1).values
            target = td_target(seq.reward, seq.terminated, next_value, cfg.gamma)
        errors = LOSSES[cfg.loss_function](taken, target, reduction="none")
        loss = (errors * trained).sum() / trained.sum().clamp(min=1)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        max_norm = cfg.grad_clip if cfg.grad_clip > 0 else float("inf")
        grad_norm = torch.nn.utils.clip_grad_norm_(self.network.parameters(), max_norm)
        self.optimizer.step()
        self.updates += 1
        self._update_target()
        td_error = ((taken - target).abs() * trained).sum() / trained.sum().clamp(min=1)
        return {
            "losses/td_loss": float(loss.detach()),
            "losses/td_error": float(td_error.detach()),
            "losses/grad_norm": float(grad_norm),
            "losses/trained_steps": float(trained.sum()),
            "charts/version": float(self.updates),
        }

    def _update_target(self) -> None:
        soft = self.config.target_update == "soft"
        if not soft and self.updates % self.config.target_period:
            return
        with torch.no_grad():
            for target, online in zip(self.target.parameters(), self.network.parameters(), strict=True):
                if soft:
                    target.lerp_(online, self.config.target_tau)
                else:
                    target.copy_(online)

    # ------------------------------------------------------------ weights

    def get_weights(self) -> dict[str, np.ndarray]:
        return {name: t.detach().cpu().numpy().copy() for name, t in self.network.state_dict().items()}

    def set_weights(self, weights: Mapping[str, np.ndarray], sync_target: bool = True) -> None:
        state = {name: torch.as_tensor(np.asarray(v), device=self.device) for name, v in weights.items()}
        self.network.load_state_dict(state)
        if sync_target:
            self.target.load_state_dict(self.network.state_dict())

    def policy(self, **kwargs: Any) -> RecurrentNNQLPolicy:
        kwargs.setdefault("observation", self.observation)
        return RecurrentNNQLPolicy(self.get_weights(), self.architecture, version=self.version, **kwargs)

    # ------------------------------------------------------------ checkpoints

    def state_dict(self) -> dict[str, Any]:
        return {
            "config": self.config.to_dict(),
            "architecture": self.architecture,
            "observation": self.observation,
            "env": self.env,
            "network": self.network.state_dict(),
            "target": self.target.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "counters": {"updates": self.updates, "transitions_added": self.transitions_added},
            "torch_rng": torch.get_rng_state(),
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        check_checkpoint_env(state.get("env"), self.env)
        check_checkpoint_observation(state.get("observation"), self.observation)
        if state["architecture"] != self.architecture:
            raise ValueError(f"checkpoint architecture {state['architecture']} != {self.architecture}")
        self.network.load_state_dict(state["network"])
        self.target.load_state_dict(state["target"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.updates = int(state["counters"]["updates"])
        self.transitions_added = int(state["counters"]["transitions_added"])
        torch.set_rng_state(state["torch_rng"])

    def save_replay(self, path: str | Path) -> None:
        """Every stored row, writer, sampler and rng (agents.replay_files); nothing if empty."""
        if len(self.replay):
            save_replay(self.replay, path)

    def load_replay(self, path: str | Path) -> None:
        """Inverse of save_replay; new trajectory ids start after the stored ones."""
        if Path(path).exists():
            load_replay(self.replay, path)
            stored = self.replay.storage.get(torch.arange(len(self.replay)))
            self.streams.start_after(int(stored.get("episode").max()))

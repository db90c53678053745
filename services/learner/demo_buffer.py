"""The learner's demonstration buffer: demo steps kept apart from actor transitions.

Demonstrations (DemoBatch, from the A* expert or a human) go into their own
TorchRL replay buffer so actor transitions never evict them; the NIRL learner
samples it. Each step is stored as a transition in the NNQL layout plus the
index of its episode (``episode``), so whole demonstrations can be recovered.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torchrl.data import LazyTensorStorage, RandomSampler, TensorDictReplayBuffer

from agents.nnql.transitions import transitions_to_tensordict
from agents.replay_files import load_replay, save_replay
from protocols.messages import DemoBatch


class DemoBuffer:
    """Demonstration steps (oldest overwritten only by newer demonstrations once ``capacity`` is full)."""

    def __init__(self, capacity: int, obs_dim: int, seed: int = 0) -> None:
        self.obs_dim = obs_dim
        self.episodes = 0
        self.replay = TensorDictReplayBuffer(
            storage=LazyTensorStorage(capacity),
            sampler=RandomSampler(),
            generator=torch.Generator().manual_seed(seed),
        )

    def __len__(self) -> int:
        return len(self.replay)

    def add(self, batch: DemoBatch) -> int:
        """Insert every step of every episode in ``batch``; returns the number of steps."""
        steps = 0
        for _meta, episode in batch.split():
            obs = np.asarray(episode["observations"], dtype=np.float32)
            td = transitions_to_tensordict(
                {
                    "obs": obs[:-1],
                    "action": episode["actions"],
                    "reward": episode["rewards"],
                    "next_obs": obs[1:],
                    "terminated": episode["terminations"],
                    "truncated": episode["truncations"],
                },
                self.obs_dim,
            )
            td.set("episode", torch.full((td.batch_size[0],), self.episodes, dtype=torch.int64))
            self.replay.extend(td)
            self.episodes += 1
            steps += td.batch_size[0]
        return steps

    def save(self, path: Path) -> None:
        if len(self.replay):
            save_replay(self.replay, path)

    def load(self, path: Path, episodes: int) -> None:
        if path.exists():
            load_replay(self.replay, path)
        self.episodes = episodes

"""NIRL's buffers: demonstrated episodes as transitions, and sampling at any batch size."""

from __future__ import annotations

import warnings

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, RandomSampler, TensorDictReplayBuffer


def demo_buffer(capacity: int, seed: int) -> TensorDictReplayBuffer:
    """A TorchRL buffer for demonstration steps (uniform sampling, its own generator)."""
    return TensorDictReplayBuffer(
        storage=LazyTensorStorage(capacity),
        sampler=RandomSampler(),
        generator=torch.Generator().manual_seed(seed),
    )


def demo_steps(observations: np.ndarray, actions: np.ndarray, terminations, truncations) -> dict:
    """One demonstrated episode (T + 1 observations, T actions) as flat transitions."""
    obs = np.asarray(observations, dtype=np.float32)
    n = len(actions)
    return {
        "obs": obs[:-1],
        "action": np.asarray(actions, dtype=np.int64),
        "reward": np.zeros(n, dtype=np.float32),  # the demonstrator's reward is unknown: NIRL learns it
        "next_obs": obs[1:],
        "terminated": np.asarray(terminations, dtype=bool),
        "truncated": np.asarray(truncations, dtype=bool),
    }


def sample(buffer: TensorDictReplayBuffer, n: int) -> TensorDict:
    """``n`` transitions from ``buffer``, whatever batch size the buffer was built with (TorchRL
    warns when the two differ; NIRL draws several batch sizes from the same buffers on purpose)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Got conflicting batch_sizes", category=UserWarning)
        return buffer.sample(n)

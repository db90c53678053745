"""NIRL's buffers: demonstration datasets checked for this learner, demonstrated episodes as
transitions, and sampling at any batch size."""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, RandomSampler, TensorDictReplayBuffer

from agents.demo_observation import load_demos_for
from agents.demos import Demo, DemoFormatError
from agents.nnql.replay_storage import columns
from worlds.config import LEARNING_NAV, NavConfig


def load_demonstrations(path: str, nav: NavConfig | None = None) -> list[Demo]:
    """The demonstrations of the Minari dataset ``path``, checked for a NIRL learner of ``nav``'s
    observation (default :data:`worlds.config.LEARNING_NAV`) and actions. Anything unusable - no
    such dataset, an empty one, steps without actions, observations of another size or recorded
    in other observation settings - raises one DemoFormatError naming ``path``."""
    nav = nav or LEARNING_NAV
    demos = load_demos_for(path, nav)
    if not demos:
        raise DemoFormatError(f"{path}: the dataset holds no demonstrations")
    n_actions = nav.robot.n_actions
    for index, demo in enumerate(demos):
        if (demo.actions >= n_actions).any():
            raise DemoFormatError(f"{path} episode {index}: actions outside 0..{n_actions - 1}")
    return demos


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


def gather(buffer: TensorDictReplayBuffer, n: int, keys: tuple | None = None) -> dict:
    """``n`` transitions from ``buffer`` as ``{key: tensor}``: only ``keys`` (those the buffer holds;
    all when None), nested keys as tuples, on the CPU.

    The indices come from the buffer's own sampler on its storage, the call ``buffer.sample(n)``
    makes, so the draws and the generator's state are the same; the rows are then read from the
    storage's columns (:func:`agents.nnql.replay_storage.columns`, as NNQL's learner reads its
    batches): TorchRL's ``sample`` reads every column through the storage's nested ``get`` and
    its locks, a third of a NIRL Q-update's time on the CPU."""
    index, _ = buffer.sampler.sample(buffer.storage, n)
    stored = columns(buffer)
    found = ((key, stored.get(key, None)) for key in (stored.keys(True, True) if keys is None else keys))
    return {key: column[index] for key, column in found if column is not None}


def as_tensordict(rows: dict, n: int) -> TensorDict:
    """``{key: tensor}`` (nested keys as tuples) as one TensorDict of batch size ``n``, built in one
    call (a ``set`` per key costs more than the gather)."""
    nested: dict = {}
    for key, value in rows.items():
        *parents, leaf = (key,) if isinstance(key, str) else key
        node = nested
        for parent in parents:
            node = node.setdefault(parent, {})
        node[leaf] = value
    return TensorDict(nested, batch_size=[n])


def sample(buffer: TensorDictReplayBuffer, n: int, device: torch.device | None = None) -> TensorDict:
    """:func:`gather` of every key as a TensorDict, whatever batch size the buffer was built with
    (NIRL draws several batch sizes from the same buffers), moved to ``device`` when it is not the
    CPU (the buffers stay in host memory)."""
    batch = as_tensordict(gather(buffer, n), n)
    return batch if device is None or device.type == "cpu" else batch.to(device, non_blocking=True)

"""Replay of fixed-length sequences for recurrent NNQL (R2D2): TorchRL's SliceSampler, used as designed.

Transitions are stored one per row, interleaved as they come (robots of a vector env, robots
of many actors), each with its trajectory id (``episode``: one id per episode of one
robot of one actor, never reused), its ``step`` within that episode and the LSTM state
(``state_h``, ``state_c``) the acting policy held before it saw ``observation``.
``SliceSampler(traj_key="episode", step_key="step", fragmented=True)`` rebuilds every
episode from those ids and steps wherever its rows lie, so a sampled slice is consecutive
steps of one episode of one robot: it never crosses an episode end nor mixes robots. Slices
of ``burn_in + seq_len`` steps; an episode (or the part of it still stored) shorter than
that gives a shorter slice, padded by the sampler with copies of its last step and masked out.

:class:`StreamEpisodes` turns (stream, episode number) - a stream is one robot of one actor
- into trajectory ids for the learner service, whose actors count their own episodes.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any, NamedTuple

import numpy as np
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, SliceSampler, TensorDictReplayBuffer

SEQUENCE_FIELDS = ("env_ids", "episode", "step", "state_h", "state_c")
"""what a recurrent transition batch carries beside the feed-forward fields (agents.nnql.learner): the
robot, its episode number, the step in that episode, the LSTM state before the step"""
MASK_KEY = ("collector", "mask")
"""where SliceSampler's pad_output marks real (True) and padded (False) steps"""


class Sequences(NamedTuple):
    """A batch of ``B`` sequences of ``L`` steps (all tensors ``(B, L, ...)``)."""

    obs: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    next_obs: torch.Tensor
    terminated: torch.Tensor
    mask: torch.Tensor
    """real steps (False: padding after the end of a short slice)"""
    step: torch.Tensor
    """step of each row within its episode (0: the episode's first)"""
    episode: torch.Tensor
    state_h: torch.Tensor
    """(B, lstm_size): the stored state at each sequence's first step"""
    state_c: torch.Tensor


def sequence_tensordict(flat: dict[str, Any], obs_dim: int, lstm_size: int) -> TensorDict:
    """N transitions with their sequence fields as one replay-ready TensorDict."""
    n = len(flat["action"])

    def column(name: str, dtype: Any, shape: tuple[int, ...]) -> torch.Tensor:
        value = torch.as_tensor(np.asarray(flat[name], dtype=dtype))
        if value.shape != (n, *shape):
            raise ValueError(f"{name}: expected shape {(n, *shape)}, got {tuple(value.shape)}")
        return value

    return TensorDict(
        {
            "observation": column("obs", np.float32, (obs_dim,)),
            "action": column("action", np.int64, ()),
            "episode": column("episode", np.int64, ()),
            "step": column("step", np.int64, ()),
            "state_h": column("state_h", np.float32, (lstm_size,)),
            "state_c": column("state_c", np.float32, (lstm_size,)),
            "next": TensorDict(
                {
                    "observation": column("next_obs", np.float32, (obs_dim,)),
                    "reward": column("reward", np.float32, ()),
                    "terminated": column("terminated", bool, ()),
                    "truncated": column("truncated", bool, ()),
                },
                batch_size=[n],
            ),
        },
        batch_size=[n],
    )


class SequenceReplay(TensorDictReplayBuffer):
    """A TorchRL replay buffer of transitions sampled as within-episode slices of ``length`` steps
    (everything else - storage, extend, len, the replay files of agents.replay_files - as any)."""

    def __init__(self, capacity: int, length: int, generator: torch.Generator | None = None):
        self.length = int(length)
        sampler = SliceSampler(
            slice_len=self.length,
            traj_key="episode",
            step_key="step",
            fragmented=True,
            strict_length=False,
            pad_output=True,
            truncated_key=None,
        )
        super().__init__(storage=LazyTensorStorage(int(capacity)), sampler=sampler, generator=generator)

    def sample_sequences(self, sequences: int) -> Sequences:
        """``sequences`` slices, each within one episode (sampler indices and mask, rows from storage)."""
        index, info = self.sampler.sample(self.storage, sequences * self.length)
        rows = self.storage.get(index)
        mask = info[MASK_KEY] if MASK_KEY in info else torch.ones(len(rows), dtype=torch.bool)

        def seq(value: torch.Tensor) -> torch.Tensor:
            return value.reshape(sequences, self.length, *value.shape[1:])

        following = rows.get("next")
        first = seq(rows.get("state_h"))[:, 0], seq(rows.get("state_c"))[:, 0]
        return Sequences(
            obs=seq(rows.get("observation")),
            action=seq(rows.get("action")),
            reward=seq(following.get("reward")),
            next_obs=seq(following.get("observation")),
            terminated=seq(following.get("terminated")),
            mask=seq(mask),
            step=seq(rows.get("step")),
            episode=seq(rows.get("episode")),
            state_h=first[0],
            state_c=first[1],
        )


class StreamEpisodes:
    """Trajectory ids for transitions of many streams (robots of actors) that number their own episodes.

    ``ids(stream, episodes)`` maps each row's episode number within ``stream`` to a learner-wide
    id: a new id whenever a stream's episode number changes, so two streams, or two episodes of
    one stream, never share an id. Only each stream's current episode is remembered.
    """

    def __init__(self, first_id: int = 0):
        self.next_id = int(first_id)
        self.current: dict[Hashable, tuple[int, int]] = {}

    def ids(self, streams: list[Hashable], episodes: np.ndarray) -> np.ndarray:
        out = np.empty(len(streams), np.int64)
        for k, (stream, episode) in enumerate(zip(streams, np.asarray(episodes).tolist(), strict=True)):
            known = self.current.get(stream)
            if known is None or known[0] != episode:
                known = (episode, self.next_id)
                self.current[stream] = known
                self.next_id += 1
            out[k] = known[1]
        return out

    def start_after(self, used: int) -> None:
        """Give new ids from ``used`` + 1 on (ids up to ``used`` are in a restored replay)."""
        self.next_id = max(self.next_id, int(used) + 1)

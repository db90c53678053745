"""Collecting transitions with a recurrent policy: what sequence replay needs, per robot.

:class:`RecurrentRollout` is :class:`agents.nnql.rollout.VectorRollout` with a
:class:`agents.nnql.recurrent_policy.RecurrentNNQLPolicy`: the policy keeps one LSTM state
per robot and the rollout zeroes it where an episode ends (before the first action of the
next one). Each transition batch also carries, per robot, its index (``env_ids``), the number
of its episode (``episode``: 0, 1, ... per robot), its ``step`` within the episode and the
state the policy held before acting (``state_h``, ``state_c``) - the fields of
agents.nnql.sequence_replay.SEQUENCE_FIELDS; the learner turns (actor, robot, episode) into
replay-wide trajectory ids. Numpy only: ``train --local`` and the actor service share it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agents.nnql.rollout import EpisodeEnd, VectorRollout


class RecurrentRollout(VectorRollout):
    """A VectorRollout whose batches carry episode ids, steps and the policy's LSTM state."""

    def __init__(self, env: Any, policy: Any):
        """``policy``: a RecurrentNNQLPolicy, or anything with its ``__call__``, ``reset_state`` and
        ``input_state`` (the actor's, services/actor/recurrent.py)."""
        super().__init__(env, policy)
        self.robots = np.arange(self.num_envs, dtype=np.int32)
        self.episode = np.full(self.num_envs, -1, np.int64)
        """each robot's current episode number"""
        self.episode_step = np.zeros(self.num_envs, np.int64)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> np.ndarray:
        self.policy.reset_state(np.ones(self.num_envs, bool))
        self.episode += 1
        self.episode_step[:] = 0
        return super().reset(seed=seed, options=options)

    def step(self) -> tuple[dict[str, np.ndarray], list[EpisodeEnd]]:
        h, c = self.policy.input_state  # the state the current actions were chosen from
        episode, step = self.episode.copy(), self.episode_step.copy()
        batch, ended = super().step()
        done = batch["terminated"] | batch["truncated"]
        self.episode_step += 1
        self.episode_step[done] = 0
        self.episode[done] += 1
        batch.update(env_ids=self.robots, episode=episode, step=step, state_h=h, state_c=c)
        return batch, ended

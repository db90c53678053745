"""The actor's acting policy when the learner is recurrent (R2D2-style NNQL, agents/nnql/recurrent_*).

:class:`RecurrentActing` is what the actor's :class:`agents.nnql.recurrent_rollout.RecurrentRollout`
calls: uniformly random actions with an all-zero LSTM state until the first weights arrive, then the
:class:`agents.nnql.recurrent_policy.RecurrentNNQLPolicy` built from them, whose memory keeps one state
per robot and is zeroed where an episode ends. A policy swapped in mid-episode starts from zero state
for every robot; the transitions record that state, which is the one the policy acted from.
"""

from __future__ import annotations

import numpy as np

from agents.nnql.recurrent_policy import RecurrentNNQLPolicy


class RecurrentActing:
    """``acting(obs) -> actions`` with ``reset_state`` and ``input_state``, random until ``use(policy)``."""

    def __init__(self, num_envs: int, n_actions: int, lstm_size: int, rng: np.random.Generator):
        self.n_actions = int(n_actions)
        self.rng = rng
        self.zero = np.zeros((int(num_envs), int(lstm_size)), np.float32)
        self.policy: RecurrentNNQLPolicy | None = None

    def use(self, policy: RecurrentNNQLPolicy) -> None:
        """Act with ``policy`` from now on, every robot's memory starting at zero."""
        if policy.architecture["lstm_size"] != self.zero.shape[1]:
            raise ValueError(
                f"weights with lstm_size {policy.architecture['lstm_size']}; this actor sends "
                f"{self.zero.shape[1]} (its --lstm-size must be the learner's)"
            )
        policy.reset_state(np.ones(len(self.zero), bool))
        self.policy = policy

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        if self.policy is None:
            return self.rng.integers(0, self.n_actions, size=len(obs), dtype=np.int64)
        return self.policy(obs)

    def reset_state(self, done: np.ndarray) -> None:
        if self.policy is not None:
            self.policy.reset_state(done)

    @property
    def input_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.policy.input_state if self.policy is not None else (self.zero, self.zero)

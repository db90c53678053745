"""n-step returns built from one-step transitions, per (actor, robot) stream (Ape-X, Rainbow).

The learner turns the one-step transitions it receives into n-step ones: the transition from s_t
keeps ``obs`` and ``action``, its reward becomes ``sum_{k<m} gamma^k r_{t+k}``, its ``next_obs``
the observation m steps later and its ``discount`` ``gamma^m``, the factor of the bootstrap
``Q(next_obs)`` in the TD target (``losses.td_target``). m is n, or less at an episode end:

- termination inside the n steps: m stops at the terminal step, ``terminated`` is set, nothing
  bootstraps;
- truncation (time limit) inside the n steps: m stops there and the target bootstraps from the
  true last ``next_obs`` with ``gamma^m``;
- a stream that breaks (the next transition does not start where the last one ended: an actor
  restarted, batches lost) is cut the same way as a truncation, so no return spans two episodes.

Streams are keyed by (actor, env_id): ``protocols.messages.TransitionBatch`` carries both, and an
actor's batch holds each robot's transitions in time order. Transitions still waiting for their n
steps are not in the replay yet (at most n - 1 per stream), and a learner restart forgets them.
TorchRL's ``MultiStepTransform`` does the same on (robot, time)-shaped batches of one collector;
the learner's batches are flat rows interleaved from many actors, hence this small accumulator.
"""

from __future__ import annotations

from collections import OrderedDict, deque
from typing import Any

import numpy as np

MAX_STREAMS = 65_536
"""streams kept waiting at most; the least recently fed is cut (as a truncation) beyond it"""


class NStepAccumulator:
    """Turns one-step transition batches into n-step ones (see the module docstring).

    ``__call__(batch, actor)`` takes the flat fields of a transition batch (``obs``, ``action``,
    ``reward``, ``next_obs``, ``terminated``, ``truncated``, ``env_ids``) and returns the n-step
    transitions that became complete, with a float32 ``discount`` (N,) column added.
    """

    def __init__(self, n_step: int, gamma: float, max_streams: int = MAX_STREAMS):
        if n_step < 1:
            raise ValueError(f"n_step={n_step}: expected >= 1")
        self.n_step = int(n_step)
        self.gamma = float(gamma)
        self.max_streams = int(max_streams)
        self.streams: OrderedDict[tuple[str, int], deque[tuple[Any, ...]]] = OrderedDict()

    def pending(self) -> int:
        """Transitions waiting for their n steps, over all streams."""
        return sum(len(q) for q in self.streams.values())

    def __call__(self, batch: dict[str, Any], actor: str = "") -> dict[str, np.ndarray]:
        obs = np.asarray(batch["obs"], dtype=np.float32)
        next_obs = np.asarray(batch["next_obs"], dtype=np.float32)
        action = np.asarray(batch["action"], dtype=np.int64).reshape(-1)
        reward = np.asarray(batch["reward"], dtype=np.float32).reshape(-1)
        terminated = np.asarray(batch["terminated"], dtype=bool).reshape(-1)
        truncated = np.asarray(batch["truncated"], dtype=bool).reshape(-1)
        env_ids = np.asarray(batch["env_ids"]).reshape(-1)
        out: list[tuple[Any, ...]] = []
        for row in range(len(action)):
            key = (actor, int(env_ids[row]))
            queue = self.streams.get(key)
            if queue is None:
                queue = self.streams[key] = deque()
                if len(self.streams) > self.max_streams:
                    _, oldest = self.streams.popitem(last=False)
                    self._flush(oldest, terminated=False, truncated=True, out=out)
            else:
                self.streams.move_to_end(key)
                if queue and not np.array_equal(queue[-1][3], obs[row]):
                    self._flush(queue, terminated=False, truncated=True, out=out)
            queue.append((obs[row], action[row], reward[row], next_obs[row]))
            if terminated[row] or truncated[row]:
                self._flush(queue, terminated=bool(terminated[row]), truncated=bool(truncated[row]), out=out)
            elif len(queue) == self.n_step:
                out.append(self._emit(queue, terminated=False, truncated=False))
                queue.popleft()
        return self._stack(out, obs.shape[1] if obs.ndim == 2 else 0)

    def _emit(self, queue: deque, terminated: bool, truncated: bool) -> tuple[Any, ...]:
        """The transition from the queue's first state to its last next_obs (m = len(queue) steps)."""
        ret = 0.0
        for _, _, r, _ in reversed(queue):
            ret = float(r) + self.gamma * ret
        first, last = queue[0], queue[-1]
        discount = self.gamma ** len(queue)
        return first[0], first[1], ret, last[3], terminated, truncated, discount

    def _flush(self, queue: deque, terminated: bool, truncated: bool, out: list) -> None:
        """Emit every waiting transition, each ending at the queue's last next_obs."""
        while queue:
            out.append(self._emit(queue, terminated, truncated))
            queue.popleft()

    @staticmethod
    def _stack(rows: list[tuple[Any, ...]], obs_dim: int) -> dict[str, np.ndarray]:
        if not rows:
            empty = np.zeros((0, obs_dim), dtype=np.float32)
            return {
                "obs": empty,
                "action": np.zeros(0, np.int64),
                "reward": np.zeros(0, np.float32),
                "next_obs": empty.copy(),
                "terminated": np.zeros(0, bool),
                "truncated": np.zeros(0, bool),
                "discount": np.zeros(0, np.float32),
            }
        obs, action, reward, next_obs, terminated, truncated, discount = zip(*rows, strict=True)
        return {
            "obs": np.stack(obs),
            "action": np.asarray(action, dtype=np.int64),
            "reward": np.asarray(reward, dtype=np.float32),
            "next_obs": np.stack(next_obs),
            "terminated": np.asarray(terminated, dtype=bool),
            "truncated": np.asarray(truncated, dtype=bool),
            "discount": np.asarray(discount, dtype=np.float32),
        }

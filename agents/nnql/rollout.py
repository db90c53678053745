"""Collecting transitions from a vector env with a policy (the actor's inner loop).

Works with any gymnasium ``VectorEnv`` in SAME_STEP autoreset mode, such as
``worlds.vector_env.NavigationVectorEnv``: when a robot's episode ends, ``step``
already returns the first observation of its next episode and the terminal one is in
``info["final_obs"]``. The transition keeps the terminal observation as ``next_obs``
so nothing bootstraps across episodes. Numpy only: ``train --local`` and the actor
service share it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from worlds.outcomes import Outcome

Policy = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class EpisodeEnd:
    """One finished episode of one robot."""

    env_id: int
    episode_return: float
    length: int
    outcome: int | None
    """``worlds.outcomes.Outcome`` code from the terminal info, None if the env gives none"""
    path_length: float | None
    success: bool | None = None
    """the terminal ``info["is_success"]`` (gymnasium-robotics / SB3 convention); None: not given"""

    @property
    def solved(self) -> bool:
        """Did the episode succeed: the env's ``is_success`` when it gives one, else reaching the goal."""
        return self.outcome == Outcome.GOAL if self.success is None else bool(self.success)


def _row(info: dict[str, Any], key: str, index: int) -> Any:
    """Entry ``index`` of a vectorised info field, None where absent (gymnasium's ``_key`` masks)."""
    if key not in info:
        return None
    mask = info.get(f"_{key}")
    if mask is not None and not mask[index]:
        return None
    return info[key][index]


class VectorRollout:
    """Steps a vector env with ``policy`` and hands back transition batches.

    ``step()`` returns ``(batch, episodes)``: a flat dict of N transitions (field names of
    ``protocols.messages.TransitionBatch``, plus ``next_action`` when ``with_next_action``,
    for SARSA: the action the policy takes at ``next_obs``) and the episodes that ended.
    The policy picks the next actions right after each step, so SARSA's next action is
    the one actually taken on the following step.
    """

    def __init__(self, env: Any, policy: Policy, *, with_next_action: bool = False):
        self.env = env
        self.policy = policy
        self.with_next_action = with_next_action
        self.num_envs = int(env.num_envs)
        self.obs: np.ndarray | None = None
        self.actions: np.ndarray | None = None
        self.returns = np.zeros(self.num_envs)
        self.lengths = np.zeros(self.num_envs, dtype=np.int64)
        self.steps = 0

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> np.ndarray:
        self.obs, _ = self.env.reset(seed=seed, options=options)
        self.actions = self.policy(self.obs)
        self.returns[:] = 0.0
        self.lengths[:] = 0
        return self.obs

    def step(self) -> tuple[dict[str, np.ndarray], list[EpisodeEnd]]:
        if self.obs is None or self.actions is None:
            raise RuntimeError("call reset() before step()")
        obs, actions = self.obs, self.actions
        next_obs, reward, terminated, truncated, info = self.env.step(actions)
        reward = np.asarray(reward, dtype=np.float32)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        done = terminated | truncated
        true_next = np.array(next_obs, dtype=np.float32, copy=True)
        self.returns += reward
        self.lengths += 1
        episodes = []
        if done.any():
            final_obs = info["final_obs"]
            final_info = info.get("final_info", {})
            for i in np.flatnonzero(done):
                true_next[i] = final_obs[i]
                outcome = _row(final_info, "outcome", i)
                path_length = _row(final_info, "path_length", i)
                success = _row(final_info, "is_success", i)
                episodes.append(
                    EpisodeEnd(
                        env_id=int(i),
                        episode_return=float(self.returns[i]),
                        length=int(self.lengths[i]),
                        outcome=None if outcome is None else int(outcome),
                        path_length=None if path_length is None else float(path_length),
                        success=None if success is None else bool(success),
                    )
                )
            self.returns[done] = 0.0
            self.lengths[done] = 0
        self.obs = np.asarray(next_obs, dtype=np.float32)
        self.actions = self.policy(self.obs)
        self.steps += self.num_envs
        batch = {
            "obs": obs,
            "action": np.asarray(actions, dtype=np.int64),
            "reward": reward,
            "next_obs": true_next,
            "terminated": terminated,
            "truncated": truncated,
        }
        if self.with_next_action:
            next_action = self.actions.copy()
            if truncated.any():  # the cut episode's next action was never taken: draw it from the policy
                next_action[truncated] = self.policy(true_next[truncated])
            batch["next_action"] = next_action
        return batch, episodes

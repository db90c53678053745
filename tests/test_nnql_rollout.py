"""VectorRollout on a gymnasium SAME_STEP vector env: true next observations, episodes, SARSA actions."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from agents.nnql.rollout import VectorRollout


def make_env(n: int) -> SyncVectorEnv:
    return SyncVectorEnv(
        [lambda: gym.make("CartPole-v1", max_episode_steps=15) for _ in range(n)],
        autoreset_mode=AutoresetMode.SAME_STEP,
    )


def test_rollout_keeps_terminal_observations_and_counts_episodes():
    env = make_env(3)
    rng = np.random.default_rng(0)
    rollout = VectorRollout(env, lambda obs: rng.integers(0, 2, len(obs)), with_next_action=True)
    rollout.reset(seed=0)
    episodes = []
    for _ in range(60):
        previous_next = rollout.obs.copy()
        batch, ended = rollout.step()
        done = batch["terminated"] | batch["truncated"]
        np.testing.assert_array_equal(batch["obs"], previous_next)
        # where the episode goes on, next_obs is the next step's obs; where it ended, it is not
        np.testing.assert_array_equal(batch["next_obs"][~done], rollout.obs[~done])
        if done.any():
            assert not np.array_equal(batch["next_obs"][done], rollout.obs[done])
        np.testing.assert_array_equal(
            batch["next_action"][~batch["truncated"]], rollout.actions[~batch["truncated"]]
        )
        assert sorted(e.env_id for e in ended) == list(np.flatnonzero(done))
        episodes += ended
    assert rollout.steps == 180
    assert len(episodes) >= 3
    assert all(1 <= e.length <= 15 for e in episodes)
    assert any(e.length == 15 for e in episodes)  # truncations counted too
    env.close()

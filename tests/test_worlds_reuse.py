"""The world's shortcuts change no number: :class:`worlds.perception.Perception` with its reuse
(plans kept per cell of an unchanged plan map, the geodesic field's Dijkstra run only as far as
the robot's cells need) gives bit-identical observations and rewards to the straightforward
program (a search at every replan, the whole field at every reset)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from worlds.config import LEARNING_NAV, LEARNING_PLAN_NAV, NavConfig
from worlds.heuristics import goal_seeking_policy
from worlds.perception import REUSE_PARAM
from worlds.vector_env import NavigationVectorEnv

KNOWN_MAP = dataclasses.replace(
    LEARNING_NAV, observation=dataclasses.replace(LEARNING_NAV.observation, subgoal="known_map")
)


def rollout(config: NavConfig, maps: str, reuse: bool, policy: str, steps: int = 300, n: int = 12):
    env = NavigationVectorEnv(n, config, maps=maps, threads=1)
    env.batch.perception.params[REUSE_PARAM] = float(reuse)
    obs, _ = env.reset(seed=3)
    seek = goal_seeking_policy(config)
    width = config.sensors.n_beams + 3  # readings + goal, what the heuristic reads
    rng = np.random.default_rng(3)
    frames, rewards, finals = [obs.copy()], [], []
    for _ in range(steps):
        actions = seek(obs[:, :width]) if policy == "goal" else rng.integers(config.robot.n_actions, size=n)
        obs, reward, terminated, truncated, _ = env.step(actions)
        frames.append(obs.copy())
        rewards.append(reward.copy())
        ended = terminated | truncated
        finals.append(np.where(ended[:, None], env.batch.final_obs, 0.0))
    planned = int((env.batch.perception.stamp >= 0).sum())  # cells with a kept plan
    env.close()
    return np.stack(frames), np.stack(rewards), np.stack(finals), planned


@pytest.mark.parametrize("maps", ["rects:16", "rooms:12x20", "discs:16", "mixed:16"])
@pytest.mark.parametrize("policy", ["random", "goal"])
def test_reused_plans_change_no_observation_or_reward(maps, policy):
    obs0, rew0, fin0, _ = rollout(LEARNING_NAV, maps, reuse=False, policy=policy)
    obs1, rew1, fin1, planned = rollout(LEARNING_NAV, maps, reuse=True, policy=policy)
    assert planned > 0  # the reusing run kept plans
    assert np.array_equal(obs0, obs1)
    assert np.array_equal(rew0, rew1)
    assert np.array_equal(fin0, fin1)


@pytest.mark.parametrize("policy", ["random", "goal"])
def test_reused_plans_keep_the_plan_length(policy):
    obs0, rew0, fin0, _ = rollout(LEARNING_PLAN_NAV, "mixed:16", reuse=False, policy=policy)
    obs1, rew1, fin1, planned = rollout(LEARNING_PLAN_NAV, "mixed:16", reuse=True, policy=policy)
    assert planned > 0
    assert np.array_equal(obs0, obs1) and np.array_equal(rew0, rew1) and np.array_equal(fin0, fin1)


def test_reused_plans_on_the_known_map_change_nothing():
    obs0, rew0, fin0, _ = rollout(KNOWN_MAP, "rooms:16", reuse=False, policy="goal")
    obs1, rew1, fin1, _ = rollout(KNOWN_MAP, "rooms:16", reuse=True, policy="goal")
    assert np.array_equal(obs0, obs1) and np.array_equal(rew0, rew1) and np.array_equal(fin0, fin1)

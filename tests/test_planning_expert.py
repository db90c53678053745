"""The expert in the environment: success rates, replanning, and faithful demonstrations."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from agents.planning.demonstrate import generate_demos
from agents.planning.expert import Expert
from worlds.config import NavConfig, ObstacleConfig
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome

CONFIG = NavConfig(pool_size=40)  # default motion and sensor noise


def _success_rate(spec: str, episodes: int, config: NavConfig) -> tuple[float, int]:
    env = NavigationEnv(config, maps=spec)
    expert = Expert(config)
    wins, replans = 0, 0
    for seed in range(episodes):
        obs, info = env.reset(seed=seed)
        expert.reset(info["task"], info["pose"])
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert.act(info["pose"], obs))
            done = terminated or truncated
        wins += info["outcome"] == Outcome.GOAL
        replans += expert.replans
    return wins / episodes, replans


@pytest.mark.parametrize("spec", ["rects:16", "rooms:16", "discs:16"])
def test_expert_reaches_the_goal_on_generated_maps(spec):
    rate, replans = _success_rate(spec, 40, CONFIG)
    print(f"expert success on {spec} with motion noise: {rate:.1%}")
    # the misses are starts whose random heading faces a wall corner with no collision-free action
    assert rate >= 0.9
    assert replans > 0  # motion noise makes it replan


def test_expert_with_moving_discs():
    config = replace(CONFIG, obstacles=ObstacleConfig(count=3))
    rate, _ = _success_rate("mixed:16", 40, config)
    print(f"expert success on mixed:16 with 3 moving discs: {rate:.1%}")
    assert rate >= 0.75


def test_demonstrations_are_the_robots_own_episodes():
    config = replace(CONFIG, robot=replace(CONFIG.robot, trans_noise=0.0, rot_noise=0.0))
    demos, stats = generate_demos("rooms:12", 6, seed=5, noise=0.3, config=config, keep_failures=True)
    assert stats.episodes == 6 and len(demos) == 6
    assert sum(stats.outcomes.values()) == 6
    env = NavigationEnv(config, maps="rooms:12")
    perturbed = 0
    for demo in demos:
        obs, info = env.reset(seed=demo.metadata["seed"])
        assert info["task"] == demo.task()
        np.testing.assert_array_equal(obs, demo.observations[0])
        for t, action in enumerate(demo.actions):  # replaying the recorded actions reproduces the episode
            obs, reward, terminated, truncated, info = env.step(int(action))
            np.testing.assert_array_equal(obs, demo.observations[t + 1])
            np.testing.assert_allclose(info["pose"], demo.poses[t + 1])
            assert reward == pytest.approx(demo.rewards[t])
            assert (terminated, truncated) == (demo.terminations[t], demo.truncations[t])
        assert info["outcome"] == demo.metadata["outcome"]
        assert demo.metadata["source"] == "astar" and demo.metadata["noise"] == 0.3
        perturbed += int((demo.labels != demo.actions).sum())
    assert perturbed > 0  # noise made the robot deviate from the expert's choice somewhere

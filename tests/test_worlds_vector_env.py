"""NavigationVectorEnv: equal to NavigationEnv for the same seeds, SAME_STEP autoreset, options."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from worlds.config import (
    NavConfig,
    ObservationConfig,
    ObstacleConfig,
    RewardConfig,
    RobotConfig,
    SensorConfig,
)
from worlds.env import NavigationEnv
from worlds.maps import Task, parse_ascii
from worlds.obstacles import DiscObstacles
from worlds.outcomes import Outcome
from worlds.vector_env import NavigationVectorEnv

ZERO_NOISE = NavConfig(
    robot=RobotConfig(trans_noise=0.0, rot_noise=0.0),
    sensors=SensorConfig(noise_std=0.0),
    obstacles=ObstacleConfig(count=2),
    pool_size=16,
)
NOISY = NavConfig(
    sensors=SensorConfig(dropout_prob=0.1),
    obstacles=ObstacleConfig(count=2, mode="patrol"),
    pool_size=16,
)

PERCEIVING = NavConfig(
    sensors=SensorConfig(n_beams=12, n_rays=48, dropout_prob=0.1),
    observation=ObservationConfig(previous_action=True, frame_stack=3, subgoal="own_map", patch_size=6),
    rewards=RewardConfig(geodesic_progress=0.1),
    obstacles=ObstacleConfig(count=2),
    pool_size=16,
)
KNOWN_MAP = NavConfig(observation=ObservationConfig(subgoal="known_map"), pool_size=16)


@pytest.mark.parametrize(
    ("config", "threads"),
    [(ZERO_NOISE, 1), (NOISY, 1), (NOISY, 2), (PERCEIVING, 1), (PERCEIVING, 2), (KNOWN_MAP, 1)],
    ids=["zero-noise", "noisy", "noisy-2-threads", "perceiving", "perceiving-2-threads", "known-map"],
)
def test_vector_env_equals_single_envs(config, threads):
    n, seed = 5, 11
    vector = NavigationVectorEnv(n, config, maps="mixed:16", seed=seed, threads=threads)
    singles = [NavigationEnv(config, maps="mixed:16") for _ in range(n)]
    obs, _ = vector.reset()
    np.testing.assert_array_equal(
        obs, np.stack([env.reset(seed=seed + i)[0] for i, env in enumerate(singles)])
    )
    rng = np.random.default_rng(0)
    episodes = 0
    for _ in range(150):
        actions = rng.integers(5, size=n)
        obs, rewards, terminated, truncated, info = vector.step(actions)
        for i, env in enumerate(singles):
            s_obs, s_reward, s_term, s_trunc, s_info = env.step(int(actions[i]))
            assert (s_reward, s_term, s_trunc) == (rewards[i], terminated[i], truncated[i])
            if s_term or s_trunc:
                episodes += 1
                assert info["_final_obs"][i]
                np.testing.assert_array_equal(info["final_obs"][i], s_obs)
                final = info["final_info"]
                assert final["outcome"][i] == s_info["outcome"] != Outcome.RUNNING
                assert final["path_length"][i] == s_info["path_length"]
                np.testing.assert_array_equal(final["pose"][i], s_info["pose"])
                assert vector.final_task(i) == env.batch.task(0)
                s_obs, _ = env.reset()
            np.testing.assert_array_equal(obs[i], s_obs)
    assert episodes > 20


def test_same_step_autoreset_and_spaces():
    env = NavigationVectorEnv(8, ZERO_NOISE, maps="rooms:16", seed=0)
    assert env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    assert env.observation_space.shape == (8, 11) and env.single_action_space.n == 5
    obs, info = env.reset()
    assert obs.shape == (8, 11) and obs.dtype == np.float32 and info == {}
    seen_done = False
    for _ in range(60):
        obs, _, terminated, truncated, info = env.step(np.zeros(8, dtype=np.int64))  # turn -90: walls soon
        done = terminated | truncated
        if done.any():
            seen_done = True
            assert (info["_final_obs"] == done).all() and (info["_final_info"] == done).all()
            assert not np.array_equal(info["final_obs"][done], obs[done])  # obs is already the next episode's
            steps = env.batch.steps[done]
            assert (steps == 0).all()
        else:
            assert info == {}
    assert seen_done


def test_per_robot_tasks_discs_maps_and_reset_mask():
    grid = parse_ascii("##########\n#........#\n#........#\n##########\n")[0]
    fixed = Task(grid, (1, 1), (1, 3))
    env = NavigationVectorEnv(3, ZERO_NOISE, maps=["rooms:16", "maze:11", "rects:12x20"], seed=1)
    env.reset()
    assert [t.grid.shape for t in env.tasks()] == [(16, 16), (11, 11), (12, 20)]
    discs = DiscObstacles([[6.5, 1.5]], [[0.0, 0.0]], 0.4)
    obs, _ = env.reset(options={"tasks": [fixed, None, fixed], "obstacles": [None, None, discs]})
    tasks = env.tasks()
    assert tasks[0] == fixed and tasks[2] == fixed and tasks[1].grid.shape == (11, 11)
    assert len(env.batch.discs(2)) == 1 and env.batch.discs(2)[0].tolist() == [6.5, 1.5, 0.4]
    before = obs.copy()
    obs, _ = env.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(obs[[0, 2]], before[[0, 2]])
    assert env.poses().shape == (3, 3)
    with pytest.raises(ValueError, match="one entry"):
        env.reset(options={"tasks": [fixed]})
    with pytest.raises(ValueError, match="actions"):
        env.step(np.array([0, 6, 1]))  # 5 is the turn-around (RobotConfig.turn_around)
    with pytest.raises(ValueError, match="3 robots"):
        NavigationVectorEnv(3, ZERO_NOISE, maps=["rooms:16"])


def test_reset_seed_reproducible_and_list_seeds():
    env = NavigationVectorEnv(4, NOISY, maps="rooms:16")
    a = env.reset(seed=3)[0]
    steps_a = [env.step(np.full(4, 2))[0] for _ in range(5)]
    b = env.reset(seed=3)[0]
    steps_b = [env.step(np.full(4, 2))[0] for _ in range(5)]
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(np.stack(steps_a), np.stack(steps_b))
    c = env.reset(seed=[3, 4, 5, 6])[0]
    np.testing.assert_array_equal(c, a)

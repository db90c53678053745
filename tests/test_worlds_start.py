"""Start headings: every episode starts with at least one collision-free action."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worlds.config import NavConfig, RobotConfig, SensorConfig
from worlds.env import NavigationEnv
from worlds.maps import Task, parse_ascii
from worlds.robot import collides
from worlds.vector_env import NavigationVectorEnv

# the start (1, 1) is a dead end: only its east neighbour is free, so facing west, north-west or
# south-west every action (turns -90..90 degrees) drives into a wall
DEAD_END = parse_ascii("######\n#S...#\n####.#\n#G...#\n######\n")[0]
DEAD_END_TASK = Task(DEAD_END, (1, 1), (3, 1))
CONFIG = NavConfig(pool_size=4)


def free_actions(grid, config: NavConfig, pose) -> list[int]:
    """Actions whose noise-free motion from ``pose`` is collision-free."""
    x, y, theta = pose
    r = config.robot
    headings = theta + r.turns
    hits = collides(grid, x, y, x + r.step * np.cos(headings), y + r.step * np.sin(headings), r.radius)
    return [a for a in range(r.n_actions) if not hits[a]]


def test_dead_end_start_gets_a_drivable_heading():
    env = NavigationEnv(CONFIG, maps="rooms:16")
    headings = []
    for seed in range(64):  # 3 of the 8 compass headings are undrivable: (5/8)^64 ~ 1e-13 to miss them
        _obs, info = env.reset(seed=seed, options={"task": DEAD_END_TASK})
        assert free_actions(DEAD_END, CONFIG, info["pose"]), f"seed {seed}: heading {info['pose'][2]}"
        assert env.reset(seed=seed, options={"task": DEAD_END_TASK})[1]["pose"][2] == info["pose"][2]
        headings.append(round(math.degrees(info["pose"][2])))
    # drivable: north, north-east, east, south-east, south (y grows down, so north is -90 degrees);
    # sampled west moves to the nearest drivable (+-90), NW/SW to their drivable neighbours
    assert set(headings) == {-90, -45, 0, 45, 90}
    assert headings.count(-90) + headings.count(90) > headings.count(0)


def test_vector_and_single_env_choose_the_same_start_heading():
    n, seed = 6, 3
    vector = NavigationVectorEnv(n, CONFIG, maps="rooms:16")
    obs, _ = vector.reset(seed=seed, options={"tasks": [DEAD_END_TASK] * n})
    for i in range(n):
        s_obs, info = NavigationEnv(CONFIG, maps="rooms:16").reset(
            seed=seed + i, options={"task": DEAD_END_TASK}
        )
        np.testing.assert_array_equal(vector.poses()[i], info["pose"])
        np.testing.assert_array_equal(obs[i], s_obs)


def test_heading_choices_one_still_turns_away_from_a_wall():
    config = NavConfig(robot=RobotConfig(heading_choices=1, trans_noise=0.0, rot_noise=0.0), pool_size=4)
    env = NavigationEnv(config, maps="rooms:16")
    pocket = parse_ascii("#####\n#G.S#\n#####\n")[0]  # S has walls east, north and south
    _obs, info = env.reset(seed=0, options={"task": Task(pocket, (1, 3), (1, 1))})
    assert free_actions(pocket, config, info["pose"]) and abs(info["pose"][2]) == pytest.approx(math.pi / 2)
    _obs, info = env.reset(seed=0, options={"task": Task(DEAD_END, (1, 2), (3, 1))})
    assert info["pose"][2] == 0.0  # drivable as sampled: kept


def test_undrivable_given_task_is_rejected():
    fat = NavConfig(robot=RobotConfig(radius=0.6), sensors=SensorConfig(noise_std=0.0), pool_size=4)
    corridor = parse_ascii("##########\n#........#\n#........#\n##########\n")[0]
    env = NavigationEnv(fat, maps="rooms:16")
    with pytest.raises(ValueError, match=r"start \(1, 1\).*no collision-free action"):
        env.reset(seed=0, options={"task": Task(corridor, (1, 1), (2, 8))})
    vector = NavigationVectorEnv(2, fat, maps="rooms:16")
    with pytest.raises(ValueError, match="no collision-free action"):
        vector.reset(seed=0, options={"tasks": [None, Task(corridor, (1, 1), (2, 8))]})


def test_random_starts_are_redrawn_until_drivable(tmp_path):
    # with a 0.55 m radius only cells with four free neighbours can move at all: the room's
    # middle 3x3 cells; random starts must land there
    room = "#######\n#.....#\n#.....#\n#.....#\n#.....#\n#.....#\n#######\n"
    path = tmp_path / "room.txt"
    path.write_text(room)
    config = NavConfig(robot=RobotConfig(radius=0.55), pool_size=4)
    env = NavigationVectorEnv(16, config, maps=str(path), seed=0)
    env.reset()
    grid = env.grid(0)
    for _ in range(3):
        for i, task in enumerate(env.tasks()):
            assert 2 <= task.start[0] <= 4 and 2 <= task.start[1] <= 4, task.start
            assert free_actions(grid, config, env.poses()[i])
        env.reset()

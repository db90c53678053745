"""NavigationEnv: gymnasium checks, seeding, rewards, termination, truncation, sensors and discs."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import worlds  # noqa: F401  (registers the env)
from agents.planning.astar import astar
from worlds.config import NavConfig, ObstacleConfig, RewardConfig, RobotConfig, SensorConfig, step_limit
from worlds.env import NavigationEnv
from worlds.maps import Task, parse_ascii
from worlds.obstacles import DiscObstacles
from worlds.outcomes import OUTCOME_NAMES, Outcome

# exact dynamics, the robot always starts facing east (+x)
EXACT = NavConfig(
    robot=RobotConfig(trans_noise=0.0, rot_noise=0.0, heading_choices=1),
    sensors=SensorConfig(noise_std=0.0),
    pool_size=8,
)
CORRIDOR = parse_ascii("##########\n#........#\n#........#\n##########\n")[0]
EAST = 2  # the straight-ahead action of the default 5 (turns -90, -45, 0, 45, 90 degrees)


def task(start, goal) -> Task:
    return Task(CORRIDOR, start, goal)


def make(config: NavConfig = EXACT, **kw) -> NavigationEnv:
    return NavigationEnv(config, maps="rooms:16", **kw)


def test_registered_and_check_env():
    env = gym.make("navlearn/Navigation-v0", config=EXACT, render_mode="rgb_array")
    assert env.spec.id == "navlearn/Navigation-v0"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env.unwrapped)
        check_env(NavigationEnv(NavConfig(obstacles=ObstacleConfig(count=3, mode="patrol"), pool_size=8)))
        check_env(NavigationEnv(NavConfig(obstacles=ObstacleConfig(count=2), pool_size=8), maps="maze:11"))
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8


def test_reset_seed_is_reproducible():
    env = NavigationEnv(NavConfig(obstacles=ObstacleConfig(count=2), pool_size=8))
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=7)
        trace = [obs]
        for action in [0, 1, 2, 3, 4, 2, 2]:
            obs, reward, terminated, truncated, _info = env.step(action)
            trace += [obs, np.array([reward])]
            if terminated or truncated:
                break
        runs.append(np.concatenate(trace))
    np.testing.assert_array_equal(runs[0], runs[1])
    first = env.reset(seed=7)[0]
    assert any(not np.array_equal(first, env.reset(seed=s)[0]) for s in (8, 9, 10))


def test_observation_layout_and_info():
    env = make()
    obs, info = env.reset(seed=0, options={"task": task((1, 1), (1, 5))})
    assert obs.dtype == np.float32 and obs.shape == (11,) and env.observation_space.contains(obs)
    # beams at -180, -135, ..., 135 degrees from the heading (east): walls at 0.5 m west/north/south
    expected = np.array([0.5, math.sqrt(2) / 2, 0.5, math.sqrt(2) / 2, 6.0, 6.0, 1.5, 0.5 * math.sqrt(2)]) / 6
    expected[7] = math.sqrt(0.5) / 6  # 135 deg is (-1, +1)/sqrt2: the wall x = 1 after 0.5 along x
    expected[5] = 1.5 * math.sqrt(2) / 6  # 45 deg: the bottom wall y = 3 after 1.5 along y
    np.testing.assert_allclose(obs[:8], expected, atol=1e-6)
    assert obs[8] == pytest.approx(4 / (4 + 6))  # goal 4 m away, squashed d / (d + max_range)
    assert obs[9:] == pytest.approx([0.0, 1.0])  # dead ahead
    assert info["pose"].tolist() == [1.5, 1.5, 0.0] and info["outcome"] == Outcome.RUNNING
    assert info["task"].goal == (1, 5) and info["path_length"] == 0.0
    obs, *_ = env.step(4)  # turn +90 degrees (to +y) and drive to (1.5, 2.0): goal at -97 degrees
    d = math.hypot(4.0, 0.5)
    assert obs[9:] == pytest.approx([-4.0 / d, -0.5 / d], abs=1e-6)


def test_goal_reward_and_termination():
    env = make()
    env.reset(seed=0, options={"task": task((1, 1), (1, 3))})  # goal centre 2 m ahead
    rewards = []
    for _ in range(3):
        _obs, reward, terminated, truncated, info = env.step(EAST)
        rewards.append(reward)
    assert rewards == pytest.approx([-0.01 + 0.05, -0.01 + 0.05, -0.01 + 0.05 + 1.0])
    assert terminated and not truncated and info["outcome"] == Outcome.GOAL
    assert info["path_length"] == pytest.approx(1.5) and info["steps"] == 3
    with pytest.raises(RuntimeError, match="reset"):
        env.step(EAST)


def test_static_collision_ends_the_episode_in_place():
    env = make()
    env.reset(seed=0, options={"task": task((1, 1), (1, 8))})
    _obs, reward, terminated, _truncated, info = env.step(0)  # turn to -y: the top wall
    assert terminated and reward == pytest.approx(-1.01)
    assert (
        info["outcome"] == Outcome.COLLISION_STATIC and OUTCOME_NAMES[info["outcome"]] == "collision_static"
    )
    assert info["pose"][:2].tolist() == [1.5, 1.5] and info["path_length"] == 0.0


def test_truncation_at_the_step_limit():
    config = NavConfig(robot=EXACT.robot, sensors=EXACT.sensors, max_steps=3, step_factor=0.0, pool_size=8)
    env = NavigationEnv(config, maps="rooms:16")
    env.reset(seed=0, options={"task": task((1, 1), (2, 8))})
    results = [env.step(EAST)[2:4] for _ in range(3)]
    assert results == [(False, False), (False, False), (False, True)]
    assert env.batch.outcome[0] == Outcome.TIMEOUT


def test_step_limit_grows_with_the_a_star_path():
    """The limit is max(max_steps, ceil(step_factor * L / step)), L the grid A* length: 4 * 8 m / 0.5 m
    = 64 steps on this task with a floor of 3; the robot circles a 0.5 m square (turning 90 degrees
    every step) near its start, and its 64th step times out, not its 63rd."""
    config = NavConfig(robot=EXACT.robot, sensors=EXACT.sensors, max_steps=3, pool_size=8)
    env = NavigationEnv(config, maps="rooms:16")
    hall = parse_ascii("\n".join(["#" * 14] + ["#" + "." * 12 + "#"] * 12 + ["#" * 14]))[0]
    the_task = Task(hall, (7, 3), (7, 11))
    _, info = env.reset(seed=0, options={"task": the_task})
    length = astar(hall, the_task.start, the_task.goal).length
    assert length == 8.0
    assert info["step_limit"] == step_limit(config, length) == 64
    circle = 4  # turn +90 degrees, then drive
    for _ in range(63):
        _, _, terminated, truncated, _ = env.step(circle)
        assert not (terminated or truncated)
    assert env.step(circle)[3] and env.batch.outcome[0] == Outcome.TIMEOUT
    assert step_limit(replace(config, max_steps=200), length) == 200  # the floor keeps short episodes


def test_reward_settings_apply():
    config = NavConfig(EXACT.robot, EXACT.sensors, RewardConfig(step=-0.5, progress=0.0), pool_size=8)
    env = NavigationEnv(config, maps="rooms:16")
    env.reset(seed=0, options={"task": task((1, 1), (1, 8))})
    assert env.step(EAST)[1] == pytest.approx(-0.5)


def test_moving_disc_is_seen_and_hit():
    env = make()
    discs = DiscObstacles([[4.5, 1.5]], [[-0.5, 0.0]], 0.3)
    obs, _ = env.reset(seed=0, options={"task": task((1, 1), (2, 8)), "obstacles": discs})
    assert obs[4] * 6 == pytest.approx(4.5 - 0.3 - 1.5)  # the east beam stops at the disc's edge
    obs, reward, terminated, _, info = env.step(EAST)  # robot 1.5 -> 2.0, disc 4.5 -> 4.0
    assert not terminated and obs[4] * 6 == pytest.approx(4.0 - 0.3 - 2.0)
    obs, reward, terminated, _, info = env.step(EAST)  # 2.0 -> 2.5 and 4.0 -> 3.5: they meet
    assert not terminated and obs[4] * 6 == pytest.approx(3.5 - 0.3 - 2.5)
    obs, reward, terminated, _, info = env.step(EAST)
    assert terminated and info["outcome"] == Outcome.COLLISION_DYNAMIC and reward == pytest.approx(-1.01)


def test_generated_discs_move_and_keep_off_walls():
    config = NavConfig(obstacles=ObstacleConfig(count=4, speed=0.3), pool_size=8)
    env = NavigationEnv(config, maps="rects:16")
    env.reset(seed=3)
    before = env.batch.discs(0).copy()
    assert len(before) == 4
    for _ in range(5):
        if env.step(int(env.np_random.integers(5)))[2]:
            break
    after = env.batch.discs(0)
    assert not np.allclose(before[:, :2], after[:, :2])
    grid = env.batch.task(0).grid
    for x, y, r in after:  # every disc still clear of blocked cells
        cells = [(int(yy), int(xx)) for xx in (x - r, x + r) for yy in (y - r, y + r)]
        assert all(grid.is_free(c) for c in cells)


def test_sensor_dropout_and_noise():
    grid_task = task((1, 1), (1, 8))
    sensors = SensorConfig(dropout_prob=1.0)
    dropped = NavigationEnv(NavConfig(robot=EXACT.robot, sensors=sensors, pool_size=8), maps="rooms:16")
    obs, _ = dropped.reset(seed=0, options={"task": grid_task})
    assert (obs[:8] == 1.0).all()
    sensors = SensorConfig(noise_std=0.3)
    noisy = NavigationEnv(NavConfig(robot=EXACT.robot, sensors=sensors, pool_size=8), maps="rooms:16")
    exact = make()
    a = noisy.reset(seed=0, options={"task": grid_task})[0][:8]
    b = exact.reset(seed=0, options={"task": grid_task})[0][:8]
    assert not np.allclose(a, b) and (a >= 0).all() and (a <= 1).all()


def test_motion_noise_changes_the_pose():
    robot = RobotConfig(heading_choices=1, trans_noise=0.05, rot_noise=0.05)
    env = NavigationEnv(NavConfig(robot=robot, pool_size=8), maps="rooms:16")
    env.reset(seed=0, options={"task": task((1, 1), (2, 8))})
    pose = env.step(EAST)[4]["pose"]
    assert pose[:2].tolist() != pytest.approx([2.0, 1.5]) and abs(pose[2]) < 0.3


def test_a_held_heading_keeps_one_step_of_heading_noise():
    """RobotConfig.held_headings: before each action the heading is turned to the nearest compass
    heading, so after any number of actions its error is the last step's noise alone; not held, the
    errors add up. Turning round in place (no drive, no collision) 30 times in the same world and
    with the same noise draws: held, each step's error is exactly the step the unheld error takes."""
    errors = {}
    for held in (0, 8):
        robot = RobotConfig(heading_choices=1, trans_noise=0.0, rot_noise=0.05, held_headings=held)
        env = NavigationEnv(NavConfig(robot=robot, pool_size=8), maps="rooms:16")
        env.reset(seed=3, options={"task": task((1, 1), (2, 8))})
        headings = [env.step(robot.turn_around)[4]["pose"][2] for _ in range(30)]
        quantum = math.pi / 4
        errors[held] = np.array([(h - round(h / quantum) * quantum) for h in headings])
    np.testing.assert_allclose(errors[8], np.diff(errors[0], prepend=0.0), atol=1e-9)
    assert np.abs(errors[8]).max() < 0.2 < np.abs(errors[0]).max()  # 4 sd of one step against a walk
    with pytest.raises(ValueError, match="held_headings"):
        RobotConfig(held_headings=-1)


def test_bad_arguments():
    with pytest.raises(ValueError, match="render_mode"):
        NavigationEnv(render_mode="human")
    with pytest.raises(ValueError, match="neither"):
        NavigationEnv(maps="nowhere.map")
    with pytest.raises(RuntimeError, match="reset"):
        make().step(0)


@pytest.mark.parametrize(
    "build",
    [
        lambda: RobotConfig(n_actions=0),
        lambda: RobotConfig(radius=0.0),
        lambda: SensorConfig(n_beams=0),
        lambda: SensorConfig(dropout_prob=1.5),
        lambda: ObstacleConfig(mode="orbit"),
        lambda: ObstacleConfig(count=-1),
        lambda: NavConfig(max_steps=0),
    ],
)
def test_config_rejects_bad_values(build):
    with pytest.raises(ValueError, match="must"):
        build()


def test_generated_patrols_are_free_segments():
    from worlds.robot import collides

    config = NavConfig(obstacles=ObstacleConfig(count=4, mode="patrol", radius=0.3), pool_size=8)
    env = NavigationEnv(config, maps="rects:16")
    moving = 0
    for seed in range(5):
        env.reset(seed=seed)
        ox, oy, ovx, ovy, _, patrol, ax, ay, bx, by, count = (a[0] for a in env.batch.disc_arrays)
        grid = env.batch.task(0).grid
        for k in range(count):
            assert patrol[k] and (ax[k], ay[k]) == (ox[k], oy[k])
            assert not collides(grid, ax[k], ay[k], bx[k], by[k], 0.3)
            moving += bool(np.hypot(ovx[k], ovy[k]) > 0)
    assert moving >= 15  # boxed-in discs stand still, most find a free direction

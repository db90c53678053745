"""Range rates (ObservationConfig.range_rate): each reading's change since the previous step, and
the `train --local` options that reach the trained task (range rate, frame stack, the disc mix)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.train_local import LocalTrainConfig, training_nav
from services.cli import main
from worlds.config import (
    LEARNING_NAV,
    NavConfig,
    ObservationConfig,
    RobotConfig,
    SensorConfig,
    check_observation,
    observation_settings,
    saved_observation,
)
from worlds.env import NavigationEnv
from worlds.maps import GridMap, Task
from worlds.obstacles import DiscObstacles
from worlds.perception import frame_layout, observation_bounds

STILL = RobotConfig(step=1e-9, trans_noise=0.0, rot_noise=0.0, heading_choices=1)
"""a robot that (nearly) stands still, facing +x"""
RATES = NavConfig(
    robot=STILL,
    sensors=SensorConfig(n_beams=8, n_rays=96, noise_std=0.0),
    observation=ObservationConfig(range_rate=True),
)
STRAIGHT = 2  # the middle of 5 actions: no turn


def open_task(width: int = 12) -> Task:
    """An empty map, 12 cells high, ``width`` wide, the robot at (1.5, 5.5)."""
    return Task(GridMap(np.zeros((12, width), dtype=bool)), (5, 1), (10, width - 2))


def rates(obs: np.ndarray, config: NavConfig = RATES) -> np.ndarray:
    start, stop = frame_layout(config)["range_rate"]
    return obs[start:stop]


def test_a_disc_approaching_gives_a_negative_rate_in_its_sector_only():
    env = NavigationEnv(RATES)
    disc = DiscObstacles([[5.5, 5.5]], [[-0.2, 0.0]], 0.3)  # 3.7 m ahead of the robot at (1.5, 5.5)
    obs, info = env.reset(seed=0, options={"task": open_task(), "obstacles": disc})
    assert info["pose"][2] == 0.0
    assert np.all(rates(obs) == 0.0)  # reset: nothing to compare with
    obs, *_ = env.step(STRAIGHT)
    ahead = 4  # sector 4 of 8 is centred on the heading (beam angles start at -pi)
    assert rates(obs)[ahead] == pytest.approx(-0.2, abs=0.01)  # the disc's speed (off-axis rays: not exact)
    others = np.delete(rates(obs), ahead)
    assert np.all(np.abs(others) < 1e-6)  # walls do not move and neither does the robot


def test_a_static_scene_gives_zero_rates_and_a_moving_robot_does_not():
    env = NavigationEnv(RATES)
    env.reset(seed=0, options={"task": open_task()})
    for _ in range(3):
        obs, *_ = env.step(STRAIGHT)
        assert np.all(np.abs(rates(obs)) < 1e-6)
    moving = NavConfig(robot=RobotConfig(trans_noise=0.0, rot_noise=0.0, heading_choices=1),
                       sensors=RATES.sensors, observation=RATES.observation)  # fmt: skip
    env = NavigationEnv(moving)
    env.reset(seed=0, options={"task": open_task(7)})  # walls 5.5 m ahead, 1.5 m behind
    obs, *_ = env.step(STRAIGHT)
    assert rates(obs, moving)[4] == pytest.approx(-0.5, abs=1e-3)  # the wall ahead came 0.5 m closer
    assert rates(obs, moving)[0] == pytest.approx(0.5, abs=1e-3)  # the wall behind went 0.5 m away


def test_rates_reset_to_zero_at_a_new_episode_and_stay_in_bounds():
    env = NavigationEnv(RATES)
    disc = DiscObstacles([[5.5, 5.5]], [[-0.2, 0.0]], 0.3)
    env.reset(seed=0, options={"task": open_task(), "obstacles": disc})
    env.step(STRAIGHT)
    obs, _ = env.reset(seed=1, options={"task": open_task(), "obstacles": disc})
    assert np.all(rates(obs) == 0.0)
    low, high = observation_bounds(RATES)
    start, stop = frame_layout(RATES)["range_rate"]
    assert np.all(low[start:stop] == -1.0) and np.all(high[start:stop] == 1.0)


def test_range_rate_is_validated_and_recorded_in_the_observation_settings():
    with pytest.raises(ValueError, match=r"observation\.range_rate"):
        ObservationConfig(range_rate=1)
    assert observation_settings(RATES)["observation.range_rate"] is True
    with pytest.raises(ValueError, match=r"observation\.range_rate=True"):
        check_observation(observation_settings(RATES), NavConfig(robot=STILL, sensors=RATES.sensors))
    # a policy saved before the option existed observes without it, and says so in an env with it
    before = {k: v for k, v in observation_settings(LEARNING_NAV).items() if k != "observation.range_rate"}
    assert saved_observation(before)["observation.range_rate"] is False
    with_rates = replace(LEARNING_NAV, observation=replace(LEARNING_NAV.observation, range_rate=True))
    with pytest.raises(ValueError, match=r"observation\.range_rate=False"):
        check_observation(saved_observation(before), with_rates)


def test_train_local_flags_reach_the_trained_task_and_the_saved_policy(tmp_path):
    # the disc mix applies to the nav `train --local` builds from its observation flags
    nav = training_nav(LocalTrainConfig(moving_discs=4), LEARNING_NAV)
    assert nav.obstacles.count == 4 and nav.obstacles.mix
    assert training_nav(LocalTrainConfig(moving_discs=0), LEARNING_NAV) is LEARNING_NAV
    assert main(["train", "--local", "--eval-dynamic-episodes", "-1"]) == 2
    out = tmp_path / "rr"
    argv = ["train", "--local", "--range-rate", "--frame-stack", "2", "--moving-discs", "2", "--steps", "400",
            "--envs", "4", "--out", str(out), "--eval-every", "200", "--eval-episodes", "3",
            "--eval-dynamic-episodes", "3", "--final-eval-episodes", "0", "--hidden-sizes", "16",
            "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    trained = json.loads((out / "summary.json").read_text())["obstacles"]
    assert trained["count"] == 2 and trained["mix"]  # what the env had, not only what was asked
    saved = json.loads((out / "config.json").read_text())["observation"]
    assert saved["observation.range_rate"] is True and saved["observation.frame_stack"] == 2
    curve = [json.loads(line) for line in (out / "curve.jsonl").read_text().splitlines()]
    assert any("eval_dynamic_success" in point for point in curve)
    policy = load_policy(out)  # evaluates in the observation it records
    result = evaluate(policy, [make_eval_set("unseen", 3), make_eval_set("dynamic", 3)])
    assert result.metrics["dynamic"].episodes == 3
    assert main(["evaluate", "--policy", str(out), "--episodes", "2", "--maps", "dynamic"]) == 0

"""Where the astar and file demonstrations come from, and the world the astar and human ones use."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from agents.demo_observation import load_demos_for
from agents.demos import Demo, load_demos
from agents.planning.demonstrate import record_episode
from agents.planning.expert import Expert
from services.demonstrator.config import DemonstratorConfig
from worlds.config import OBSERVATIONS, NavConfig, ObstacleConfig
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome


def nav_config(config: DemonstratorConfig) -> NavConfig:
    """The world the learner's policies see (``config.observation``, one of
    :data:`worlds.config.OBSERVATIONS`) with ``config.obstacles`` moving discs."""
    return replace(OBSERVATIONS[config.observation], obstacles=ObstacleConfig(count=config.obstacles))


def expert_episodes(config: DemonstratorConfig, stop: threading.Event) -> Iterator[Demo]:
    """Expert demonstrations, one per ``1 / rate`` seconds, until ``stop`` (failures skipped unless kept)."""
    nav = nav_config(config)
    env = NavigationEnv(nav, maps=config.maps)
    expert = Expert(nav)
    rng = np.random.default_rng([config.seed, 1013])
    index = 0
    next_time = time.monotonic()
    while not stop.is_set():
        demo, _ = record_episode(env, expert, config.seed + index, config.noise, rng)
        index += 1
        if config.keep_failures or demo.metadata["outcome"] == Outcome.GOAL:
            yield demo
        if config.rate > 0:
            next_time += 1.0 / config.rate
            stop.wait(max(0.0, next_time - time.monotonic()))


def check_file(config: DemonstratorConfig) -> None:
    """A DemoFormatError unless ``config.file`` loads and was recorded in the learner's observation
    (``config.observation``): the learner would drop every batch of another width."""
    load_demos_for(config.file, nav_config(config))


def file_episodes(config: DemonstratorConfig) -> Iterator[Demo]:
    for demo in load_demos(config.file):
        if config.keep_failures or demo.metadata["outcome"] == Outcome.GOAL:
            yield demo

"""Moving-disc mix (ObstacleConfig.mix): each episode draws its disc count from 0..count."""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from worlds.config import LEARNING_NAV, ObstacleConfig, with_moving_discs
from worlds.vector_env import NavigationVectorEnv


def disc_counts(nav, episodes: int = 120) -> Counter:
    """Disc counts of the episodes that start after an autoreset (random actions, 8 robots)."""
    env = NavigationVectorEnv(8, config=nav, seed=0)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    counts: Counter = Counter()
    while sum(counts.values()) < episodes:
        _, _, terminated, truncated, _ = env.step(rng.integers(0, env.single_action_space.n, 8))
        for i in np.flatnonzero(terminated | truncated):
            counts[int(env.batch.disc_arrays[10][i])] += 1
    env.close()
    return counts


def test_mix_draws_every_count_from_zero_to_the_maximum():
    counts = disc_counts(with_moving_discs(LEARNING_NAV, 3))
    assert set(counts) == {0, 1, 2, 3}
    assert min(counts.values()) >= 15  # roughly uniform: 120 episodes over 4 counts


def test_without_mix_the_count_is_fixed_and_zero_means_unchanged():
    assert with_moving_discs(LEARNING_NAV, 0) is LEARNING_NAV
    fixed = replace(LEARNING_NAV, obstacles=ObstacleConfig(count=2))
    assert set(disc_counts(fixed, 40)) == {2}
    with pytest.raises(ValueError, match="moving discs"):
        with_moving_discs(LEARNING_NAV, -1)

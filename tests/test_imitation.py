"""Behaviour cloning: dataset extraction, split, training, and a learned policy far above random."""

from __future__ import annotations

import numpy as np
import pytest

from agents.demos import make_demo
from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.policies import load_policy
from agents.imitation.config import ImitationConfig
from agents.imitation.train import extract_dataset, save_trained, split_episodes, train_policy
from agents.planning.demonstrate import generate_demos
from worlds.config import NavConfig
from worlds.generators import generate_task

TOY_OBS = 11  # the width of the 8-beam observation a policy saved without observation settings reads


def _toy_demos(n: int, rng: np.random.Generator) -> list:
    """Synthetic episodes whose correct action is a function of the observation."""
    task = generate_task("rects", 8, 8, 0)
    demos = []
    for _ in range(n):
        steps = 12
        obs = rng.uniform(-1, 1, (steps + 1, TOY_OBS)).astype(np.float32)
        actions = (obs[:-1, 0] > 0).astype(int) + 2 * (obs[:-1, 1] > 0)
        demos.append(make_demo(obs, actions, np.zeros(steps), np.zeros(steps), np.zeros(steps),
                               np.zeros((steps + 1, 3)), task, "file", None, 0.0, 1))  # fmt: skip
    return demos


def test_split_and_extraction():
    train, val = split_episodes(10, 0.2, seed=0)
    assert len(val) == 2 and len(train) == 8 and not set(train) & set(val)
    assert np.array_equal(split_episodes(10, 0.2, seed=0)[1], val)
    with pytest.raises(ValueError):
        split_episodes(1, 0.2, seed=0)
    demos = _toy_demos(3, np.random.default_rng(0))
    x, y = extract_dataset(demos)
    assert x.shape == (36, TOY_OBS) and y.shape == (36,)
    np.testing.assert_array_equal(x[:12], demos[0].observations[:-1])


def test_training_learns_a_separable_rule_and_stops_early(tmp_path):
    demos = _toy_demos(60, np.random.default_rng(1))
    config = ImitationConfig(hidden_sizes=(32,), max_epochs=300, patience=5, lr=3e-3, seed=3)
    result = train_policy(demos, config, n_actions=4)
    assert result.best["val_accuracy"] > 0.9
    assert len(result.history) < config.max_epochs  # early stopping kicked in
    assert result.best_epoch == int(np.argmin([r["val_loss"] for r in result.history]))
    again = train_policy(demos, config, n_actions=4)  # seeded: same run
    assert again.history == result.history
    policy = load_policy(save_trained(tmp_path / "p", result, config))
    obs = np.random.default_rng(2).uniform(-1, 1, (100, TOY_OBS)).astype(np.float32)
    np.testing.assert_array_equal(policy(obs), result.policy()(obs))


@pytest.mark.slow
def test_learned_policy_beats_random_on_unseen_maps():
    config = NavConfig(pool_size=64)
    demos, _ = generate_demos("rects:12", 400, seed=0, noise=0.3, config=config)
    imitation = ImitationConfig(hidden_sizes=(64, 64), max_epochs=60, patience=8)
    policy = train_policy(demos, imitation, n_actions=config.robot.n_actions).policy()
    eval_set = make_eval_set("unseen", 60, seed=0, size=12, families=("rects",))
    rng = np.random.default_rng(0)
    learned = evaluate(policy, eval_set, config).metrics["unseen"]
    random = evaluate(lambda obs: rng.integers(0, 5, len(obs)), eval_set, config).metrics["unseen"]
    print(
        f"unseen rects:12 success: learned {learned.success.value:.1%} "
        f"[{learned.success.low:.1%}, {learned.success.high:.1%}], random {random.success.value:.1%}, "
        f"SPL {learned.spl:.2f}, path ratio {learned.path_ratio:.3f}"
    )
    assert learned.success.value >= random.success.value + 0.25
    assert learned.success.low > random.success.high  # the intervals do not overlap

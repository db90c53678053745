"""Replay insert / sample / priority update through the NNQL learner (TorchRL buffers)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.ratelimit import RateLimiter
from agents.nnql.transitions import transitions_to_tensordict

OBS_DIM, N_ACTIONS = 6, 3


def random_batch(rng: np.random.Generator, n: int, next_action: bool = False) -> dict[str, np.ndarray]:
    batch = {
        "obs": rng.random((n, OBS_DIM), dtype=np.float32),
        "action": rng.integers(0, N_ACTIONS, n),
        "reward": rng.standard_normal(n).astype(np.float32),
        "next_obs": rng.random((n, OBS_DIM), dtype=np.float32),
        "terminated": rng.random(n) < 0.2,
        "truncated": rng.random(n) < 0.1,
    }
    if next_action:
        batch["next_action"] = rng.integers(0, N_ACTIONS, n)
    return batch


def small_config(**overrides) -> NNQLConfig:
    base = dict(hidden_sizes=(16,), batch_size=32, replay_capacity=500, learning_starts=64, utd_ratio=0.25)
    base.update(overrides)
    return NNQLConfig(**base)


def test_torchrl_segment_tree_extension_loads():
    # The prioritized sampler needs torchrl's C++ extension, which loads only with the pinned torch.
    from torchrl._torchrl import SumSegmentTreeFp32  # noqa: F401


def test_flat_batch_becomes_torchrl_layout():
    batch = random_batch(np.random.default_rng(0), 10)
    td = transitions_to_tensordict(batch, OBS_DIM)
    assert td.batch_size == torch.Size([10])
    assert td["next", "reward"].shape == (10, 1)
    assert td["action"].dtype == torch.int64
    expected_done = batch["terminated"] | batch["truncated"]
    assert np.array_equal(td["next", "done"].squeeze(-1).numpy(), expected_done)
    np.testing.assert_array_equal(td["next", "observation"].numpy(), batch["next_obs"])
    with pytest.raises(ValueError, match="observations"):
        transitions_to_tensordict({**batch, "obs": batch["obs"][:, :3]}, OBS_DIM)
    with pytest.raises(KeyError, match="reward"):
        transitions_to_tensordict({k: v for k, v in batch.items() if k != "reward"}, OBS_DIM)


def test_insert_wraps_at_capacity_and_sample_has_batch_size():
    learner = NNQLLearner(small_config(replay_capacity=100), OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(1)
    for _ in range(3):
        assert learner.add(random_batch(rng, 40)) == 40
    assert len(learner.replay) == 100
    assert learner.transitions_added == 120
    sample = learner.replay.sample()
    assert sample.batch_size == torch.Size([32])
    assert set(sample.keys()) >= {"observation", "action", "next", "index"}


def test_update_to_data_ratio_bounds_updates():
    """The pacing of train --local: the service's RateLimiter with no slack around the learner."""
    config = small_config(learning_starts=64, utd_ratio=0.25)
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    limiter = RateLimiter(config.utd_ratio, max(config.learning_starts, config.batch_size), tolerance=1.0)
    rng = np.random.default_rng(2)
    limiter.inserted(learner.add(random_batch(rng, 32)))
    assert limiter.updates_allowed(len(learner.replay)) == 0  # below learning_starts
    limiter.inserted(learner.add(random_batch(rng, 40)))  # 72 >= 64: 8 past the start * 0.25 + 1
    due = limiter.updates_allowed(len(learner.replay))
    assert due == 3
    learner.update(due)
    limiter.updated(due)
    assert learner.updates == 3 and limiter.updates_allowed(len(learner.replay)) == 0
    limiter.inserted(learner.add(random_batch(rng, 40)))
    assert limiter.updates_allowed(len(learner.replay)) == 10  # then one update per 4 transitions


def test_prioritized_sampler_follows_td_errors():
    learner = NNQLLearner(
        small_config(prioritized=True, priority_alpha=1.0, priority_beta=1.0), OBS_DIM, N_ACTIONS
    )
    learner.add(random_batch(np.random.default_rng(3), 200))
    sample = learner.replay.sample()
    assert "priority_weight" in sample
    # one transition gets a huge TD error, every other a tiny one
    everything = torch.arange(200)
    priorities = torch.full((200,), 1e-6)
    priorities[17] = 1e3
    learner.replay.update_priority(everything, priorities)
    drawn = torch.cat([learner.replay.sample()["index"] for _ in range(8)])
    assert (drawn == 17).float().mean() > 0.95
    # an update writes fresh TD errors back as priorities
    before = learner.replay._sampler._sum_tree.query(0, 200)
    metrics = learner.update()
    after = learner.replay._sampler._sum_tree.query(0, 200)
    assert after != pytest.approx(before)
    assert metrics["losses/td_error"] > 0


def test_uniform_sampler_has_no_priorities():
    learner = NNQLLearner(small_config(), OBS_DIM, N_ACTIONS)
    learner.add(random_batch(np.random.default_rng(4), 100))
    assert "priority_weight" not in learner.replay.sample()


def test_sarsa_learner_requires_next_action():
    learner = NNQLLearner(small_config(sarsa=True, double_q=False), OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(5)
    with pytest.raises(KeyError, match="next_action"):
        learner.add(random_batch(rng, 8))
    learner.add(random_batch(rng, 100, next_action=True))
    assert np.isfinite(learner.update()["losses/td_loss"])


def test_message_objects_and_tensordicts_are_accepted():
    from types import SimpleNamespace

    batch = random_batch(np.random.default_rng(6), 12)
    message = SimpleNamespace(actor="a1", policy_version=3, **batch)  # the shape of a TransitionBatch
    from_message = transitions_to_tensordict(message, OBS_DIM)
    assert (from_message == transitions_to_tensordict(batch, OBS_DIM)).all()
    assert (transitions_to_tensordict(from_message, OBS_DIM) == from_message).all()

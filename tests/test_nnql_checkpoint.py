"""Checkpoint -> load equality: weights, target network, optimiser, counters, replay contents."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from tests.test_nnql_replay import N_ACTIONS, OBS_DIM, random_batch


def assert_nested_equal(a, b):
    if isinstance(a, torch.Tensor):
        assert torch.equal(a, b)
    elif isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_nested_equal(a[key], b[key])
    elif isinstance(a, list | tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            assert_nested_equal(x, y)
    else:
        assert a == b


@pytest.mark.parametrize("prioritized", [False, True])
def test_checkpoint_roundtrip(tmp_path, prioritized):
    config = NNQLConfig(
        hidden_sizes=(16, 16), batch_size=32, replay_capacity=300, learning_starts=64, prioritized=prioritized
    )
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(0)
    for _ in range(4):
        learner.add(random_batch(rng, 50))
        if learner.ready():
            learner.update(4)
    assert learner.updates > 0
    path = learner.save_checkpoint(tmp_path / "ckpt")
    assert sorted(p.name for p in path.iterdir()) == ["learner.pt", "policy", "replay"]

    restored = NNQLLearner.from_checkpoint(path)
    assert (restored.updates, restored.transitions_added) == (learner.updates, learner.transitions_added)
    assert_nested_equal(restored.loss.state_dict(), learner.loss.state_dict())  # online + target
    assert_nested_equal(restored.optimizer.state_dict(), learner.optimizer.state_dict())
    assert restored.target_updater.state_dict() == learner.target_updater.state_dict()
    for name, value in learner.get_weights().items():
        np.testing.assert_array_equal(restored.get_weights()[name], value)
    assert len(restored.replay) == len(learner.replay) == 200
    assert (restored.replay[:] == learner.replay[:]).all()
    if prioritized:
        tree, restored_tree = learner.replay._sampler._sum_tree, restored.replay._sampler._sum_tree
        assert [tree[i] for i in range(200)] == [restored_tree[i] for i in range(200)]

    # both continue identically: same samples, same updates
    batch = random_batch(rng, 50)
    learner.add(batch)
    restored.add(batch)
    metrics = learner.update()
    assert restored.update() == metrics
    # a second save replaces the first atomically
    learner.save_checkpoint(path)
    assert NNQLLearner.from_checkpoint(path).updates == learner.updates


def test_set_weights_syncs_target(tmp_path):
    config = NNQLConfig(hidden_sizes=(8,), batch_size=16, learning_starts=16)
    a, b = (
        NNQLLearner(config, OBS_DIM, N_ACTIONS),
        NNQLLearner(NNQLConfig(hidden_sizes=(8,), seed=3), OBS_DIM, N_ACTIONS),
    )
    b.set_weights(a.get_weights())
    obs = np.random.default_rng(1).random((5, OBS_DIM), dtype=np.float32)
    # the default dueling head travels folded and comes back unfolded: equal Q up to float rounding
    np.testing.assert_allclose(a.q_values(obs), b.q_values(obs), rtol=1e-5, atol=1e-6)
    target = {k: v for k, v in b.loss.state_dict().items() if k.startswith("target_")}
    online = {k.replace("target_", ""): v for k, v in target.items()}
    for key, value in online.items():
        assert torch.equal(b.loss.state_dict()[key], value)
    policy = a.policy()
    np.testing.assert_allclose(policy.q_values(obs), a.q_values(obs), rtol=1e-5, atol=1e-6)
    a.save_policy(tmp_path / "p")
    assert (tmp_path / "p" / "model.safetensors").is_file()

"""The lean update path (agents/nnql/lean.py) against TorchRL's loss module and updater.

Two learners built alike hold the same networks, replay and sampler state. One runs
``update(n)`` (plain tensors, several batches per sampler call); the other draws the same indices
from its own sampler and runs ``train_step`` (DQNLoss or SarsaLoss + SoftUpdate or HardUpdate)
on the TensorDicts the replay stores there. Every parameter, the target network, the optimiser
state and (prioritized) the priorities must agree to float tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.nnql.learner import NNQLLearner
from tests.test_nnql_replay import N_ACTIONS, OBS_DIM, random_batch, small_config

VARIANTS = {
    "double-soft-huber": {},
    "prioritized": {"prioritized": True},
    "hard-target-l2": {"target_update": "hard", "target_period": 3, "loss_function": "l2"},
    "max-q-l1": {"double_q": False, "loss_function": "l1"},
    "sarsa": {"sarsa": True, "double_q": False},
    "no-clip": {"grad_clip": 0.0},
}


def twins(overrides: dict) -> tuple[NNQLLearner, NNQLLearner]:
    config = small_config(batch_size=32, replay_capacity=400, learning_starts=64, **overrides)
    lean, plain = NNQLLearner(config, OBS_DIM, N_ACTIONS), NNQLLearner(config, OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(7)
    for _ in range(3):
        batch = random_batch(rng, 100, next_action=config.sarsa)
        lean.add(batch)
        plain.add(batch)
    return lean, plain


def plain_updates(learner: NNQLLearner, n: int) -> None:
    """What ``update(n)`` does, one TorchRL ``train_step`` per batch, from the same sampler draws."""
    size, replay = learner.config.batch_size, learner.replay
    if learner.config.prioritized:
        for _ in range(n):
            index, info = replay.sampler.sample(replay.storage, size)
            td = replay.storage.get(index)
            td.set("index", index)
            td.set("priority_weight", info["priority_weight"])
            learner.train_step(td)  # writes the priorities back itself
    else:
        index, _ = replay.sampler.sample(replay.storage, n * size)
        for i in range(n):
            learner.train_step(replay.storage.get(index[i * size : (i + 1) * size]))
    learner.update_credit = max(learner.update_credit - n, 0.0)


def assert_same_state(a: NNQLLearner, b: NNQLLearner) -> None:
    state_a, state_b = a.loss.state_dict(), b.loss.state_dict()  # online and target networks
    assert state_a.keys() == state_b.keys()
    assert any(key.startswith("target_") for key in state_a)
    for key in state_a:
        torch.testing.assert_close(state_a[key], state_b[key], rtol=1e-5, atol=1e-6, msg=key)
    opt_a, opt_b = a.optimizer.state_dict()["state"], b.optimizer.state_dict()["state"]
    assert opt_a.keys() == opt_b.keys()
    for key in opt_a:
        for name in ("exp_avg", "exp_avg_sq", "step"):
            torch.testing.assert_close(opt_a[key][name], opt_b[key][name], rtol=1e-5, atol=1e-7)
    assert a.target_updater.state_dict() == b.target_updater.state_dict()
    assert (a.updates, a.update_credit) == (b.updates, b.update_credit)


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_lean_update_matches_torchrl_path(variant):
    lean, plain = twins(VARIANTS[variant])
    assert_same_state(lean, plain)
    for n in (1, 5, 1, 7):
        before = [p.detach().clone() for p in lean.network.parameters()]
        metrics = lean.update(n)
        plain_updates(plain, n)
        assert metrics["charts/version"] == lean.version
        assert all(np.isfinite(list(metrics.values())))
        assert any(not torch.equal(p, q) for p, q in zip(before, lean.network.parameters(), strict=True))
        assert_same_state(lean, plain)
    if lean.config.prioritized:
        tree_a, tree_b = lean.replay.sampler._sum_tree, plain.replay.sampler._sum_tree
        np.testing.assert_allclose(
            [tree_a[i] for i in range(len(lean.replay))],
            [tree_b[i] for i in range(len(plain.replay))],
            rtol=1e-4,
        )
    # the TorchRL path continues from the lean one: its loss module sees the same target network
    td = lean.replay.storage.get(torch.arange(64))
    torch.testing.assert_close(
        lean.loss(td.clone())["loss"], plain.loss(td.clone())["loss"], rtol=1e-5, atol=1e-6
    )


def test_target_network_shares_the_loss_modules_storage():
    lean, _ = twins({})
    target = lean.lean.target
    for param, shared in zip(
        target.parameters(), lean.loss.target_value_network_params.values(True, True), strict=True
    ):
        assert param.data_ptr() == shared.data_ptr()
        assert not param.requires_grad
    lean.set_weights({k: v + 1.0 for k, v in lean.get_weights().items()})  # sync_target copies in place
    obs = torch.rand(4, OBS_DIM)
    torch.testing.assert_close(target(obs), lean.network(obs))


def test_update_counts_and_validates():
    lean, _ = twins({})
    credit = lean.update_credit
    lean.update(3)
    assert lean.version == 3 and lean.update_credit == max(credit - 3, 0.0)
    with pytest.raises(ValueError, match="n must be >= 1"):
        lean.update(0)

"""TD targets: the pure function, and TorchRL's DQNLoss / our SarsaLoss agreeing with it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.nnql.losses import td_target
from agents.nnql.networks import QNetwork
from agents.nnql.transitions import transitions_to_tensordict

OBS_DIM, N_ACTIONS, GAMMA = 4, 3, 0.9


def test_td_target_by_hand():
    reward = torch.tensor([1.0, -1.0, 0.5])
    terminated = torch.tensor([False, True, False])
    next_value = torch.tensor([2.0, 10.0, -4.0])
    expected = torch.tensor([1.0 + 0.9 * 2.0, -1.0, 0.5 - 0.9 * 4.0])
    torch.testing.assert_close(td_target(reward, terminated, next_value, 0.9), expected)


def make_learner(**overrides) -> NNQLLearner:
    config = NNQLConfig(hidden_sizes=(8,), batch_size=16, learning_starts=16, gamma=GAMMA, **overrides)
    return NNQLLearner(config, OBS_DIM, N_ACTIONS)


def make_batch(n: int = 16, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "obs": rng.standard_normal((n, OBS_DIM)).astype(np.float32),
        "action": rng.integers(0, N_ACTIONS, n),
        "reward": rng.standard_normal(n).astype(np.float32),
        "next_obs": rng.standard_normal((n, OBS_DIM)).astype(np.float32),
        "terminated": np.arange(n) % 3 == 0,
        "truncated": np.arange(n) % 5 == 0,  # truncated transitions still bootstrap
        "next_action": rng.integers(0, N_ACTIONS, n),
    }


def perturb_target(learner: NNQLLearner) -> None:
    with torch.no_grad():
        for param in learner.loss.target_value_network_params.values(True, True):
            param.add_(0.5 * torch.randn_like(param))


def q_online_and_target(learner: NNQLLearner, obs: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    obs_t = torch.as_tensor(obs)
    online = learner.network(obs_t).detach()
    target_net = QNetwork.from_architecture(learner.architecture)  # dueling or plain, as trained
    target_state = {
        name.split("module.0.module.")[-1]: value
        for name, value in learner.loss.state_dict().items()
        if name.startswith("target_value_network_params")
    }
    target_net.load_state_dict(target_state)
    return online, target_net(obs_t).detach()


def squared_td_errors(learner: NNQLLearner, batch: dict[str, np.ndarray]) -> torch.Tensor:
    td = transitions_to_tensordict(batch, OBS_DIM)
    learner.loss(td)
    return td["td_error"].squeeze(-1)


def expected_errors(learner, batch, next_value_fn) -> torch.Tensor:
    q_now, _ = q_online_and_target(learner, batch["obs"])
    q_next_online, q_next_target = q_online_and_target(learner, batch["next_obs"])
    predicted = q_now.gather(1, torch.as_tensor(batch["action"]).view(-1, 1)).squeeze(1)
    next_value = next_value_fn(q_next_online, q_next_target)
    target = td_target(
        torch.as_tensor(batch["reward"]), torch.as_tensor(batch["terminated"]), next_value, GAMMA
    )
    return (predicted - target) ** 2


def test_dqn_loss_is_q_learning_with_target_network():
    learner = make_learner(double_q=False)
    perturb_target(learner)
    batch = make_batch()
    expected = expected_errors(learner, batch, lambda online, target: target.max(1).values)
    torch.testing.assert_close(squared_td_errors(learner, batch), expected)


def test_double_dqn_picks_with_online_values_with_target():
    learner = make_learner(double_q=True)
    perturb_target(learner)
    batch = make_batch(seed=1)

    def double(online, target):
        return target.gather(1, online.argmax(1, keepdim=True)).squeeze(1)

    expected = expected_errors(learner, batch, double)
    torch.testing.assert_close(squared_td_errors(learner, batch), expected)
    plain = expected_errors(learner, batch, lambda online, target: target.max(1).values)
    assert not torch.allclose(expected, plain)  # the batch really tells the two apart


def test_sarsa_loss_bootstraps_on_the_taken_action():
    learner = make_learner(sarsa=True, double_q=False)
    perturb_target(learner)
    batch = make_batch(seed=2)
    next_action = torch.as_tensor(batch["next_action"]).view(-1, 1)
    expected = expected_errors(
        learner, batch, lambda online, target: target.gather(1, next_action).squeeze(1)
    )
    torch.testing.assert_close(squared_td_errors(learner, batch), expected)


def test_config_rejects_bad_values():
    with pytest.raises(ValueError, match="exploration"):
        NNQLConfig(exploration="softmax")
    with pytest.raises(ValueError, match="sarsa"):
        NNQLConfig(sarsa=True, double_q=True)
    with pytest.raises(ValueError, match="unknown field"):
        NNQLConfig.from_dict({"learning_rate": 1e-3})
    config = NNQLConfig(hidden_sizes=[32, 16])
    assert NNQLConfig.from_dict(config.to_dict()) == config

"""The numpy NNQL policy: same Q-values as the torch network, Boltzmann/epsilon/greedy behaviour, files."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.nnql.config import NNQLConfig
from agents.nnql.networks import QNetwork
from agents.nnql.policy import (
    NNQLPolicy,
    boltzmann_probabilities,
    epsilon_at,
    load_policy_dir,
    temperature_at,
)
from protocols.messages import ExplorationSchedule

ARCH = {"obs_dim": 5, "n_actions": 4, "hidden_sizes": [12, 7], "activation": "relu"}


def weights_of(network: QNetwork) -> dict[str, np.ndarray]:
    return {name: value.detach().numpy().copy() for name, value in network.state_dict().items()}


def fixed_q_policy(q_row: list[float], **kwargs) -> NNQLPolicy:
    """A policy whose Q-values are q_row for every observation (zero weights, bias = q_row)."""
    arch = {"obs_dim": 2, "n_actions": len(q_row), "hidden_sizes": [3], "activation": "relu"}
    weights = {
        "0.weight": np.zeros((3, 2), np.float32),
        "0.bias": np.zeros(3, np.float32),
        "2.weight": np.zeros((len(q_row), 3), np.float32),
        "2.bias": np.asarray(q_row, np.float32),
    }
    return NNQLPolicy(weights, arch, **kwargs)


@pytest.mark.parametrize("activation", ["relu", "tanh", "elu"])
def test_numpy_forward_matches_torch(activation):
    torch.manual_seed(0)
    network = QNetwork.from_architecture({**ARCH, "activation": activation})
    policy = NNQLPolicy(weights_of(network), network.architecture)
    obs = np.random.default_rng(0).standard_normal((9, 5)).astype(np.float32)
    expected = network(torch.as_tensor(obs)).detach().numpy()
    np.testing.assert_allclose(policy.q_values(obs), expected, rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(policy(obs), expected.argmax(1))


def test_boltzmann_probabilities():
    probs = boltzmann_probabilities(np.array([[0.0, np.log(3.0)], [1000.0, 1000.0]]), 1.0)
    np.testing.assert_allclose(probs, [[0.25, 0.75], [0.5, 0.5]])
    cold = boltzmann_probabilities(np.array([[0.0, 0.1]]), 1e-3)
    assert cold[0, 1] > 0.999
    with pytest.raises(ValueError):
        boltzmann_probabilities(np.zeros((1, 2)), 0.0)


def test_boltzmann_policy_samples_softmax_frequencies():
    q_row = [0.0, 0.5, 1.0]
    policy = fixed_q_policy(q_row, mode="boltzmann", temperature=0.5, seed=0)
    actions = policy(np.zeros((20000, 2), np.float32))
    freq = np.bincount(actions, minlength=3) / len(actions)
    np.testing.assert_allclose(freq, boltzmann_probabilities(np.array(q_row), 0.5), atol=0.015)


def test_greedy_and_epsilon_modes():
    obs = np.zeros((5000, 2), np.float32)
    greedy = fixed_q_policy([0.0, 2.0, 1.0], mode="greedy")
    assert set(greedy(obs)) == {1}
    eps = fixed_q_policy([0.0, 2.0, 1.0], mode="epsilon", epsilon=0.3, seed=1)
    freq = np.bincount(eps(obs), minlength=3) / len(obs)
    np.testing.assert_allclose(freq, [0.1, 0.8, 0.1], atol=0.02)
    assert set(eps.greedy()(obs)) == {1}


def test_exploration_schedules():
    config = NNQLConfig(temperature_start=1.0, temperature_end=0.01, temperature_decay_updates=100)
    assert temperature_at(config, 0) == pytest.approx(1.0)
    assert temperature_at(config, 50) == pytest.approx(0.1)  # geometric halfway
    assert temperature_at(config, 10_000) == pytest.approx(0.01)
    config = NNQLConfig(exploration="epsilon", epsilon_start=1.0, epsilon_end=0.1, epsilon_decay_updates=10)
    assert epsilon_at(config, 5) == pytest.approx(0.55)
    policy = fixed_q_policy([0.0, 1.0])
    policy.explore_as(config, 10)
    assert (policy.mode, policy.epsilon) == ("epsilon", pytest.approx(0.1))


def test_an_actor_explores_as_the_schedule_in_the_weights_says():
    """The ExplorationSchedule a WeightsUpdate carries gives the policy the config's exploration."""
    config = NNQLConfig(exploration="epsilon", epsilon_start=1.0, epsilon_end=0.1, epsilon_decay_updates=10)
    from_config, from_wire = fixed_q_policy([0.0, 1.0]), fixed_q_policy([0.0, 1.0])
    from_config.explore_as(config, 5)
    from_wire.explore_as(ExplorationSchedule.of(config), 5)
    assert (from_wire.mode, from_wire.epsilon, from_wire.temperature) == (
        from_config.mode,
        from_config.epsilon,
        from_config.temperature,
    )
    nirl = ExplorationSchedule(  # NIRL sends no epsilon: the policy keeps its own
        exploration="boltzmann", temperature_start=0.5, temperature_end=0.05, temperature_decay_updates=100
    )
    from_wire.explore_as(nirl, 100)
    assert (from_wire.mode, from_wire.temperature, from_wire.epsilon) == (
        "boltzmann",
        pytest.approx(0.05),
        from_config.epsilon,
    )


def test_save_load_roundtrip_and_bad_weights(tmp_path):
    torch.manual_seed(1)
    network = QNetwork.from_architecture(ARCH)
    policy = NNQLPolicy(weights_of(network), ARCH, version=42)
    policy.save(tmp_path / "p", note="test")
    weights, config = load_policy_dir(tmp_path / "p")
    assert config["model"] == "nnql" and config["version"] == 42 and config["architecture"] == ARCH
    loaded = NNQLPolicy.load(tmp_path / "p")
    obs = np.random.default_rng(2).standard_normal((4, 5)).astype(np.float32)
    np.testing.assert_array_equal(loaded.q_values(obs), policy.q_values(obs))
    assert loaded.version == 42
    with pytest.raises(ValueError, match="architecture"):
        NNQLPolicy(
            {k: v for k, v in weights.items() if k != "4.weight"} | {"4.weight": np.zeros((4, 3))}, ARCH
        )
    with pytest.raises(ValueError, match="observations"):
        loaded.q_values(np.zeros((3, 4), np.float32))
    with pytest.raises(FileNotFoundError):
        NNQLPolicy.load(tmp_path / "missing")

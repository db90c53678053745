"""The Q-network: a feature-based function approximator Q(s, .) (thesis ch. 4).

An MLP (TorchRL's ``MLP``) maps the observation - normalised range readings plus
goal distance and bearing - to one Q-value per discrete action. Its architecture is
a small JSON-able dict so weights can travel without the class (see policy.py).
"""

from __future__ import annotations

from typing import Any

from torch import nn
from torchrl.data import Categorical
from torchrl.modules import MLP, QValueActor

from agents.nnql.config import NNQLConfig

ACTIVATIONS: dict[str, type[nn.Module]] = {"relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU}
OBSERVATION_KEY = "observation"


class QNetwork(MLP):
    """MLP from observations (..., obs_dim) to Q-values (..., n_actions).

    Parameters are named ``"<layer index>.weight"`` / ``"<layer index>.bias"`` (the
    ``nn.Sequential`` layout), linear layers at even indices with the activation
    between them; ``policy.q_values_numpy`` relies on that layout.
    """

    def __init__(
        self, obs_dim: int, n_actions: int, hidden_sizes: list[int] | tuple[int, ...], activation: str
    ):
        if activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {activation!r}; expected one of {sorted(ACTIVATIONS)}")
        super().__init__(
            in_features=int(obs_dim),
            out_features=int(n_actions),
            num_cells=[int(h) for h in hidden_sizes],
            activation_class=ACTIVATIONS[activation],
        )
        self.architecture = {
            "obs_dim": int(obs_dim),
            "n_actions": int(n_actions),
            "hidden_sizes": [int(h) for h in hidden_sizes],
            "activation": activation,
        }

    @classmethod
    def from_config(cls, config: NNQLConfig, obs_dim: int, n_actions: int) -> QNetwork:
        return cls(obs_dim, n_actions, config.hidden_sizes, config.activation)

    @classmethod
    def from_architecture(cls, architecture: dict[str, Any]) -> QNetwork:
        return cls(
            architecture["obs_dim"],
            architecture["n_actions"],
            architecture["hidden_sizes"],
            architecture["activation"],
        )


def make_q_actor(network: QNetwork) -> QValueActor:
    """Wrap the network as TorchRL's QValueActor (reads "observation", writes action/action_value)."""
    spec = Categorical(network.architecture["n_actions"])
    return QValueActor(network, in_keys=[OBSERVATION_KEY], spec=spec)

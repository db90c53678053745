"""The Q-network: a feature-based function approximator Q(s, .) (thesis ch. 4); network "mlp", and
the head every other variant ends in (agents.nnql.q_networks).

An MLP (TorchRL's ``MLP``) maps the observation - normalised range readings plus
goal distance and bearing - to one Q-value per discrete action. Its architecture is
a small JSON-able dict so weights can travel without the class (see policy.py).

With ``NNQLConfig.dueling`` the last layer is TorchRL's dueling head (``DuelingMlpDQNet``):
Q = V(h) + A(h) - mean_a A(h) over the last hidden layer h. That is linear in h, so
:func:`export_weights` folds value and advantage into one linear layer - the plain MLP
layout every actor, evaluator and policy file runs (``agents.mlp.mlp_forward``, the one
numpy forward) - and :func:`import_weights` unfolds it exactly. Its architecture dict has
``"dueling": true``; plain networks' dicts are unchanged, so older files and checkpoints load.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn
from torchrl.data import Categorical
from torchrl.modules import MLP, QValueActor
from torchrl.modules.models.models import DuelingMlpDQNet

from agents.mlp import ACTIVATION_NAMES
from agents.nnql.config import NNQLConfig

ACTIVATIONS: dict[str, type[nn.Module]] = dict(zip(ACTIVATION_NAMES, (nn.ReLU, nn.Tanh, nn.ELU), strict=True))
"""agents.mlp.ACTIVATION_NAMES' torch modules"""


def activation_class(name: str) -> type[nn.Module]:
    """The torch module of activation ``name``; ValueError naming the choices for another."""
    if name not in ACTIVATIONS:
        raise ValueError(f"unknown activation {name!r}; expected one of {sorted(ACTIVATIONS)}")
    return ACTIVATIONS[name]


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
        super().__init__(
            in_features=int(obs_dim),
            out_features=int(n_actions),
            num_cells=[int(h) for h in hidden_sizes],
            activation_class=activation_class(activation),
        )
        self.architecture = {
            "obs_dim": int(obs_dim),
            "n_actions": int(n_actions),
            "hidden_sizes": [int(h) for h in hidden_sizes],
            "activation": activation,
        }

    @classmethod
    def from_config(cls, config: NNQLConfig, obs_dim: int, n_actions: int) -> nn.Module:
        """The network the config asks for: this MLP, or a :class:`DuelingQNetwork`."""
        kind = DuelingQNetwork if config.dueling else cls
        return kind(obs_dim, n_actions, config.hidden_sizes, config.activation)

    @classmethod
    def from_architecture(cls, architecture: dict[str, Any]) -> nn.Module:
        kind = DuelingQNetwork if architecture.get("dueling", False) else cls
        return kind(
            architecture["obs_dim"],
            architecture["n_actions"],
            architecture["hidden_sizes"],
            architecture["activation"],
        )


class DuelingQNetwork(DuelingMlpDQNet):
    """Dueling Q-network: ``features`` (the MLP's hidden layers, last one activated) feeding a linear
    ``value`` (1) and ``advantage`` (n_actions) head, combined as V + A - mean(A)."""

    def __init__(
        self, obs_dim: int, n_actions: int, hidden_sizes: list[int] | tuple[int, ...], activation: str
    ):
        hidden = [int(h) for h in hidden_sizes]
        super().__init__(
            out_features=int(n_actions),
            mlp_kwargs_feature={
                "in_features": int(obs_dim),
                "num_cells": hidden[:-1],
                "out_features": hidden[-1],
                "activation_class": activation_class(activation),
                "activate_last_layer": True,
            },
            mlp_kwargs_output={"in_features": hidden[-1], "depth": 0},
        )
        self.architecture = {
            "obs_dim": int(obs_dim),
            "n_actions": int(n_actions),
            "hidden_sizes": hidden,
            "activation": activation,
            "dueling": True,
        }


def output_layer(hidden_sizes) -> int:
    """Index of the output layer in the plain MLP layout (``"<index>.weight"``): each hidden layer is a
    linear module followed by its activation."""
    return 2 * len(hidden_sizes)


def export_weights(network: nn.Module) -> dict[str, np.ndarray]:
    """The network's weights in the plain MLP layout (``"<index>.weight"``), float32 arrays.

    A dueling head's value (w_v, b_v) and advantage (W_a, b_a) layers become one layer
    W = W_a - mean_a W_a + w_v, b = b_a - mean_a b_a + b_v: the same Q for every input.
    """
    state = {name: t.detach().cpu().numpy().copy() for name, t in network.state_dict().items()}
    if not isinstance(network, DuelingQNetwork):
        return state
    weights = {
        name.removeprefix("features."): value for name, value in state.items() if name.startswith("features.")
    }
    last = output_layer(network.architecture["hidden_sizes"])
    w_a, b_a = state["advantage.0.weight"], state["advantage.0.bias"]
    w_v, b_v = state["value.0.weight"], state["value.0.bias"]
    weights[f"{last}.weight"] = (w_a - w_a.mean(axis=0, keepdims=True) + w_v).astype(np.float32)
    weights[f"{last}.bias"] = (b_a - b_a.mean() + b_v).astype(np.float32)
    return weights


def import_weights(network: nn.Module, weights: dict[str, Any]) -> None:
    """Load plain-layout weights (:func:`export_weights`'s) into ``network``; a dueling head gets the
    exact unfolding A = the folded layer, V = its mean over actions (so V + A - mean A = Q)."""
    device = next(network.parameters()).device
    state = {name: torch.as_tensor(np.asarray(value), device=device) for name, value in weights.items()}
    if isinstance(network, DuelingQNetwork):
        last = output_layer(network.architecture["hidden_sizes"])
        w, b = state.pop(f"{last}.weight"), state.pop(f"{last}.bias")
        state = {f"features.{name}": value for name, value in state.items()}
        state["advantage.0.weight"], state["advantage.0.bias"] = w, b
        state["value.0.weight"], state["value.0.bias"] = w.mean(0, keepdim=True), b.mean(0, keepdim=True)
    network.load_state_dict(state)


def make_q_actor(network: QNetwork) -> QValueActor:
    """Wrap the network as TorchRL's QValueActor (reads "observation", writes action/action_value)."""
    spec = Categorical(network.architecture["n_actions"])
    return QValueActor(network, in_keys=[OBSERVATION_KEY], spec=spec)

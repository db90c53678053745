"""The forward pass of a saved or received network, chosen by its architecture dict.

A plain MLP architecture (``obs_dim``, ``n_actions``, ``hidden_sizes``, ``activation``) runs in
numpy (:func:`agents.mlp.mlp_forward`), so an actor or evaluator of an MLP policy never loads
torch. An architecture with a ``patch`` entry is the CNN-over-the-own-map Q-network of
:mod:`agents.nnql.patch_network`, one with ``image`` the CNN over a Gymnasium env's image
(:mod:`agents.nnql.image_network`), one with ``local`` the action-local branch; each runs that very
torch module (the learner's forward, one
definition), without gradients. When that brings torch into the process (an actor, the evaluator,
``navlearn evaluate``), torch is held to one intra-op thread, as BLAS is there: a batch of a few
dozen observations gains nothing from more on 2 shared cores. A process that already runs torch
(the learner, ``train --local``) keeps its own setting.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np

from agents.mlp import check_layers, mlp_forward, mlp_layers

TORCH_ONLY = ("patch", "local", "image")
"""architecture entries of the Q-network variants that run in torch (agents.nnql.q_networks): the patch
CNN, the action-local branch, the image CNN"""


class Forward(Protocol):
    def __call__(self, obs: np.ndarray) -> np.ndarray: ...

    def weights(self) -> dict[str, np.ndarray]: ...

    def load(self, weights: Mapping[str, np.ndarray]) -> None: ...


class MLPForward:
    """numpy MLP: outputs (N, n_actions) of observations (N, obs_dim)."""

    def __init__(self, weights: Mapping[str, np.ndarray], architecture: Mapping[str, Any]):
        self.architecture = dict(architecture)
        self.activation = architecture["activation"]
        self.load(weights)

    def load(self, weights: Mapping[str, np.ndarray]) -> None:
        """Swap in new weights of the same architecture (shapes checked)."""
        self.layers = check_layers(mlp_layers(dict(weights)), self.architecture)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return mlp_forward(self.layers, self.activation, obs)

    def weights(self) -> dict[str, np.ndarray]:
        """A copy of the weights in ``nn.Sequential`` naming (``"0.weight"``, ``"0.bias"``, ...)."""
        out = {}
        for index, (weight, bias) in zip(range(0, 2 * len(self.layers), 2), self.layers, strict=True):
            out[f"{index}.weight"] = np.ascontiguousarray(weight.T)
            out[f"{index}.bias"] = bias.copy()
        return out


class TorchForward:
    """The learner's torch module rebuilt from the architecture dict, loaded with ``weights``."""

    def __init__(self, weights: Mapping[str, np.ndarray], architecture: Mapping[str, Any]):
        first = "torch" not in sys.modules
        import torch  # only policies with a CNN need torch; MLP actors start without it

        from agents.nnql.q_networks import network_from_architecture

        if first:
            torch.set_num_threads(1)

        self.torch = torch
        self.module = network_from_architecture(architecture).eval()
        self.load(weights)

    def load(self, weights: Mapping[str, np.ndarray]) -> None:
        """Swap in new weights of the same architecture (names and shapes checked)."""
        torch = self.torch
        state = {name: torch.as_tensor(np.array(value, dtype=np.float32)) for name, value in weights.items()}
        try:
            self.module.load_state_dict(state)
        except RuntimeError as exc:  # missing / unexpected names, wrong shapes
            raise ValueError(f"weights do not fit the architecture: {exc}") from None

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        with self.torch.inference_mode():
            return self.module(self.torch.as_tensor(np.asarray(obs, dtype=np.float32))).numpy()

    def weights(self) -> dict[str, np.ndarray]:
        return {name: t.detach().numpy().copy() for name, t in self.module.state_dict().items()}


def network_forward(weights: Mapping[str, np.ndarray], architecture: Mapping[str, Any]) -> Forward:
    """The forward pass of ``architecture`` with ``weights``; ValueError when they do not fit."""
    if any(key in architecture for key in TORCH_ONLY):
        return TorchForward(weights, architecture)
    return MLPForward(weights, architecture)

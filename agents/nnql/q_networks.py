"""The Q-network variants of NNQL and the one place that picks among them.

=========  ===========================================  ===============================
network    module (its own config)                      what it is
=========  ===========================================  ===============================
mlp        agents.nnql.networks (the head's fields)     the MLP, dueling or not
local      agents.nnql.action_local (LocalConfig)       the MLP plus the action-local branch
patch      agents.nnql.patch_network (PatchConfig)      a CNN over the own-map patch beside the MLP
cnn        agents.nnql.image_network (ImageConfig)      a CNN over a Gymnasium env's image, then the MLP
=========  ===========================================  ===============================

``NNQLConfig.network`` chooses ("auto": by the observation, :meth:`NNQLConfig.resolved`); every
variant ends in the MLP of ``hidden_sizes`` and ``activation``. The learner builds its network with
:func:`build_q_network` (from NNQLConfig and the observation: navlearn's observation settings, or a
Gymnasium env's image description); actors, the evaluator and saved policies
rebuild it with :func:`network_from_architecture` from the architecture dict the network records
(agents.forward runs a plain MLP in numpy instead).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torch import nn

from agents.nnql import action_local, image_network, patch_network
from agents.nnql.action_local import LocalQNetwork
from agents.nnql.config import NNQLConfig
from agents.nnql.image_network import ImageQNetwork
from agents.nnql.networks import QNetwork
from agents.nnql.patch_network import PatchQNetwork


def build_q_network(
    config: NNQLConfig,
    obs_dim: int,
    n_actions: int,
    observation: Mapping[str, Any] | None = None,
    image: Mapping[str, Any] | None = None,
) -> nn.Module:
    """The learner's Q-network: the variant ``config.network`` names (resolved on ``observation``,
    navlearn's observation settings or None, and ``image``, a Gymnasium env's image description or
    None), built from its own config by its module."""
    image = None if image is None else dict(image)
    config = config.resolved(None if observation is None else dict(observation), image)
    if config.network == "mlp":
        return QNetwork.from_config(config, obs_dim, n_actions)
    if config.network == "local":
        head = QNetwork.from_config(config, obs_dim, n_actions).architecture
        return action_local.build(config.local, head, observation)
    if config.network == "cnn":
        return image_network.build(
            config.cnn, image, obs_dim, n_actions, config.hidden_sizes, config.activation, config.dueling
        )
    return patch_network.build(
        config.patch, obs_dim, n_actions, config.hidden_sizes, config.activation, observation
    )


def network_from_architecture(architecture: Mapping[str, Any]) -> nn.Module:
    """The module an architecture dict describes (a saved policy's, or a WeightsUpdate's)."""
    if "image" in architecture:
        return ImageQNetwork(architecture)
    if "patch" in architecture:
        return PatchQNetwork(architecture)
    if "local" in architecture:
        return LocalQNetwork(architecture)
    return QNetwork.from_architecture(dict(architecture))

"""The Q-network variants of NNQL and the one place that picks among them.

=====================  ===========================================  ==========================
variant                module                                       chosen when
=====================  ===========================================  ==========================
MLP (default)          agents.nnql.networks (QNetwork, dueling)     no patch, action_local 0
MLP + action-local     agents.nnql.action_local (LocalQNetwork)     no patch, action_local k
patch CNN (+ branch)   agents.nnql.patch_network (PatchQNetwork)    a patch, q_network auto
=====================  ===========================================  ==========================

The learner builds its network with :func:`build_q_network` (from NNQLConfig and the observation);
actors, the evaluator and saved policies rebuild it with :func:`network_from_architecture` from the
architecture dict the network records (agents.forward runs a plain MLP in numpy instead).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from torch import nn

from agents.nnql.action_local import VIEW_KEYS, LocalQNetwork, view_layout
from agents.nnql.config import NNQLConfig
from agents.nnql.networks import QNetwork
from agents.nnql.patch_network import PatchQNetwork, patch_layout
from worlds.config import NavConfig, with_observation


def build_q_network(
    config: NNQLConfig, obs_dim: int, n_actions: int, observation: Mapping[str, Any] | None = None
) -> nn.Module:
    """The learner's Q-network: :class:`PatchQNetwork` when the observation has a patch and
    ``config.q_network`` is "auto" (a plain head: ``config.dueling`` is the MLP's), else the flat-MLP
    :class:`agents.nnql.networks.QNetwork` (dueling or not, as the config says), with the
    action-local branch (:class:`LocalQNetwork`) when ``config.action_local`` is set."""
    layout = patch_layout(observation) if config.q_network == "auto" else None
    if layout is None:
        if config.cnn_goal or config.cnn_embed:
            raise ValueError(
                f"NNQLConfig.cnn_goal={config.cnn_goal}, cnn_embed={config.cnn_embed} shape the patch"
                " network: they need an observation with a patch (observation.patch_size > 0) and"
                " q_network='auto'"
                f" (got {config.q_network!r})"
            )
        if not config.action_local:
            return QNetwork.from_config(config, obs_dim, n_actions)
        if not observation:
            raise ValueError(
                f"NNQLConfig.action_local={config.action_local}: the branch reads the readings and the goal"
                " where the observation's settings put them; build the learner with its observation"
            )
        view = view_layout(with_observation(NavConfig(), dict(observation)))
        head = QNetwork.from_config(config, obs_dim, n_actions).architecture
        local = {key: view[key] for key in VIEW_KEYS}
        return LocalQNetwork({**head, "frame_dim": view["frame_dim"],
                              "local": {**local, "window": config.action_local}})  # fmt: skip
    local = {key: layout.pop(key) for key in VIEW_KEYS}
    goal_at, max_range = local["goal_at"], layout.pop("max_range")
    extra = {"goal": {"at": goal_at, "max_range": max_range}} if config.cnn_goal else {}
    if config.cnn_embed:
        extra["embed"] = config.cnn_embed
    local = {**local, "window": config.action_local}
    return PatchQNetwork({
        "obs_dim": obs_dim, "n_actions": n_actions, "hidden_sizes": config.hidden_sizes,
        "activation": config.activation,
        "patch": {**layout, "channels": config.cnn_channels, "kernel_sizes": config.cnn_kernel_sizes,
                  "strides": config.cnn_strides, **extra},
        **({"local": local} if config.action_local else {}),
    })  # fmt: skip


def network_from_architecture(architecture: Mapping[str, Any]) -> nn.Module:
    """The module an architecture dict describes (a saved policy's, or a WeightsUpdate's)."""
    if "patch" in architecture:
        return PatchQNetwork(architecture)
    if "local" in architecture:
        return LocalQNetwork(architecture)
    return QNetwork.from_architecture(dict(architecture))

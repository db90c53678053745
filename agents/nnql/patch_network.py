"""The Q-network for observations with a patch of the robot's own map: a small CNN beside the MLP.

When the observation holds the egocentric patch (``worlds.config.ObservationConfig.patch_size``),
the flat observation vector is split in two: the patch of every frame, reshaped to image channels
``(2 * frame_stack, P, P)`` (occupancy, visits; newest frame first), goes through TorchRL's
``ConvNet``; everything else (readings, goal, subgoal, previous action of every frame) is kept as a
vector. The CNN's flattened features and that vector are concatenated and TorchRL's ``MLP`` maps
them to one Q-value per action (variant F of the observation ablation, ``bench/perception.py``).

The split follows :func:`worlds.perception.frame_layout`: in one frame the patch starts at
``start`` and holds ``2 * P * P`` values in the order (u, v, channel), ``u`` from back to front
along the heading and ``v`` from right to left. The architecture dict (saved in the policy's
``config.json`` and sent with the weights) records that layout and the CNN's shape, so actors and
the evaluator rebuild the same module; they run this module's forward too (torch, one definition
of it), see :mod:`agents.forward`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from torch import nn
from torchrl.modules import MLP, ConvNet

from agents.nnql.config import NNQLConfig
from agents.nnql.networks import ACTIVATIONS, QNetwork
from worlds.config import NavConfig, with_observation
from worlds.perception import frame_dim, frame_layout

PATCH_KEYS = ("size", "start", "frame_dim", "frames", "channels", "kernel_sizes", "strides")


def patch_layout(observation: Mapping[str, Any] | None) -> dict[str, int] | None:
    """Where the patch sits in an observation with these settings (``worlds.config.observation_settings``);
    None when there is no patch."""
    if not observation or not observation.get("observation.patch_size"):
        return None
    nav = with_observation(NavConfig(), dict(observation))
    return {
        "size": nav.observation.patch_size,
        "start": frame_layout(nav)["patch"][0],
        "frame_dim": frame_dim(nav),
        "frames": nav.observation.frame_stack,
    }


class PatchQNetwork(nn.Module):
    """Q(s, .) from a flat observation (..., obs_dim): ConvNet over the patch, MLP over [features, rest]."""

    def __init__(self, architecture: Mapping[str, Any]):
        super().__init__()
        arch = dict(architecture)
        patch = dict(arch["patch"])
        missing = [k for k in PATCH_KEYS if k not in patch]
        if missing:
            raise ValueError(f"architecture['patch'] lacks {missing}")
        if arch["activation"] not in ACTIVATIONS:
            raise ValueError(f"unknown activation {arch['activation']!r}; expected {sorted(ACTIVATIONS)}")
        self.size, self.frames = int(patch["size"]), int(patch["frames"])
        self.start, self.frame_dim = int(patch["start"]), int(patch["frame_dim"])
        self.stop = self.start + 2 * self.size**2
        fits = 0 <= self.start < self.stop <= self.frame_dim
        if not fits or self.frames * self.frame_dim != int(arch["obs_dim"]):
            raise ValueError(
                f"architecture['patch']={patch} does not fit obs_dim={arch['obs_dim']} "
                f"(frames * frame_dim, the patch's 2 * size**2 values inside a frame)"
            )
        rest = self.frames * (self.frame_dim - (self.stop - self.start))
        self.cnn = ConvNet(
            in_features=2 * self.frames,
            num_cells=[int(c) for c in patch["channels"]],
            kernel_sizes=[int(k) for k in patch["kernel_sizes"]],
            strides=[int(s) for s in patch["strides"]],
            activation_class=ACTIVATIONS[arch["activation"]],
        )
        try:
            with torch.no_grad():
                features = self.cnn(torch.zeros(1, 2 * self.frames, self.size, self.size)).shape[-1]
        except RuntimeError as exc:  # the kernels do not fit the image
            raise ValueError(
                f"architecture['patch']: a {self.size}x{self.size} patch is too small for convolutions of "
                f"kernel sizes {patch['kernel_sizes']} and strides {patch['strides']} ({exc})"
            ) from None
        self.head = MLP(
            in_features=features + rest,
            out_features=int(arch["n_actions"]),
            num_cells=[int(h) for h in arch["hidden_sizes"]],
            activation_class=ACTIVATIONS[arch["activation"]],
        )
        self.architecture = {
            "obs_dim": int(arch["obs_dim"]),
            "n_actions": int(arch["n_actions"]),
            "hidden_sizes": [int(h) for h in arch["hidden_sizes"]],
            "activation": arch["activation"],
            "patch": {
                **{k: int(patch[k]) for k in ("size", "start", "frame_dim", "frames")},
                **{k: [int(x) for x in patch[k]] for k in ("channels", "kernel_sizes", "strides")},
                "cnn_features": int(features),
            },
        }

    def split(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(patch images (B, 2 * frames, P, P), the other inputs (B, rest)) of observations (..., obs_dim)."""
        frames = obs.reshape(-1, self.frames, self.frame_dim)
        patch = frames[..., self.start : self.stop].reshape(-1, self.frames, self.size, self.size, 2)
        images = patch.permute(0, 1, 4, 2, 3).reshape(-1, 2 * self.frames, self.size, self.size)
        rest = torch.cat([frames[..., : self.start], frames[..., self.stop :]], dim=-1)
        return images, rest.reshape(len(frames), -1)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        images, rest = self.split(obs)
        q = self.head(torch.cat([self.cnn(images), rest], dim=-1))
        return q.reshape(*obs.shape[:-1], q.shape[-1])


def build_q_network(
    config: NNQLConfig, obs_dim: int, n_actions: int, observation: Mapping[str, Any] | None = None
) -> nn.Module:
    """The learner's Q-network: :class:`PatchQNetwork` when the observation has a patch and
    ``config.q_network`` is "auto" (a plain head: ``config.dueling`` is the MLP's), else the flat-MLP
    :class:`agents.nnql.networks.QNetwork` (dueling or not, as the config says)."""
    layout = patch_layout(observation) if config.q_network == "auto" else None
    if layout is None:
        return QNetwork.from_config(config, obs_dim, n_actions)
    return PatchQNetwork({
        "obs_dim": obs_dim, "n_actions": n_actions, "hidden_sizes": config.hidden_sizes,
        "activation": config.activation,
        "patch": {**layout, "channels": config.cnn_channels, "kernel_sizes": config.cnn_kernel_sizes,
                  "strides": config.cnn_strides},
    })  # fmt: skip


def network_from_architecture(architecture: Mapping[str, Any]) -> nn.Module:
    """The module an architecture dict describes (a saved policy's, or a WeightsUpdate's)."""
    if "patch" in architecture:
        return PatchQNetwork(architecture)
    return QNetwork.from_architecture(dict(architecture))

"""The Q-network for observations with a patch of the robot's own map: a small CNN beside the MLP.

When the observation holds the egocentric patch (``worlds.config.ObservationConfig.patch_size``),
the flat observation vector is split in two: the patch of every frame, reshaped to image channels
``(2 * frame_stack, P, P)`` (occupancy, visits; newest frame first), goes through TorchRL's
``ConvNet``; everything else (readings, goal, subgoal, previous action of every frame) is kept as a
vector. The CNN's flattened features and that vector are concatenated and TorchRL's ``MLP`` maps
them to one Q-value per action (variant F of the observation ablation, ``bench/perception.py``).

The split follows :func:`worlds.perception.frame_layout`: in one frame the patch starts at
``start`` and holds ``2 * P * P`` values in the order (u, v, channel), ``u`` from back to front
along the heading and ``v`` from right to left.

Its own settings are ``agents.nnql.config.PatchConfig`` (``NNQLConfig.patch``, network "patch");
:func:`build` makes the network from them. With ``goal`` the CNN gets one more channel per frame:
the goal drawn into the patch (:func:`goal_images`), from the frame's own goal distance and bearing,
so the convolutions can relate the walls to where the goal lies (a conv net cannot read that from a
vector the MLP gets after it). Nothing else is added: it is the observation's goal, placed where it
is. With ``embed`` a linear layer (and the activation) maps the CNN's flattened features to that
many before the head.
With ``window`` the action-local branch (:mod:`agents.nnql.action_local`) adds its part.

The architecture dict (saved in the policy's ``config.json`` and sent with the weights) records that
layout and the CNN's shape, so actors and the evaluator rebuild the same module; they run this
module's forward too (torch, one definition of it), see :mod:`agents.forward`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from torch import nn
from torchrl.modules import MLP, ConvNet

from agents.nnql.action_local import VIEW_KEYS, ActionLocal, view_layout
from agents.nnql.config import PatchConfig
from agents.nnql.networks import activation_class
from worlds.config import NavConfig, with_observation
from worlds.perception import frame_layout

PATCH_KEYS = ("size", "start", "frame_dim", "frames", "channels", "kernel_sizes", "strides")
GOAL_CELL_M = 1.0
"""metres per patch cell when the goal is drawn into the patch: the patch samples map cells, and the
map generators' (``worlds.generators``) cells are 1 m; a map of other cells sees its goal scaled"""


def goal_images(goal: torch.Tensor, size: int, max_range: float) -> torch.Tensor:
    """(..., size, size) images of the goal in the egocentric patch, from goal parts (..., 3) of the
    observation (``d / (d + max_range)``, left and forward unit components; ``worlds.kernel``).

    The goal's continuous cell index is ``forward / cell + size / 2 - 1/2`` along ``u`` (back to front)
    and ``left / cell + size / 2 - 1/2`` along ``v`` (right to left), as the patch samples cell
    centres; a goal outside the patch is moved along its bearing onto the border cells. Its unit mass
    is split bilinearly between the four cells around it."""
    squashed = goal[..., 0].clamp(0.0, 1.0 - 1e-6)
    distance = max_range * squashed / (1.0 - squashed) / GOAL_CELL_M
    centre = size / 2 - 0.5
    du, dv = distance * goal[..., 2], distance * goal[..., 1]
    reach = torch.maximum(du.abs(), dv.abs()).clamp(min=1e-9)
    scale = torch.clamp(centre / reach, max=1.0)
    u, v = centre + du * scale, centre + dv * scale
    u0 = u.floor().clamp(0, size - 2)
    v0 = v.floor().clamp(0, size - 2)
    fu, fv = (u - u0).clamp(0.0, 1.0), (v - v0).clamp(0.0, 1.0)
    image = goal.new_zeros(*goal.shape[:-1], size * size)
    base = (u0 * size + v0).long()
    corners = ((0, (1 - fu) * (1 - fv)), (1, (1 - fu) * fv), (size, fu * (1 - fv)), (size + 1, fu * fv))
    for off, weight in corners:
        image.scatter_add_(-1, (base + off).unsqueeze(-1), weight.unsqueeze(-1))
    return image.reshape(*goal.shape[:-1], size, size)


def patch_layout(observation: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """Where the patch sits in an observation with these settings (``worlds.config.observation_settings``),
    and where its goal part and readings are (for :func:`goal_images` and :class:`ActionLocal`); None
    when there is no patch."""
    if not observation or not observation.get("observation.patch_size"):
        return None
    nav = with_observation(NavConfig(), dict(observation))
    return {
        "size": nav.observation.patch_size,
        "start": frame_layout(nav)["patch"][0],
        "frames": nav.observation.frame_stack,
        "max_range": nav.sensors.max_range,
        **view_layout(nav),
    }


def build(
    config: PatchConfig,
    obs_dim: int,
    n_actions: int,
    hidden_sizes: tuple[int, ...],
    activation: str,
    observation: Mapping[str, Any] | None,
) -> PatchQNetwork:
    """Network "patch" from its own settings, the head MLP's ``hidden_sizes`` and ``activation``, and
    where ``observation`` (navlearn's observation settings, with a patch) puts the patch."""
    layout = patch_layout(observation)
    if layout is None:
        raise ValueError(
            "NNQLConfig.network='patch' needs an observation with the own-map patch"
            " (observation.patch_size > 0)"
        )
    local = {key: layout.pop(key) for key in VIEW_KEYS}
    goal_at, max_range = local["goal_at"], layout.pop("max_range")
    patch = {
        **layout,
        "channels": config.channels,
        "kernel_sizes": config.kernel_sizes,
        "strides": config.strides,
    }
    if config.goal:
        patch["goal"] = {"at": goal_at, "max_range": max_range}
    if config.embed:
        patch["embed"] = config.embed
    architecture = {"obs_dim": obs_dim, "n_actions": n_actions, "hidden_sizes": hidden_sizes,
                    "activation": activation, "patch": patch}  # fmt: skip
    if config.window:
        architecture["local"] = {**local, "window": config.window}
    return PatchQNetwork(architecture)


class PatchQNetwork(nn.Module):
    """Q(s, .) from a flat observation (..., obs_dim): ConvNet over the patch, MLP over [features, rest]."""

    def __init__(self, architecture: Mapping[str, Any]):
        super().__init__()
        arch = dict(architecture)
        patch = dict(arch["patch"])
        missing = [k for k in PATCH_KEYS if k not in patch]
        if missing:
            raise ValueError(f"architecture['patch'] lacks {missing}")
        activation_class(arch["activation"])  # ValueError for an unknown one, before anything is built
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
        goal = patch.get("goal")  # {"at": the goal part's index in a frame, "max_range": m}; absent: off
        self.goal = None if goal is None else (int(goal["at"]), float(goal["max_range"]))
        if self.goal is not None and not 0 <= self.goal[0] <= self.frame_dim - 3:
            raise ValueError(f"architecture['patch']['goal']={goal}: the goal part is outside a frame")
        self.channels = (3 if self.goal else 2) * self.frames
        self.cnn = ConvNet(
            in_features=self.channels,
            num_cells=[int(c) for c in patch["channels"]],
            kernel_sizes=[int(k) for k in patch["kernel_sizes"]],
            strides=[int(s) for s in patch["strides"]],
            activation_class=activation_class(arch["activation"]),
        )
        try:
            with torch.no_grad():
                features = self.cnn(torch.zeros(1, self.channels, self.size, self.size)).shape[-1]
        except RuntimeError as exc:  # the kernels do not fit the image
            raise ValueError(
                f"architecture['patch']: a {self.size}x{self.size} patch is too small for convolutions of "
                f"kernel sizes {patch['kernel_sizes']} and strides {patch['strides']} ({exc})"
            ) from None
        embed = int(patch.get("embed", 0))  # 0: the flat features go to the head as they are
        activation = activation_class(arch["activation"])
        self.embed = nn.Sequential(nn.Linear(features, embed), activation()) if embed else None
        self.head = MLP(
            in_features=(embed or features) + rest,
            out_features=int(arch["n_actions"]),
            num_cells=[int(h) for h in arch["hidden_sizes"]],
            activation_class=activation_class(arch["activation"]),
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
        if self.goal is not None:
            self.architecture["patch"]["goal"] = {"at": self.goal[0], "max_range": self.goal[1]}
        if embed:
            self.architecture["patch"]["embed"] = embed
        local = arch.get("local")  # the ActionLocal spec; absent: off
        self.local = None if local is None else ActionLocal(local, activation)
        if self.local is not None:
            self.local.check_fits(self.frame_dim, int(arch["n_actions"]))
            self.architecture["local"] = self.local.spec

    def split(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(patch images (B, channels, P, P): occupancy and visits of each frame, then each frame's goal
        image with ``goal``; the other inputs (B, rest)) of observations (..., obs_dim)."""
        frames = obs.reshape(-1, self.frames, self.frame_dim)
        patch = frames[..., self.start : self.stop].reshape(-1, self.frames, self.size, self.size, 2)
        images = patch.permute(0, 1, 4, 2, 3).reshape(-1, 2 * self.frames, self.size, self.size)
        if self.goal is not None:
            at, max_range = self.goal
            images = torch.cat([images, goal_images(frames[..., at : at + 3], self.size, max_range)], dim=1)
        rest = torch.cat([frames[..., : self.start], frames[..., self.stop :]], dim=-1)
        return images, rest.reshape(len(frames), -1)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        images, rest = self.split(obs)
        features = self.cnn(images) if self.embed is None else self.embed(self.cnn(images))
        q = self.head(torch.cat([features, rest], dim=-1))
        if self.local is not None:
            q = q + self.local(obs.reshape(-1, self.frames, self.frame_dim)[:, 0])
        return q.reshape(*obs.shape[:-1], q.shape[-1])

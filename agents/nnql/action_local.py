"""The action-local branch: what one small MLP, shared by the actions, makes of each action's view.

With ``NNQLConfig.network`` "local" (its own settings: ``agents.nnql.config.LocalConfig``, window
k) a branch (:class:`ActionLocal`) adds to each action's Q-value
what one small MLP, shared by the actions, makes of the newest frame seen from that action's heading:
the 2k+1 readings centred on it and the goal's distance and bearing turned to it. A wall ahead of an
action is then the same input whichever action it is ahead of (weight sharing over the robot's
rotations), so a collision learned for one action is learned for all. It sits beside the flat MLP
(:class:`LocalQNetwork`, built by :func:`build`; NIRL's ``local`` too) or beside the patch CNN
(:class:`agents.nnql.patch_network.PatchQNetwork`, ``PatchConfig.window``). agents.nnql.q_networks
picks the variant.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from torch import nn
from torchrl.modules import MLP

from agents.nnql.config import LocalConfig
from agents.nnql.networks import QNetwork, activation_class
from worlds.config import NavConfig, with_observation
from worlds.perception import frame_dim, frame_layout

LOCAL_HIDDEN = 32
"""hidden width of the action-local branch's MLP"""
VIEW_KEYS = ("readings_at", "n_readings", "headings", "turns", "goal_at")
"""what :class:`ActionLocal`'s spec takes of :func:`view_layout` (with its ``window``)"""


def view_layout(nav: NavConfig) -> dict[str, Any]:
    """Where a frame's readings and goal part sit and each action's heading among the readings: what
    :class:`ActionLocal` needs of any observation (with or without a patch)."""
    layout = frame_layout(nav)
    return {
        "frame_dim": frame_dim(nav),
        "goal_at": layout["goal"][0],
        "readings_at": layout["readings"][0],
        "n_readings": layout["readings"][1] - layout["readings"][0],
        "headings": nearest_readings(nav),
        "turns": [float(t) for t in nav.robot.turns],
    }


def nearest_readings(nav: NavConfig) -> list[int]:
    """Index of the reading whose direction is nearest each action's heading change."""
    angles = nav.sensors.beam_angles
    gap = np.angle(np.exp(1j * (angles[None, :] - nav.robot.turns[:, None])))
    return [int(i) for i in np.abs(gap).argmin(axis=1)]


class ActionLocal(nn.Module):
    """(B, n_actions) from frames (B, frame_dim): one MLP, shared by the actions, over each action's
    own view - the ``2 * window + 1`` readings centred on its heading (wrapping round: the readings
    cover the full circle) and the goal's (squashed distance, left, forward) turned to that heading."""

    def __init__(self, spec: Mapping[str, Any], activation: type[nn.Module]):
        super().__init__()
        self.spec = {"window": int(spec["window"]), "readings_at": int(spec["readings_at"]),
                     "n_readings": int(spec["n_readings"]), "headings": [int(h) for h in spec["headings"]],
                     "turns": [float(t) for t in spec["turns"]], "goal_at": int(spec["goal_at"]),
                     "hidden": int(spec.get("hidden", LOCAL_HIDDEN))}  # fmt: skip
        window, n = self.spec["window"], self.spec["n_readings"]
        if not 1 <= 2 * window + 1 <= n or len(self.spec["headings"]) != len(self.spec["turns"]):
            raise ValueError(
                f"action-local window {window}: an action's view of 2 * {window} + 1 readings must fit"
                f" the {n} readings (window <= {(n - 1) // 2}; --local-window or --patch-window)"
            )
        offsets = torch.arange(-window, window + 1)
        index = (torch.tensor(self.spec["headings"])[:, None] + offsets) % n + self.spec["readings_at"]
        turns = torch.tensor(self.spec["turns"], dtype=torch.float32)
        # derived from the spec, neither weights nor buffers (the loss trains exactly the parameters)
        self.index, self.turns = index, torch.stack([turns.cos(), turns.sin()])
        self.mlp = MLP(in_features=2 * window + 4, out_features=1, num_cells=[self.spec["hidden"]],
                       activation_class=activation)  # fmt: skip

    def check_fits(self, frame_dim: int, n_actions: int) -> None:
        """ValueError unless the spec's readings and goal part lie inside a frame of ``frame_dim`` and it
        has a turn per action (what both Q-networks with the branch check of their frames)."""
        spec = self.spec
        inside = (
            0 <= spec["goal_at"] <= frame_dim - 3 and spec["readings_at"] + spec["n_readings"] <= frame_dim
        )
        if not inside or n_actions != len(spec["turns"]):
            raise ValueError(
                f"architecture['local']={spec} does not fit frames of {frame_dim} with {n_actions} actions"
            )

    def forward(self, frame: torch.Tensor) -> torch.Tensor:
        near = frame[:, self.index.to(frame.device)]  # (B, A, 2w+1)
        cos, sin = self.turns.to(frame.device)
        at = self.spec["goal_at"]
        squashed, left, forward = (frame[:, at + i : at + i + 1] for i in range(3))  # (B, 1) each
        turned = (
            squashed.expand(-1, len(cos)),
            left * cos - forward * sin,  # the goal's bearing minus the action's turn
            forward * cos + left * sin,
        )
        view = torch.cat([near, torch.stack(turned, dim=-1)], dim=-1)
        return self.mlp(view).squeeze(-1)


class LocalQNetwork(nn.Module):
    """Q(s, .) of an observation without a patch: the flat MLP's (plain or dueling, ``head``) plus
    :class:`ActionLocal`'s over the newest frame (the first ``frame_dim`` features)."""

    def __init__(self, architecture: Mapping[str, Any]):
        super().__init__()
        arch = dict(architecture)
        local, self.frame_dim = arch.pop("local"), int(arch.pop("frame_dim"))
        self.head = QNetwork.from_architecture(arch)
        self.local = ActionLocal(local, activation_class(arch["activation"]))
        obs_dim = int(arch["obs_dim"])
        if self.frame_dim < 1 or obs_dim % self.frame_dim:
            raise ValueError(
                f"architecture: frame_dim={self.frame_dim} does not fit frames in obs_dim={obs_dim}"
            )
        self.local.check_fits(self.frame_dim, int(arch["n_actions"]))
        self.architecture = {**self.head.architecture, "frame_dim": self.frame_dim, "local": self.local.spec}

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        flat = obs.reshape(-1, obs.shape[-1])
        q = self.head(flat) + self.local(flat[:, : self.frame_dim])
        return q.reshape(*obs.shape[:-1], q.shape[-1])


def build(
    config: LocalConfig, head: Mapping[str, Any], observation: Mapping[str, Any] | None
) -> LocalQNetwork:
    """Network "local": the MLP of architecture ``head`` (``QNetwork``'s, dueling or not) plus the branch
    of ``config.window``, where ``observation`` (navlearn's observation settings) puts the readings."""
    if not observation:
        raise ValueError(
            "NNQLConfig.network='local': the action-local branch reads the readings and the goal where the "
            "observation's settings put them; build the learner with its observation"
        )
    view = view_layout(with_observation(NavConfig(), dict(observation)))
    local = {key: view[key] for key in VIEW_KEYS}
    return LocalQNetwork(
        {**head, "frame_dim": view["frame_dim"], "local": {**local, "window": config.window}}
    )

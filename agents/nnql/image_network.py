"""The Q-network for a Gymnasium env whose observation is an image: convolutions, then the MLP head.

Network "cnn" (its own settings: ``agents.nnql.config.ImageConfig``, ``NNQLConfig.cnn``). The wire
and the replay carry the observation flat, as every env's (``worlds.own_env.make_env`` flattens it
with gymnasium's ``FlattenObservation``, C order); the learner knows the image from its own copy of
the env (``worlds.own_env.describe_env``: shape, channels last or first, scale 1/255). The forward
undoes the flattening: the flat float vector is reshaped to the image, moved to channels-first (what
``torch.nn.Conv2d`` takes), scaled to 0..1, and goes through the convolutions with ReLU (and the
max-pool the small-image rule puts after the first), flattened; then the MLP head of
``hidden_sizes`` and ``activation``, plain or dueling (``agents.nnql.networks``: TorchRL's ``MLP`` or
``DuelingMlpDQNet``, as network "mlp" builds it, its input the convolutions' features).

The convolutions are torch's own layers in an ``nn.Sequential``: TorchRL's ``ConvNet`` has no
pooling between its layers, which rl-starter-files' MiniGrid CNN has. Which convolutions an image gets
is ``ImageConfig.convolutions``' rule (Nature DQN from 36 px, the MiniGrid CNN below).

The architecture dict (saved in the policy's ``config.json``, sent with the weights, kept in
checkpoints) holds the MLP head's keys and ``image``: the image description and the convolutions, so
actors, the evaluator and ``navlearn evaluate --policy`` rebuild the same module
(``agents.nnql.q_networks.network_from_architecture``) and run this forward in torch
(:mod:`agents.forward`). The dueling head stays unfolded (value and advantage layers): only the plain
MLP's forward runs in numpy.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import torch
from torch import nn

from agents.nnql.config import ImageConfig
from agents.nnql.networks import QNetwork
from worlds.own_env import image_hwc

IMAGE_KEYS = ("shape", "channels_last", "scale", "channels", "kernel_sizes", "strides", "pool")
"""what ``architecture["image"]`` holds (and ``cnn_features``, the flattened features, as built)"""


DESCRIPTION_KEYS = ("shape", "channels_last", "scale")
"""the keys of ``worlds.own_env.image_description`` (the rest of ``architecture["image"]`` is the CNN)"""


def architecture_image(architecture: Mapping[str, Any]) -> dict[str, Any] | None:
    """The image description an architecture was built on (None: not network "cnn"): what a learner
    rebuilt from a checkpoint builds on again."""
    image = architecture.get("image")
    return None if image is None else {key: image[key] for key in DESCRIPTION_KEYS}


def build(
    config: ImageConfig,
    image: Mapping[str, Any],
    obs_dim: int,
    n_actions: int,
    hidden_sizes: tuple[int, ...],
    activation: str,
    dueling: bool,
) -> ImageQNetwork:
    """Network "cnn" over ``image`` (``worlds.own_env.image_description``) from its own settings and the
    head's ``hidden_sizes``, ``activation`` and ``dueling``."""
    conv = config.convolutions(dict(image))
    conv.pop("out")
    architecture = {"obs_dim": obs_dim, "n_actions": n_actions, "hidden_sizes": list(hidden_sizes),
                    "activation": activation, "image": {**dict(image), **conv}}  # fmt: skip
    if dueling:
        architecture["dueling"] = True
    return ImageQNetwork(architecture)


class ImageQNetwork(nn.Module):
    """Q(s, .) from flat observations (..., obs_dim) that are images: ``cnn`` then ``head``."""

    def __init__(self, architecture: Mapping[str, Any]):
        super().__init__()
        arch = dict(architecture)
        image = dict(arch["image"])
        missing = [key for key in IMAGE_KEYS if key not in image]
        if missing:
            raise ValueError(f"architecture['image'] lacks {missing}")
        self.shape = tuple(int(n) for n in image["shape"])
        self.channels_last, self.scale = bool(image["channels_last"]), float(image["scale"])
        height, width, channels = image_hwc(image)
        if len(self.shape) != 3 or height * width * channels != int(arch["obs_dim"]):
            raise ValueError(
                f"architecture['image'] shape {list(self.shape)} does not fit obs_dim={arch['obs_dim']}"
            )
        sizes = [int(c) for c in image["channels"]]
        kernels, strides = [int(k) for k in image["kernel_sizes"]], [int(s) for s in image["strides"]]
        pool = int(image["pool"])
        if not sizes or not len(sizes) == len(kernels) == len(strides):
            raise ValueError("architecture['image']: one channels, kernel size and stride per convolution")
        layers: list[nn.Module] = []
        for i, (size, kernel, stride) in enumerate(zip(sizes, kernels, strides, strict=True)):
            layers += [nn.Conv2d(sizes[i - 1] if i else channels, size, kernel, stride), nn.ReLU()]
            if i == 0 and pool:
                layers.append(nn.MaxPool2d(pool))
        self.cnn = nn.Sequential(*layers, nn.Flatten())
        try:
            with torch.no_grad():
                features = self.cnn(torch.zeros(1, channels, height, width)).shape[-1]
        except RuntimeError as exc:  # the kernels do not fit the image
            raise ValueError(
                f"architecture['image']: a {height}x{width} image is too small for convolutions of kernel "
                f"sizes {kernels}, strides {strides} and pool {pool} ({exc})"
            ) from None
        head = {key: arch[key] for key in ("n_actions", "hidden_sizes", "activation")}
        self.head = QNetwork.from_architecture({**head, "obs_dim": features, "dueling": arch.get("dueling")})
        self.architecture = {
            "obs_dim": int(arch["obs_dim"]),
            "n_actions": int(arch["n_actions"]),
            "hidden_sizes": [int(h) for h in arch["hidden_sizes"]],
            "activation": arch["activation"],
            "image": {
                "shape": list(self.shape),
                "channels_last": self.channels_last,
                "scale": self.scale,
                "channels": sizes,
                "kernel_sizes": kernels,
                "strides": strides,
                "pool": pool,
                "cnn_features": int(features),
            },
        }
        if arch.get("dueling"):
            self.architecture["dueling"] = True

    def images(self, obs: torch.Tensor) -> torch.Tensor:
        """(B, C, H, W) images scaled to 0..1 of flat observations (..., obs_dim)."""
        images = obs.reshape(-1, *self.shape)
        if self.channels_last:
            images = images.permute(0, 3, 1, 2)
        return images * self.scale

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        q = self.head(self.cnn(self.images(obs)))
        return q.reshape(*obs.shape[:-1], q.shape[-1])

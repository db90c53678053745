"""NNQL hyper-parameters (thesis ch. 4, cleanrl-style): NNQLConfig, and the small configs of the
Q-network variants it selects with one field (``network``).

Each variant is a module (agents.nnql.networks: the MLP; agents.nnql.action_local: the action-local
branch; agents.nnql.patch_network: the patch CNN; agents.nnql.image_network: the CNN over a Gymnasium
env's image observation), built by agents.nnql.q_networks from the config
below that is its own. The configs live here, not beside the torch modules, so every command's flags
(services.common.options: ``--local-window``, ``--patch-channels``, ``--cnn-channels``, ...) are built
without torch.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from agents.mlp import ACTIVATION_NAMES
from protocols.messages import EXPLORATIONS
from worlds.own_env import image_hwc

STORAGES = ("memory", "memmap")
"""Where a replay keeps its transitions (agents.nnql.replay_storage): RAM or memory-mapped files."""

TARGET_UPDATES = ("soft", "hard")
LOSS_FUNCTIONS = ("l2", "smooth_l1", "l1")
NETWORKS = ("auto", "mlp", "local", "patch", "cnn")
"""the Q-network variants NNQLConfig.network chooses among (agents.nnql.q_networks)"""
CONV_FIELDS = ("channels", "kernel_sizes", "strides")
RETIRED_FIELDS = ("recurrent", "lstm_size", "seq_len", "burn_in", "sequences")
"""fields of the retired recurrent variant, which older configs (checkpoints, saved policies'
nnql_config) still hold: dropped when read, unless ``recurrent`` is set"""
RECURRENT_RETIRED = (
    "NNQL's recurrent (LSTM, R2D2-style) variant is retired: the feed-forward Q-network does better on "
    "every measured task (its figures: docs/notebook.md, results/perception/); commit a731e15 still "
    "trains and evaluates it"
)


@dataclass
class LocalConfig:
    """The action-local branch (agents.nnql.action_local), network "local": the flat MLP plus one small
    MLP, shared by the actions, over each action's own view of the newest frame."""

    window: int = 3
    """k: an action's view is the 2k+1 newest readings centred on its heading and the goal's distance
    and bearing seen from that heading (the same small MLP for each action, so what one action learns of
    a wall ahead holds for all; no planner)"""

    def __post_init__(self) -> None:
        if isinstance(self.window, bool) or int(self.window) != self.window or self.window < 1:
            raise ValueError(f"LocalConfig.window={self.window!r}: expected an integer >= 1 (--local-window)")


@dataclass
class PatchConfig:
    """The patch CNN (agents.nnql.patch_network), network "patch": a small CNN over the own-map patch
    (observation.patch_size > 0) beside the MLP over the other inputs."""

    channels: tuple[int, ...] = (16, 32)
    """output channels of the patch CNN's convolutions"""
    kernel_sizes: tuple[int, ...] = (3, 3)
    """kernel side of each convolution"""
    strides: tuple[int, ...] = (2, 1)
    """stride of each convolution"""
    goal: bool = False
    """draw the goal into the CNN's input, one more image channel per frame (bilinear at the goal's
    egocentric position in patch cells, on the patch's border when farther), so the convolutions see
    where the goal lies among the walls instead of only the MLP reading its distance and bearing (no
    planner: the network learns what to make of it)"""
    embed: int = 0
    """0: the CNN's flattened features go to the MLP head as they are (800 beside 27 other inputs for
    a 16x16 patch); > 0: a linear layer and the activation first map them to this many features, so
    the readings and goal are not a few inputs among hundreds"""
    window: int = 0
    """0: off; k > 0: the action-local branch (LocalConfig.window's k) beside the CNN"""

    def __post_init__(self) -> None:
        for name in CONV_FIELDS:
            values = tuple(int(v) for v in getattr(self, name))
            setattr(self, name, values)
            if not values or min(values) < 1 or len(values) != len(self.channels):
                raise ValueError(
                    f"PatchConfig.{name}={values}: need positive values, one per convolution "
                    f"({len(self.channels)} in channels; --patch-{name.replace('_', '-')})"
                )
        if self.embed < 0:
            raise ValueError(f"PatchConfig.embed={self.embed}: expected >= 0 (0: no embedding layer)")
        if self.window < 0:
            raise ValueError(f"PatchConfig.window={self.window}: expected >= 0 (0: no action-local branch)")

    def to_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), **{name: list(getattr(self, name)) for name in CONV_FIELDS}}


NATURE_MIN_SIDE = 36
"""the shorter side, in pixels, from which an image gets the Nature DQN convolutions (the smallest
image they reduce to 1x1: 36 -> 8 -> 3 -> 1)"""
NATURE = ((32, 64, 64), (8, 4, 3), (4, 2, 1))
"""Mnih et al. 2015's convolutions (channels, kernel sizes, strides), Stable-Baselines3's NatureCNN"""
AUTO_CNN_MIN_SIDE = NATURE_MIN_SIDE
"""the shorter side, in pixels, from which ``network="auto"`` learns an image with the CNN: a rendered
frame (Atari's 84, a 64x64 render). A smaller image (MiniGrid's 7x7x3 view of object codes 0..10) goes
to the MLP, flattened: on MiniGrid-DoorKey-5x5 the MLP reached 95% success on every seed (55-269 s);
the CNN stayed at 0% through 300 s on both seeds tried (codes scaled by 1/255) and took 247 s with
them unscaled (results/own-env/cnn-vs-mlp/).
``--network cnn`` still builds the CNN on a small image."""
MINIGRID = ((16, 32, 64), (2, 2, 2), (1, 1, 1))
"""rl-starter-files' MiniGrid CNN (model.py, ACModel.image_conv): 2x2 stride-1 convolutions, a 2x2
max-pool after the first"""


@dataclass
class ImageConfig:
    """The image CNN (agents.nnql.image_network), network "cnn": convolutions with ReLU over a Gymnasium
    env's image observation (worlds.own_env.image_description) scaled to 0..1, flattened into the MLP
    head of ``hidden_sizes`` and ``activation`` (dueling as ``dueling`` says).

    The convolutions, left empty (the default), follow the image's shorter side: from 36 px (Atari's 84,
    a 64x64 render) the Nature DQN stack (:data:`NATURE`: 32 8x8 stride 4, 64 4x4 stride 2, 64 3x3
    stride 1); below (MiniGrid's 7x7x3 view) rl-starter-files' MiniGrid CNN (:data:`MINIGRID`: 16, 32
    and 64 channels of 2x2 stride 1, a 2x2 max-pool after the first), the max-pool left out where it
    would shrink the view below 1x1 (under 7 px), and under 4 px only the convolutions that fit."""

    channels: tuple[int, ...] = field(default=(), metadata={"shown": "by the image's size"})
    """output channels of each convolution; empty: by the image's shorter side, from 36 px the Nature
    DQN stack (32 8x8/4, 64 4x4/2, 64 3x3/1), below it 2x2 stride-1 convolutions of 16, 32, 64 channels
    with a 2x2 max-pool after the first where the view stays >= 1x1 (rl-starter-files' MiniGrid CNN)"""
    kernel_sizes: tuple[int, ...] = field(default=(), metadata={"shown": "by the image's size"})
    """kernel side of each convolution (with --cnn-channels; empty: by the image's size)"""
    strides: tuple[int, ...] = field(default=(), metadata={"shown": "by the image's size"})
    """stride of each convolution (with --cnn-channels; empty: by the image's size)"""

    def __post_init__(self) -> None:
        for name in CONV_FIELDS:
            setattr(self, name, tuple(int(v) for v in getattr(self, name)))
        given = [getattr(self, name) for name in CONV_FIELDS]
        if any(given) and (min(min(v, default=0) for v in given) < 1 or len({len(v) for v in given}) != 1):
            raise ValueError(
                f"ImageConfig channels={self.channels}, kernel_sizes={self.kernel_sizes}, strides="
                f"{self.strides}: give all three with one positive value per convolution (--cnn-channels, "
                "--cnn-kernel-sizes, --cnn-strides), or none for the stack by the image's size"
            )

    def convolutions(self, image: dict[str, Any]) -> dict[str, Any]:
        """The convolutions over ``image`` (an image description): ``channels``, ``kernel_sizes``,
        ``strides``, ``pool`` (the side of a max-pool after the first, 0: none) and ``out`` (the side
        of the last feature maps, height and width). ValueError naming the options when given ones do
        not fit the image."""
        height, width, _ = image_hwc(image)
        if self.channels:
            conv = {"channels": list(self.channels), "kernel_sizes": list(self.kernel_sizes),
                    "strides": list(self.strides), "pool": 0}  # fmt: skip
        else:
            conv = default_convolutions(min(height, width))
        out = [conv_out(side, conv) for side in (height, width)]
        if min(out) < 1 and not self.channels:
            raise ValueError(
                f"network cnn: a {height}x{width} image is too small for a 2x2 convolution; learn it "
                "flattened with --network mlp"
            )
        if min(out) < 1:
            raise ValueError(
                f"--cnn-channels {self.channels} --cnn-kernel-sizes {self.kernel_sizes} --cnn-strides "
                f"{self.strides}: convolutions that shrink a {height}x{width} image below 1x1; give smaller "
                "kernels or strides, or none for the stack by the image's size"
            )
        return {**conv, "out": out}

    def to_dict(self) -> dict[str, Any]:
        return {name: list(getattr(self, name)) for name in CONV_FIELDS}


def auto_cnn(image: dict[str, Any] | None) -> bool:
    """Whether ``network="auto"`` learns ``image`` (an image description, None: not an image) with the
    CNN: when its shorter side is at least :data:`AUTO_CNN_MIN_SIDE` pixels."""
    return image is not None and min(image_hwc(image)[:2]) >= AUTO_CNN_MIN_SIDE


def default_convolutions(side: int) -> dict[str, Any]:
    """:class:`ImageConfig`'s rule: the convolutions of an image whose shorter side is ``side`` px."""
    stack = NATURE if side >= NATURE_MIN_SIDE else MINIGRID
    conv = {"channels": list(stack[0]), "kernel_sizes": list(stack[1]), "strides": list(stack[2]), "pool": 0}
    if stack is NATURE:
        return conv
    if conv_out(side, {**conv, "pool": 2}) >= 1:
        return {**conv, "pool": 2}
    fit = max(1, min(3, side - 1))  # each 2x2 stride-1 convolution takes one pixel off
    return {name: value[:fit] if isinstance(value, list) else value for name, value in conv.items()}


def conv_out(side: int, conv: dict[str, Any]) -> int:
    """The side of the feature maps that ``conv``'s convolutions (no padding; ``pool`` after the first)
    leave of ``side`` pixels."""
    for i, (kernel, stride) in enumerate(zip(conv["kernel_sizes"], conv["strides"], strict=True)):
        side = (side - kernel) // stride + 1 if side >= kernel else 0
        if i == 0 and conv["pool"]:
            side //= conv["pool"]
    return side


@dataclass
class NNQLConfig:
    """Neural-network Q-learning: Q-network, replay, loss, target network and exploration.

    Exploration schedules are functions of the learner's update count (the policy
    version), so local training and distributed actors, which only see versioned
    weights, explore the same way.
    """

    hidden_sizes: tuple[int, ...] = (128, 128)
    """widths of the Q-network's hidden layers (MLP over range sensors + goal features)"""
    activation: str = field(default="relu", metadata={"choices": ACTIVATION_NAMES})
    """hidden activation: relu, tanh or elu"""
    lr: float = 1e-3
    """Adam learning rate"""
    gamma: float = 0.98
    """discount factor"""
    batch_size: int = 256
    """transitions per gradient update"""
    replay_capacity: int = 100_000
    """replay buffer size in transitions (oldest overwritten first)"""
    learning_starts: int = 2_000
    """transitions in replay before the first update"""
    utd_ratio: float = 0.0625
    """gradient updates per inserted transition (update-to-data ratio; 0.0625 = one per 16)"""
    prioritized: bool = False
    """prioritized replay (TorchRL PrioritizedSampler) instead of uniform sampling"""
    priority_alpha: float = 0.3
    """priority exponent; TorchRL's DQNLoss writes the squared TD error, so 0.3 acts like 0.6 on |td|"""
    priority_beta: float = 0.4
    """importance-sampling exponent of prioritized replay"""
    priority_eps: float = 1e-6
    """added to priorities so no transition becomes unsampleable"""
    target_update: str = field(default="soft", metadata={"choices": TARGET_UPDATES})
    """target network update: soft (Polyak, tau each update) or hard (copy every target_period updates)"""
    target_tau: float = 0.005
    """Polyak factor of soft target updates"""
    target_period: int = 500
    """updates between hard target copies"""
    n_step: int = 1
    """bootstrap after n steps: target sum_k<n gamma^k r_k + gamma^n Q(s_n) (Ape-X / Rainbow); the learner
    builds the returns per (actor, robot) stream, stopping at episode ends (agents/nnql/nstep.py)"""
    dueling: bool = True
    """dueling head of the MLP (networks mlp and local): Q = V(s) + A(s, a) - mean_a A(s, a) over the last
    hidden layer (Wang et al. 2016), saved folded into one linear layer, so actors run the plain MLP
    forward; on by default (the shipped policy's recipe, chosen on validation); the cnn network's head
    is dueling too (unfolded: it runs in torch); the patch network keeps a plain head whatever this says"""
    double_q: bool = True
    """double Q-learning: the online network picks the next action, the target network values it"""
    sarsa: bool = False
    """SARSA variant: bootstrap on the next action actually taken (needs next_action in transitions)"""
    loss_function: str = field(default="smooth_l1", metadata={"choices": LOSS_FUNCTIONS})
    """TD loss: l2, smooth_l1 (Huber) or l1"""
    grad_clip: float = 10.0
    """max global gradient norm (0 disables clipping)"""
    exploration: str = field(default="boltzmann", metadata={"choices": EXPLORATIONS})
    """behaviour policy: boltzmann (softmax over Q / temperature, the thesis' policy) or epsilon (greedy)"""
    temperature_start: float = 0.2
    """Boltzmann temperature at version 0"""
    temperature_end: float = 0.01
    """Boltzmann temperature after temperature_decay_updates (geometric decay)"""
    temperature_decay_updates: int = 12_000
    """updates over which the temperature decays"""
    epsilon_start: float = 1.0
    """epsilon at version 0 (exploration='epsilon')"""
    epsilon_end: float = 0.05
    """epsilon after epsilon_decay_updates (linear decay)"""
    epsilon_decay_updates: int = 10_000
    """updates over which epsilon decays"""
    seed: int = 0
    """seeds network initialisation and replay sampling"""
    torch_threads: int = 1
    """torch intra-op threads, set process-wide by the learner (small MLPs are fastest on one)"""
    network: str = field(default="auto", metadata={"choices": NETWORKS})
    """the Q-network (agents.nnql.q_networks): mlp (the MLP alone), local (the MLP plus the action-local
    branch, ``local``), patch (a CNN over the own-map patch beside the MLP, ``patch``; needs
    observation.patch_size > 0) or auto: patch when the observation has a patch, local on navlearn's
    world's other observations (the shipped policy's recipe), mlp where no navlearn observation says
    where the readings are (a Gymnasium env, --env); cnn (convolutions over a Gymnasium env's image
    observation, then the MLP, ``cnn``): what auto picks for an env whose observation is an image (a Box
    (H, W, C) or (C, H, W) of uint8 0..255 with 1, 3 or 4 channels, Stable-Baselines3's rule) of at
    least 36 pixels a side (``AUTO_CNN_MIN_SIDE``); a smaller one goes to the MLP, flattened"""
    local: LocalConfig = field(default_factory=LocalConfig)
    """network local's own settings (the action-local branch)"""
    patch: PatchConfig = field(default_factory=PatchConfig)
    """network patch's own settings (the patch CNN)"""
    cnn: ImageConfig = field(default_factory=ImageConfig)
    """network cnn's own settings (the image CNN)"""

    def __post_init__(self) -> None:
        self.hidden_sizes = tuple(int(h) for h in self.hidden_sizes)
        if isinstance(self.local, dict):  # from a config file
            self.local = LocalConfig(**self.local)
        if isinstance(self.patch, dict):
            self.patch = PatchConfig(**self.patch)
        if isinstance(self.cnn, dict):
            self.cnn = ImageConfig(**self.cnn)
        checks = {
            "activation": (self.activation, ACTIVATION_NAMES),
            "target_update": (self.target_update, TARGET_UPDATES),
            "exploration": (self.exploration, EXPLORATIONS),
            "loss_function": (self.loss_function, LOSS_FUNCTIONS),
            "network": (self.network, NETWORKS),
        }
        for name, (value, allowed) in checks.items():
            if value not in allowed:
                raise ValueError(f"NNQLConfig.{name}={value!r}: expected one of {allowed}")
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise ValueError(f"NNQLConfig.hidden_sizes={self.hidden_sizes}: need positive widths")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"NNQLConfig.gamma={self.gamma}: expected 0 < gamma <= 1")
        if self.batch_size < 1 or self.replay_capacity < self.batch_size:
            raise ValueError("NNQLConfig: need 1 <= batch_size <= replay_capacity")
        if self.utd_ratio <= 0:
            raise ValueError(f"NNQLConfig.utd_ratio={self.utd_ratio}: expected > 0")
        if not 0.0 < self.target_tau <= 1.0 or self.target_period < 1:
            raise ValueError("NNQLConfig: need 0 < target_tau <= 1 and target_period >= 1")
        if min(self.temperature_start, self.temperature_end) <= 0:
            raise ValueError("NNQLConfig: Boltzmann temperatures must be > 0")
        if isinstance(self.n_step, bool) or int(self.n_step) != self.n_step or self.n_step < 1:
            raise ValueError(f"NNQLConfig.n_step={self.n_step!r}: expected an integer >= 1")
        if self.sarsa and self.n_step > 1:
            raise ValueError("NNQLConfig.n_step: SARSA bootstraps one step ahead; use n_step=1 with sarsa")
        if self.sarsa and self.double_q:
            raise ValueError("NNQLConfig: sarsa bootstraps on the taken action; set double_q=False")

    def resolved(self, observation: dict[str, Any] | None, image: dict[str, Any] | None = None) -> NNQLConfig:
        """This config with ``network`` the variant it builds on ``observation`` (navlearn's observation
        settings, ``worlds.config.observation_settings``; None for another env) or ``image`` (a
        Gymnasium env's image observation, ``worlds.own_env.image_description``; None when it is not
        one): "auto" resolved as its docstring says. ValueError, naming the option, for a variant the
        observation cannot feed or a variant's settings changed while another variant is built (they
        would be silently ignored)."""
        has_patch = bool((observation or {}).get("observation.patch_size"))
        network = self.network
        if network == "auto":
            own_env = "cnn" if auto_cnn(image) else "mlp"
            network = "patch" if has_patch else "local" if observation else own_env
        if network == "patch" and not has_patch:
            raise ValueError(
                "NNQLConfig.network='patch' needs an observation with the own-map patch "
                "(observation.patch_size > 0, e.g. `navlearn train --local --patch-size 16`)"
            )
        if network == "local" and not observation:
            raise ValueError(
                "NNQLConfig.network='local': the action-local branch reads the readings and the goal where "
                "navlearn's observation settings put them; build the learner with its observation (another "
                "env: --network mlp)"
            )
        if network == "cnn" and not image:
            world = "navlearn's world observes range readings and the goal"
            what = world if observation else "this env's observation is not one"
            raise ValueError(
                f"NNQLConfig.network='cnn' (--network cnn) needs an image observation, and {what} (an "
                "image: a Box (H, W, C) or (C, H, W) of uint8 0..255 with 1, 3 or 4 channels, "
                "worlds.own_env.image_description); drop --network cnn (auto picks the variant) or give "
                "--network mlp"
            )
        if network == "cnn":
            self.cnn.convolutions(image)  # given convolutions that do not fit: refused now
        defaults = (("local", LocalConfig()), ("patch", PatchConfig()), ("cnn", ImageConfig()))
        for name, default in defaults:
            if network != name and getattr(self, name) != default:
                raise ValueError(
                    f"NNQLConfig.{name}={getattr(self, name)} shapes network {name!r}, and this config "
                    f"builds {network!r} (network={self.network!r}): add --network {name}"
                    + (" and --patch-size" if name == "patch" and not has_patch else "")
                    + (" with an --env whose observation is an image" if name == "cnn" and not image else "")
                    + f" or drop the --{name}-* options"
                )
        return dataclasses.replace(self, network=network)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able copy (tuples become lists)."""
        data = dataclasses.asdict(self)
        data["hidden_sizes"] = list(self.hidden_sizes)
        data["patch"] = self.patch.to_dict()
        data["cnn"] = self.cnn.to_dict()
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any], observation: dict[str, Any] | None = None) -> NNQLConfig:
        """Inverse of to_dict; unknown keys are an error so typos do not pass silently. A config saved
        before the recurrent variant was retired loads (its fields dropped) unless it is recurrent; one
        saved with the variants' fields flat (before ``network``) loads as the variant it built
        (:func:`from_flat_variant`, given the ``observation`` it was trained on)."""
        if data.get("recurrent"):
            raise ValueError(RECURRENT_RETIRED)
        data = {k: v for k, v in data.items() if k not in RETIRED_FIELDS}
        if any(key in data for key in FLAT_VARIANT_FIELDS):
            data = from_flat_variant(data, observation)
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"NNQLConfig: unknown field(s) {unknown}")
        return cls(**data)


FLAT_VARIANT_FIELDS = (
    "q_network", "action_local", "cnn_channels", "cnn_kernel_sizes", "cnn_strides", "cnn_goal", "cnn_embed"
)  # fmt: skip
"""the Q-network variants' settings as NNQLConfig held them flat before ``network`` chose a variant with
its own config (saved in policies' config.json ``nnql_config``, checkpoints and run summaries)"""


def from_flat_variant(data: dict[str, Any], observation: dict[str, Any] | None) -> dict[str, Any]:
    """``data`` with the flat variant fields (:data:`FLAT_VARIANT_FIELDS`) as ``network``, ``local`` and
    ``patch``: what those fields built on ``observation`` (a policy's or checkpoint's ``observation``
    settings). ``q_network`` "auto" built the patch CNN when the observation had a patch, "mlp" never
    did; otherwise ``action_local`` k > 0 added the branch (network local), 0 left the MLP alone."""
    data = dict(data)
    if "network" in data:
        raise ValueError(f"NNQLConfig: both network and the flat variant fields {FLAT_VARIANT_FIELDS} given")
    old = {key: data.pop(key) for key in FLAT_VARIANT_FIELDS if key in data}
    window = int(old.get("action_local", 0))
    has_patch = bool((observation or {}).get("observation.patch_size"))
    conv = {name: old[f"cnn_{name}"] for name in CONV_FIELDS if f"cnn_{name}" in old}
    patch = {**conv, "goal": bool(old.get("cnn_goal", False)), "embed": int(old.get("cnn_embed", 0))}
    if old.get("q_network", "auto") == "auto" and has_patch:
        return {**data, "network": "patch", "patch": {**patch, "window": window}}
    if window:
        return {**data, "network": "local", "local": {"window": window}}
    return {**data, "network": "mlp"}

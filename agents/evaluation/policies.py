"""Saved policies: one on-disk format for every learner, and ``load_policy`` to evaluate any of them.

A policy directory holds two files (written atomically, temp + rename):

* ``model.safetensors`` - the weights of an MLP in ``nn.Sequential`` layout (TorchRL's
  ``MLP``): ``"0.weight"``, ``"0.bias"``, ``"2.weight"``, ... one linear layer at every
  even index, the activation between them; float32. An NNQL Q-network with a CNN over the
  own-map patch (architecture entry ``patch``, :mod:`agents.nnql.patch_network`) names its
  tensors ``"cnn.*"`` and ``"head.*"`` and is run by that torch module (:mod:`agents.forward`); so
  does the CNN over a Gymnasium env's image observation (architecture entry ``image``,
  :mod:`agents.nnql.image_network`).
* ``config.json`` - ``{"model": name, "kind": kind, "version": int, "architecture":
  {"obs_dim", "n_actions", "hidden_sizes", "activation"}, "observation": {...}, ...}`` plus any
  metadata. ``observation`` holds the settings that fix what the policy observes
  (:data:`worlds.config.OBSERVATION_FIELDS`); a policy saved without it observes
  :data:`worlds.config.LEGACY_OBSERVATION` (8 beams and the goal, one frame), and a setting it lacks
  (added after it was saved) its legacy value (:func:`worlds.config.saved_observation`). A policy
  trained on a user's Gymnasium env records ``env`` (``{"id", "kwargs", "module"}``,
  :meth:`worlds.own_env.EnvConfig.record`) instead, and ``navlearn evaluate --policy`` rebuilds that env.

A policy of NNQL's retired recurrent variant (``lstm_size`` in its architecture) is refused, naming
the commit that still evaluates it (:data:`agents.nnql.config.RECURRENT_RETIRED`).

``kind`` says what the network outputs: ``"q_network"`` (Q-values, NNQL) or
``"policy_logits"`` (action logits, imitation and NIRL neural policies). Both are
evaluated greedily (argmax over actions), with numpy only for MLPs, so loading one
needs no torch.

``goal_distance_cap`` (metres, optional) caps the goal distance the network reads: a goal further
than that reads as that far (every frame's goal distance, in its squashed form ``d / (d +
max_range)``). The shipped ``pretrained/nnql`` reads at most 20 m: trained on maps of at most 64 m, its
network strays from its own-map subgoal towards the goal's bearing when the goal is much further,
and on whole 512x512 maps it timed out (docs/navigation-by-size.md, section 11).

``use_known_map`` gives the robot its map: a policy that plans its subgoal on the map it builds from its
readings (``own_map``) plans it on the true map instead (``known_map``), the same inputs from another
planner's map, for a user who has the map (``navlearn evaluate --known-map``; docs/navigation-by-size.md,
section 16).

``load_policy_or_baseline`` also accepts the name ``heuristic``: the goal-seeking
baseline of :mod:`worlds.heuristics`, for comparing a learned policy with it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from safetensors import SafetensorError
from safetensors.numpy import load_file

from agents.forward import network_forward
from agents.mlp import ACTIVATION_NAMES, ARCHITECTURE_KEYS, CONFIG_FILE, KINDS, WEIGHTS_FILE, save_policy
from agents.nnql.config import RECURRENT_RETIRED
from agents.shield import ReadingShield, ScanActor
from agents.shield import for_nav as shield_for
from worlds.config import NavConfig, check_observation, saved_observation, with_observation
from worlds.heuristics import goal_seeking_policy
from worlds.perception import frame_dim, frame_layout, observation_dim

__all__ = [
    "GreedyMLPPolicy",
    "PolicyFormatError",
    "load_policy",
    "load_policy_or_baseline",
    "save_policy",
]
HEURISTIC = "heuristic"
"""the name that ``load_policy_or_baseline`` reads as the goal-seeking baseline"""


class PolicyFormatError(ValueError):
    """A policy directory that cannot be loaded (missing files, unknown kind, weights that do not fit)."""


class GreedyMLPPolicy:
    """``policy(obs (N, obs_dim)) -> actions (N,) int64``: argmax of the MLP's outputs."""

    def __init__(self, weights: dict[str, np.ndarray], config: dict[str, Any]):
        self.config = config
        self.architecture = config["architecture"]
        self.model = str(config.get("model", ""))
        self.kind = str(config["kind"])
        self.version = int(config.get("version", 0))
        self.env = config.get("env")
        """the Gymnasium env it was trained on (``worlds.own_env.EnvConfig.record``); None: our world"""
        self.shield: ReadingShield | None = None
        """the reading shield it acts through (:meth:`use_shield`); None: the network's argmax"""
        self.goal_distance_cap: float | None = None
        """the farthest goal distance the network reads (m; module docstring); None: as observed"""
        self._goal_read: float | None = None  # the cap as the observation writes it
        if self.env is not None:  # a user's env: its spaces, not navlearn's observation, size the input
            self.observation = None
            self._load(weights)
            return
        self.observation = saved_observation(config.get("observation"))
        try:
            nav = self.nav_config()
        except (TypeError, ValueError) as exc:
            raise PolicyFormatError(f"observation settings {self.observation}: {exc}") from None
        if observation_dim(nav) != self.architecture["obs_dim"]:
            raise PolicyFormatError(
                f"observation settings {self.observation} give {observation_dim(nav)} inputs, the network "
                f"takes obs_dim={self.architecture['obs_dim']}"
            )
        cap = config.get("goal_distance_cap")
        if cap is not None and not (isinstance(cap, int | float) and cap > 0):
            raise PolicyFormatError(f"goal_distance_cap={cap!r}: must be a positive number of metres")
        if cap is not None:
            self.goal_distance_cap = float(cap)
            self._goal_read = self.goal_distance_cap / (self.goal_distance_cap + nav.sensors.max_range)
        goal = frame_layout(nav)["goal"][0]
        self._goal_columns = goal + frame_dim(nav) * np.arange(nav.observation.frame_stack)
        self._load(weights)

    def _load(self, weights: dict[str, np.ndarray]) -> None:
        try:
            self._set_weights(weights)
        except (KeyError, ValueError) as exc:
            raise PolicyFormatError(str(exc)) from None

    def _set_weights(self, weights: dict[str, np.ndarray]) -> None:
        self.forward = network_forward(weights, self.architecture)

    @property
    def obs_dim(self) -> int:
        return int(self.architecture["obs_dim"])

    def nav_config(self, base: NavConfig | None = None) -> NavConfig:
        """``base`` (default ``NavConfig()``) with this policy's observation settings."""
        return with_observation(base or NavConfig(), self.observation)

    def outputs(self, obs: np.ndarray) -> np.ndarray:
        """The network's outputs (Q-values or logits), ``(N, n_actions)``."""
        obs = np.asarray(obs, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.obs_dim:
            raise ValueError(f"expected observations (N, {self.obs_dim}), got {obs.shape}")
        if self._goal_read is not None:
            obs = obs.copy()
            obs[:, self._goal_columns] = np.minimum(obs[:, self._goal_columns], np.float32(self._goal_read))
        return self.forward(obs)

    def use_shield(self, nav: NavConfig | None, track_discs: bool = True) -> GreedyMLPPolicy:
        """Act through the reading shield of ``nav``'s robot and sensor (:mod:`agents.shield`: never an
        action the current readings say hits something) with its disc tracker behind it (unless
        ``track_discs`` is False; :mod:`agents.disc_tracker`), or through none when ``nav`` is None;
        returns the policy. ``nav`` must observe what the policy observes."""
        if nav is not None and self.env is not None:
            raise ValueError(f"{self!r} acts in a Gymnasium env; the reading shield is for navlearn's robot")
        if nav is not None:
            check_observation(self.observation, nav)
        self.shield = None if nav is None else shield_for(nav, track_discs)
        return self

    def use_known_map(self) -> GreedyMLPPolicy:
        """Give the robot its map: the policy's subgoal is planned on the true map (``known_map``)
        instead of the map it builds from its readings (``own_map``), as a robot localised in its map
        plans on it; returns the policy. The inputs are the same (the waypoint's distance and
        bearing, the plan's length), only the planner's map changes; the range readings still drive
        the network and its shield (call before :meth:`use_shield` and :meth:`nav_config`). A
        ValueError for a policy that observes no own-map subgoal (nothing would change)."""
        subgoal = (self.observation or {}).get("observation.subgoal")
        if subgoal != "own_map":
            raise ValueError(
                f"{self!r} observes subgoal={subgoal!r}: a known map changes only a policy that plans "
                "its subgoal on its own map (observation.subgoal='own_map')"
            )
        self.observation = {**self.observation, "observation.subgoal": "known_map"}
        return self

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The actions for one frame: the shield's one-frame choice (no disc tracker, which needs
        the scans and the robots' history: :meth:`scan_actor`)."""
        outputs = self.outputs(obs)
        if self.shield is None:
            return outputs.argmax(axis=1).astype(np.int64)
        return self.shield.choose(outputs, obs)

    def scan_actor(self, n: int) -> ScanActor | None:
        """``act(obs, rays, fresh)`` for ``n`` robots driven step by step, through the shield and its
        disc tracker (:meth:`agents.shield.ReadingShield.actor`); None without a shield."""
        return None if self.shield is None else self.shield.actor(self.outputs, n)

    def __repr__(self) -> str:
        shield = ", shielded" if self.shield is not None else ""
        known = ", known map" if (self.observation or {}).get("observation.subgoal") == "known_map" else ""
        return (
            f"{type(self).__name__}(model={self.model!r}, kind={self.kind!r}, "
            f"version={self.version}{shield}{known})"
        )


def load_policy(path: str | Path) -> GreedyMLPPolicy:
    """The greedy policy saved in directory ``path`` by any navlearn learner."""
    path = Path(path)
    config_path, weights_path = path / CONFIG_FILE, path / WEIGHTS_FILE
    if not config_path.is_file() or not weights_path.is_file():
        raise PolicyFormatError(f"{path}: not a policy directory (expected {CONFIG_FILE} and {WEIGHTS_FILE})")
    try:
        config = json.loads(config_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise PolicyFormatError(f"{config_path}: not valid JSON ({exc})") from None
    if not isinstance(config, dict) or config.get("kind") not in KINDS:
        kind = config.get("kind") if isinstance(config, dict) else None
        raise PolicyFormatError(f"{config_path}: unknown policy kind {kind!r}; this version loads {KINDS}")
    architecture = config.get("architecture")
    if not isinstance(architecture, dict) or any(k not in architecture for k in ARCHITECTURE_KEYS):
        raise PolicyFormatError(f"{config_path}: 'architecture' must hold {ARCHITECTURE_KEYS}")
    if "lstm_size" in architecture:
        raise PolicyFormatError(f"{path}: {RECURRENT_RETIRED}")
    if architecture["activation"] not in ACTIVATION_NAMES:
        raise PolicyFormatError(f"{config_path}: unknown activation {architecture['activation']!r}")
    try:
        weights = load_file(str(weights_path))
    except (SafetensorError, OSError) as exc:
        raise PolicyFormatError(f"{weights_path}: unreadable safetensors file ({exc})") from None
    try:
        return GreedyMLPPolicy(weights, config)
    except (KeyError, ValueError) as exc:
        raise PolicyFormatError(f"{path}: {exc}") from None


def load_policy_or_baseline(spec: str | Path, config: NavConfig | None = None):
    """``load_policy(spec)``, or the goal-seeking baseline for ``config`` when ``spec`` is
    ``heuristic`` and no directory of that name exists. A missing directory is a
    :class:`PolicyFormatError` naming it."""
    path = Path(spec)
    if str(spec) == HEURISTIC and not path.exists():
        return goal_seeking_policy(config)
    if not path.is_dir():
        raise PolicyFormatError(f"{path}: no such policy directory (or {HEURISTIC!r} for the baseline)")
    return load_policy(path)

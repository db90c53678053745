"""Saved policies: one on-disk format for every learner, and ``load_policy`` to evaluate any of them.

A policy directory holds two files (written atomically, temp + rename):

* ``model.safetensors`` - the weights of an MLP in ``nn.Sequential`` layout (TorchRL's
  ``MLP``): ``"0.weight"``, ``"0.bias"``, ``"2.weight"``, ... one linear layer at every
  even index, the activation between them; float32.
* ``config.json`` - ``{"model": name, "kind": kind, "version": int, "architecture":
  {"obs_dim", "n_actions", "hidden_sizes", "activation"}, ...}`` plus any metadata.

``kind`` says what the network outputs: ``"q_network"`` (Q-values, NNQL) or
``"policy_logits"`` (action logits, imitation and NIRL neural policies). Both are
evaluated greedily (argmax over actions), with numpy only, so loading a policy
needs no torch.

``load_policy_or_baseline`` also accepts the name ``heuristic``: the goal-seeking
baseline of :mod:`worlds.heuristics`, for comparing a learned policy with it.
"""

from __future__ import annotations

import itertools
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from agents.nnql.policy import mlp_forward, q_layers
from worlds.config import NavConfig
from worlds.heuristics import goal_seeking_policy

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
KINDS = ("q_network", "policy_logits")
ACTIVATIONS = ("relu", "tanh", "elu")
ARCHITECTURE_KEYS = ("obs_dim", "n_actions", "hidden_sizes", "activation")
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
        self.layers = q_layers(weights)
        sizes = [
            self.architecture["obs_dim"],
            *self.architecture["hidden_sizes"],
            self.architecture["n_actions"],
        ]
        expected = list(itertools.pairwise(sizes))
        got = [w.shape for w, _ in self.layers]
        if got != expected or any(b.shape != (w.shape[1],) for w, b in self.layers):
            raise PolicyFormatError(
                f"weights do not fit the architecture: layer shapes {got}, expected {expected}"
            )

    @property
    def obs_dim(self) -> int:
        return int(self.architecture["obs_dim"])

    def outputs(self, obs: np.ndarray) -> np.ndarray:
        """The network's outputs (Q-values or logits), ``(N, n_actions)``."""
        obs = np.asarray(obs, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.obs_dim:
            raise ValueError(f"expected observations (N, {self.obs_dim}), got {obs.shape}")
        return mlp_forward(self.layers, self.architecture["activation"], obs)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return self.outputs(obs).argmax(axis=1).astype(np.int64)

    def __repr__(self) -> str:
        return f"GreedyMLPPolicy(model={self.model!r}, kind={self.kind!r}, version={self.version})"


def save_policy(
    path: str | Path,
    weights: dict[str, np.ndarray],
    architecture: dict[str, Any],
    model: str,
    kind: str,
    version: int = 0,
    **metadata: Any,
) -> Path:
    """Write a policy directory (see the module docstring); returns its path."""
    from safetensors.numpy import save_file

    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    missing = [k for k in ARCHITECTURE_KEYS if k not in architecture]
    if missing:
        raise ValueError(f"architecture lacks {missing}")
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    config = {
        "model": model,
        "kind": kind,
        "version": int(version),
        "architecture": dict(architecture),
        **metadata,
    }
    tensors = {name: np.ascontiguousarray(value, dtype=np.float32) for name, value in weights.items()}
    save_file(tensors, str(path / (WEIGHTS_FILE + ".tmp")))
    os.replace(path / (WEIGHTS_FILE + ".tmp"), path / WEIGHTS_FILE)
    (path / (CONFIG_FILE + ".tmp")).write_text(json.dumps(config, indent=2, sort_keys=True) + "\n")
    os.replace(path / (CONFIG_FILE + ".tmp"), path / CONFIG_FILE)
    return path


def load_policy(path: str | Path) -> GreedyMLPPolicy:
    """The greedy policy saved in directory ``path`` by any navlearn learner."""
    from safetensors import SafetensorError
    from safetensors.numpy import load_file

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
    if architecture["activation"] not in ACTIVATIONS:
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

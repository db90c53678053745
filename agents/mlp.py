"""The MLP every navlearn learner saves, in numpy: its layers, forward pass and files.

The policy directory's format (``model.safetensors`` in ``nn.Sequential`` layout + ``config.json``)
is described in :mod:`agents.evaluation.policies`; :func:`save_policy` here is its one writer. Shared
by ``agents.nnql.policy`` (actors) and ``agents.evaluation.policies`` (``load_policy`` for any
learner's policy); numpy only, no torch.
"""

from __future__ import annotations

import itertools
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from safetensors.numpy import save_file

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
KINDS = ("q_network", "policy_logits")
ACTIVATION_NAMES = ("relu", "tanh", "elu")
"""the hidden activations every navlearn network takes, by name (the one list; torch classes in
agents.nnql.networks.ACTIVATIONS, numpy in :func:`activate`)"""
ARCHITECTURE_KEYS = ("obs_dim", "n_actions", "hidden_sizes", "activation")

Layers = list[tuple[np.ndarray, np.ndarray]]


def mlp_layers(weights: dict[str, np.ndarray]) -> Layers:
    """(W^T, b) per linear layer, in order, from ``"<index>.weight"/"<index>.bias"`` names."""
    indices = sorted({int(name.split(".")[0]) for name in weights})
    layers = []
    for index in indices:
        weight = np.ascontiguousarray(np.asarray(weights[f"{index}.weight"], dtype=np.float32).T)
        bias = np.asarray(weights[f"{index}.bias"], dtype=np.float32)
        layers.append((weight, bias))
    return layers


def check_layers(layers: Layers, architecture: dict[str, Any]) -> Layers:
    """``layers`` if their shapes are those of ``architecture``'s MLP, else ValueError naming both."""
    sizes = [architecture["obs_dim"], *architecture["hidden_sizes"], architecture["n_actions"]]
    expected = list(itertools.pairwise(sizes))
    got = [w.shape for w, _ in layers]
    if got != expected or any(b.shape != (w.shape[1],) for w, b in layers):
        raise ValueError(f"weights do not fit the architecture: layer shapes {got}, expected {expected}")
    return layers


def mlp_forward(layers: Layers, activation: str, obs: np.ndarray) -> np.ndarray:
    """Outputs (N, n_actions) of a batch of observations (N, obs_dim)."""
    x = np.asarray(obs, dtype=np.float32)
    for i, (weight, bias) in enumerate(layers):
        x = x @ weight + bias
        if i < len(layers) - 1:
            x = activate(x, activation)
    return x


def activate(x: np.ndarray, activation: str) -> np.ndarray:
    """The hidden activation applied to ``x`` (in place where numpy allows)."""
    if activation == "relu":
        return np.maximum(x, 0.0, out=x)
    if activation == "tanh":
        return np.tanh(x, out=x)
    if activation == "elu":
        return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))
    raise ValueError(f"unknown activation {activation!r}")


def save_policy(
    path: str | Path,
    weights: dict[str, np.ndarray],
    architecture: dict[str, Any],
    model: str,
    kind: str,
    version: int = 0,
    **metadata: Any,
) -> Path:
    """Write a policy directory (see the module docstring); returns its path. The one writer of the format."""
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

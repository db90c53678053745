"""The NNQL control policy for actors and evaluation: built from weights, numpy for MLPs.

Actors never hold a learner: they get a ``dict[str, np.ndarray]`` of weights (from a
WeightsUpdate or a policy directory) plus the architecture dict, and act on a batch
of observations at once. Exploration is the thesis' stochastic policy - Boltzmann
(softmax of Q / temperature) with a decaying temperature - or epsilon-greedy; greedy
for evaluation. No torch import here, so an actor process starts fast; a Q-network with a CNN
over the own-map patch runs the learner's torch module (:mod:`agents.forward`).

On disk a policy is a directory with ``model.safetensors`` (the weights) and
``config.json`` (model name, kind, architecture, version).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from safetensors.numpy import load_file

from agents.forward import network_forward
from agents.mlp import CONFIG_FILE, WEIGHTS_FILE, save_policy
from agents.nnql.config import NNQLConfig
from worlds.config import saved_observation

MODEL_NAME = "nnql"
POLICY_KIND = "q_network"
MODES = ("greedy", "boltzmann", "epsilon")


# ---------------------------------------------------------------- pure maths


def boltzmann_probabilities(q_values: np.ndarray, temperature: float) -> np.ndarray:
    """softmax(Q / temperature) along the last axis, numerically stable."""
    if temperature <= 0:
        raise ValueError(f"temperature must be > 0, got {temperature}")
    logits = (q_values - q_values.max(axis=-1, keepdims=True)) / temperature
    exp = np.exp(logits)
    return exp / exp.sum(axis=-1, keepdims=True)


def temperature_at(config: NNQLConfig, version: int) -> float:
    """Boltzmann temperature after ``version`` updates: geometric decay from start to end."""
    frac = min(max(version, 0) / max(config.temperature_decay_updates, 1), 1.0)
    return float(config.temperature_start * (config.temperature_end / config.temperature_start) ** frac)


def epsilon_at(config: NNQLConfig, version: int) -> float:
    """Epsilon after ``version`` updates: linear decay from start to end."""
    frac = min(max(version, 0) / max(config.epsilon_decay_updates, 1), 1.0)
    return float(config.epsilon_start + frac * (config.epsilon_end - config.epsilon_start))


# ---------------------------------------------------------------- the policy


class NNQLPolicy:
    """Vectorised Q-network policy: ``policy(obs (N, obs_dim)) -> actions (N,) int64``.

    mode "greedy" (argmax Q, ties to the lowest action), "boltzmann" (sample from
    softmax(Q / temperature)) or "epsilon" (uniform with probability epsilon, else
    greedy). ``explore_as(config, version)`` sets mode and parameter from the config's
    schedules, which is what actors call when new weights arrive.
    """

    def __init__(
        self,
        weights: dict[str, np.ndarray],
        architecture: dict[str, Any],
        *,
        mode: str = "greedy",
        temperature: float = 1.0,
        epsilon: float = 0.0,
        version: int = 0,
        seed: int | None = None,
        observation: dict[str, Any] | None = None,
    ):
        if mode not in MODES:
            raise ValueError(f"unknown policy mode {mode!r}; expected one of {MODES}")
        self.architecture = dict(architecture)
        self.observation = None if observation is None else dict(observation)
        """the observation settings (worlds.config.OBSERVATION_FIELDS) it was trained with, if known"""
        self.mode = mode
        self.temperature = float(temperature)
        self.epsilon = float(epsilon)
        self.rng = np.random.default_rng(seed)
        self.set_weights(weights, version)

    def set_weights(self, weights: dict[str, np.ndarray], version: int | None = None) -> None:
        """Swap in new weights (same architecture); shapes are checked."""
        if getattr(self, "forward", None) is None:
            self.forward = network_forward(weights, self.architecture)
        else:
            self.forward.load(weights)
        if version is not None:
            self.version = int(version)

    def explore_as(self, schedule: NNQLConfig, version: int) -> None:
        """Behaviour-policy exploration for policy version ``version``: ``schedule`` is the NNQLConfig
        (local training) or the ``protocols.messages.ExplorationSchedule`` a WeightsUpdate carries
        (actors; same field names, and a schedule may leave the unused mode's fields None)."""
        self.mode = schedule.exploration
        if schedule.temperature_start is not None:
            self.temperature = temperature_at(schedule, version)
        if schedule.epsilon_start is not None:
            self.epsilon = epsilon_at(schedule, version)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.architecture["obs_dim"]:
            raise ValueError(f"expected observations (N, {self.architecture['obs_dim']}), got {obs.shape}")
        return self.forward(obs)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        q = self.q_values(obs)
        greedy = q.argmax(axis=1)
        if self.mode == "greedy":
            return greedy.astype(np.int64)
        if self.mode == "epsilon":
            explore = self.rng.random(len(q)) < self.epsilon
            random_actions = self.rng.integers(0, q.shape[1], size=len(q))
            return np.where(explore, random_actions, greedy).astype(np.int64)
        probs = boltzmann_probabilities(q, self.temperature)
        cumulative = probs.cumsum(axis=1)
        draws = self.rng.random((len(q), 1)) * cumulative[:, -1:]
        return np.minimum((draws > cumulative).sum(axis=1), q.shape[1] - 1).astype(np.int64)

    def greedy(self) -> NNQLPolicy:
        """A greedy copy with a copy of the weights (for evaluation)."""
        policy = NNQLPolicy.__new__(NNQLPolicy)
        policy.__dict__.update(self.__dict__)
        policy.forward = network_forward(self.get_weights(), self.architecture)
        policy.mode = "greedy"
        return policy

    # ------------------------------------------------------------ files

    def get_weights(self) -> dict[str, np.ndarray]:
        """A copy of the weights, named as ``set_weights`` takes them."""
        return self.forward.weights()

    def save(self, path: str | Path, **metadata: Any) -> Path:
        """Write ``model.safetensors`` + ``config.json`` (with the observation settings, when known)."""
        if self.observation is not None:
            metadata.setdefault("observation", self.observation)
        return save_policy_dir(path, self.get_weights(), self.architecture, self.version, **metadata)

    @classmethod
    def load(cls, path: str | Path, **kwargs: Any) -> NNQLPolicy:
        """Read a policy directory written by ``save``/``save_policy_dir`` (greedy unless told)."""
        weights, config = load_policy_dir(path)
        kwargs.setdefault("version", config.get("version", 0))
        kwargs.setdefault("observation", saved_observation(config.get("observation")))
        return cls(weights, config["architecture"], **kwargs)


def save_policy_dir(
    path: str | Path,
    weights: dict[str, np.ndarray],
    architecture: dict[str, Any],
    version: int,
    **metadata: Any,
) -> Path:
    """Weights as safetensors plus a JSON config (:func:`agents.mlp.save_policy`)."""
    return save_policy(path, weights, architecture, MODEL_NAME, POLICY_KIND, version, **metadata)


def load_policy_dir(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(weights, config) of a policy directory; a clear error if it is not an NNQL policy."""
    path = Path(path)
    config_path, weights_path = path / CONFIG_FILE, path / WEIGHTS_FILE
    if not config_path.is_file() or not weights_path.is_file():
        raise FileNotFoundError(f"{path}: expected {CONFIG_FILE} and {WEIGHTS_FILE}")
    config = json.loads(config_path.read_text())
    if config.get("model") != MODEL_NAME:
        raise ValueError(f"{config_path}: model is {config.get('model')!r}, not {MODEL_NAME!r}")
    return load_file(str(weights_path)), config

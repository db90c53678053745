"""The recurrent NNQL policy for actors and evaluation: numpy only, one LSTM state per robot.

The network (agents/nnql/recurrent_net.py trains it) is an MLP encoder, an LSTM and an MLP
Q head; its weights travel as a ``dict[str, np.ndarray]`` named as the torch module's
``state_dict``: ``encoder.0.weight``, ``lstm.lstm.weight_ih_l0`` ..., ``head.0.weight`` ...
The architecture dict adds ``lstm_size`` to the feed-forward one, which is how a policy
directory says it is recurrent (:func:`is_recurrent`).

``policy(obs (N, obs_dim))`` advances each robot's (h, c) by one step and returns actions;
``input_state`` keeps the state the last call started from (what R2D2 stores with a
transition), ``reset_state(mask)`` zeroes the robots whose episode ended (or resizes the
state to ``len(mask)`` robots, all zero). Exploration (Boltzmann, epsilon, greedy) is the
feed-forward policy's (:class:`agents.nnql.policy.NNQLPolicy`), only the forward pass differs.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import numpy as np

from agents.mlp import activate, mlp_forward, mlp_layers
from agents.nnql.policy import NNQLPolicy, load_policy_dir
from worlds.config import saved_observation

LSTM_PREFIX = "lstm.lstm."
"""weight names of the LSTM inside the torch module (TorchRL's LSTMModule wraps an nn.LSTM as .lstm)"""


def is_recurrent(architecture: dict[str, Any]) -> bool:
    """Whether an architecture dict (config.json's, or a learner's) describes the recurrent Q-network."""
    return "lstm_size" in architecture


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (np.tanh(0.5 * x) + 1.0)


class RecurrentQ:
    """Numpy forward pass of the recurrent Q-network, shapes checked against the architecture."""

    def __init__(self, weights: dict[str, np.ndarray], architecture: dict[str, Any]):
        arch = architecture
        hidden, size = [int(h) for h in arch["hidden_sizes"]], int(arch["lstm_size"])
        part = {"encoder": {}, "head": {}}
        for name, value in weights.items():
            prefix, _, rest = name.partition(".")
            if prefix in part:
                part[prefix][rest] = value
        self.encoder = mlp_layers(part["encoder"])
        self.head = mlp_layers(part["head"])
        f32 = np.float32
        self.w_ih = np.ascontiguousarray(np.asarray(weights[LSTM_PREFIX + "weight_ih_l0"], f32).T)
        self.w_hh = np.ascontiguousarray(np.asarray(weights[LSTM_PREFIX + "weight_hh_l0"], f32).T)
        self.bias = np.asarray(weights[LSTM_PREFIX + "bias_ih_l0"], f32) + np.asarray(
            weights[LSTM_PREFIX + "bias_hh_l0"], f32
        )
        head_sizes = [size, *hidden[1:], int(arch["n_actions"])]
        expected = {
            "encoder": [(int(arch["obs_dim"]), hidden[0])],
            "head": list(itertools.pairwise(head_sizes)),
            "lstm": [(hidden[0], 4 * size), (size, 4 * size)],
        }
        got = {
            "encoder": [w.shape for w, _ in self.encoder],
            "head": [w.shape for w, _ in self.head],
            "lstm": [self.w_ih.shape, self.w_hh.shape],
        }
        if got != expected or self.bias.shape != (4 * size,):
            raise ValueError(f"weights do not fit the recurrent architecture: {got}, expected {expected}")
        self.activation = arch["activation"]
        self.size = size

    def step(
        self, obs: np.ndarray, h: np.ndarray, c: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Q (N, n_actions), h', c') after one step from state (h, c), each (N, lstm_size)."""
        x = activate(mlp_forward(self.encoder, self.activation, obs), self.activation)
        gates = x @ self.w_ih + h @ self.w_hh + self.bias
        n = self.size
        i, f = _sigmoid(gates[:, :n]), _sigmoid(gates[:, n : 2 * n])
        g, o = np.tanh(gates[:, 2 * n : 3 * n]), _sigmoid(gates[:, 3 * n :])
        c = f * c + i * g
        h = o * np.tanh(c)
        return mlp_forward(self.head, self.activation, h), h, c


class Memory:
    """One LSTM state (h, c) per robot, stepped by a :class:`RecurrentQ`."""

    def __init__(self, size: int):
        self.size = int(size)
        self.reset(np.zeros(0, bool))

    def reset(self, done: np.ndarray) -> None:
        """Zero the state of robots where ``done``; a batch of another size starts all at zero."""
        done = np.asarray(done, bool)
        if not hasattr(self, "h") or len(self.h) != len(done):
            self.h = np.zeros((len(done), self.size), np.float32)
            self.c = np.zeros_like(self.h)
        else:
            self.h[done] = 0.0
            self.c[done] = 0.0
        self.input_state = (self.h.copy(), self.c.copy())
        """the state the last ``advance`` started from (what a transition stores)"""

    def advance(self, net: RecurrentQ, obs: np.ndarray) -> np.ndarray:
        """Q-values (N, n_actions) of one step of every robot; their states move on."""
        if len(self.h) != len(obs):
            raise ValueError(f"the memory holds the state of {len(self.h)} robots, got {len(obs)}: reset it")
        self.input_state = (self.h, self.c)
        q, self.h, self.c = net.step(obs, self.h, self.c)
        return q


class RecurrentNNQLPolicy(NNQLPolicy):
    """:class:`NNQLPolicy` over the recurrent Q-network, with one (h, c) per robot (:class:`Memory`)."""

    def set_weights(self, weights: dict[str, np.ndarray], version: int | None = None) -> None:
        self.net = RecurrentQ(weights, self.architecture)
        self.weights = {name: np.asarray(value, np.float32).copy() for name, value in weights.items()}
        if version is not None:
            self.version = int(version)
        if not hasattr(self, "memory"):
            self.memory = Memory(self.net.size)

    def reset_state(self, done: np.ndarray) -> None:
        """Zero the memory of robots where ``done`` (see :meth:`Memory.reset`)."""
        self.memory.reset(done)

    @property
    def input_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.memory.input_state

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """Q-values of one step of every robot; advances their memory."""
        obs = np.asarray(obs, dtype=np.float32)
        if obs.ndim != 2 or obs.shape[1] != self.architecture["obs_dim"]:
            raise ValueError(f"expected observations (N, {self.architecture['obs_dim']}), got {obs.shape}")
        return self.memory.advance(self.net, obs)

    def greedy(self) -> RecurrentNNQLPolicy:
        """A greedy copy sharing the weights, with a memory of its own."""
        policy = RecurrentNNQLPolicy.__new__(RecurrentNNQLPolicy)
        policy.__dict__.update(self.__dict__)
        policy.mode = "greedy"
        policy.memory = Memory(self.net.size)
        return policy

    def get_weights(self) -> dict[str, np.ndarray]:
        return {name: value.copy() for name, value in self.weights.items()}

    @classmethod
    def load(cls, path: str | Path, **kwargs: Any) -> RecurrentNNQLPolicy:
        weights, config = load_policy_dir(path)
        if not is_recurrent(config["architecture"]):
            raise ValueError(f"{path}: a feed-forward Q-network, not a recurrent one (no lstm_size)")
        kwargs.setdefault("version", config.get("version", 0))
        kwargs.setdefault("observation", saved_observation(config.get("observation")))
        return cls(weights, config["architecture"], **kwargs)

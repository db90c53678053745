"""A neural navigation policy learned from demonstrations by back-propagation (thesis ch. 3).

The dataset extracted from the demonstrations pairs each observation the robot
had with the action the expert took there. An MLP maps the observation to action
logits and is trained with cross-entropy (behaviour cloning). Episodes - not
steps - are split into training and validation sets, so validation measures
generalisation to unseen runs; training stops when the validation loss has not
improved for ``patience`` epochs, and the best epoch's weights are kept.
Everything is seeded. The result is saved in the shared policy format
(``agents.evaluation.policies``: safetensors + JSON, kind ``policy_logits``).
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torchrl.modules import MLP

from agents.demos import Demo
from agents.evaluation.policies import GreedyMLPPolicy, save_policy
from agents.imitation.config import ImitationConfig
from agents.nnql.networks import activation_class

MODEL_NAME = "imitation"


@dataclass
class TrainResult:
    """The trained network and how training went."""

    network: nn.Module
    architecture: dict
    history: list[dict] = field(default_factory=list)
    best_epoch: int = 0
    train_steps: int = 0
    val_steps: int = 0
    observation: dict | None = None
    """the observation settings of the demonstrations (worlds.config.observation_settings); None: legacy"""

    @property
    def best(self) -> dict:
        return self.history[self.best_epoch]

    def policy(self) -> GreedyMLPPolicy:
        """The greedy numpy policy of the best weights (what ``load_policy`` would return)."""
        weights = {k: v.detach().cpu().numpy() for k, v in self.network.state_dict().items()}
        config = {"model": MODEL_NAME, "kind": "policy_logits", "architecture": self.architecture}
        if self.observation is not None:
            config["observation"] = self.observation
        return GreedyMLPPolicy(weights, config)


def extract_dataset(demos: Sequence[Demo]) -> tuple[np.ndarray, np.ndarray]:
    """(observation, label) pairs: each step's observation with the expert's choice there
    (``Demo.labels``: its own action even where noise made the robot do something else)."""
    if not demos:
        raise ValueError("no demonstrations")
    obs = np.concatenate([d.observations[:-1] for d in demos]).astype(np.float32)
    actions = np.concatenate([d.labels for d in demos]).astype(np.int64)
    return obs, actions


def split_episodes(n_episodes: int, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of training and validation episodes (at least one of each when n >= 2)."""
    if n_episodes < 2:
        raise ValueError(f"need at least 2 demonstrations to hold some out, got {n_episodes}")
    order = np.random.default_rng([seed, 17]).permutation(n_episodes)
    n_val = min(n_episodes - 1, max(1, round(val_fraction * n_episodes)))
    return np.sort(order[n_val:]), np.sort(order[:n_val])


def _loss_and_accuracy(network: nn.Module, obs: torch.Tensor, actions: torch.Tensor) -> tuple[float, float]:
    with torch.no_grad():
        logits = network(obs)
        loss = nn.functional.cross_entropy(logits, actions).item()
        accuracy = (logits.argmax(dim=1) == actions).float().mean().item()
    return loss, accuracy


def train_policy(
    demos: Sequence[Demo],
    config: ImitationConfig | None = None,
    n_actions: int | None = None,
    on_epoch: Callable[[dict], None] | None = None,
    observation: dict | None = None,
) -> TrainResult:
    """Train the MLP policy on ``demos`` (agents.demos.Demo, or agents.env_demos.EnvDemo of a user's env:
    anything with ``observations`` and ``labels``); ``on_epoch(record)`` sees each epoch's figures.
    ``observation``: the settings the demonstrations were recorded in, kept with the policy."""
    config = config or ImitationConfig()
    train_idx, val_idx = split_episodes(len(demos), config.val_fraction, config.seed)
    x_train, y_train = extract_dataset([demos[i] for i in train_idx])
    x_val, y_val = extract_dataset([demos[i] for i in val_idx])
    obs_dim = x_train.shape[1]
    n_actions = int(n_actions or max(y_train.max(), y_val.max()) + 1)
    architecture = {
        "obs_dim": int(obs_dim),
        "n_actions": n_actions,
        "hidden_sizes": [int(h) for h in config.hidden_sizes],
        "activation": config.activation,
    }
    torch.set_num_threads(config.torch_threads)
    torch.manual_seed(config.seed)
    network = MLP(
        in_features=obs_dim,
        out_features=n_actions,
        num_cells=list(config.hidden_sizes),
        activation_class=activation_class(config.activation),
    )
    optimiser = torch.optim.Adam(network.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    xt, yt = torch.from_numpy(x_train), torch.from_numpy(y_train)
    xv, yv = torch.from_numpy(x_val), torch.from_numpy(y_val)
    generator = torch.Generator().manual_seed(config.seed)
    result = TrainResult(
        network, architecture, train_steps=len(yt), val_steps=len(yv), observation=observation
    )
    best_loss, best_state, since_best = float("inf"), copy.deepcopy(network.state_dict()), 0
    for epoch in range(config.max_epochs):
        network.train()
        order = torch.randperm(len(yt), generator=generator)
        for lo in range(0, len(order), config.batch_size):
            batch = order[lo : lo + config.batch_size]
            loss = nn.functional.cross_entropy(network(xt[batch]), yt[batch])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
        network.eval()
        train_loss, train_acc = _loss_and_accuracy(network, xt, yt)
        val_loss, val_acc = _loss_and_accuracy(network, xv, yv)
        record = {"epoch": epoch, "train_loss": train_loss, "train_accuracy": train_acc,
                  "val_loss": val_loss, "val_accuracy": val_acc}  # fmt: skip
        result.history.append(record)
        if on_epoch is not None:
            on_epoch(record)
        if val_loss < best_loss:
            best_loss, best_state, since_best = val_loss, copy.deepcopy(network.state_dict()), 0
            result.best_epoch = epoch
        else:
            since_best += 1
            if since_best >= config.patience:
                break
    network.load_state_dict(best_state)
    return result


def save_trained(path: str | Path, result: TrainResult, config: ImitationConfig, **metadata) -> Path:
    """Write the best weights and the training summary in the shared policy format."""
    weights = {k: v.detach().cpu().numpy() for k, v in result.network.state_dict().items()}
    return save_policy(
        path,
        weights,
        result.architecture,
        model=MODEL_NAME,
        kind="policy_logits",
        version=1,
        training={
            "config": asdict(config),
            "best_epoch": result.best_epoch,
            "epochs": len(result.history),
            "train_steps": result.train_steps,
            "val_steps": result.val_steps,
            **{k: round(v, 6) for k, v in result.best.items() if k != "epoch"},
        },
        **({} if result.observation is None else {"observation": result.observation}),
        **metadata,
    )

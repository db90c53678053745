"""NIRL on disk: the policy directory (shared format + the reward network) and checkpoints."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import torch
from safetensors.numpy import save_file

from agents.mlp import save_policy
from agents.replay_files import load_replay, save_replay

MODEL_NAME = "nirl"
REWARD_FILE = "reward.safetensors"
STATE_FILE = "nirl.pt"


def save_policy_files(learner: Any, path: str | Path, **metadata: Any) -> Path:
    """The Q-network in the shared policy format (``agents.mlp``: model "nirl",
    kind "q_network", loadable by ``navlearn evaluate``) plus ``reward.safetensors``."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    save_file(learner.reward_weights(), str(path / (REWARD_FILE + ".tmp")))
    os.replace(path / (REWARD_FILE + ".tmp"), path / REWARD_FILE)
    metadata.setdefault("nirl_config", learner.config.to_dict())
    return save_policy(
        path,
        learner.get_weights(),
        learner.q.architecture,
        model=MODEL_NAME,
        kind="q_network",
        version=learner.version,
        reward_architecture=learner.reward.architecture,
        iteration=learner.iteration,
        **metadata,
    )


def save_checkpoint(learner: Any, path: str | Path) -> Path:
    """A directory with q/ (the NNQLLearner checkpoint), nirl.pt (reward network, optimiser,
    counters) and demos/ when the learner owns its demonstration buffer; replaced atomically."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    learner.q.save_checkpoint(tmp / "q")
    torch.save(learner.state_dict(), tmp / STATE_FILE)
    if learner.owns_demos and len(learner.demos):
        save_replay(learner.demos, tmp / "demos")
    old = path.with_name(f".{path.name}.old{os.getpid()}")
    if path.exists():
        os.replace(path, old)
    os.replace(tmp, path)
    shutil.rmtree(old, ignore_errors=True)
    return path


def load_checkpoint(learner: Any, path: str | Path) -> None:
    path = Path(path)
    learner.q.load_checkpoint(path / "q")
    learner.load_state_dict(torch.load(path / STATE_FILE, weights_only=True))
    if learner.owns_demos and (path / "demos").exists():
        load_replay(learner.demos, path / "demos")

"""NIRL on disk: the policy directory (shared format + the reward network), the learner's state
(reward network, optimiser, frozen prior, counters) and checkpoints, loadable on any device."""

from __future__ import annotations

import copy
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from safetensors.numpy import save_file
from safetensors.torch import load_file

from agents.mlp import save_policy
from agents.nirl.config import FORMAT_VERSION, SAVED_WITHOUT
from agents.nirl.networks import RewardNetwork
from agents.nirl.progress import ProgressPotential
from agents.nnql.persistence import replace_dir
from agents.replay_files import load_replay, save_replay

if TYPE_CHECKING:  # the learner calls these functions with itself; typing only, no import cycle at run time
    from agents.nirl.learner import NIRLLearner

MODEL_NAME = "nirl"
REWARD_FILE = "reward.safetensors"
POTENTIAL_FILE = "potential.safetensors"
"""the progress potential's weights (``NIRLConfig.fixed_reward = "progress"``), beside the reward's"""
STATE_FILE = "nirl.pt"


def save_policy_files(learner: NIRLLearner, path: str | Path, **metadata: Any) -> Path:
    """The Q-network in the shared policy format (``agents.mlp``: model "nirl",
    kind "q_network", loadable by ``navlearn evaluate``) plus ``reward.safetensors`` and, with a
    progress potential, ``potential.safetensors`` (``navlearn nirl reward`` draws both)."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    files = {REWARD_FILE: learner.reward_weights()}
    potential = learner.potential
    if potential is not None:
        files[POTENTIAL_FILE] = {k: t.detach().cpu().numpy() for k, t in potential.mlp.state_dict().items()}
        metadata.setdefault("potential_architecture", potential.architecture)
    for name, weights in files.items():
        save_file(weights, str(path / (name + ".tmp")))
        os.replace(path / (name + ".tmp"), path / name)
    metadata.setdefault("nirl_config", learner.config.to_dict())
    if learner.q.observation is not None:
        metadata.setdefault("observation", learner.q.observation)
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


def load_potential(path: str | Path) -> ProgressPotential | None:
    """The progress potential a policy directory holds (``potential.safetensors`` and its architecture
    in config.json, as :func:`save_policy_files` writes them), None if it has none."""
    path = Path(path)
    config = path / "config.json"
    architecture = json.loads(config.read_text()).get("potential_architecture") if config.is_file() else None
    if architecture is None or not (path / POTENTIAL_FILE).is_file():
        return None
    potential = ProgressPotential.from_architecture(architecture)
    potential.mlp.load_state_dict(load_file(str(path / POTENTIAL_FILE)))
    return potential.eval()


def nirl_state(learner: NIRLLearner) -> dict[str, Any]:
    """Reward network, its optimiser, the frozen prior, the progress potential (if any), whether the
    reward is fixed, and NIRL's counters (the Q side is NNQLLearner's)."""
    potential = learner.potential
    return {
        "format": FORMAT_VERSION,
        "config": learner.config.to_dict(),
        "reward_architecture": learner.reward.architecture,
        "reward": learner.reward.state_dict(),
        "reward_optimizer": learner.reward_optimizer.state_dict(),
        "prior_network": None if learner.prior_network is None else learner.prior_network.state_dict(),
        "potential": None if potential is None else potential.state_dict(),
        "reward_fixed": learner.reward_fixed,
        "counters": {
            "iteration": learner.iteration,
            "reward_steps": learner.reward_steps,
            "warm_updates": learner.warm_updates,
            "reward_credit": learner.reward_credit,
            "demo_episodes": learner.demo_episodes,
            "demo_path_steps": learner.demo_path_steps,
        },
    }


def load_nirl_state(learner: NIRLLearner, state: Mapping[str, Any]) -> None:
    """Inverse of nirl_state. A state saved before cores existed (format 1) was the max-margin
    learner's: it loads into a learner with ``core="max_margin"`` and is refused, with the fix
    named, by the others."""
    version = int(state.get("format", 1))
    saved_config = SAVED_WITHOUT | state["config"]
    saved_core = saved_config["core"]
    core = learner.config.core
    if version > FORMAT_VERSION:
        raise ValueError(f"NIRL state format {version} is newer than this version reads ({FORMAT_VERSION})")
    if saved_core != core:
        raise ValueError(
            f"NIRL state was saved by the {saved_core!r} core (format {version}); this learner runs "
            f"{core!r}: load it with NIRLConfig(core={saved_core!r}) or start a fresh run"
        )
    saved_dueling = bool(saved_config["dueling"])
    if saved_dueling != learner.config.dueling:
        head = "a dueling" if saved_dueling else "a plain"
        flag = "--dueling" if saved_dueling else "--no-dueling"
        raise ValueError(
            f"NIRL state's Q-network has {head} head (dueling={saved_dueling}), this learner's "
            f"dueling={learner.config.dueling}: load it with NIRLConfig(dueling={saved_dueling}) ({flag}) "
            "or start a fresh run"
        )
    saved = RewardNetwork.from_architecture(state["reward_architecture"]).architecture
    if saved != learner.reward.architecture:
        raise ValueError(
            f"NIRL state's reward network {saved} differs from this learner's {learner.reward.architecture}"
        )
    learner.reward.load_state_dict(state["reward"])
    learner.reward_optimizer.load_state_dict(state["reward_optimizer"])
    if state.get("prior_network") is not None:
        learner.prior_network = copy.deepcopy(learner.q.network).requires_grad_(False)
        learner.prior_network.load_state_dict(state["prior_network"])
    potential = learner.potential
    if potential is not None and state.get("potential") is not None:
        saved_inputs = saved_config["potential_inputs"]
        if saved_inputs != learner.config.potential_inputs:
            raise ValueError(
                f"NIRL state's progress potential reads potential_inputs={saved_inputs!r}; this learner's "
                f"reads {learner.config.potential_inputs!r}: load it with "
                f"NIRLConfig(potential_inputs={saved_inputs!r}) (--potential-inputs {saved_inputs}) "
                "or start a fresh run"
            )
        potential.load_state_dict(state["potential"])
    if state.get("reward_fixed"):
        learner.fix_reward()
    counters = state["counters"]
    learner.iteration = int(counters["iteration"])
    learner.reward_steps = int(counters["reward_steps"])
    learner.warm_updates = int(counters["warm_updates"])
    learner.reward_credit = float(counters["reward_credit"])
    learner.demo_episodes = int(counters["demo_episodes"])
    learner.demo_path_steps = int(counters.get("demo_path_steps", 0))


def save_checkpoint(learner: NIRLLearner, path: str | Path) -> Path:
    """A directory with q/ (the NNQLLearner checkpoint), nirl.pt (reward network, optimiser,
    counters) and demos/ when the learner owns its demonstration buffer; replaced atomically."""

    def write(tmp: Path) -> None:
        learner.q.save_checkpoint(tmp / "q")
        torch.save(learner.state_dict(), tmp / STATE_FILE)
        if learner.owns_demos and len(learner.demos):
            save_replay(learner.demos, tmp / "demos")

    return replace_dir(path, write)


def load_checkpoint(learner: NIRLLearner, path: str | Path) -> None:
    path = Path(path)
    state = torch.load(path / STATE_FILE, map_location=learner.device, weights_only=True)
    try:  # first: its checks name the setting that loads it, before q/'s bare shape mismatch
        learner.load_state_dict(state)
    except ValueError as error:
        raise ValueError(f"NIRL checkpoint {path}: {error}") from error
    learner.q.load_checkpoint(path / "q")
    if learner.owns_demos and (path / "demos").exists():
        load_replay(learner.demos, path / "demos")

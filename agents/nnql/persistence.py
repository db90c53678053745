"""The NNQL learner's outputs: the policy version, saved policies and checkpoint directories.

A checkpoint is a directory: ``learner.pt`` (the learner's ``state_dict``), ``replay/`` (its
``save_replay``) and ``policy/`` (its ``save_policy``), written beside its final path and swapped
in atomically, so a crash leaves either the old checkpoint or the new one.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from agents.nnql.config import NNQLConfig
from agents.nnql.policy import save_policy_dir
from worlds.config import NavConfig, observation_differences, saved_observation, with_observation

CHECKPOINT_STATE = "learner.pt"
CHECKPOINT_REPLAY = "replay"
CHECKPOINT_POLICY = "policy"


def check_checkpoint_observation(saved: dict | None, mine: dict | None) -> None:
    """Raise a ValueError naming every observation setting (``worlds.config.observation_settings``)
    where a checkpoint's network (``saved``) and this learner's (``mine``) differ; settings a record
    lacks did not exist when it was written (their legacy value, off)."""
    if saved is None or mine is None:
        return
    learner = with_observation(NavConfig(), saved_observation(mine))
    wrong = observation_differences(saved_observation(saved), learner, other="this learner")
    if wrong:
        raise ValueError(
            "the checkpoint's network observes " + ", ".join(wrong) + ": resume it with the "
            "--observation it was trained in, or give a new --run (or --checkpoint-dir)"
        )


def check_checkpoint_env(saved: dict | None, mine: dict | None) -> None:
    """Raise a ValueError naming both envs when a checkpoint's network was trained on another env
    (``worlds.own_env.EnvConfig.record``; None, or a checkpoint from before envs were recorded:
    navlearn's world) than this learner's."""
    if (saved or None) == (mine or None):
        return
    named = [
        "navlearn's world" if r is None else f"env {r['id']} {r.get('kwargs') or ''}".strip()
        for r in (saved, mine)
    ]
    fix = "no --env" if saved is None else f"--env {saved['id']}"
    raise ValueError(
        f"the checkpoint's network was trained on {named[0]}, this learner runs {named[1]}: resume it with "
        f"{fix} (and its --env-kwargs), or give a new --run (or --checkpoint-dir)"
    )


def replace_dir(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Have ``write`` fill a fresh directory beside ``path``, then swap it in for ``path``: a crash
    leaves either the old directory or the new one (a checkpoint's write)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    write(tmp)
    old = path.with_name(f".{path.name}.old{os.getpid()}")
    if path.exists():
        os.replace(path, old)
    os.replace(tmp, path)
    shutil.rmtree(old, ignore_errors=True)
    return path


class LearnerOutputs:
    """Mixin of an NNQL learner with ``config``, ``network`` (with an ``architecture``), ``observation``,
    ``updates``, ``device`` and the methods ``get_weights``, ``state_dict`` / ``load_state_dict`` and
    ``save_replay`` / ``load_replay``."""

    config: NNQLConfig
    network: torch.nn.Module
    observation: dict[str, Any] | None
    env: dict[str, Any] | None = None
    """the Gymnasium env trained on (``worlds.own_env.EnvConfig.record``), recorded in saved policies so
    ``navlearn evaluate --policy`` rebuilds it; None: navlearn's world"""
    updates: int
    device: torch.device

    @property
    def architecture(self) -> dict[str, Any]:
        return dict(self.network.architecture)

    @property
    def version(self) -> int:
        """Policy version: the number of gradient updates so far."""
        return self.updates

    def save_policy(self, path: str | Path, **metadata: Any) -> Path:
        """model.safetensors + config.json (loadable by ``navlearn evaluate``), with the learner's
        config and the observation settings when known."""
        metadata.setdefault("nnql_config", self.config.to_dict())
        if self.observation is not None:
            metadata.setdefault("observation", self.observation)
        if self.env is not None:
            metadata.setdefault("env", self.env)
        return save_policy_dir(path, self.get_weights(), self.architecture, self.version, **metadata)

    def save_checkpoint(self, path: str | Path) -> Path:
        """A directory with learner.pt, replay/ and policy/, replaced atomically."""

        def write(tmp: Path) -> None:
            torch.save(self.state_dict(), tmp / CHECKPOINT_STATE)
            self.save_replay(tmp / CHECKPOINT_REPLAY)
            self.save_policy(tmp / CHECKPOINT_POLICY)

        return replace_dir(path, write)

    def load_checkpoint(self, path: str | Path) -> None:
        """Inverse of save_checkpoint (the policy/ copy is for readers, not needed here)."""
        path = Path(path)
        self.load_state_dict(torch.load(path / CHECKPOINT_STATE, map_location=self.device, weights_only=True))
        self.load_replay(path / CHECKPOINT_REPLAY)

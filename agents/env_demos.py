"""Demonstrations on a user's Gymnasium env (``--env``): recorded and read through Minari's own API.

navlearn's own demonstrations (agents.demos) carry its world's map, poses and expert plan; a user's env
has none of these, only what Gymnasium defines. A demonstrator - a trained policy directory or the
user's callable ``module:fn`` (flat observation -> action) - plays the env as NNQL takes it
(worlds.own_env.make_env: observations flattened); the observations, actions, rewards, terminations
and truncations of each episode go into Minari's ``EpisodeBuffer`` and ``create_dataset_from_buffers``
writes them as a Minari dataset with the env's Gymnasium spec where it has one (Minari's DataCollector
would need jax, which navlearn does not install). The dataset metadata adds ``navlearn_env``: the env's
record (worlds.own_env.EnvConfig.record: id, kwargs, module), the one thing a callable-made env has
no spec for. :func:`load_env_demos` reads it with
``minari.load_dataset`` and refuses, in one sentence naming both, a dataset recorded on another env
than the learner's, or whose spaces are not that env's.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.demos import ENV_KEY, DemoFormatError, clear_target, dataset_location, datasets_root
from worlds.own_env import EnvConfig, make_env


@dataclass
class EnvDemo:
    """One demonstration episode on a user's env: ``T + 1`` flat observations (the reset one first) and
    ``T`` actions, rewards, terminations and truncations."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray

    @property
    def labels(self) -> np.ndarray:
        """What behaviour cloning imitates: the actions taken."""
        return self.actions

    def __len__(self) -> int:
        return len(self.actions)


@dataclass
class RecordStats:
    """What a recording produced."""

    episodes: int
    steps: int
    mean_return: float


def env_name(record: dict[str, Any] | None) -> str:
    """An env record as the user wrote it: ``ID`` or ``ID {kwargs}``."""
    if not record:
        return "navlearn's world"
    kwargs = record.get("kwargs") or {}
    return record["id"] + (f" {json.dumps(kwargs, sort_keys=True)}" if kwargs else "")


def record_env_demos(
    path: str | Path,
    env: EnvConfig,
    act: Callable[[np.ndarray], int],
    episodes: int,
    seed: int = 0,
    demonstrator: str = "",
    overwrite: bool = False,
) -> tuple[Path, RecordStats]:
    """Play ``episodes`` episodes of ``env`` with ``act`` (one flat observation -> one action), episode
    ``i`` reset with ``seed + i``, and write them as the Minari dataset ``path`` (a directory named like
    ``NAME-v0``); ``demonstrator`` says who acted (kept as Minari's algorithm name)."""
    import minari
    from minari.data_collector import EpisodeBuffer

    if episodes < 1:
        raise ValueError(f"episodes={episodes}: need at least 1")
    target = clear_target(path, overwrite)
    root, dataset_id = target.parent, target.name
    played = make_env(env)
    buffers, returns = [], []
    try:
        for i in range(episodes):
            obs, _ = played.reset(seed=seed + i)
            rows: dict[str, list] = {"observations": [obs], "actions": [], "rewards": [],
                                     "terminations": [], "truncations": []}  # fmt: skip
            done = False
            while not done:
                action = int(act(obs))
                obs, reward, terminated, truncated, _ = played.step(action)
                for key, value in zip(rows, (obs, action, float(reward), terminated, truncated), strict=True):
                    rows[key].append(value)
                done = terminated or truncated
            returns.append(sum(rows["rewards"]))
            buffers.append(EpisodeBuffer(id=i, seed=seed + i, **rows))
        root.mkdir(parents=True, exist_ok=True)
        with datasets_root(root), warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # optional provenance fields left unset
            dataset = minari.create_dataset_from_buffers(
                dataset_id=dataset_id,
                buffer=buffers,
                env=played if played.spec is not None else None,  # its Gymnasium spec, where it has one
                observation_space=played.observation_space,
                action_space=played.action_space,
                algorithm_name=demonstrator or "navlearn demos record",
                author={"navlearn"},
                description=f"demonstrations on {env_name(env.record())} by {demonstrator or 'a callable'}",
            )
            dataset.storage.update_metadata({ENV_KEY: json.dumps(env.record(), sort_keys=True)})
    finally:
        played.close()
    steps = sum(len(b.actions) for b in buffers)
    return target, RecordStats(episodes, steps, float(np.mean(returns)))


def dataset_env(path: str | Path) -> dict[str, Any] | None:
    """The env record a dataset was recorded on (None: not a dataset of a user's env)."""
    import minari

    root, dataset_id = dataset_location(path)
    with datasets_root(root):
        metadata = minari.load_dataset(dataset_id).storage.metadata
    return json.loads(metadata[ENV_KEY]) if ENV_KEY in metadata else None


def load_env_demos(path: str | Path, env: EnvConfig) -> list[EnvDemo]:
    """The episodes of the dataset ``path`` recorded on ``env`` (:func:`record_env_demos`); a
    :class:`agents.demos.DemoFormatError` naming the file for a dataset of another env (both named),
    of other spaces, of navlearn's world, or one that does not load."""
    import minari

    root, dataset_id = dataset_location(path)
    target = root / dataset_id
    if not (target / "data").is_dir():
        raise DemoFormatError(f"{target}: no Minari dataset there (no data/ directory)")
    try:
        with datasets_root(root):
            dataset = minari.load_dataset(dataset_id)
        metadata = dataset.storage.metadata
    except Exception as exc:  # h5py/json/minari errors on damaged files: one clear line
        raise DemoFormatError(f"{target}: unreadable dataset ({type(exc).__name__}: {exc})") from None
    if ENV_KEY not in metadata:
        raise DemoFormatError(
            f"{target}: demonstrations of navlearn's world, not of --env {env.env}; record them on that env "
            "with `navlearn demos record --env ...`"
        )
    recorded = json.loads(metadata[ENV_KEY])
    if recorded != env.record():
        raise DemoFormatError(
            f"{target}: recorded on env {env_name(recorded)}, but this learner runs env "
            f"{env_name(env.record())}: give --env (and --env-kwargs) as recorded, or record on this env"
        )
    mine = make_env(env)
    try:
        spaces = (mine.observation_space, mine.action_space)
    finally:
        mine.close()
    if (dataset.observation_space, dataset.action_space) != spaces:
        raise DemoFormatError(
            f"{target}: its spaces {dataset.observation_space}, {dataset.action_space} are not env "
            f"{env_name(recorded)}'s {spaces[0]}, {spaces[1]} (the env changed since it was recorded?)"
        )
    return [
        EnvDemo(
            observations=np.asarray(ep.observations, dtype=np.float32).reshape(len(ep.actions) + 1, -1),
            actions=np.asarray(ep.actions, dtype=np.int64).reshape(-1),
            rewards=np.asarray(ep.rewards, dtype=np.float64),
            terminations=np.asarray(ep.terminations, dtype=bool),
            truncations=np.asarray(ep.truncations, dtype=bool),
        )
        for ep in dataset.iterate_episodes()
    ]

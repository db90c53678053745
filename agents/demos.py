"""Demonstrations at rest: Minari datasets written and read through Minari's own API.

A demonstration dataset is a directory ``PATH`` holding a Minari dataset whose
id is ``PATH.name`` in the datasets root ``PATH.parent`` (Minari's
``MINARI_DATASETS_PATH``): ``PATH/data/main_data.hdf5`` and
``PATH/data/metadata.json``. It is written with
``minari.create_dataset_from_buffers`` from ``minari.data_collector.EpisodeBuffer``
objects and read back with ``minari.load_dataset``.

One Minari episode per demonstration, holding the robot's own observations
(``T + 1`` rows, the reset observation first), actions, rewards,
terminations and truncations (``T`` rows), per-step infos aligned with the
observations (``T + 1`` rows): ``pose`` (``x, y, theta``) and, when the
actions were perturbed, ``expert_action`` (what the expert would have done at
that observation; -1 on the last row), and per-episode metadata stored as Minari episode
options (``options/<key>`` attributes):

=========== ==========================================================
map_id      the map's name
start, goal cells ``(row, col)``
source      ``astar`` (the expert), ``human`` or ``file``
seed        the seed of the episode's environment reset
noise       probability that the recorded action was a random one
outcome     the final ``worlds.outcomes.Outcome`` code
grid        the occupancy grid, ``np.packbits`` of ``blocked`` (with
            ``grid_shape`` and ``cell_size``), so the task can be rebuilt
=========== ==========================================================

The dataset metadata carries ``navlearn_format`` (:data:`FORMAT_VERSION`) and, in its
``navlearn`` JSON, ``observation``: the observation settings the robot recorded
(``worlds.config.observation_settings``, like a saved policy's ``config.json``). With the
own-map subgoal the observation depends on the trajectory, so a demonstration is recorded in the
observation it is meant for, never converted. A dataset written before that record observes
``worlds.config.LEGACY_OBSERVATION`` (8 beams + goal) when its width is that one's.
Loading checks the format, the spaces and every episode's arrays (and
``agents.demo_observation`` the observation against a learner's), and raises
:class:`DemoFormatError` with one clear message naming the file for anything else.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np

from worlds.config import NavConfig, with_observation
from worlds.maps import Cell, GridMap, Task
from worlds.perception import observation_dim

FORMAT_VERSION = 1
ENV_KEY = "navlearn_env"
"""the dataset metadata key of a demonstration set of a user's Gymnasium env (agents.env_demos): the
env's record as JSON"""
SOURCES = ("astar", "human", "file")
_REQUIRED_OPTIONS = (
    "map_id",
    "start",
    "goal",
    "source",
    "noise",
    "outcome",
    "grid",
    "grid_shape",
    "cell_size",
)


class DemoFormatError(ValueError):
    """A demonstration dataset that cannot be used (missing, corrupted, foreign or wrong version)."""


@dataclass
class Demo:
    """One demonstration episode (see the module docstring for the layout)."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    poses: np.ndarray
    metadata: dict = field(default_factory=dict)
    grid: GridMap | None = None
    expert_actions: np.ndarray | None = None
    """the expert's own choice at each step (differs from ``actions`` where noise was injected)"""

    @property
    def labels(self) -> np.ndarray:
        """The expert's choices when recorded, else the actions taken."""
        return self.actions if self.expert_actions is None else self.expert_actions

    def __len__(self) -> int:
        return len(self.actions)

    def task(self) -> Task:
        """The navigation task this demonstration solved."""
        if self.grid is None:
            raise DemoFormatError("this demonstration carries no grid")
        return Task(
            self.grid, tuple(self.metadata["start"]), tuple(self.metadata["goal"]), self.metadata["map_id"]
        )


def make_demo(
    observations: Iterable,
    actions: Iterable,
    rewards: Iterable,
    terminations: Iterable,
    truncations: Iterable,
    poses: Iterable,
    task: Task,
    source: str,
    seed: int | None,
    noise: float,
    outcome: int,
    expert_actions: Iterable | None = None,
) -> Demo:
    """Build a :class:`Demo` from one recorded episode, checking its shapes."""
    if source not in SOURCES:
        raise ValueError(f"source must be one of {SOURCES}, got {source!r}")
    demo = Demo(
        observations=np.asarray(observations, dtype=np.float32),
        actions=np.asarray(actions, dtype=np.int64),
        rewards=np.asarray(rewards, dtype=np.float64),
        terminations=np.asarray(terminations, dtype=bool),
        truncations=np.asarray(truncations, dtype=bool),
        poses=np.asarray(poses, dtype=np.float64),
        metadata={
            "map_id": task.map_id or task.grid.name,
            "start": (int(task.start[0]), int(task.start[1])),
            "goal": (int(task.goal[0]), int(task.goal[1])),
            "source": source,
            "seed": None if seed is None else int(seed),
            "noise": float(noise),
            "outcome": int(outcome),
        },
        grid=task.grid,
        expert_actions=None if expert_actions is None else np.asarray(expert_actions, dtype=np.int64),
    )
    _check_demo(demo, "new demonstration")
    return demo


def _check_demo(demo: Demo, where: str) -> None:
    t = len(demo.actions)
    if t == 0:
        raise DemoFormatError(f"{where}: empty episode")
    if demo.observations.ndim != 2 or len(demo.observations) != t + 1:
        raise DemoFormatError(
            f"{where}: expected {t + 1} observation rows, got shape {demo.observations.shape}"
        )
    for name in ("rewards", "terminations", "truncations"):
        if getattr(demo, name).shape != (t,):
            raise DemoFormatError(f"{where}: {name} has shape {getattr(demo, name).shape}, expected ({t},)")
    if demo.poses.shape != (t + 1, 3):
        raise DemoFormatError(f"{where}: poses have shape {demo.poses.shape}, expected ({t + 1}, 3)")
    if not (np.isfinite(demo.observations).all() and np.isfinite(demo.poses).all()):
        raise DemoFormatError(f"{where}: non-finite observations or poses")
    if demo.expert_actions is not None and demo.expert_actions.shape != (t,):
        raise DemoFormatError(
            f"{where}: expert_actions have shape {demo.expert_actions.shape}, expected ({t},)"
        )


@contextlib.contextmanager
def datasets_root(root: Path) -> Iterator[None]:
    """Point Minari's ``MINARI_DATASETS_PATH`` at ``root`` for the duration of a call."""
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def dataset_location(path: str | Path) -> tuple[Path, str]:
    """``(datasets root, dataset id)`` of a dataset directory; Minari wants ids like ``expert-v0``."""
    from minari.dataset.minari_dataset import DATASET_ID_RE

    path = Path(path).resolve()
    match = DATASET_ID_RE.fullmatch(path.name)
    if not match or match.group("version") is None:
        raise DemoFormatError(
            f"{path}: the directory name must be a Minari dataset id NAME-vVERSION, such as 'expert-v0'"
        )
    return path.parent, path.name


def clear_target(path: str | Path, overwrite: bool) -> Path:
    """The directory of a new dataset at ``path`` (its parent the datasets root, its name the dataset
    id: :func:`dataset_location`), made room for: an existing dataset there is removed with
    ``overwrite``, refused without (FileExistsError naming it and the way out)."""
    root, dataset_id = dataset_location(path)
    target = root / dataset_id
    if target.exists():
        if not overwrite:
            raise FileExistsError(f"{target} exists (pass overwrite=True / --overwrite to replace it)")
        shutil.rmtree(target)
    return target


def write_demos(
    path: str | Path,
    demos: list[Demo],
    observation_space: gym.spaces.Box,
    action_space: gym.spaces.Discrete,
    description: str = "",
    extra_metadata: dict | None = None,
    overwrite: bool = False,
    observation: dict | None = None,
) -> Path:
    """Write ``demos`` as the Minari dataset ``path`` (a directory); returns it. ``observation``:
    the settings the robot observed (``worlds.config.observation_settings(nav)``), recorded."""
    import minari
    from minari.data_collector import EpisodeBuffer

    target = clear_target(path, overwrite)
    root, dataset_id = target.parent, target.name
    if not demos:
        raise ValueError("no demonstrations to write")
    extra = dict(extra_metadata or {})
    if observation is not None:
        width = observation_dim(with_observation(NavConfig(), observation))
        if (width,) != observation_space.shape:
            raise ValueError(f"observation settings {observation} give {width} values: {observation_space}")
        extra["observation"] = dict(observation)
    buffers = []
    for i, demo in enumerate(demos):
        _check_demo(demo, f"demo {i}")
        if demo.grid is None:
            raise ValueError(f"demo {i} has no grid")
        meta = demo.metadata
        options = {
            **{k: v for k, v in meta.items() if v is not None and k != "seed"},
            "start": np.asarray(meta["start"], dtype=np.int64),
            "goal": np.asarray(meta["goal"], dtype=np.int64),
            "grid": np.packbits(demo.grid.blocked),
            "grid_shape": np.asarray(demo.grid.shape, dtype=np.int64),
            "cell_size": float(demo.grid.cell_size),
        }
        buffers.append(
            EpisodeBuffer(
                id=i,
                seed=meta.get("seed"),
                options=options,
                observations=list(demo.observations),
                actions=list(demo.actions),
                rewards=list(demo.rewards),
                terminations=list(demo.terminations),
                truncations=list(demo.truncations),
                infos=_infos(demo),
            )
        )
    root.mkdir(parents=True, exist_ok=True)
    with datasets_root(root), warnings.catch_warnings():
        # Minari warns about optional provenance fields (permalink, e-mail, env spec) we leave unset.
        warnings.simplefilter("ignore", UserWarning)
        dataset = minari.create_dataset_from_buffers(
            dataset_id=dataset_id,
            buffer=buffers,
            observation_space=observation_space,
            action_space=action_space,
            algorithm_name="navlearn modified A* expert",
            author={"navlearn"},
            description=description or "navlearn navigation demonstrations",
        )
        dataset.storage.update_metadata(
            {"navlearn_format": FORMAT_VERSION, "navlearn": json.dumps(extra, sort_keys=True)}
        )
    return target


def _infos(demo: Demo) -> dict[str, np.ndarray]:
    infos = {"pose": demo.poses}
    if demo.expert_actions is not None:
        infos["expert_action"] = np.append(demo.expert_actions, -1)
    return infos


def _read_demo(episode, meta: dict, where: str, obs_dim: int) -> Demo:
    options = meta.get("options")
    if not isinstance(options, dict) or any(k not in options for k in _REQUIRED_OPTIONS):
        raise DemoFormatError(f"{where}: episode metadata lacks navlearn keys {_REQUIRED_OPTIONS}")
    infos = episode.infos or {}
    if "pose" not in infos:
        raise DemoFormatError(f"{where}: no per-step 'pose' infos")
    shape = tuple(int(v) for v in options["grid_shape"])
    try:
        blocked = np.unpackbits(np.asarray(options["grid"], dtype=np.uint8), count=shape[0] * shape[1])
        grid = GridMap(blocked.reshape(shape).astype(bool), cell_size=float(options["cell_size"]), name="")
    except ValueError as exc:
        raise DemoFormatError(f"{where}: bad stored grid ({exc})") from None
    grid = GridMap(grid.blocked, grid.cell_size, name=str(options["map_id"]))
    start: Cell = (int(options["start"][0]), int(options["start"][1]))
    goal: Cell = (int(options["goal"][0]), int(options["goal"][1]))
    demo = Demo(
        observations=np.asarray(episode.observations, dtype=np.float32),
        actions=np.asarray(episode.actions, dtype=np.int64).reshape(-1),
        rewards=np.asarray(episode.rewards, dtype=np.float64),
        terminations=np.asarray(episode.terminations, dtype=bool),
        truncations=np.asarray(episode.truncations, dtype=bool),
        poses=np.asarray(infos["pose"], dtype=np.float64),
        expert_actions=(
            np.asarray(infos["expert_action"], dtype=np.int64)[:-1] if "expert_action" in infos else None
        ),
        metadata={
            "map_id": str(options["map_id"]),
            "start": start,
            "goal": goal,
            "source": str(options["source"]),
            "seed": meta.get("seed"),
            "noise": float(options["noise"]),
            "outcome": int(options["outcome"]),
        },
        grid=grid,
    )
    _check_demo(demo, where)
    if demo.observations.shape[1] != obs_dim:
        raise DemoFormatError(
            f"{where}: observations have {demo.observations.shape[1]} columns, not {obs_dim}"
        )
    if demo.metadata["source"] not in SOURCES:
        raise DemoFormatError(f"{where}: unknown source {demo.metadata['source']!r}")
    return demo


def load_demos(path: str | Path) -> list[Demo]:
    """Load and validate the demonstration dataset at ``path`` (a directory written by
    :func:`write_demos` or ``navlearn demos generate``); ``agents.demo_observation.load_demos_for``
    also checks its observation against a learner's."""
    import minari

    root, dataset_id = dataset_location(path)
    target = root / dataset_id
    if not target.exists():
        raise DemoFormatError(f"{target}: no such demonstration dataset (the directory does not exist)")
    if not (target / "data").is_dir():
        raise DemoFormatError(f"{target}: not a Minari dataset (no data/ directory)")
    try:
        with datasets_root(root):
            dataset = minari.load_dataset(dataset_id)
        metadata = dataset.storage.metadata
        version = metadata.get("navlearn_format")
        if version is None and ENV_KEY in metadata:
            env = json.loads(metadata[ENV_KEY])
            raise DemoFormatError(
                f"{target}: demonstrations on the Gymnasium env {env['id']}, not navlearn's world: NIRL "
                "learns its reward from the world's features (the map, the robot's poses, the plan to the "
                "goal), which that env lacks; learn from them by behaviour cloning: navlearn imitate train "
                f"--env {env['id']} --demos {target}"
            )
        if version is None:
            raise DemoFormatError(f"{target}: a Minari dataset, but not a navlearn demonstration set")
        if version != FORMAT_VERSION:
            raise DemoFormatError(f"{target}: navlearn format {version}, this version reads {FORMAT_VERSION}")
        obs_space, act_space = dataset.observation_space, dataset.action_space
        if not (isinstance(obs_space, gym.spaces.Box) and len(obs_space.shape) == 1):
            raise DemoFormatError(f"{target}: observation space {obs_space} is not a flat Box")
        if not isinstance(act_space, gym.spaces.Discrete):
            raise DemoFormatError(f"{target}: action space {act_space} is not Discrete")
        ids = list(range(dataset.total_episodes))
        metas = list(dataset.storage.get_episode_metadata(ids))
        demos = [
            _read_demo(ep, meta, f"{target} episode {i}", obs_space.shape[0])
            for i, (ep, meta) in enumerate(zip(dataset.iterate_episodes(ids), metas, strict=True))
        ]
    except DemoFormatError:
        raise
    except Exception as exc:  # h5py/json/minari errors on damaged files: one clear line
        raise DemoFormatError(
            f"{target}: unreadable demonstration dataset ({type(exc).__name__}: {exc})"
        ) from None
    if any((d.actions < 0).any() or (d.actions >= act_space.n).any() for d in demos):
        raise DemoFormatError(f"{target}: actions outside 0..{act_space.n - 1}")
    return demos


def dataset_info(path: str | Path) -> dict:
    """The dataset-level metadata (Minari's plus navlearn's ``navlearn`` JSON, decoded)."""
    import minari

    root, dataset_id = dataset_location(path)
    with datasets_root(root):
        metadata = dict(minari.load_dataset(dataset_id).storage.metadata)
    metadata["navlearn"] = json.loads(metadata.get("navlearn", "{}"))
    return metadata

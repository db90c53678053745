"""Bad demonstration files for NIRL: each fails with one clear error naming the file, through the
library (``agents.nirl.buffers.load_demonstrations``) and `navlearn nirl train`."""

from __future__ import annotations

import gymnasium as gym
import h5py
import numpy as np
import pytest

from agents.demos import DemoFormatError, make_demo, write_demos
from agents.nirl.buffers import load_demonstrations
from services.cli import main
from worlds.config import OBSERVATIONS
from worlds.maps import GridMap, Task


def _write(path, obs_dim: int = 11, episodes: int = 2):
    rng = np.random.default_rng(0)
    grid = GridMap(np.zeros((8, 8), bool), cell_size=0.5, name="open")
    demos = [
        make_demo(
            observations=rng.uniform(0, 1, (7, obs_dim)),
            actions=rng.integers(0, 5, 6),
            rewards=np.zeros(6),
            terminations=np.r_[np.zeros(5), 1],
            truncations=np.zeros(6),
            poses=rng.uniform(0, 4, (7, 3)),
            task=Task(grid, (1, 1), (6, 6), "open"),
            source="astar",
            seed=i,
            noise=0.0,
            outcome=1,
        )
        for i in range(episodes)
    ]
    space = gym.spaces.Box(-1.0, 1.0, (obs_dim,), np.float32)
    return write_demos(path, demos, space, gym.spaces.Discrete(5))


def _bad_datasets(tmp_path) -> dict[str, tuple]:
    """name -> (path, what the message must say)"""
    narrow = _write(tmp_path / "narrow-v0", obs_dim=9)
    empty = tmp_path / "empty-v0"
    (empty / "data").mkdir(parents=True)
    no_actions = _write(tmp_path / "noactions-v0")
    with h5py.File(no_actions / "data" / "main_data.hdf5", "r+") as fh:
        for name in fh:
            del fh[name]["actions"]
    return {
        "wrong observation size": (narrow, "observations have 9 values per step"),
        "empty": (empty, "unreadable|no demonstrations|empty"),
        "missing actions": (no_actions, "actions"),
        "dataset id that does not exist": (tmp_path / "nosuch-v0", "no such demonstration dataset"),
    }


def test_a_good_dataset_loads(tmp_path):
    # written without an observation record, 11 wide: an 8-beam set, loaded in its own observation
    assert len(load_demonstrations(str(_write(tmp_path / "good-v0")), OBSERVATIONS["plain"])) == 2


def test_bad_demonstration_files_fail_with_one_clear_error_naming_the_file(tmp_path, capsys):
    for case, (path, message) in _bad_datasets(tmp_path).items():
        with pytest.raises(DemoFormatError, match=message) as info:
            load_demonstrations(str(path))
        assert str(path.resolve()) in str(info.value) or str(path) in str(info.value), case
        code = main(["nirl", "train", "--demos", str(path), "--out", str(tmp_path / "run"), "--no-progress"])
        err = capsys.readouterr().err
        assert code == 2, case
        assert err.count("\n") == 1 and path.name in err, (case, err)

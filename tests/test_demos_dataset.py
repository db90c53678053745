"""Minari demonstration datasets: round trip, and clear errors for bad files."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from agents.demos import DemoFormatError, dataset_info, load_demos, make_demo, write_demos
from worlds.maps import GridMap, Task

OBS_SPACE = gym.spaces.Box(-1.0, 1.0, (11,), np.float32)
ACT_SPACE = gym.spaces.Discrete(5)


def _demos(n: int = 4) -> list:
    rng = np.random.default_rng(0)
    grid = GridMap(rng.random((12, 17)) < 0.15, cell_size=0.5, name="toy")
    free = grid.free_cells()
    out = []
    for i in range(n):
        steps = 5 + i
        task = Task(grid, tuple(free[i]), tuple(free[-1 - i]), "toy")
        out.append(
            make_demo(
                observations=rng.uniform(-1, 1, (steps + 1, 11)),
                actions=rng.integers(0, 5, steps),
                rewards=rng.normal(size=steps),
                terminations=np.r_[np.zeros(steps - 1), 1],
                truncations=np.zeros(steps),
                poses=rng.uniform(0, 5, (steps + 1, 3)),
                task=task,
                source="astar",
                seed=100 + i,
                noise=0.3,
                outcome=1,
                expert_actions=rng.integers(0, 5, steps) if i % 2 else None,
            )
        )
    return out


def test_round_trip(tmp_path):
    demos = _demos()
    path = write_demos(tmp_path / "expert-v0", demos, OBS_SPACE, ACT_SPACE, extra_metadata={"maps": "toy"})
    loaded = load_demos(path)
    assert len(loaded) == len(demos)
    for a, b in zip(demos, loaded, strict=True):
        np.testing.assert_array_equal(a.observations, b.observations)
        np.testing.assert_array_equal(a.actions, b.actions)
        np.testing.assert_allclose(a.rewards, b.rewards)
        np.testing.assert_array_equal(a.terminations, b.terminations)
        np.testing.assert_array_equal(a.truncations, b.truncations)
        np.testing.assert_allclose(a.poses, b.poses)
        np.testing.assert_array_equal(a.labels, b.labels)
        assert (a.expert_actions is None) == (b.expert_actions is None)
        assert a.metadata == b.metadata
        assert b.grid == a.grid and b.task() == a.task()
    assert dataset_info(path)["navlearn"] == {"maps": "toy"}
    with pytest.raises(FileExistsError):
        write_demos(path, demos, OBS_SPACE, ACT_SPACE)
    write_demos(path, demos[:1], OBS_SPACE, ACT_SPACE, overwrite=True)
    assert len(load_demos(path)) == 1


def test_bad_shapes_are_refused():
    demo = _demos(1)[0]
    with pytest.raises(DemoFormatError, match="observation rows"):
        make_demo(demo.observations[:-1], demo.actions, demo.rewards, demo.terminations, demo.truncations,
                  demo.poses, demo.task(), "astar", 0, 0.0, 1)  # fmt: skip
    with pytest.raises(ValueError, match="source"):
        make_demo(demo.observations, demo.actions, demo.rewards, demo.terminations, demo.truncations,
                  demo.poses, demo.task(), "robot", 0, 0.0, 1)  # fmt: skip


def test_missing_corrupted_and_foreign_files_give_clear_errors(tmp_path, monkeypatch):
    with pytest.raises(DemoFormatError, match="no such demonstration dataset"):
        load_demos(tmp_path / "nothing-v0")
    path = write_demos(tmp_path / "broken-v0", _demos(2), OBS_SPACE, ACT_SPACE)
    (path / "data" / "main_data.hdf5").write_bytes(b"this is not hdf5" * 10)
    with pytest.raises(DemoFormatError, match="unreadable"):
        load_demos(path)

    import minari
    from minari.data_collector import EpisodeBuffer

    foreign_root = tmp_path / "foreign"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(foreign_root))
    episode = EpisodeBuffer(
        observations=[np.zeros(11, np.float32)] * 3,
        actions=[0, 1],
        rewards=[0.0, 0.0],
        terminations=[False, True],
        truncations=[False, False],
    )
    with pytest.warns(UserWarning):
        minari.create_dataset_from_buffers(
            "other-v0", [episode], observation_space=OBS_SPACE, action_space=ACT_SPACE
        )
    with pytest.raises(DemoFormatError, match="not a navlearn demonstration set"):
        load_demos(foreign_root / "other-v0")
    with pytest.raises(DemoFormatError, match="dataset id"):
        load_demos(tmp_path / "no-version")

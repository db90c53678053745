"""A memory-mapped replay (agents/nnql/replay_storage.py): checkpoints that never copy it, resumes."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from agents.nnql.learner import NNQLLearner
from services.learner.config import LearnerConfig
from tests.test_nnql_replay import N_ACTIONS, OBS_DIM, random_batch, small_config


def contents(learner: NNQLLearner) -> dict[str, np.ndarray]:
    stored = learner.replay.storage[: len(learner.replay)]
    return {key: stored.get(key).numpy().copy() for key in (("next", "reward"), "observation", "action")}


def assert_same_replay(a: NNQLLearner, b: NNQLLearner) -> None:
    assert len(a.replay) == len(b.replay)
    assert a.replay.writer.state_dict() == b.replay.writer.state_dict()
    for key, value in contents(a).items():
        np.testing.assert_array_equal(contents(b)[key], value, err_msg=str(key))


def directory_bytes(path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def test_checkpoint_holds_state_not_transitions_and_resumes_in_place(tmp_path):
    config = small_config(replay_capacity=300)
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS, replay_dir=tmp_path / "replay")
    rng = np.random.default_rng(0)
    for _ in range(4):
        learner.add(random_batch(rng, 50))
        learner.train_due()
    path = learner.save_checkpoint(tmp_path / "ckpt")
    assert sorted(p.name for p in (path / "replay").iterdir()) == ["memmap.json"]

    restored = NNQLLearner.from_checkpoint(path, replay_dir=tmp_path / "replay")
    assert_same_replay(learner, restored)
    # same sampler draws afterwards (the generator's state is in the checkpoint), same updates
    batch = random_batch(rng, 50)
    learner.add(batch)
    restored.add(batch)
    assert restored.update(3) == learner.update(3)


def test_checkpoint_size_does_not_grow_with_capacity(tmp_path):
    sizes = []
    for capacity in (1_000, 1_000_000):
        learner = NNQLLearner(
            small_config(replay_capacity=capacity), OBS_DIM, N_ACTIONS, replay_dir=tmp_path / f"r{capacity}"
        )
        learner.add(random_batch(np.random.default_rng(0), 500))
        sizes.append(directory_bytes(learner.save_checkpoint(tmp_path / f"ckpt{capacity}") / "replay"))
    assert sizes[0] == pytest.approx(sizes[1], abs=16) and sizes[0] < 32_000  # the generator state is most


@pytest.mark.parametrize("after", [30, 250])  # 250 wraps the ring of 200 past the checkpoint's cursor
def test_reinserting_what_came_after_the_checkpoint_restores_the_buffer(tmp_path, after):
    """What the learner service's write-ahead log does after a kill -9: the slots written after the
    checkpoint are written again, in the same order, and the buffer is what it was before the crash."""
    config = small_config(replay_capacity=200)
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS, replay_dir=tmp_path / "replay")
    rng = np.random.default_rng(1)
    learner.add(random_batch(rng, 170))
    path = learner.save_checkpoint(tmp_path / "ckpt")
    logged = [random_batch(rng, n) for n in (after // 2, after - after // 2)]
    for batch in logged:
        learner.add(batch)
    before_crash = contents(learner)
    del learner  # no checkpoint: the process dies here

    resumed = NNQLLearner.from_checkpoint(path, replay_dir=tmp_path / "replay")
    assert len(resumed.replay) == 170
    for batch in logged:
        resumed.add(batch)
    for key, value in before_crash.items():
        np.testing.assert_array_equal(contents(resumed)[key], value, err_msg=str(key))
    rewards = np.sort(before_crash[("next", "reward")].reshape(-1))
    assert len(np.unique(rewards)) == len(rewards)  # nothing twice


def test_refusals(tmp_path):
    with pytest.raises(ValueError, match="memory-mapped replay samples uniformly"):
        NNQLLearner(small_config(prioritized=True), OBS_DIM, N_ACTIONS, replay_dir=tmp_path / "r")
    learner = NNQLLearner(small_config(), OBS_DIM, N_ACTIONS, replay_dir=tmp_path / "r")
    learner.add(random_batch(np.random.default_rng(0), 80))
    path = learner.save_checkpoint(tmp_path / "ckpt")
    with pytest.raises(ValueError, match="memory-mapped replay's state; build the learner with replay_dir"):
        NNQLLearner.from_checkpoint(path)
    with pytest.raises(ValueError, match="open it with replay_dir="):
        NNQLLearner.from_checkpoint(path, replay_dir=tmp_path / "elsewhere")
    with pytest.raises(ValueError, match="--replay-storage memmap keeps the replay under --checkpoint-dir"):
        LearnerConfig(checkpoint_dir="", replay_storage="memmap")
    with pytest.raises(ValueError, match="replay_storage='disk'"):
        LearnerConfig(replay_storage="disk")
    assert (
        LearnerConfig(checkpoint_dir=str(tmp_path), replay_storage="memmap").replay_dir == tmp_path / "replay"
    )


def test_memmap_columns_feed_the_lean_update(tmp_path):
    """The hot loop reads sampled rows from the memory-mapped columns as it does from RAM."""
    in_ram = NNQLLearner(small_config(), OBS_DIM, N_ACTIONS)
    on_disk = NNQLLearner(small_config(), OBS_DIM, N_ACTIONS, replay_dir=tmp_path / "r")
    batch = random_batch(np.random.default_rng(2), 150)
    in_ram.add(batch)
    on_disk.add(batch)
    assert on_disk.update(4) == in_ram.update(4)
    for a, b in zip(in_ram.network.parameters(), on_disk.network.parameters(), strict=True):
        assert torch.equal(a, b)


def test_loading_into_a_learner_that_already_sampled_reads_the_loaded_rows(tmp_path):
    """The hot loop keeps views of the storage's columns; a resume must not leave it on stale ones.
    (A RAM replay is only ever loaded into while empty, before any view exists.)"""
    replay_dir = tmp_path / "r"
    saved = NNQLLearner(small_config(), OBS_DIM, N_ACTIONS, replay_dir=replay_dir)
    saved.add(random_batch(np.random.default_rng(3), 150))
    path = saved.save_checkpoint(tmp_path / "ckpt")
    used = NNQLLearner.from_checkpoint(path, replay_dir=replay_dir)
    used.add(random_batch(np.random.default_rng(4), 100))  # rows the checkpoint does not hold
    used.update(2)  # views of the columns are cached now
    used.load_checkpoint(path)
    assert len(used.replay) == 150
    fresh = NNQLLearner.from_checkpoint(path, replay_dir=replay_dir)
    assert used.update(3) == fresh.update(3)

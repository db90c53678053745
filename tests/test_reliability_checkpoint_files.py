"""Checkpoint files on a damaged or hostile disk: checksums, setting aside, no pickle, zeroed replay.

In-process tests of services.learner.checkpoint (manifest, verification, newest intact
checkpoint) and agents.replay_files (the replay written without pickle). The same
damage to a real learner process is in tests/test_reliability_storage.py.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from agents.replay_files import ReplayFormatError, load_replay
from services.learner.checkpoint import (
    MANIFEST,
    CheckpointDamaged,
    CheckpointDir,
    NoIntactCheckpoint,
    verify,
    write_manifest,
)
from tests.test_nnql_replay import N_ACTIONS, OBS_DIM, random_batch


def _learner(prioritized: bool = False) -> NNQLLearner:
    config = NNQLConfig(
        hidden_sizes=(16,), batch_size=16, replay_capacity=500, learning_starts=32, prioritized=prioritized
    )
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(0)
    for _ in range(3):
        learner.add(random_batch(rng, 60))
        learner.train_due()
    return learner


def _checkpoints(root: Path, n: int) -> tuple[CheckpointDir, list[Path], NNQLLearner]:
    learner = _learner()
    ckpts = CheckpointDir(root, keep=5)
    paths = []
    for _ in range(n):
        paths.append(ckpts.save(lambda tmp: learner.save_checkpoint(tmp / "nnql")))
        learner.add(random_batch(np.random.default_rng(len(paths)), 10))
    return ckpts, paths, learner


class Marker:
    """Unpickling this creates ``path``: proof that a loader ran code from a file."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.write_text, (self.path, "code ran"))


# ---------------------------------------------------------------- manifest and verification


def test_every_checkpoint_carries_a_manifest_of_its_files(tmp_path):
    _, (path,), _ = _checkpoints(tmp_path, 1)
    manifest = json.loads((path / MANIFEST).read_text())
    listed = set(manifest["files"])
    on_disk = {p.relative_to(path).as_posix() for p in path.rglob("*") if p.is_file()} - {MANIFEST}
    assert listed == on_disk and "nnql/learner.pt" in listed and "nnql/replay/replay.safetensors" in listed
    assert verify(path) == sum(f["size"] for f in manifest["files"].values())


@pytest.mark.parametrize(
    "damage",
    ["cut learner.pt by 200 B", "garbage json", "zeroed replay", "extra file", "no manifest", "bit flip"],
)
def test_damage_is_detected_naming_the_file(tmp_path, damage):
    _, (path,), _ = _checkpoints(tmp_path, 1)
    state, replay = path / "nnql" / "learner.pt", path / "nnql" / "replay" / "replay.safetensors"
    if damage == "cut learner.pt by 200 B":
        state.write_bytes(state.read_bytes()[:-200])
        expected = "learner.pt"
    elif damage == "garbage json":
        (path / "nnql" / "replay" / "replay.json").write_text("{garbage")
        expected = "replay.json"
    elif damage == "zeroed replay":
        replay.write_bytes(bytes(replay.stat().st_size))
        expected = "replay.safetensors"
    elif damage == "extra file":
        (path / "nnql" / "replay" / "prefetch.pkl").write_bytes(b"x")
        expected = "prefetch.pkl"
    elif damage == "no manifest":
        (path / MANIFEST).unlink()
        expected = MANIFEST
    else:
        data = bytearray(replay.read_bytes())
        data[len(data) // 2] ^= 0x01
        replay.write_bytes(bytes(data))
        expected = "replay.safetensors"
    with pytest.raises(CheckpointDamaged, match=expected):
        verify(path)


def test_damaged_newest_is_set_aside_and_the_newest_intact_is_used(tmp_path, caplog):
    ckpts, paths, _ = _checkpoints(tmp_path, 3)
    state = paths[2] / "nnql" / "learner.pt"
    state.write_bytes(state.read_bytes()[:-200])
    (paths[1] / "nnql" / "learner.pt").write_bytes(b"garbage")
    assert ckpts.newest_intact() == paths[0]
    assert ckpts.all() == [paths[0]]
    aside = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("damaged-"))
    assert aside == ["damaged-ckpt-00000002", "damaged-ckpt-00000003"]
    assert "ckpt-00000003 is damaged" in caplog.text and "learner.pt" in caplog.text
    assert "bytes, the manifest says" in caplog.text  # the reason, not only the file
    assert ckpts.save(lambda tmp: (tmp / "x").write_text("next")).name == "ckpt-00000002"


def test_when_every_checkpoint_is_damaged_nothing_is_renamed(tmp_path):
    ckpts, paths, _ = _checkpoints(tmp_path, 2)
    for path in paths:
        (path / "nnql" / "learner.pt").write_bytes(b"garbage")
    with pytest.raises(NoIntactCheckpoint, match="no intact checkpoint"):
        ckpts.newest_intact()
    assert ckpts.all() == paths  # an operator decides; a restart does not silently start afresh


def test_checkpoint_writer_refuses_without_free_space(tmp_path, monkeypatch):
    import errno
    import shutil

    ckpts = CheckpointDir(tmp_path)
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda _p: usage._replace(free=10_000))
    wrote = []
    with pytest.raises(OSError) as failure:
        ckpts.save(lambda tmp: wrote.append(tmp), estimate=50_000)
    assert failure.value.errno == errno.ENOSPC and str(tmp_path) in str(failure.value)
    assert wrote == [] and ckpts.all() == []  # refused before writing anything


# ---------------------------------------------------------------- the replay, without pickle


@pytest.mark.parametrize("prioritized", [False, True])
def test_replay_files_hold_no_pickle(tmp_path, prioritized):
    learner = _learner(prioritized)
    learner.save_checkpoint(tmp_path / "ckpt")
    names = {p.name for p in (tmp_path / "ckpt" / "replay").rglob("*") if p.is_file()}
    assert not {n for n in names if n.endswith((".pkl", ".pickle", ".pt", ".t"))}, names
    for file in (tmp_path / "ckpt" / "replay").rglob("*"):
        if file.is_file():
            assert not file.read_bytes().startswith(b"\x80"), f"{file} looks like a pickle"


def test_crafted_pickles_in_a_checkpoint_never_run(tmp_path):
    learner = _learner()
    path = learner.save_checkpoint(tmp_path / "ckpt")
    marker = tmp_path / "marker"
    replay = path / "replay"
    for name in ("prefetch.pkl", "transform.t", "sampler/prefetch.pkl"):
        (replay / name).parent.mkdir(exist_ok=True)
        (replay / name).write_bytes(pickle.dumps(Marker(marker)))
    restored = NNQLLearner(learner.config, OBS_DIM, N_ACTIONS)
    restored.load_checkpoint(path)
    assert not marker.exists(), "a pickle in the checkpoint ran code"
    assert len(restored.replay) == len(learner.replay)
    assert (restored.replay[:] == learner.replay[:]).all()

    (path / "learner.pt").write_bytes(pickle.dumps(Marker(marker)))  # torch.load(weights_only=True)
    with pytest.raises(pickle.UnpicklingError):
        NNQLLearner(learner.config, OBS_DIM, N_ACTIONS).load_checkpoint(path)
    assert not marker.exists()


def test_torchrl_format_replay_is_refused_with_a_reason(tmp_path):
    learner = _learner()
    learner.replay.dumps(tmp_path / "old")  # what navlearn wrote before: TorchRL's own dumps
    (tmp_path / "old" / "prefetch.pkl").write_bytes(pickle.dumps(Marker(tmp_path / "marker")))
    with pytest.raises(ReplayFormatError, match=r"unpickles prefetch\.pkl"):
        load_replay(_learner().replay, tmp_path / "old")
    assert not (tmp_path / "marker").exists()


@pytest.mark.parametrize("damage", ["zeroed", "truncated", "rows"])
def test_zeroed_or_truncated_replay_is_detected_without_a_manifest(tmp_path, damage):
    learner = _learner()
    learner.save_replay(tmp_path / "replay")
    arrays = tmp_path / "replay" / "replay.safetensors"
    if damage == "zeroed":
        arrays.write_bytes(bytes(arrays.stat().st_size))
    elif damage == "truncated":
        arrays.write_bytes(arrays.read_bytes()[: arrays.stat().st_size // 2])
    else:
        meta = json.loads((tmp_path / "replay" / "replay.json").read_text())
        (tmp_path / "replay" / "replay.json").write_text(json.dumps({**meta, "len": meta["len"] + 7}))
    fresh = NNQLLearner(learner.config, OBS_DIM, N_ACTIONS)
    with pytest.raises(ReplayFormatError, match="replay"):
        fresh.load_replay(tmp_path / "replay")


def test_manifest_is_written_after_the_files(tmp_path):
    (tmp_path / "a").write_bytes(b"abc")
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "b").write_bytes(b"defg")
    assert write_manifest(tmp_path) == 7
    assert verify(tmp_path) == 7

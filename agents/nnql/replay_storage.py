"""Where the NNQL replay keeps its transitions, and what a checkpoint of it writes.

``memory``: TorchRL's ``LazyTensorStorage`` in RAM; a checkpoint writes every stored row
(``agents.replay_files``), so its cost grows with the replay (about 110 bytes per transition
of the default observation).

``memmap``: TorchRL's ``LazyMemmapStorage``, one file per column under a directory the
caller names (the learner service puts it at ``<checkpoint dir>/replay``), so capacities
beyond RAM work (10 M transitions are about 1.1 GB on disk) and a checkpoint never copies
them: it flushes the column files (``fsync``: the cost of the pages written since the last
flush, not of the capacity) and records a few hundred bytes - the length, the writer's
cursor, the sampling generator's state and the directory (``memmap.json``). Resuming opens
the files in place (TorchRL's ``LazyMemmapStorage`` loading from its own scratch
directory) and sets length and cursor back. Transitions inserted after that checkpoint sit
in the slots after the cursor; the learner service's write-ahead log inserts them again,
in the order they first came, into the same slots, so the buffer comes back as it was.
Only the newest checkpoint matches the files (they keep changing after it). Prioritized
replay is refused with memmap: its sum and min trees live in RAM and would be written
whole at every checkpoint.

The TorchRL internals this needs (the storage's ``_storage`` TensorDict and ``_len``, as
TorchRL's own checkpointers use them) are touched here only; ``columns`` also serves the
learner's hot loop, which reads sampled rows straight from the columns.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import LazyMemmapStorage, LazyTensorStorage, TensorDictReplayBuffer

STATE_FILE = "memmap.json"


def make_storage(capacity: int, directory: str | Path | None) -> LazyTensorStorage:
    """RAM storage when ``directory`` is None, else memory-mapped files in ``directory``."""
    if directory is None:
        return LazyTensorStorage(capacity)
    directory = Path(directory).absolute()
    directory.mkdir(parents=True, exist_ok=True)
    return LazyMemmapStorage(capacity, scratch_dir=directory, existsok=True)


def is_memmap(replay: TensorDictReplayBuffer) -> bool:
    return isinstance(replay.storage, LazyMemmapStorage)


def columns(replay: TensorDictReplayBuffer) -> TensorDictBase:
    """The storage's TensorDict at full capacity (rows past ``len(replay)`` are not data yet)."""
    return replay.storage._storage


def _column_files(replay: TensorDictReplayBuffer) -> list[str]:
    return [tensor.filename for tensor in columns(replay).values(True, True)]


def save_memmap(replay: TensorDictReplayBuffer, rng: torch.Generator, path: Path) -> None:
    """Flush the column files and write ``path/memmap.json`` (length, cursor, rng, directory)."""
    storage = replay.storage
    if storage.initialized:
        for name in _column_files(replay):
            fd = os.open(name, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
    path.mkdir(parents=True, exist_ok=True)
    state = {
        "storage": "memmap",
        "directory": storage.scratch_dir,
        "capacity": storage.max_size,
        "len": len(storage),
        "initialized": bool(storage.initialized),
        "writer": {k: int(v) for k, v in replay.writer.state_dict().items()},
        "rng": rng.get_state().tolist(),
    }
    (path / STATE_FILE).write_text(json.dumps(state))


def load_memmap(replay: TensorDictReplayBuffer, rng: torch.Generator, path: Path) -> None:
    """Open the column files named by ``path/memmap.json`` in place and restore length, cursor, rng."""
    state = json.loads((path / STATE_FILE).read_text())
    storage = replay.storage
    if Path(state["directory"]).absolute() != Path(storage.scratch_dir).absolute():
        raise ValueError(
            f"checkpoint {path} holds a memmap replay in {state['directory']}, but this learner's replay "
            f"is in {storage.scratch_dir}; open it with replay_dir={state['directory']!r}"
        )
    if state["capacity"] != storage.max_size:
        raise ValueError(
            f"checkpoint {path}: memmap replay of capacity {state['capacity']}, "
            f"this learner's is {storage.max_size}"
        )
    if state["initialized"]:
        storage._storage = TensorDict.load_memmap(storage.scratch_dir)
        storage.initialized = True
    storage._len = int(state["len"])
    replay.writer.load_state_dict(state["writer"])
    rng.set_state(torch.tensor(state["rng"], dtype=torch.uint8))


def has_memmap_state(path: Path) -> bool:
    return (path / STATE_FILE).exists()

"""Ingest stalls caused by checkpoints: a RAM replay (written whole) against a memory-mapped one (flushed).

For each replay storage and capacity, a `navlearn learner` subprocess (default NNQL settings,
write-ahead log with fsync always, a checkpoint every ``--every`` seconds) takes transition
batches from 4 actors publishing as fast as its acknowledgements let them (the real Outbox,
batches of 128 transitions). Measured:

* the longest ingest stall: the longest time any actor waited between two acknowledgements,
  after the first second of acknowledgements, split into gaps that overlap a checkpoint and
  gaps that do not (the learner's updates, write-ahead-log fsyncs and the machine's other
  load); beside them the median gap, the ordinary pace;
* each checkpoint's duration as the learner logs it (writing networks, optimiser, replay
  or its state, demonstrations, service state; fsync; rename), the final one at shutdown
  excluded.

The replay is not pre-filled: a RAM replay's checkpoint writes its storage at full capacity
however full it is (TorchRL's ``dumps`` memory-maps the whole preallocated TensorDict), a
memory-mapped one flushes what changed since the last flush.

Then (``--filled``) the learner alone, its replay filled to capacity first: the time of one
checkpoint written as the service writes it (``CheckpointDir.save``: checksum manifest, fsync,
rename) after 20,000 more rows, RAM against memory-mapped, so the two are compared at the same
fill (the service runs above fill only what 12 s of ingest brings).

    python -m bench.checkpoint_stall                      # memory 100k, 1M; memmap 100k, 1M, 10M
    python -m bench.checkpoint_stall --cases memmap:10000000 --seconds 20
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from bench._common import machine_load
from services.learner.checkpoint import CheckpointDir
from tests.stall_helpers import run_case

CASES = ("memory:100000", "memory:1000000", "memmap:100000", "memmap:1000000", "memmap:10000000")


def checkpoint_filled(storage: str, capacity: int, root: Path) -> dict:
    """A checkpoint (as the service writes it: checksummed, fsynced, renamed) of a learner whose
    replay is full, after 20,000 more rows (the ring wrapped)."""
    from agents.nnql.config import NNQLConfig
    from agents.nnql.learner import NNQLLearner
    from bench._common import N_ACTIONS, OBS_DIM, random_transitions

    replay_dir = root / f"filled-{storage}-{capacity}" if storage == "memmap" else None
    learner = NNQLLearner(NNQLConfig(replay_capacity=capacity), OBS_DIM, N_ACTIONS, replay_dir=replay_dir)
    rng = np.random.default_rng(0)
    chunk = random_transitions(100_000, rng)
    for _ in range(capacity // 100_000):
        learner.add(chunk)
    checkpoints = CheckpointDir(root / f"ckpt-{storage}-{capacity}", keep=1)  # the service's: manifest, fsync

    def save() -> Path:
        return checkpoints.save(lambda tmp: learner.save_checkpoint(tmp / "nnql"))

    save()  # first save: imports, file creation, the first flush
    learner.add(random_transitions(20_000, rng))
    start = time.perf_counter()
    path = save()
    seconds = time.perf_counter() - start
    written = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
    shutil.rmtree(checkpoints.root, ignore_errors=True)
    if replay_dir is not None:
        shutil.rmtree(replay_dir, ignore_errors=True)
    print(f"filled {storage:6s} {capacity:>10,d}: checkpoint {seconds:.3f} s, {written / 1e6:.1f} MB in it")
    return {"storage": storage, "capacity": capacity, "checkpoint_s": round(seconds, 3), "bytes": written}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--cases", nargs="*", default=list(CASES), help="STORAGE:CAPACITY ... (none: skip)")
    parser.add_argument("--seconds", type=float, default=12.0, help="measured seconds per case")
    parser.add_argument("--every", type=float, default=3.0, help="seconds between checkpoints")
    parser.add_argument("--actors", type=int, default=4)
    parser.add_argument("--batch", type=int, default=128, help="transitions per batch")
    parser.add_argument("--dir", default=None, help="where checkpoints go (default: a temporary directory)")
    parser.add_argument(
        "--filled",
        nargs="*",
        default=["memory:1000000", "memmap:1000000", "memmap:10000000"],
        help="STORAGE:CAPACITY cases checkpointed full by the learner alone (none: skip)",
    )
    args = parser.parse_args()
    print(f"bench/checkpoint_stall.py {vars(args)} load {machine_load()}")
    root = Path(tempfile.mkdtemp(prefix="stall-", dir=args.dir))
    try:
        results = []
        for case in args.cases:
            storage, capacity = case.split(":")
            results.append(run_case(storage, int(capacity), args, root))
        filled = []
        for case in args.filled:
            storage, capacity = case.split(":")
            filled.append(checkpoint_filled(storage, int(capacity), root))
    finally:
        shutil.rmtree(root, ignore_errors=True)
    print(json.dumps({"cases": results, "filled": filled, "load_after": machine_load()}))


if __name__ == "__main__":
    main()

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
import itertools
import json
import re
import shutil
import tempfile
import threading
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from bench._common import free_port, machine_load, settings, spawn, stop
from services.common.transport import open_session
from services.learner.checkpoint import CheckpointDir
from tests.reliability_helpers import TracedActor

CASES = ("memory:100000", "memory:1000000", "memmap:100000", "memmap:1000000", "memmap:10000000")
CHECKPOINT_LINE = re.compile(
    r"^(\S+ \S+) navlearn\.learner INFO checkpoint \S+ \(version \d+, replay (\d+)\) in ([0-9.]+) s", re.M
)


class TimedActor(TracedActor):
    """A traced actor that also records when each acknowledgement arrived."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.ack_times: list[float] = []

    def _on_ack(self, sample) -> None:
        self.ack_times.append(time.time())
        super()._on_ack(sample)


def run_case(storage: str, capacity: int, args: argparse.Namespace, root: Path) -> dict:
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"stall{port}"
    ckpt = root / f"{storage}-{capacity}"
    argv = [
        "-m",
        "services.cli",
        "learner",
        "--listen",
        endpoint,
        "--run",
        run,
        "--checkpoint-dir",
        str(ckpt),
    ]
    argv += ["--checkpoint-every", str(args.every), "--replay-storage", storage]
    argv += ["--replay-capacity", str(capacity), "--log-every", "1000"]
    learner = spawn(*argv)
    session = open_session(settings(endpoint, run))
    actors = [TimedActor(session, run, f"a{i}", per_batch=args.batch) for i in range(args.actors)]
    done = threading.Event()

    def publish(actor: TimedActor) -> None:
        while not done.is_set():
            actor.send_one(done)

    threads = [threading.Thread(target=publish, args=(a,), daemon=True) for a in actors]
    try:
        for thread in threads:
            thread.start()
        deadline = time.monotonic() + 120
        while not all(a.ack_times for a in actors) and time.monotonic() < deadline:
            time.sleep(0.2)
        start = time.time() + 1.0
        time.sleep(1.0 + args.seconds)
        end = time.time()
    finally:
        done.set()
        for thread in threads:
            thread.join(10)
        for actor in actors:
            actor.close()
        session.close()
        out = stop(learner, timeout=300)
    checkpoints = []  # (start, end, replay size), the final one at shutdown left out
    for line in list(CHECKPOINT_LINE.finditer(out))[:-1]:
        finished = datetime.strptime(line[1], "%Y-%m-%d %H:%M:%S,%f").timestamp()
        checkpoints.append((finished - float(line[3]), finished, int(line[2])))
    during, outside = [0.0], [0.0]
    for actor in actors:
        times = [t for t in actor.ack_times if start <= t <= end]
        for before, after in itertools.pairwise(times):
            overlaps = any(before < c_end and c_start < after for c_start, c_end, _ in checkpoints)
            (during if overlaps else outside).append(after - before)
    gaps = during[1:] + outside[1:]
    acked = sum(len([t for t in a.ack_times if start <= t <= end]) for a in actors) * args.batch
    shutil.rmtree(ckpt, ignore_errors=True)
    result = {
        "storage": storage,
        "capacity": capacity,
        "longest_stall_s": round(max(gaps), 3),
        "longest_stall_over_checkpoint_s": round(max(during), 3),
        "longest_stall_otherwise_s": round(max(outside), 3),
        "median_gap_s": round(float(np.median(gaps)), 4),
        "checkpoints": len(checkpoints),
        "checkpoint_s": [round(c[1] - c[0], 3) for c in checkpoints],
        "checkpoint_max_s": max((round(c[1] - c[0], 3) for c in checkpoints), default=None),
        "replay_at_last_checkpoint": checkpoints[-1][2] if checkpoints else 0,
        "acked_transitions_per_s": round(acked / (end - start), 1),
    }
    print(
        f"{storage:6s} {capacity:>10,d}: longest stall {result['longest_stall_s']:.3f} s (over a checkpoint "
        f"{result['longest_stall_over_checkpoint_s']:.3f} s, "
        f"otherwise {result['longest_stall_otherwise_s']:.3f} s, median gap "
        f"{result['median_gap_s'] * 1000:.1f} ms), {len(checkpoints)} checkpoints, longest "
        f"{result['checkpoint_max_s']} s, {result['acked_transitions_per_s']:.0f} transitions/s acked"
    )
    return result


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

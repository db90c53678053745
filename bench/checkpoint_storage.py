"""What checksummed, pickle-free checkpoints cost (issue 19): write, verify and load times.

A learner's NNQL replay holding ``--transitions`` transitions of the real robot's
observation (11 floats) is written, in interleaved rounds, two ways:

- ``torchrl``: TorchRL's ``dumps`` (what navlearn wrote before; its loader unpickles
  ``prefetch.pkl``), the old checkpoint with no checksums;
- ``navlearn``: ``agents.replay_files`` (safetensors + JSON) inside ``CheckpointDir.save``,
  which adds the manifest (SHA-256 of every file) and its fsyncs.

Per round it times the write, the manifest alone, ``verify`` (reading every byte back)
and the load into a fresh learner. Medians over ``--rounds``. Last line: one JSON object.

    nice -n 5 python bench/checkpoint_storage.py --transitions 100000 --rounds 5
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from services.learner.checkpoint import CheckpointDir, verify, write_manifest

OBS_DIM, N_ACTIONS = 11, 5


def filled_learner(transitions: int, capacity: int) -> NNQLLearner:
    learner = NNQLLearner(NNQLConfig(hidden_sizes=(128, 128), replay_capacity=capacity), OBS_DIM, N_ACTIONS)
    rng = np.random.default_rng(0)
    for start in range(0, transitions, 10_000):
        n = min(10_000, transitions - start)
        learner.add(
            {
                "obs": rng.random((n, OBS_DIM), dtype=np.float32),
                "action": rng.integers(0, N_ACTIONS, n),
                "reward": rng.random(n, dtype=np.float32),
                "next_obs": rng.random((n, OBS_DIM), dtype=np.float32),
                "terminated": rng.random(n) < 0.01,
                "truncated": np.zeros(n, bool),
            }
        )
    return learner


def timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def one_round(learner: NNQLLearner, work: Path) -> dict[str, float]:
    config = learner.config
    old = work / "old"
    shutil.rmtree(old, ignore_errors=True)

    def write_old() -> None:  # the previous checkpoint: TorchRL's dumps, files flushed, no manifest
        learner.replay.dumps(old)
        for p in old.rglob("*"):
            if p.is_file():
                with open(p, "rb") as fh:
                    os.fsync(fh.fileno())

    out = {"torchrl_write_s": timed(write_old), "torchrl_bytes": size(old)}
    fresh = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    out["torchrl_load_s"] = timed(lambda: fresh.replay.loads(old))

    ckpts = CheckpointDir(work / "new", keep=1)
    path = None

    def write_new() -> None:
        nonlocal path
        path = ckpts.save(lambda tmp: learner.save_replay(tmp / "replay"))

    out["navlearn_write_s"] = timed(write_new)
    out["navlearn_bytes"] = size(path)
    out["manifest_s"] = timed(lambda: write_manifest(path))  # the checksum part alone, again
    out["verify_s"] = timed(lambda: verify(path))
    fresh = NNQLLearner(config, OBS_DIM, N_ACTIONS)
    out["navlearn_load_s"] = timed(lambda: fresh.load_replay(path / "replay"))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--transitions", type=int, default=100_000, help="transitions in the replay")
    parser.add_argument("--capacity", type=int, default=100_000, help="replay capacity (navlearn's default)")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds; medians are reported")
    parser.add_argument("--dir", default=None, help="where to write (default: a temporary directory)")
    args = parser.parse_args()

    learner = filled_learner(args.transitions, max(args.capacity, args.transitions))
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        rounds = [one_round(learner, Path(tmp)) for _ in range(args.rounds)]
    result = {
        "transitions": len(learner.replay),
        "rounds": args.rounds,
        "load_avg_1m": os.getloadavg()[0],
        **{k: round(statistics.median(r[k] for r in rounds), 4) for k in rounds[0]},
        "navlearn_write_s_range": [round(min(r["navlearn_write_s"] for r in rounds), 4),
                                   round(max(r["navlearn_write_s"] for r in rounds), 4)],
        "torchrl_write_s_range": [round(min(r["torchrl_write_s"] for r in rounds), 4),
                                  round(max(r["torchrl_write_s"] for r in rounds), 4)],
    }  # fmt: skip
    print(json.dumps(result))


if __name__ == "__main__":
    main()

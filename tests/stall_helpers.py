"""The measurement behind tests/test_checkpoint_stall.py and bench/checkpoint_stall.py: a real
`navlearn learner` checkpointing on a timer while traced actors publish through the real Outbox, and
the longest wait between two acknowledgements, split by whether it overlaps a checkpoint."""

from __future__ import annotations

import argparse
import itertools
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from services.common.transport import ZenohSettings, open_session
from tests.reliability_helpers import TracedActor


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def spawn(*argv: str) -> subprocess.Popen:
    """A child Python process whose stdout this one reads (NAVLEARN_* variables dropped: flags rule)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    return subprocess.Popen(
        [sys.executable, *argv], env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )


def stop(process: subprocess.Popen, timeout: float = 60) -> str:
    """SIGTERM, then SIGKILL after ``timeout``; returns what the process printed."""
    process.send_signal(signal.SIGTERM)
    try:
        out, _ = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out or ""


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
    session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
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

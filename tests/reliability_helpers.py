"""A traceable actor for the reliability tests: every transition carries a unique id in its reward.

It sends through the real Outbox (at-least-once: kept until acknowledged, resent
after a learner restart) and records which ids the learner acknowledged, so a
test can compare them with what the learner's replay buffer holds.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from protocols import keys
from protocols.codec import decode, encode
from protocols.flow import Ack
from protocols.messages import TransitionBatch
from services.common.outbox import Outbox
from services.ops.status import query_status
from worlds.config import LEARNING_NAV, observation_settings
from worlds.perception import observation_dim

OBS_DIM, N_ACTIONS = observation_dim(LEARNING_NAV), 5  # what the learner service takes, 5 turns


class TracedActor:
    """Publishes batches of ``per_batch`` transitions whose rewards are ids ``first_id, first_id+1, ...``."""

    def __init__(self, session, run: str, actor: str, per_batch: int = 8, first_id: int = 1) -> None:
        import zenoh

        self.actor = actor
        self.sender = f"{actor}#{time.time_ns()}"
        self.per_batch = per_batch
        self.next_id = first_id
        self.seq = 0
        self.ids_by_seq: dict[int, np.ndarray] = {}
        self.payloads: dict[int, bytes] = {}
        """encoded batches by seq, to replay a resend by hand"""
        self.acked_seqs: set[int] = set()
        self._lock = threading.Lock()
        self.publisher = session.declare_publisher(
            keys.transitions(run, actor), congestion_control=zenoh.CongestionControl.BLOCK
        )
        self.outbox = Outbox(
            self.publisher.put, lambda: self.publisher.matching_status.matching, 64, 4, ack_timeout=3.0
        )
        self.acks = session.declare_subscriber(keys.acks(run, actor), self._on_ack)

    def _on_ack(self, sample) -> None:
        ack = decode(sample.payload.to_bytes())
        if isinstance(ack, Ack) and ack.actor == self.sender:
            with self._lock:
                self.acked_seqs.add(ack.accepted_seq)
            self.outbox.on_ack(ack.accepted_seq)

    def make_batch(self) -> TransitionBatch:
        n = self.per_batch
        ids = np.arange(self.next_id, self.next_id + n, dtype=np.float32)
        self.next_id += n
        self.seq += 1
        self.ids_by_seq[self.seq] = ids
        rng = np.random.default_rng(self.seq)
        return TransitionBatch(
            sender=self.sender,
            seq=self.seq,
            actor=self.actor,
            model="nnql",
            policy_version=0,
            env_ids=np.arange(n, dtype=np.int32),
            obs=rng.random((n, OBS_DIM), dtype=np.float32),
            action=rng.integers(0, N_ACTIONS, n),
            reward=ids,
            next_obs=rng.random((n, OBS_DIM), dtype=np.float32),
            terminated=np.zeros(n, bool),
            truncated=np.zeros(n, bool),
        )

    def send_one(self, stop: threading.Event) -> None:
        batch = self.make_batch()
        self.payloads[batch.seq] = encode(batch)
        self.outbox.put(batch.seq, self.payloads[batch.seq])
        self.outbox.flush(stop)

    def acked_ids(self) -> np.ndarray:
        with self._lock:
            seqs = sorted(self.acked_seqs)
        return np.concatenate([self.ids_by_seq[s] for s in seqs]) if seqs else np.zeros(0, np.float32)

    def sent_ids(self) -> np.ndarray:
        return np.concatenate(list(self.ids_by_seq.values())) if self.ids_by_seq else np.zeros(0, np.float32)

    def close(self) -> None:
        self.acks.undeclare()
        self.publisher.undeclare()


def settle(session, run: str, timeout: float = 60.0) -> None:
    """Wait until the learner's flood counters stop moving (the router may still be delivering a
    flood after the flooder stopped). Only the flooder's: a normal actor keeps sending meanwhile,
    so the learner's total of batches never stops moving (with it here, every settle ran out its
    whole timeout)."""
    watched = ("rejected/batch_too_large", "dropped/sender_full/flood", "transitions/flood")
    last, deadline = None, time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = query_status(session, run, timeout=5.0)
        now = status and tuple(status.counters.get(k, 0) for k in watched)
        if now is not None and now == last:
            return
        last = now
        time.sleep(1.5)


def caught_up(actor: TracedActor, timeout: float = 60.0) -> None:
    """Wait until ``actor``'s outbox holds no more than its window (no backlog of unsent batches)."""
    deadline = time.monotonic() + timeout
    while len(actor.outbox) > actor.outbox.window and time.monotonic() < deadline:
        time.sleep(0.1)


def learner_argv(endpoint: str, run: str, checkpoint_dir: Path, *extra: str) -> list[str]:
    return [
        sys.executable, "-m", "services.cli", "learner", "--listen", endpoint, "--run", run,
        "--checkpoint-dir", str(checkpoint_dir), "--hidden-sizes", "16", "--batch-size", "16",
        "--learning-starts", "64", "--broadcast-every", "5", "--log-every", "2", *extra,
    ]  # fmt: skip


def start_learner(argv: list[str], log_path: Path) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    with open(log_path, "ab") as log:
        return subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT)


def stop_process(process: subprocess.Popen, timeout: float = 60.0) -> None:
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def stored_ids(checkpoint: Path, replay_capacity: int | None = None) -> np.ndarray:
    """The reward ids in the replay buffer of a learner checkpoint (``ckpt-*`` directory) written by a
    learner with ``replay_capacity`` (default: NNQLConfig's; TorchRL loads a storage only into one of
    the same size)."""
    from agents.nnql.config import NNQLConfig
    from agents.nnql.learner import NNQLLearner

    config = NNQLConfig(hidden_sizes=(16,), batch_size=16, learning_starts=64)
    if replay_capacity is not None:
        config = dataclasses.replace(config, replay_capacity=replay_capacity)
    memmap = checkpoint / "nnql" / "replay" / "memmap.json"  # a memory-mapped replay: its files' directory
    replay_dir = json.loads(memmap.read_text())["directory"] if memmap.exists() else None
    # built as the learner service builds it: on the learning observation's settings (the network
    # variant they resolve to, services/learner/run.py)
    observation = observation_settings(LEARNING_NAV)
    learner = NNQLLearner(config, OBS_DIM, N_ACTIONS, replay_dir=replay_dir, observation=observation)
    learner.load_checkpoint(checkpoint / "nnql")
    n = len(learner.replay)
    if n == 0:
        return np.zeros(0, np.float32)
    return learner.replay.storage[:n][("next", "reward")].reshape(-1).numpy()

"""Bounded memory under abuse: per-sender inbox limits; a flooding actor against a real learner."""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from protocols import keys
from protocols.codec import encode
from protocols.limits import Limits
from protocols.messages import TransitionBatch
from services.common.transport import ZenohSettings, open_session
from services.learner.fairqueue import FairQueue, SenderFull
from services.learner.inbox import Inbox
from services.ops.status import query_status
from tests.conftest import free_port
from tests.reliability_helpers import (
    N_ACTIONS,
    OBS_DIM,
    TracedActor,
    learner_argv,
    start_learner,
    stop_process,
)


def test_fair_queue_bounds_each_sender_and_serves_round_robin():
    q: FairQueue[str] = FairQueue(capacity=6, per_sender=3)
    for i in range(3):
        q.put_nowait("flood", f"f{i}")
    with pytest.raises(SenderFull):
        q.put_nowait("flood", "f3")
    q.put_nowait("calm", "c0")
    q.put_nowait("calm", "c1")
    q.put_nowait("other", "o0")
    with pytest.raises(queue.Full):
        q.put_nowait("calm", "c2")  # 6 in all
    taken = [q.get_nowait() for _ in range(6)]
    assert taken == ["f0", "c0", "o0", "f1", "c1", "f2"]
    with pytest.raises(queue.Empty):
        q.get(timeout=0.05)


class _Sample:
    """What the inbox's Zenoh callback reads of a sample: its key and its payload bytes."""

    def __init__(self, key: str, data: bytes) -> None:
        self.key_expr, self.payload, self._data = key, self, data

    def to_bytes(self) -> bytes:
        return self._data


def test_a_full_share_drops_before_decoding():
    inbox = Inbox(Limits(n_actions=N_ACTIONS), capacity=16, run="r", per_sender=2)
    batch = TransitionBatch(
        actor="flood",
        model="nnql",
        policy_version=0,
        env_ids=np.arange(4, dtype=np.int32),
        obs=np.zeros((4, OBS_DIM), np.float32),
        action=np.zeros(4, np.int64),
        reward=np.zeros(4, np.float32),
        next_obs=np.zeros((4, OBS_DIM), np.float32),
        terminated=np.zeros(4, bool),
        truncated=np.zeros(4, bool),
    )
    for seq in (1, 2):
        batch.seq = seq
        inbox.on_sample(_Sample(keys.transitions("r", "flood"), encode(batch)))
    assert inbox.transitions.sender_full("flood") and not inbox.transitions.sender_full("calm")
    inbox.on_sample(_Sample(keys.transitions("r", "flood"), b"not a message"))  # dropped, never decoded
    inbox.on_sample(_Sample(keys.transitions("r", "calm"), b"not a message"))  # decoded, rejected
    counts = inbox.counts()
    assert counts["dropped/sender_full/flood"] == 1 and counts["rejected/malformed"] == 1, counts
    assert inbox.transitions.qsize() == 2


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(180)
def test_flooding_actor_is_bounded_and_counted_while_the_learner_trains(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"flood{port}"
    argv = learner_argv(endpoint, run, tmp_path / "ckpt", "--inbox-size", "32")
    learner = start_learner(argv, tmp_path / "learner.log")
    session = None
    stop = threading.Event()
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        calm = TracedActor(session, run, "calm")
        flood = TracedActor(session, run, "flood", per_batch=256)
        for _ in range(20):  # the learner is up and training before the flood
            calm.send_one(stop)
        deadline = time.monotonic() + 60
        while len(calm.acked_seqs) < 20 and time.monotonic() < deadline:
            time.sleep(0.2)
        rss_before = rss_mb(learner.pid)
        version_before = query_status(session, run, timeout=5.0).versions["nnql"]
        payload = encode(flood.make_batch())  # the same batch again and again, acks ignored
        flood_until = time.monotonic() + 6.0
        while time.monotonic() < flood_until:
            for _ in range(50):
                flood.publisher.put(payload)
            calm.send_one(stop)
        for _ in range(10):
            calm.send_one(stop)
        deadline = time.monotonic() + 60
        while len(calm.outbox) and time.monotonic() < deadline:
            calm.outbox.flush(stop)
            time.sleep(0.2)
        time.sleep(1.0)
        status = query_status(session, run, timeout=5.0)
        rss_after = rss_mb(learner.pid)
        calm.close()
        flood.close()
    finally:
        stop.set()
        if session is not None:
            session.close()
        stop_process(learner)
    counters = status.counters
    assert counters.get("dropped/sender_full/flood", 0) > 0, counters
    assert counters.get("dropped/sender_full/calm", 0) == 0
    assert len(calm.outbox) == 0 and len(calm.acked_seqs) == calm.seq  # the calm actor lost nothing
    assert status.versions["nnql"] > version_before  # still training
    assert rss_after - rss_before < 300, (rss_before, rss_after)
    print(
        f"flood dropped {counters['dropped/sender_full/flood']}, "
        f"duplicates {counters.get('duplicates_dropped')}"
        f", rss {rss_before:.0f} -> {rss_after:.0f} MB, version {version_before} -> {status.versions['nnql']}"
    )

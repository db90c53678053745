"""Bounded by bytes and fair by work (issue #19), the pure parts: the inbox's queues bound bytes as
well as items and serve senders by bytes (so transitions), not by batches; a transition batch
larger than the learner's row limit is refused with a reason before it is decoded; the set of
sender names is bounded (an ACL's names always pass); one batch holds the rate limiter's other
inserts back by at most ``tolerance`` updates."""

from __future__ import annotations

import queue
from pathlib import Path

import numpy as np
import pytest

from agents.nnql.config import NNQLConfig
from agents.nnql.ratelimit import RateLimiter
from protocols import keys
from protocols.codec import encode
from protocols.limits import Limits
from protocols.messages import TransitionBatch
from services.learner.config import LearnerConfig
from services.learner.fairqueue import MESSAGE_WORK, FairQueue, SenderFull
from services.learner.inbox import Inbox, max_batch_rows, transition_bytes_bound
from services.ops.acl import Deployment, acl_publishers, write_deployment
from tests.reliability_helpers import N_ACTIONS, OBS_DIM

MB = 2**20


class Sample:
    """What the inbox's Zenoh callback reads of a sample: its key and payload (bytes and length)."""

    def __init__(self, key: str, data: bytes) -> None:
        self.key_expr, self.payload, self._data = key, self, data

    def to_bytes(self) -> bytes:
        return self._data

    def __len__(self) -> int:
        return len(self._data)


def batch(actor: str, rows: int, seq: int = 1) -> bytes:
    return encode(
        TransitionBatch(
            sender=f"{actor}#1",
            seq=seq,
            actor=actor,
            model="nnql",
            policy_version=0,
            env_ids=np.zeros(rows, np.int32),
            obs=np.zeros((rows, OBS_DIM), np.float32),
            action=np.arange(rows) % N_ACTIONS,
            reward=np.zeros(rows, np.float32),
            next_obs=np.zeros((rows, OBS_DIM), np.float32),
            terminated=np.zeros(rows, bool),
            truncated=np.zeros(rows, bool),
        )
    )


# ---------------------------------------------------------------- the fair queue


def test_fair_queue_bounds_bytes_per_sender_and_in_all():
    q: FairQueue[str] = FairQueue(capacity=100, per_sender=100, capacity_bytes=1000, per_sender_bytes=400)
    q.put_nowait("a", "a0", 300)
    with pytest.raises(SenderFull):
        q.put_nowait("a", "a1", 200)  # 500 > 400 for one sender
    assert q.sender_full("a", 200) and not q.sender_full("a", 100)
    q.put_nowait("b", "b0", 400)
    with pytest.raises(SenderFull):
        q.put_nowait("c", "c0", 401)  # larger than any one sender's share
    q.put_nowait("c", "c0", 300)
    with pytest.raises(queue.Full):
        q.put_nowait("d", "d0", 1)  # 1001 bytes in all
    assert q.nbytes() == 1000
    q.get_nowait()
    assert q.nbytes() == 700


def test_fair_queue_serves_bytes_not_batches():
    """A flooder's large items and a calm sender's small ones, both backlogged: each gets half of
    the work served; the calm sender's items do not wait behind the flooder's backlog."""
    q: FairQueue[tuple[str, int]] = FairQueue(capacity=10_000, per_sender=10_000)
    big, small = 100_000, 2_000
    for _ in range(50):
        q.put_nowait("flood", ("flood", big), big)
    for _ in range(5000):
        q.put_nowait("calm", ("calm", small), small)
    served = {"flood": 0, "calm": 0}
    while sum(served.values()) < 40 * (big + MESSAGE_WORK):  # both still backlogged
        sender, nbytes = q.get_nowait()
        served[sender] += nbytes + MESSAGE_WORK
    assert abs(served["flood"] - served["calm"]) <= big + MESSAGE_WORK, served


def test_a_light_sender_is_served_next_however_long_a_flooders_backlog():
    q: FairQueue[str] = FairQueue(capacity=1000, per_sender=1000)
    for i in range(200):
        q.put_nowait("flood", f"f{i}", 100_000)
    for _ in range(20):
        q.get_nowait()
    q.put_nowait("calm", "c0", 2_000)  # arrives behind 180 waiting flood batches
    assert q.peek() == "c0" and q.get_nowait() == "c0"


# ---------------------------------------------------------------- the inbox


def test_a_batch_over_the_row_limit_is_refused_with_a_reason_before_decoding():
    inbox = Inbox(Limits(n_actions=N_ACTIONS, max_obs_dim=OBS_DIM), capacity=16, run="r", max_rows=100)
    key = keys.transitions("r", "a1")
    inbox.on_sample(Sample(key, batch("a1", 100)))
    inbox.on_sample(Sample(key, batch("a1", 101, seq=2)))  # decoded, then refused by its rows
    huge = b"\x00" * (transition_bytes_bound(100, OBS_DIM) + 1)
    inbox.on_sample(Sample(key, huge))  # refused by its size: not msgpack, yet never decoded
    counts = inbox.counts()
    assert counts == {"rejected/batch_too_large": 2}, counts
    assert inbox.transitions.qsize() == 1


def test_the_set_of_names_is_bounded_and_an_acls_names_always_pass():
    inbox = Inbox(
        Limits(n_actions=N_ACTIONS), capacity=64, run="r", max_names=3, known_names=frozenset({"a1"})
    )
    for i in range(10):
        inbox.on_sample(Sample(keys.transitions("r", f"x{i}"), batch(f"x{i}", 4)))
    inbox.on_sample(Sample(keys.transitions("r", "a1"), batch("a1", 4)))
    inbox.on_sample(Sample(keys.transitions("r", "x0"), batch("x0", 4, seq=2)))  # a known name: still in
    inbox.on_sample(Sample(keys.transitions("r", "junk"), b"garbage"))  # no room: never decoded
    assert inbox.names() == {"x0", "x1", "x2"}
    assert inbox.counts() == {"rejected/too_many_names": 8}
    assert inbox.transitions.qsize() == 5


def test_garbage_under_new_names_does_not_use_up_the_names():
    inbox = Inbox(Limits(n_actions=N_ACTIONS), capacity=64, run="r", max_names=2)
    for i in range(5):
        inbox.on_sample(Sample(keys.transitions("r", f"junk{i}"), b"garbage"))
    inbox.on_sample(Sample(keys.transitions("r", "a1"), batch("a1", 4)))
    assert inbox.names() == {"a1"} and inbox.counts()["rejected/malformed"] == 5


def test_the_inbox_bounds_bytes_not_only_batches():
    limits = Limits(n_actions=N_ACTIONS, max_message_bytes=MB)
    inbox = Inbox(limits, capacity=1000, run="r", capacity_bytes=4 * MB)
    payload = batch("a1", 20_000)  # about 0.9 MB
    for _ in range(10):
        inbox.on_sample(Sample(keys.transitions("r", "a1"), payload))
    assert inbox.transitions.nbytes() <= MB  # a quarter of 4 MB for one actor
    assert inbox.counts()["dropped/sender_full"] >= 8
    with pytest.raises(ValueError, match="raise the inbox's bytes"):
        Inbox(limits, capacity=10, run="r", capacity_bytes=MB)


def test_the_row_limit_fits_the_replay_and_the_rate_limiter():
    nnql = NNQLConfig()
    assert max_batch_rows(LearnerConfig(), nnql) == min(1000, int(64 / nnql.utd_ratio))
    assert max_batch_rows(LearnerConfig(max_batch_fraction=0.5, rate_tolerance=8), nnql) == int(
        8 / nnql.utd_ratio
    )
    with pytest.raises(ValueError, match="--max-batch-fraction"):
        max_batch_rows(LearnerConfig(max_batch_fraction=1e-9), nnql)


# ---------------------------------------------------------------- the rate limiter


def test_one_batch_holds_the_others_back_by_at_most_the_tolerance():
    """Any mix of batches up to max_rows: the updates owed never exceed the band, so after any insert
    a batch of the smallest size goes in within ``tolerance`` updates, and none waits forever."""
    limiter = RateLimiter(updates_per_insert=0.0625, min_size=256, tolerance=64)
    rng = np.random.default_rng(0)
    waited_for = []
    for _ in range(2000):
        rows = int(rng.choice([16, 128, limiter.max_rows()]))
        ran = 0
        while not limiter.can_insert(rows):
            assert limiter.can_update(limiter.inserts)  # never both closed
            limiter.updated()
            ran += 1
        waited_for.append(ran)
        limiter.inserted(rows)
        assert limiter.diff <= limiter.max_diff
    assert max(waited_for) <= limiter.tolerance + 1


def test_before_the_fix_one_large_batch_blocked_inserts_for_its_rows_times_the_ratio():
    limiter = RateLimiter(updates_per_insert=0.125, min_size=64, tolerance=64)
    assert not limiter.can_insert(300_000)  # it would owe 37,500 updates: refused, never inserted
    assert limiter.max_rows() == 512


# ---------------------------------------------------------------- names from an ACL


def test_the_learner_reads_the_publishers_of_an_acl(tmp_path: Path):
    d = Deployment(run="r1", actors=["a1", "a2"], demonstrators=["d1=astar"], evaluators=["ev1"])
    files = write_deployment(tmp_path, d)
    assert acl_publishers(files["acl.json5"], "r1") == {"a1", "a2", "astar", "ev1"}
    assert acl_publishers(files["acl.json5"], "other-run") == set()

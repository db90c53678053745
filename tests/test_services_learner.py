"""`navlearn learner` as a real subprocess (hosting its router on a free loopback port).

The test process is an actor and a late joiner: it asks for weights, sends bad and good
transition batches, reads acknowledgements and status, then stops the learner with SIGTERM.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import free_port

from protocols import keys
from protocols.codec import decode, encode
from protocols.flow import Ack
from protocols.messages import DemoBatch, EpisodeMeta, EvalReport, TransitionBatch, WeightsUpdate
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(300)]
OBS_DIM, N_ACTIONS = observation_dim(LEARNING_NAV), 5  # what the learner service takes, 5 turns


def batch(actor: str, seq: int, n: int = 32, **override) -> TransitionBatch:
    rng = np.random.default_rng(seq)
    fields = dict(
        actor=actor,
        model="nnql",
        policy_version=0,
        env_ids=np.arange(n, dtype=np.int32),
        obs=rng.random((n, OBS_DIM), dtype=np.float32),
        action=rng.integers(0, N_ACTIONS, n),
        reward=rng.random(n, dtype=np.float32),
        next_obs=rng.random((n, OBS_DIM), dtype=np.float32),
        terminated=np.zeros(n, bool),
        truncated=np.zeros(n, bool),
    )
    fields.update(override)
    return TransitionBatch(sender=actor, seq=seq, **fields)


@pytest.fixture
def learner(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"lt{port}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    argv = [
        sys.executable, "-m", "services.cli", "learner", "--listen", endpoint, "--run", run,
        "--checkpoint-dir", str(tmp_path / "ckpt"), "--hidden-sizes", "16", "--batch-size", "16",
        "--learning-starts", "64", "--broadcast-every", "5", "--log-every", "2",
    ]  # fmt: skip
    log = open(tmp_path / "learner.log", "wb")  # noqa: SIM115 - closed below
    process = subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT)
    session = None
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        yield process, session, run, tmp_path
    finally:
        if session is not None:
            session.close()
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(60)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        log.close()


def wait_status(session, run, predicate, timeout=120.0):
    deadline = time.monotonic() + timeout
    status = None
    while time.monotonic() < deadline:
        status = query_status(session, run, timeout=2.0)
        if status is not None and predicate(status):
            return status
        time.sleep(0.3)
    raise AssertionError(f"status never satisfied the condition; last {status}")


def test_learner_serves_weights_rejects_bad_input_trains_acks_and_checkpoints(learner):
    process, session, run, tmp_path = learner
    wait_status(session, run, lambda s: True)

    # a late joiner gets the newest weights from the queryable
    replies = [
        decode(r.ok.payload.to_bytes()) for r in session.get(keys.weights(run, "nnql"), timeout=5) if r.ok
    ]
    assert len(replies) == 1 and isinstance(replies[0], WeightsUpdate)
    assert replies[0].version == 0 and replies[0].architecture["obs_dim"] == OBS_DIM
    assert replies[0].exploration.exploration == "boltzmann" and "exploration" not in replies[0].architecture

    # bad input is counted by reason, never crashes the learner
    key = keys.transitions(run, "a1")
    session.put(key, b"\x93not a navlearn message")
    session.put(key, encode(batch("a1", 1, obs=np.full((32, OBS_DIM), np.nan, np.float32))))
    session.put(key, encode(batch("a2", 1)))  # another actor's batch on a1's key
    session.put(key, encode(EvalReport(model="nnql", policy_version=0, metrics={})))
    session.put(key, encode(batch("a1", 1, action=np.full(32, N_ACTIONS))))
    status = wait_status(session, run, lambda s: s.counters.get("transitions_rejected", 0) >= 5)
    for reason in ("malformed", "nonfinite", "key", "kind", "action_range"):
        assert status.counters[f"rejected/{reason}"] == 1, reason

    # good batches are inserted, acknowledged, trained on; new weights are broadcast
    acks, versions = [], []
    got_weights = threading.Event()

    def on_weights(sample):
        versions.append(decode(sample.payload.to_bytes()).version)
        got_weights.set()

    ack_sub = session.declare_subscriber(
        keys.acks(run, "a1"), lambda s: acks.append(decode(s.payload.to_bytes()))
    )
    weights_sub = session.declare_subscriber(keys.weights(run, "nnql"), on_weights)
    time.sleep(0.5)
    for seq in range(2, 10):
        session.put(key, encode(batch("a1", seq)))
    status = wait_status(session, run, lambda s: s.counters.get("transitions_received", 0) == 8 * 32)
    status = wait_status(session, run, lambda s: s.versions["nnql"] > 0)
    assert got_weights.wait(30) and max(versions) > 0
    deadline = time.monotonic() + 10
    while len(acks) < 8 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert all(isinstance(a, Ack) for a in acks) and sorted(a.accepted_seq for a in acks) == list(
        range(2, 10)
    )
    assert status.replay_sizes["transitions"] == 256 and "a1" in status.actors_last_seen
    assert status.counters["transitions_rejected"] == 5
    ack_sub.undeclare()
    weights_sub.undeclare()

    # demonstrations go to their own buffer, never into the actors' replay
    lengths = np.array([3, 5], np.int32)
    demo = DemoBatch(
        source="astar",
        episode_lengths=lengths,
        obs=np.random.default_rng(1).random((int(lengths.sum()) + 2, OBS_DIM), dtype=np.float32),
        actions=np.zeros(8, np.int64),
        rewards=np.zeros(8, np.float32),
        terminations=np.array([0, 0, 1, 0, 0, 0, 0, 1], bool),
        truncations=np.zeros(8, bool),
        episodes=[EpisodeMeta(map_id="m", start=(1, 1), goal=(3, 3)) for _ in range(2)],
    )
    session.put(keys.demos(run, "astar"), encode(demo))
    status = wait_status(session, run, lambda s: s.replay_sizes["demos"] == 8)
    assert status.replay_sizes["transitions"] == 256 and status.counters["demo_steps"] == 8

    # SIGTERM: clean exit with a checkpoint holding the counters
    process.send_signal(signal.SIGTERM)
    assert process.wait(60) == 0
    checkpoints = sorted((tmp_path / "ckpt").glob("ckpt-*"))
    saved = json.loads((checkpoints[-1] / "service.json").read_text())
    assert saved["counters"]["transitions_received"] == 256
    assert saved["inbox_counts"]["rejected/malformed"] == 1
    assert saved["limiter"]["updates"] >= status.versions["nnql"]


def test_a_replayed_batch_with_a_rewritten_sender_is_acknowledged_not_stored_again(learner):
    """Issue 43's attack: an old, acknowledged batch replayed with its ``sender`` rewritten."""
    _process, session, run, _tmp_path = learner
    wait_status(session, run, lambda s: True)
    key = keys.transitions(run, "a1")
    acks = []
    sub = session.declare_subscriber(
        keys.acks(run, "a1"), lambda s: acks.append(decode(s.payload.to_bytes()))
    )
    time.sleep(0.5)
    original = batch("a1", 1)
    original.sender = "a1#1000"
    session.put(key, encode(original))
    wait_status(session, run, lambda s: s.replay_sizes["transitions"] == 32)
    for n, sender in enumerate(("a1#2000", "mallory#1", "a1#1000x"), start=2):
        copy = batch("a1", 1)  # the same content (same seed), another sender
        copy.sender = sender
        session.put(key, encode(copy))
        status = wait_status(session, run, lambda s, n=n: s.counters.get("duplicates_by_content", 0) == n - 1)
    assert status.replay_sizes["transitions"] == 32 and status.counters["duplicates_dropped"] == 3
    session.put(key, encode(batch("a1", 2)))  # new content is still taken
    status = wait_status(session, run, lambda s: s.replay_sizes["transitions"] == 64)
    deadline = time.monotonic() + 10
    while len(acks) < 5 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert {a.actor for a in acks} >= {"a1#1000", "a1#2000", "mallory#1"}  # each sender hears "stored"
    sub.undeclare()

"""kill -9 of a real learner while a demonstrator publishes: every acknowledged demonstration step is
in the learner's demonstration buffer exactly once afterwards (the transitions' guarantee, for demos).

The demonstrator side is the service's own DemoPublisher (its Outbox, acks on
``acks/<source>``) publishing episodes whose rewards are unique ids.
"""

from __future__ import annotations

import signal
import threading
import time

import numpy as np
import pytest

from agents.demos import Demo
from services.common.transport import ZenohSettings, open_session
from services.demonstrator.demonstrator import DemonstratorConfig, DemoPublisher
from services.learner.checkpoint import CheckpointDir
from services.ops.status import query_status
from tests.conftest import free_port
from tests.reliability_helpers import OBS_DIM, learner_argv, start_learner, stop_process
from tests.test_reliability_kill import wait_for

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]
STEPS = 6  # per episode


def episode(first_id: int) -> Demo:
    rng = np.random.default_rng(first_id)
    return Demo(
        observations=rng.random((STEPS + 1, OBS_DIM), dtype=np.float32),
        actions=rng.integers(0, 5, STEPS),
        rewards=np.arange(first_id, first_id + STEPS, dtype=np.float32),
        terminations=np.arange(STEPS) == STEPS - 1,
        truncations=np.zeros(STEPS, bool),
        poses=np.zeros((STEPS + 1, 3)),
        metadata={"start": (1, 1), "goal": (5, 5), "map_id": "test"},
    )


def stored_demo_ids(checkpoint) -> np.ndarray:
    from services.learner.demo_buffer import DemoBuffer
    from services.learner.service import LearnerConfig

    demos = DemoBuffer(LearnerConfig().demo_capacity, OBS_DIM)
    demos.load(checkpoint / "demos", 0)
    n = len(demos)
    return demos.replay.storage[:n][("next", "reward")].reshape(-1).numpy() if n else np.zeros(0)


def test_sigkill_learner_loses_no_acknowledged_demonstration(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"killdemo{port}"
    ckpt_dir = tmp_path / "ckpt"
    argv = learner_argv(endpoint, run, ckpt_dir, "--checkpoint-every", "1")
    log_path = tmp_path / "learner.log"
    learner = start_learner(argv, log_path)
    stop, sending = threading.Event(), threading.Event()
    session = publisher = thread = None
    ids_by_seq: dict[int, np.ndarray] = {}
    payloads: dict[int, bytes] = {}
    acked: set[int] = set()
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        config = DemonstratorConfig(source="astar", id="d1", ack_timeout=3.0)
        publisher = DemoPublisher(session, run, config, stop)
        outbox = publisher.outbox
        on_ack, put = outbox.on_ack, outbox.put
        outbox.on_ack = lambda seq: (acked.add(seq), on_ack(seq))
        outbox.put = lambda seq, payload: (payloads.__setitem__(seq, payload), put(seq, payload))

        def publish_forever() -> None:
            next_id = 1
            while not stop.is_set():
                if sending.is_set():
                    ids_by_seq[publisher.seq + 1] = np.arange(next_id, next_id + STEPS, dtype=np.float32)
                    publisher.publish([episode(next_id)])
                    next_id += STEPS
                time.sleep(0.01)

        thread = threading.Thread(target=publish_forever, daemon=True)
        sending.set()
        thread.start()
        wait_for(lambda: len(acked) >= 30 and CheckpointDir(ckpt_dir).latest(), 120, "30 demo acks")
        learner.send_signal(signal.SIGKILL)
        learner.wait()
        killed_at, killed_seq = len(acked), publisher.seq
        time.sleep(1.0)
        learner = start_learner(argv, log_path)
        wait_for(lambda: len(acked) >= killed_at + 15, 120, "demo acks after the restart")
        sending.clear()
        assert publisher.drain(timeout=60), "the demonstrator's outbox did not drain"
        for seq in (1, max(s for s in acked if s <= killed_seq)):  # resends: recognised as duplicates
            publisher.publisher.put(payloads[seq])
        total = STEPS * len(ids_by_seq)
        deadline = time.monotonic() + 30
        while (status := query_status(session, run, timeout=5.0)) is None or (
            (status.replay_sizes["demos"] < total or status.counters.get("duplicates_dropped", 0) < 2)
            and time.monotonic() < deadline
        ):
            time.sleep(0.3)
    finally:
        stop.set()
        if thread is not None:
            thread.join(10)
        if publisher is not None:
            publisher.close()
        if session is not None:
            session.close()
        stop_process(learner)

    stored = stored_demo_ids(CheckpointDir(ckpt_dir).latest())
    unique, counts = np.unique(stored, return_counts=True)
    assert counts.max() == 1, f"{int((counts > 1).sum())} demo steps stored twice"
    acked_ids = np.concatenate([ids_by_seq[s] for s in sorted(acked)])
    missing = np.setdiff1d(acked_ids, unique)
    assert missing.size == 0, f"{missing.size} acknowledged demo steps lost"
    assert len(acked) == len(ids_by_seq)  # everything published was acknowledged in the end
    assert status.replay_sizes["demos"] == len(unique) == total
    assert status.counters["duplicates_dropped"] >= 2
    assert "write-ahead log replayed" in log_path.read_text()
    print(f"demo batches {len(ids_by_seq)}, steps stored {len(unique)}, resent {outbox.resent}")

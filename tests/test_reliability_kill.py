"""kill -9 of a real learner process: every acknowledged transition is in replay exactly once afterwards.

A traceable actor (tests/reliability_helpers.py: unique ids in the rewards, the
real Outbox) sends to a learner process that checkpoints every second; the
learner is SIGKILLed mid-stream and restarted on the same checkpoint directory.
Its write-ahead log replays what was acknowledged after the last checkpoint, the
actor resends what was not acknowledged, the learner drops the duplicates.
"""

from __future__ import annotations

import signal
import threading
import time

import numpy as np
import pytest

from services.common.transport import ZenohSettings, open_session
from services.learner.checkpoint import CheckpointDir
from services.ops.status import query_status
from tests.conftest import free_port
from tests.reliability_helpers import TracedActor, learner_argv, start_learner, stop_process, stored_ids

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(240)]


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.2)
    raise AssertionError(f"timed out waiting for {what}")


@pytest.mark.parametrize("replay_storage", ["memory", "memmap"])
def test_sigkill_learner_loses_no_acknowledged_transition_and_stores_none_twice(tmp_path, replay_storage):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"kill{port}"
    ckpt_dir = tmp_path / "ckpt"
    argv = learner_argv(
        endpoint, run, ckpt_dir, "--checkpoint-every", "1", f"--replay-storage={replay_storage}"
    )
    log_path = tmp_path / "learner.log"
    learner = start_learner(argv, log_path)
    session = actor = None
    stop, sending = threading.Event(), threading.Event()
    sender = None
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        actor = TracedActor(session, run, "a1")

        def send_forever() -> None:
            while not stop.is_set():
                if sending.is_set():
                    actor.send_one(stop)
                time.sleep(0.01)

        sender = threading.Thread(target=send_forever, daemon=True)
        sending.set()
        sender.start()
        wait_for(lambda: len(actor.acked_seqs) >= 40 and CheckpointDir(ckpt_dir).latest(), 120, "40 acks")
        version_before = query_status(session, run, timeout=5.0).versions["nnql"]

        learner.send_signal(signal.SIGKILL)  # mid-stream: batches in flight, some acked since the checkpoint
        learner.wait()
        killed_at = len(actor.acked_seqs)
        killed_seq = actor.seq
        time.sleep(1.0)  # the actor keeps producing into its outbox meanwhile
        learner = start_learner(argv, log_path)
        wait_for(lambda: len(actor.acked_seqs) >= killed_at + 20, 120, "acks after the restart")
        sending.clear()
        wait_for(lambda: len(actor.outbox) == 0, 60, "the outbox to drain")
        # resends of a batch from the checkpoint and of the last one acknowledged before the kill
        # (maybe only in the write-ahead log): both recognised as duplicates
        for seq in (1, max(s for s in actor.acked_seqs if s <= killed_seq)):
            actor.publisher.put(actor.payloads[seq])
        total = len(actor.sent_ids())
        deadline = time.monotonic() + 30  # the status snapshot is refreshed every 0.5 s
        while (status := query_status(session, run, timeout=5.0)) is None or (
            (status.replay_sizes["transitions"] < total or status.counters.get("duplicates_dropped", 0) < 2)
            and time.monotonic() < deadline
        ):
            time.sleep(0.3)
        assert status.versions["nnql"] >= version_before  # the policy version continues
    finally:
        stop.set()
        if sender is not None:
            sender.join(10)
        if actor is not None:
            actor.close()
        if session is not None:
            session.close()
        stop_process(learner)  # SIGTERM: a final checkpoint holding everything

    acked = actor.acked_ids()
    latest = CheckpointDir(ckpt_dir).latest()
    memmap = (latest / "nnql" / "replay" / "memmap.json").exists()  # its state only, not the transitions
    assert memmap == (replay_storage == "memmap") == (ckpt_dir / "replay").is_dir()
    stored = stored_ids(latest)
    unique, counts = np.unique(stored, return_counts=True)
    assert counts.max() == 1, f"{int((counts > 1).sum())} transitions stored twice"
    missing = np.setdiff1d(acked, unique)
    assert missing.size == 0, f"{missing.size} acknowledged transitions lost"
    assert np.isin(unique, actor.sent_ids()).all()
    assert len(acked) == len(actor.sent_ids())  # everything sent was acknowledged in the end
    counters = status.counters
    assert counters["transitions/a1"] == status.replay_sizes["transitions"] == len(unique)
    log_text = log_path.read_text()
    assert "write-ahead log replayed" in log_text
    assert counters["duplicates_dropped"] >= 2
    print(
        f"sent {len(actor.sent_ids())}, acked {len(acked)}, stored {len(unique)}, "
        f"duplicates dropped {counters.get('duplicates_dropped', 0)}, resent {actor.outbox.resent}, "
        f"replayed {counters.get('wal_replayed', 0)}"
    )

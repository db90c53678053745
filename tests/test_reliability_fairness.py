"""A flooder in its own process against a real learner (issue #19): valid batches of the largest
accepted size on its own key as fast as Zenoh takes them, and ~60 MB valid batches on 4 more keys.
A normal actor's acknowledged rate (it sends at its own pace, within its fair share, as a real
actor's robots do), measured in interleaved rounds with and without the flood, falls by at most
SLOWDOWN_BOUND; the learner's RSS grows by at most RSS_BOUND_MB; the large batches
are refused with their reason, the flooder's excess dropped on its own share; nothing of the
normal actor is lost. And a flood of distinct actor names leaves the status readable and small.

The flooder runs under ``nice -n 19``: on this one 2-core host it would otherwise take CPU time
from the learner and the normal actor that an attacker on another host could not; what it costs
the learner (every message it sends reaches the learner's Zenoh callbacks) is measured."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path

import pytest
import zenoh

from protocols import keys
from protocols.codec import encode
from services.actor.flooder import launch, make_batch
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status
from tests.conftest import free_port
from tests.reliability_helpers import (
    TracedActor,
    caught_up,
    learner_argv,
    settle,
    start_learner,
    stop_process,
)

REPO = Path(__file__).resolve().parents[1]
SLOWDOWN_BOUND = 0.20
"""the normal actor's acknowledged rate under the flood is at least 80% of its rate without"""
RSS_BOUND_MB = 600
"""the learner's RSS under the flood grows by at most this (two inbox queues of 256 MB, plus
Zenoh's buffers for the message being received)"""
ROUNDS, ROUND_S = 2, 8.0
NORMAL_RATE = 25.0
"""batches/s the normal actor offers (16 transitions each): well within its fair share"""
BLOCK = zenoh.CongestionControl.BLOCK


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class Normal:
    """A traced actor offering NORMAL_RATE batches/s through the real Outbox (window 4), as a real
    actor's robots produce data at their own pace: about a twentieth of what this learner takes."""

    def __init__(self, session, run: str) -> None:
        self.actor = TracedActor(session, run, "normal", per_batch=16)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        due = time.monotonic()
        while not self.stop.is_set():
            self.actor.send_one(self.stop)
            # held back by the learner, a real actor's robots stop too: no burst to make up for it
            due = max(due + 1.0 / NORMAL_RATE, time.monotonic())
            self.stop.wait(due - time.monotonic())

    def acked(self) -> int:
        return len(self.actor.acked_seqs)

    def close(self, drain_s: float) -> None:
        self.stop.set()
        self.thread.join(10)
        flush = threading.Event()
        deadline = time.monotonic() + drain_s
        while len(self.actor.outbox) and time.monotonic() < deadline:
            threading.Timer(1.0, flush.set).start()
            self.actor.outbox.flush(flush)
            flush.clear()
            time.sleep(0.2)
        self.actor.close()


def flooder(endpoint: str, run: str) -> subprocess.Popen:
    """The flooder, returned once it floods (at nice 19 on a busy host its start can take a while)."""
    args = ["--connect", endpoint, "--run", run, "--id", "flood", "--rows", "1000", "--big-mb", "60",
            "--big-keys", "4"]  # fmt: skip
    return launch(args, nice=19)


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.alone  # a ratio of two rates: a test beside it would disturb one phase and not the other
@pytest.mark.timeout(400)
def test_a_flooder_slows_a_normal_actor_by_at_most_the_bound_and_memory_stays_bounded(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"fair{port}"
    argv = learner_argv(endpoint, run, tmp_path / "ckpt", "--checkpoint-every", "0")  # no periodic stall
    learner = start_learner(argv, tmp_path / "learner.log")
    session = normal = None
    rates: dict[str, list[float]] = {"alone": [], "flood": []}
    peak = 0.0
    try:
        session = open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120))
        normal = Normal(session, run)
        deadline = time.monotonic() + 120
        while normal.acked() < 50 and time.monotonic() < deadline:
            time.sleep(0.2)
        assert normal.acked() >= 50, (tmp_path / "learner.log").read_text()[-2000:]
        settle(session, run)
        baseline_rss = rss_mb(learner.pid)
        for _ in range(ROUNDS):
            for phase in ("alone", "flood"):
                proc = flooder(endpoint, run) if phase == "flood" else None
                start, acked0 = time.monotonic(), normal.acked()
                while time.monotonic() - start < ROUND_S:
                    peak = max(peak, rss_mb(learner.pid))
                    time.sleep(0.1)
                rates[phase].append((normal.acked() - acked0) / (time.monotonic() - start))
                if proc is not None:
                    stop_process(proc, timeout=30)
                    print("flooder:", proc.stdout.read().strip().splitlines()[-1:])
                    settle(session, run)  # what the router still held of the flood is through
                caught_up(normal.actor)  # the next phase starts without a backlog to catch up on
        status = query_status(session, run, timeout=5.0)
        normal.close(drain_s=60)
        lost = len(normal.actor.outbox)
    finally:
        if normal is not None:
            normal.stop.set()
        if session is not None:
            session.close()
        stop_process(learner)
    alone, flood = sum(rates["alone"]), sum(rates["flood"])
    counters = status.counters
    print(
        f"normal actor: {rates['alone']} batches/s alone, {rates['flood']} flooded "
        f"(slowdown {1 - flood / alone:.1%}); learner RSS {baseline_rss:.0f} MB, peak {peak:.0f} MB; "
        f"too large {counters.get('rejected/batch_too_large')}, flood dropped "
        f"{counters.get('dropped/sender_full/flood')}, flood stored {counters.get('transitions/flood')}"
    )
    assert counters.get("rejected/batch_too_large", 0) > 0  # the ~60 MB batches, by their reason
    assert counters.get("transitions/flood", 0) > 0  # the flooder's valid batches get their share
    assert lost == 0 and counters.get("dropped/sender_full/normal", 0) == 0
    assert flood >= (1 - SLOWDOWN_BOUND) * alone, rates
    assert peak - baseline_rss <= RSS_BOUND_MB, (baseline_rss, peak)


@pytest.mark.integration
@pytest.mark.timeout(240)
def test_a_flood_of_actor_names_is_refused_beyond_the_bound_and_status_stays_small(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"names{port}"
    argv = learner_argv(endpoint, run, tmp_path / "ckpt", "--max-names", "32", "--checkpoint-every", "1")
    learner = start_learner(argv, tmp_path / "learner.log")
    try:
        with open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120)) as session:
            deadline = time.monotonic() + 120
            while query_status(session, run, timeout=2.0) is None and time.monotonic() < deadline:
                time.sleep(0.5)
            for i in range(2000):
                payload = encode(make_batch(f"n{i}", 4, 1))
                session.put(keys.transitions(run, f"n{i}"), payload, congestion_control=BLOCK)
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:  # until the 32 admitted batches are inserted
                status = query_status(session, run, timeout=5.0)
                if (
                    status is not None
                    and len([k for k in status.counters if k.startswith("transitions/")]) >= 32
                ):
                    break
                time.sleep(0.5)
            time.sleep(1.0)
            status = query_status(session, run, timeout=5.0)
            size = len(encode(status))
        stop_process(learner)  # with a final checkpoint: the names survive a restart, bounded
        learner = start_learner(argv, tmp_path / "learner.log")
        with open_session(ZenohSettings(connect=[endpoint], run=run, connect_timeout=120)) as session:
            deadline = time.monotonic() + 120
            resumed = None
            while resumed is None and time.monotonic() < deadline:
                resumed = query_status(session, run, timeout=2.0)
    finally:
        stop_process(learner)
    actors = [k for k in status.counters if k.startswith("transitions/")]
    print(
        f"status {size} bytes, {len(actors)} actors, refused {status.counters.get('rejected/too_many_names')}"
    )
    assert len(actors) == 32 and status.counters["rejected/too_many_names"] == 2000 - 32
    assert size < 64 * 1024, size
    assert resumed is not None and len([k for k in resumed.counters if k.startswith("transitions/")]) == 32
    assert json.dumps(resumed.counters)  # readable

"""Bounded memory under abuse, against a real learner process on 127.0.0.1: oversized and malformed
messages are rejected and counted by reason, and a stuck evaluator (a weights subscriber frozen with
SIGSTOP) neither stops the learner's training nor makes its memory grow."""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import zenoh

from protocols import keys
from protocols.codec import encode
from protocols.messages import TransitionBatch
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status
from tests.conftest import free_port
from tests.reliability_helpers import TracedActor, learner_argv, start_learner, stop_process
from tests.test_reliability_flood import rss_mb
from tests.test_reliability_kill import wait_for

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(180)]
STUCK_SUBSCRIBER = """
import sys, time, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", '["%s"]')
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
session.declare_subscriber("%s", lambda sample: None)
print("ready", flush=True)
time.sleep(600)
"""


def wide_batch(n: int = 4, obs_dim: int = 4096) -> TransitionBatch:
    return TransitionBatch(
        sender="wide#1", seq=1, actor="wide", model="nnql", policy_version=0,
        env_ids=np.arange(n, dtype=np.int32), obs=np.zeros((n, obs_dim), np.float32),
        action=np.zeros(n, np.int64), reward=np.zeros(n, np.float32),
        next_obs=np.zeros((n, obs_dim), np.float32),
        terminated=np.zeros(n, bool), truncated=np.zeros(n, bool),
    )  # fmt: skip


def test_oversized_messages_and_a_stuck_evaluator_leave_the_learner_training(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"abuse{port}"
    argv = learner_argv(endpoint, run, tmp_path / "ckpt", "--hidden-sizes", "256", "256")
    learner = start_learner(argv, tmp_path / "learner.log")
    stuck = session = None
    stop = threading.Event()
    sender = None
    try:
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        actor = TracedActor(session, run, "calm")

        def send_forever() -> None:
            while not stop.is_set():
                actor.send_one(stop)

        sender = threading.Thread(target=send_forever, daemon=True)
        sender.start()
        wait_for(
            lambda: (s := query_status(session, run)) is not None and s.versions["nnql"] > 20, 90, "training"
        )

        # 1. oversized (65 MiB, above the 64 MiB limit) and malformed (obs wider than the learner's)
        huge = np.random.default_rng(0).bytes(65 * 2**20)
        memory = []
        for round_ in (1, 2):  # memory after the second round: the first round's messages are not kept
            for _ in range(4):  # BLOCK: with the default (drop) Zenoh itself may drop such a big message
                session.put(
                    keys.transitions(run, "big"), huge, congestion_control=zenoh.CongestionControl.BLOCK
                )
                session.put(keys.transitions(run, "wide"), encode(wide_batch()))
            wait_for(
                lambda n=4 * round_: (
                    (s := query_status(session, run)).counters.get("rejected/oversize", 0) >= n
                    and s.counters.get("rejected/shape", 0) >= n
                ),
                60,
                "the rejections to be counted",
            )
            memory.append(rss_mb(learner.pid))
        del huge
        version = query_status(session, run).versions["nnql"]
        wait_for(lambda: query_status(session, run).versions["nnql"] > version + 20, 60, "training after")
        assert memory[1] < memory[0] + 100, f"learner memory after each round of 4 x 65 MiB: {memory} MB"

        # 2. a weights subscriber that stops reading: the learner hosts the router it is connected to
        code = STUCK_SUBSCRIBER % (endpoint, keys.weights(run, "nnql"))
        stuck = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
        assert stuck.stdout.readline().strip() == "ready"
        time.sleep(1.0)
        os.kill(stuck.pid, signal.SIGSTOP)
        versions, memory = [], []
        for _ in range(6):  # 30 s with the evaluator frozen
            time.sleep(5.0)
            status = query_status(session, run, timeout=5.0)
            versions.append(status.versions["nnql"] if status else -1)
            memory.append(rss_mb(learner.pid))
        assert all(b > a for a, b in itertools.pairwise(versions)), f"training stalled: versions {versions}"
        assert max(memory) - memory[0] < 150, f"learner memory grew: {memory} MB"
        print(f"versions every 5 s with a frozen evaluator: {versions}; learner RSS {memory} MB")
    finally:
        stop.set()
        if sender is not None:
            sender.join(10)
        if stuck is not None:
            os.kill(stuck.pid, signal.SIGCONT)
            stuck.kill()
            stuck.wait()
        if session is not None:
            session.close()
        stop_process(learner)

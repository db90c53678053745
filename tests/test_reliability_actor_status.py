"""A real actor process whose learner stops acknowledging: its own status (status/actor:<id>, and
`navlearn status --actors`) says it is held back by back-pressure, with nothing dropped."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time

import pytest

from protocols import keys
from services.actor.status import BlockedShare, query_actor_statuses
from services.common.transport import ZenohSettings, open_session
from tests.reliability_helpers import stop_process
from tests.test_wire_zenoh import start_router, stop

RUN = "actorstatus"


def test_blocked_share_is_the_waiting_share_of_the_window() -> None:
    share = BlockedShare(window=5.0)
    assert share.share() == 0.0
    for t in range(11):
        share.add(0.8 * t, now=float(t))  # waiting 0.8 s of every second
    assert share.share() == pytest.approx(0.8)
    share.add(8.0, now=20.0)  # then 10 s without waiting
    assert share.share() < 0.5


@pytest.mark.integration
@pytest.mark.timeout(120)
def test_an_actor_reports_back_pressure_when_the_learner_stops_acknowledging(tmp_path) -> None:
    endpoint, router, _ = start_router()
    actor = None
    try:
        with open_session(ZenohSettings(connect=[endpoint], connect_timeout=10, run=RUN)) as session:
            received = threading.Event()
            # a "learner" that takes the batches but never acknowledges them
            session.declare_subscriber(keys.transitions(RUN, "a1"), lambda s: received.set())
            env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
            argv = [sys.executable, "-m", "services.cli", "actor", "--connect", endpoint, "--run", RUN,
                    "--id", "a1", "--envs", "2", "--maps", "rooms:10", "--batch-steps", "4",
                    "--ack-window", "2", "--ack-timeout", "600", "--log-every", "1"]  # fmt: skip
            with open(tmp_path / "actor.log", "wb") as log:
                actor = subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT)
            assert received.wait(60), (tmp_path / "actor.log").read_text()[-2000:]
            deadline, status = time.monotonic() + 30, None
            while time.monotonic() < deadline:
                status = query_actor_statuses(session, RUN, timeout=2.0).get("a1")
                if status is not None and status.counters["backpressure"]:
                    break
                time.sleep(0.5)
            assert status is not None, "the actor did not answer status/actor:a1"
            c = status.counters
            assert c["backpressure"] == 1 and status.rates["waiting_for_learner_share"] > 0.5
            assert c["unacknowledged"] == c["ack_window"] == 2 and c["batches_acknowledged"] == 0
            assert c["outbox_capacity"] == 64
            assert status.versions == {"nnql": 0}
            steps = c["robot_steps"]
            time.sleep(2.0)
            again = query_actor_statuses(session, RUN, timeout=2.0)["a1"].counters
            assert again["robot_steps"] == steps  # it stopped stepping rather than drop anything
            assert again["waiting_for_learner_ms"] >= c["waiting_for_learner_ms"] + 1500
            done = subprocess.run(
                [sys.executable, "-m", "services.cli", "status", "--connect", endpoint, "--run", RUN,
                 "--actors", "--json", "--timeout", "2"],
                capture_output=True, text=True, timeout=60, env=env,
            )  # fmt: skip
            view = json.loads(done.stdout)
            assert done.returncode == 1 and view["learner"] is None  # no learner status answered
            assert view["actor_status"]["a1"]["counters"]["backpressure"] == 1
    finally:
        if actor is not None:
            stop_process(actor)
        stop(router)

"""Recurrent NNQL through the distributed path, on loopback with real processes: `navlearn learner
--recurrent` + `navlearn actor --recurrent`.

The actor keeps an LSTM state per robot and sends SequenceBatches (episode, step, state); the learner
stores them per (actor, robot) stream, trains on within-episode sequences and broadcasts weights,
which the actor applies (its progress line names the version). A feed-forward TransitionBatch is
refused by the recurrent learner (counted as rejected/kind)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import free_port
from test_nirl_services import stop_all

from protocols import keys
from protocols.codec import encode
from protocols.messages import TransitionBatch
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(400)]


def test_recurrent_learner_trains_on_actor_sequences_and_the_actor_follows_its_weights(tmp_path):
    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"rec{port}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    cli = [sys.executable, "-m", "services.cli"]
    small = ["--lstm-size", "8"]
    argvs = {
        "learner": [*cli, "learner", "--listen", endpoint, "--run", run, "--recurrent", *small,
                    "--hidden-sizes", "16", "--seq-len", "4", "--burn-in", "2", "--sequences", "4",
                    "--learning-starts", "64", "--broadcast-every", "5", "--log-every", "2",
                    "--checkpoint-dir", str(tmp_path / "ckpt")],
        "actor": [*cli, "actor", "--connect", endpoint, "--run", run, "--id", "a1", "--recurrent", *small,
                  "--envs", "4", "--seed", "1", "--batch-steps", "8", "--log-every", "1"],
    }  # fmt: skip
    logs = {name: open(tmp_path / f"{name}.log", "wb") for name in argvs}  # noqa: SIM115 - closed below
    processes: dict[str, subprocess.Popen] = {}
    session = None

    def actor_versions() -> list[int]:
        return [int(v) for v in re.findall(r"\| version (\d+) \(", (tmp_path / "actor.log").read_text())]

    try:
        processes["learner"] = subprocess.Popen(
            argvs["learner"], env=env, stdout=logs["learner"], stderr=subprocess.STDOUT
        )
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        processes["actor"] = subprocess.Popen(
            argvs["actor"], env=env, stdout=logs["actor"], stderr=subprocess.STDOUT
        )
        n, obs_dim = 4, observation_dim(LEARNING_NAV)
        plain = TransitionBatch(
            sender="ff#1", seq=1, actor="ff", model="nnql", policy_version=0,
            env_ids=np.arange(n), obs=np.zeros((n, obs_dim)), action=np.zeros(n), reward=np.zeros(n),
            next_obs=np.zeros((n, obs_dim)), terminated=np.zeros(n, bool), truncated=np.zeros(n, bool),
        )  # fmt: skip
        status, versions = None, []
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            session.put(keys.transitions(run, "ff"), encode(plain))
            status = query_status(session, run)
            versions = actor_versions()
            if (
                status is not None
                and status.counters.get("updates", 0) >= 10
                and status.counters.get("rejected/kind", 0) >= 1
                and max(versions, default=0) >= 5
            ):
                break
            assert all(p.poll() is None for p in processes.values()), "a process exited early"
            time.sleep(1.0)
        assert status is not None, "the learner never answered its status query"
        learner_log = (tmp_path / "learner.log").read_text()
        assert status.counters.get("updates", 0) >= 10, learner_log[-3000:]
        assert status.replay_sizes["transitions"] >= 64
        assert status.counters.get("rejected/kind", 0) >= 1  # the feed-forward batch was refused
        assert max(versions, default=0) >= 5, (tmp_path / "actor.log").read_text()[-3000:]
        assert "ignoring weights" not in (tmp_path / "actor.log").read_text()
    finally:
        if session is not None:
            session.close()
        codes = stop_all(processes)
        for log in logs.values():
            log.close()
    assert codes == {"learner": 0, "actor": 0}, codes

"""The whole system under a real supervisord, with the shipped deploy/supervisord.conf.

Router, learner, two actors and the evaluator run as real processes on 127.0.0.1
(a free port, a temporary NAVLEARN_HOME, tiny settings through the services'
environment variables). The test watches the learner's status over Zenoh and checks:
training progresses and evaluations arrive; `navlearn status --json` answers; a killed
actor's liveliness token goes, the other actor keeps sending and status marks the
stopped one gone; a learner stopped with SIGTERM and started again resumes counters and
replay from its checkpoint; after a router restart the processes reconnect by themselves.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import free_port

from services.common.transport import Presence, ZenohSettings, open_session
from services.ops.status import query_alive, query_status, status_dict

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(600)]
CONF = Path(__file__).resolve().parents[1] / "deploy" / "supervisord.conf"
SMALL = {
    "NAVLEARN_NNQL_HIDDEN_SIZES": "32 32",
    "NAVLEARN_NNQL_BATCH_SIZE": "32",
    "NAVLEARN_NNQL_LEARNING_STARTS": "256",
    "NAVLEARN_NNQL_REPLAY_CAPACITY": "20000",
    "NAVLEARN_LEARNER_BROADCAST_EVERY": "20",
    "NAVLEARN_LEARNER_CHECKPOINT_EVERY": "20",
    "NAVLEARN_LEARNER_LOG_EVERY": "5",
    "NAVLEARN_ACTOR_ENVS": "4",
    "NAVLEARN_ACTOR_BATCH_STEPS": "8",
    "NAVLEARN_ACTOR_LOG_EVERY": "5",
    "NAVLEARN_EVALUATOR_EPISODES": "4",
}


class Cluster:
    """supervisord with the shipped config, plus a Zenoh client session to read status."""

    def __init__(self, home: Path, extra: dict[str, str] | None = None, actors: int = 2) -> None:
        port = free_port()
        self.home = home
        self.run = f"it{port}"
        self.endpoint = f"tcp/127.0.0.1:{port}"
        env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
        env.update(SMALL)
        env.update(
            NAVLEARN_HOME=str(home),
            NAVLEARN_RUN=self.run,
            NAVLEARN_ROUTER_LISTEN=self.endpoint,
            NAVLEARN_ROUTER=self.endpoint,
            NAVLEARN_ACTORS=str(actors),
            PATH=f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}",
        )
        env.update(extra or {})
        self.env = env
        (home / "logs").mkdir(parents=True)
        self.supervisord = subprocess.Popen(
            [sys.executable, "-m", "supervisor.supervisord", "-n", "-c", str(CONF)],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.STDOUT,
        )
        self.session = None

    def connect(self) -> None:
        settings = ZenohSettings(mode="client", connect=[self.endpoint], run=self.run, connect_timeout=60)
        self.session = open_session(settings)

    def ctl(self, *args: str, check: bool = True) -> str:
        result = subprocess.run(
            [sys.executable, "-m", "supervisor.supervisorctl", "-c", str(CONF), *args],
            env=self.env,
            capture_output=True,
            text=True,
            timeout=180,
        )
        if check and result.returncode != 0:
            raise AssertionError(f"supervisorctl {' '.join(args)}: {result.stdout}{result.stderr}")
        return result.stdout

    def status(self) -> dict | None:
        status = query_status(self.session, self.run, timeout=2.0)
        if status is None:
            return None
        return status_dict(status, query_alive(self.session, self.run, timeout=1.0))

    def wait_for(self, what: str, predicate: Callable[[dict], bool], timeout: float) -> dict:
        deadline = time.monotonic() + timeout
        view = None
        while time.monotonic() < deadline:
            view = self.status()
            if view is not None and view["learner"] is not None and predicate(view):
                return view
            time.sleep(0.5)
        logs = {p.name: p.read_text()[-1500:] for p in sorted((self.home / "logs").glob("*.log"))}
        raise AssertionError(f"timed out waiting for {what}; last status {view}; logs {logs}")

    def close(self) -> None:
        pids = [int(p) for p in self.ctl("pid", "all", check=False).split() if p.isdigit()]
        if self.session is not None:
            self.session.close()
        self.supervisord.terminate()  # supervisord stops every program (SIGTERM, then SIGKILL)
        try:
            self.supervisord.wait(200)
        except subprocess.TimeoutExpired:
            self.supervisord.kill()
            self.supervisord.wait()
        for pid in pids:  # only if supervisord itself could not stop them
            with contextlib.suppress(OSError):  # gone already, as it should be
                if b"navlearn" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    os.kill(pid, 9)


@pytest.fixture
def cluster(tmp_path):
    cluster = Cluster(tmp_path / "home")
    try:
        cluster.connect()
        yield cluster
    finally:
        cluster.close()


def version(view: dict) -> int:
    return view["learner"]["versions"]["nnql"]


def actor_transitions(view: dict, actor: str) -> int:
    return view["learner"]["actors"].get(actor, {}).get("transitions", 0)


def test_supervised_training_survives_actor_loss_and_learner_and_router_restarts(cluster):
    host = os.uname().nodename
    a0, a1 = f"{host}-0", f"{host}-1"

    # training progresses: replay grows, versions increase, evaluation reports arrive
    first = cluster.wait_for("training to start", lambda v: version(v) > 0, timeout=240)
    progressed = cluster.wait_for(
        "more versions, both actors and an evaluation",
        lambda v: (
            version(v) > version(first)
            and v["learner"]["replay_sizes"]["transitions"] > first["learner"]["replay_sizes"]["transitions"]
            and actor_transitions(v, a0) > 0
            and actor_transitions(v, a1) > 0
            and v["learner"]["last_eval"] is not None
        ),
        timeout=240,
    )
    assert progressed["learner"]["counters"]["transitions_rejected"] == 0
    assert set(progressed["learner"]["last_eval"]["families"]) == {"unseen", "dynamic"}

    # `navlearn status --json` answers, and sees every process alive
    out = subprocess.run(
        [sys.executable, "-m", "services.cli", "status", "--json", "--connect", cluster.endpoint],
        env=cluster.env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    view = json.loads(out.stdout)
    assert sorted(view["alive"]["actor"]) == [a0, a1]
    assert view["alive"]["learner"] == ["learner"] and view["alive"]["evaluator"] == ["evaluator"]
    assert version(view) >= version(progressed)

    # a killed actor's token goes; the other keeps sending; status marks the stopped one gone
    gone = threading.Event()
    presence = Presence(
        cluster.session,
        cluster.run,
        "actor",
        on_change=lambda r, i, alive: gone.set() if i == a0 and not alive else 0,
    )
    try:
        cluster.ctl("signal", "KILL", "actor:actor-0")
        assert gone.wait(30), "the killed actor's liveliness token did not disappear"
    finally:
        presence.close()
    cluster.ctl("stop", "actor:actor-0", check=False)  # keep it down (supervisord restarts crashed programs)
    before = cluster.status()
    after = cluster.wait_for(
        "actor-0 gone and actor-1 still sending",
        lambda v: (
            not v["learner"]["actors"][a0]["alive"]
            and actor_transitions(v, a1) > actor_transitions(before, a1)
            and version(v) > version(before)
        ),
        timeout=120,
    )
    assert a0 not in after["alive"].get("actor", [])

    # SIGTERM the learner (supervisorctl stop), start it again: it resumes from its checkpoint
    last = cluster.status()
    cluster.ctl("stop", "learner")
    checkpoints = sorted((cluster.home / "checkpoints").glob("ckpt-*"))
    saved = json.loads((checkpoints[-1] / "service.json").read_text())
    assert saved["limiter"]["updates"] >= version(last)
    assert saved["counters"]["transitions_received"] >= last["learner"]["counters"]["transitions_received"]
    cluster.ctl("start", "learner")
    resumed = cluster.wait_for(
        "the restarted learner", lambda v: v["learner"]["sender"] != last["learner"]["sender"], 240
    )
    assert version(resumed) >= saved["limiter"]["updates"]
    assert resumed["learner"]["counters"]["transitions_received"] >= saved["counters"]["transitions_received"]
    assert resumed["learner"]["replay_sizes"]["transitions"] >= last["learner"]["replay_sizes"]["transitions"]
    assert "resumed from" in (cluster.home / "logs" / "learner.log").read_text()

    # restart the router: learner, actor and evaluator reconnect by themselves
    cluster.ctl("restart", "router")
    cluster.wait_for(
        "training to continue after a router restart",
        lambda v: actor_transitions(v, a1) > actor_transitions(resumed, a1) and version(v) > version(resumed),
        timeout=120,
    )

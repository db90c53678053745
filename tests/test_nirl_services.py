"""NIRL in the distributed system, on loopback with real processes: demonstrator(astar) +
demonstrator(file) + learner --nirl + actor --model nirl + evaluator --compare nirl.

Checks that the demonstrations of both sources arrive (status counts them per source), that
NIRL's version grows, that the actor follows weights/nirl, and that the evaluator reports
both models (and plots them with the imitation reference)."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import re
import signal
import subprocess
import sys
import time

import pytest
from conftest import free_port

from protocols import keys
from protocols.codec import decode
from protocols.messages import EvalReport
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(600)]
SMALL_NIRL = {
    "hidden_sizes": [16],
    "reward_hidden_sizes": [16],
    "batch_size": 16,
    "demo_batch_size": 16,
    "warmstart_updates": 40,
    "q_updates": 20,
    "reward_updates": 5,
}


def stop_all(processes: dict[str, subprocess.Popen]) -> dict[str, int]:
    for process in processes.values():
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    codes = {}
    for name, process in processes.items():
        try:
            codes[name] = process.wait(60)
        except subprocess.TimeoutExpired:
            process.kill()
            codes[name] = process.wait()
    return codes


def test_demonstrators_learner_actor_evaluator_train_and_compare_nirl(tmp_path):
    from gymnasium import spaces

    from agents.demos import write_demos
    from agents.imitation.config import ImitationConfig
    from agents.imitation.train import save_trained, train_policy
    from agents.planning.demonstrate import generate_demos
    from worlds.config import LEARNING_NAV, NavConfig, observation_settings
    from worlds.env import observation_space

    # the file demonstrator sends what the learner takes (LEARNING_NAV); the imitation reference
    # is a policy of the plain observation, which its config.json leaves unrecorded (legacy)
    learning, _ = generate_demos("rooms:10", 4, seed=3, config=LEARNING_NAV)
    dataset = tmp_path / "demos" / "expert-v0"
    write_demos(dataset, learning, observation_space(LEARNING_NAV), spaces.Discrete(5),
                observation=observation_settings(LEARNING_NAV))  # fmt: skip
    demos, _ = generate_demos("rooms:10", 4, seed=3, config=NavConfig())
    imitation = tmp_path / "imitation"
    result = train_policy(demos, ImitationConfig(hidden_sizes=(16,), max_epochs=3), n_actions=5)
    save_trained(imitation, result, ImitationConfig(hidden_sizes=(16,), max_epochs=3))
    (tmp_path / "nirl.json").write_text(json.dumps(SMALL_NIRL))

    port = free_port()
    endpoint, run = f"tcp/127.0.0.1:{port}", f"nirl{port}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    cli = [sys.executable, "-m", "services.cli"]
    zenoh = ["--connect", endpoint, "--run", run]
    argvs = {
        "learner": [*cli, "learner", "--listen", endpoint, "--run", run, "--nirl", "--nirl-config",
                    str(tmp_path / "nirl.json"), "--checkpoint-dir", str(tmp_path / "ckpt"), "--hidden-sizes",
                    "16", "--batch-size", "16", "--learning-starts", "64", "--broadcast-every", "10",
                    "--log-every", "2"],
        "astar": [*cli, "demonstrator", *zenoh, "--source", "astar", "--maps", "rooms:10", "--rate", "0",
                  "--episodes", "2", "--noise", "0.2"],
        "file": [*cli, "demonstrator", *zenoh, "--source", "file", "--file", str(dataset)],
        "actor": [*cli, "actor", *zenoh, "--id", "a1", "--model", "nirl", "--envs", "4", "--seed", "1",
                  "--log-every", "1"],
        "evaluator": [*cli, "evaluator", *zenoh, "--compare", "nirl", "--families", "unseen", "--episodes",
                      "3", "--imitation", str(imitation), "--out", str(tmp_path / "eval")],
    }  # fmt: skip
    logs = {name: open(tmp_path / f"{name}.log", "wb") for name in argvs}  # noqa: SIM115 - closed below
    processes = {}
    session = None
    reports: queue.Queue = queue.Queue()
    try:
        processes["learner"] = subprocess.Popen(
            argvs["learner"], env=env, stdout=logs["learner"], stderr=subprocess.STDOUT
        )
        session = open_session(ZenohSettings(mode="client", connect=[endpoint], run=run, connect_timeout=120))
        subscriber = session.declare_subscriber(
            keys.everything(run, "eval"), lambda s: reports.put(decode(s.payload.to_bytes()))
        )
        for name in ("astar", "file", "actor", "evaluator"):
            processes[name] = subprocess.Popen(
                argvs[name], env=env, stdout=logs[name], stderr=subprocess.STDOUT
            )

        def actor_versions() -> list[int]:
            """NIRL policy versions the actor logged as applied (its progress line, every second)."""
            text = (tmp_path / "actor.log").read_text()
            return [int(v) for v in re.findall(r"\| version (\d+) \(", text)]

        models: set[str] = set()
        first_nirl, status = None, None
        deadline = time.monotonic() + 400
        while time.monotonic() < deadline:
            try:
                report = reports.get(timeout=1.0)
                if isinstance(report, EvalReport):
                    models.add(report.model)
            except queue.Empty:
                pass
            status = query_status(session, run)
            if status is not None and "nirl" in status.versions:
                first_nirl = status.versions["nirl"] if first_nirl is None else first_nirl
                demos_in = (
                    status.counters.get("demo_episodes/astar", 0),
                    status.counters.get("demo_episodes/file", 0),
                )
                grown = status.versions["nirl"] > max(first_nirl, SMALL_NIRL["warmstart_updates"])
                if (
                    demos_in == (2, 4)
                    and grown
                    and models >= {"nnql", "nirl"}
                    and max(actor_versions(), default=0)
                ):
                    break
        assert status is not None, "the learner never answered on status/learner"
        assert (
            status.counters.get("demo_episodes/astar") == 2 and status.counters.get("demo_episodes/file") == 4
        )
        assert status.versions["nirl"] > SMALL_NIRL["warmstart_updates"], status.versions
        assert any(k.startswith("nirl/") for k in status.losses), status.losses
        assert models >= {"nnql", "nirl"}, models
        subscriber.undeclare()
    finally:
        if session is not None:
            session.close()
        for name in ("astar", "file"):  # done once acknowledged; Zenoh's close can take seconds when loaded
            with contextlib.suppress(KeyError, subprocess.TimeoutExpired):
                processes[name].wait(60)
        codes = stop_all(processes)
        for log in logs.values():
            log.close()
    assert codes == dict.fromkeys(argvs, 0), {n: (tmp_path / f"{n}.log").read_text()[-2000:] for n in argvs}
    lines = [json.loads(line) for line in (tmp_path / "eval" / "evaluations.jsonl").read_text().splitlines()]
    assert {p["model"] for p in lines} >= {"nnql", "nirl", "reference"}
    assert (tmp_path / "eval" / "learning_curve.png").stat().st_size > 10_000
    assert (tmp_path / "ckpt").exists() and list((tmp_path / "ckpt").glob("*/nirl/nirl.pt"))
    assert max(actor_versions(), default=0) > 0, "the actor never applied weights/nirl"

"""The README's secure recipe end to end through the real services: `navlearn credentials`, a
`navlearn router` with user/password + ACL, learner, actor, demonstrator, evaluator and
`navlearn status`, each with its own credentials. Batches are acknowledged, weights applied, demos
stored and evaluations reported; impersonation, weight poisoning, forged acks and snooping are still
refused (issue #19: under the generated ACL an actor's matching status was never True, so its
outbox never sent)."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from protocols import keys
from protocols.codec import encode
from protocols.messages import TransitionBatch
from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status
from tests.reliability_helpers import N_ACTIONS, OBS_DIM
from tests.test_wire_zenoh import REPO, start, start_router, stop

RUN = "r1"


def credentials(out: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "services.cli", "credentials", "--out", str(out), "--run", RUN,
         "--actors", "a1", "a2", "--demonstrators", "astar", "--evaluators", "ev1"],
        capture_output=True, text=True, timeout=60, check=True, cwd=REPO,
    )  # fmt: skip


def service(name: str, endpoint: str, secrets: Path, user: str, *flags: str):
    return start(
        ["-m", "services.cli", name, "--connect", endpoint, "--run", RUN,
         "--credentials", str(secrets / f"{user}.credentials"), *flags]
    )  # fmt: skip


def status_view(endpoint: str, secrets: Path) -> dict:
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "status", "--connect", endpoint, "--run", RUN, "--json",
         "--actors", "--credentials", str(secrets / "status.credentials"), "--timeout", "5"],
        capture_output=True, text=True, timeout=60, cwd=REPO,
    )  # fmt: skip
    return json.loads(done.stdout) if done.returncode == 0 and done.stdout.strip() else {}


def trained(view: dict) -> bool:
    learner, actors = view.get("learner"), view.get("actor_status", {})
    if not learner or "a1" not in actors:
        return False
    a1, counters = actors["a1"]["counters"], learner["counters"]
    return (
        a1.get("batches_acknowledged", 0) > 0
        and a1.get("weights_applied", 0) > 0
        and a1.get("learner_reachable") == 1
        and counters.get("demo_batches", 0) > 0
        and learner["last_eval"] is not None
    )


def batch(actor: str, n: int = 8) -> TransitionBatch:
    return TransitionBatch(
        sender=f"{actor}#1",
        seq=1,
        actor=actor,
        model="nnql",
        policy_version=0,
        env_ids=np.arange(n, dtype=np.int32),
        obs=np.zeros((n, OBS_DIM), np.float32),
        action=np.zeros(n, np.int64) % N_ACTIONS,
        reward=np.full(n, 7.0, np.float32),
        next_obs=np.zeros((n, OBS_DIM), np.float32),
        terminated=np.zeros(n, bool),
        truncated=np.zeros(n, bool),
    )


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_secure_recipe_trains_and_still_refuses_what_it_must(tmp_path: Path) -> None:
    secrets = tmp_path / "secrets"
    credentials(secrets)
    compiled = subprocess.run(  # the recipe's compile step: before any process's clock starts
        [sys.executable, "-m", "services.cli", "world", "compile"],
        capture_output=True, text=True, timeout=600, check=True, cwd=REPO,
    )  # fmt: skip
    assert "robot world" in compiled.stdout, compiled.stdout
    endpoint, router, _ = start_router(
        "--auth-dictionary", str(secrets / "users.txt"), "--acl", str(secrets / "acl.json5")
    )
    procs: list[subprocess.Popen] = [router]
    logs: dict[str, list[str]] = {}
    try:
        for name, user, flags in (
            ("learner", "learner", ["--checkpoint-dir", str(tmp_path / "ckpt"), "--hidden-sizes", "16",
                                    "--batch-size", "16", "--learning-starts", "64", "--broadcast-every", "5",
                                    "--log-every", "5", "--acl-names", str(secrets / "acl.json5")]),
            ("actor", "a1", ["--id", "a1", "--envs", "2", "--batch-steps", "8", "--maps", "rooms:12",
                             "--log-every", "5"]),
            ("demonstrator", "astar", ["--id", "astar", "--source", "astar", "--rate", "0", "--episodes",
                                       "2", "--maps", "rooms:12"]),
            ("evaluator", "ev1", ["--id", "ev1", "--episodes", "2", "--families", "unseen", "--max-evals",
                                  "1", "--out", str(tmp_path / "eval")]),
        ):  # fmt: skip
            proc, lines = service(name, endpoint, secrets, user, *flags)
            procs.append(proc)
            logs[name] = lines
        view: dict = {}
        deadline = time.monotonic() + 420  # a cold numba cache costs each process about a minute here
        while time.monotonic() < deadline and not trained(view):
            time.sleep(3)
            view = status_view(endpoint, secrets)
        assert trained(view), (view, {k: v[-8:] for k, v in logs.items()})
        assert view["learner"]["counters"]["batches_received"] > 0
        refused = forbidden_actions(endpoint, secrets)
        refused["impersonation"] = query_learner(endpoint, secrets).counters.get("transitions/a2", 0)
    finally:
        for proc in reversed(procs):
            stop(proc, timeout=60)
    # delivered: a1's batches as a2 (learner's count), forged weights and acks at a2, what a1 read
    assert refused == {"impersonation": 0, "weight_poisoning": 0, "forged_acks": 0, "snooping": 0}


def query_learner(endpoint: str, secrets: Path):
    settings = ZenohSettings(
        connect=[endpoint], connect_timeout=20, run=RUN, credentials_file=str(secrets / "status.credentials")
    )
    with open_session(settings) as session:
        status = query_status(session, RUN, timeout=5.0)
    assert status is not None
    return status


def forbidden_actions(endpoint: str, secrets: Path) -> dict[str, int]:
    """What a1 (with its own valid credentials) gets through when it tries what it may not:
    publish weights, acknowledge a2's batches, read a2's and the demonstrator's data (its batches
    as a2 are counted by the learner)."""

    def session(user: str):
        return open_session(
            ZenohSettings(
                connect=[endpoint],
                connect_timeout=20,
                run=RUN,
                credentials_file=str(secrets / f"{user}.credentials"),
            )
        )

    got: dict[str, list[tuple[str, bytes]]] = {"weights": [], "acks": [], "snooped": []}
    lock = threading.Lock()

    def keep(into: str):
        def on_sample(sample) -> None:
            with lock:
                got[into].append((str(sample.key_expr), sample.payload.to_bytes()[:16]))

        return on_sample

    p = keys.prefix(RUN)
    with session("a1") as a1, session("a2") as a2:
        a2.declare_subscriber(keys.weights(RUN, "nnql"), keep("weights"))
        a2.declare_subscriber(keys.acks(RUN, "a2"), keep("acks"))
        for expr in (
            f"{p}/**",
            f"{p}/transitions/*",
            keys.transitions(RUN, "a2"),
            keys.everything(RUN, "demos"),
        ):
            a1.declare_subscriber(expr, keep("snooped"))
        time.sleep(1.0)
        forged_batch = encode(batch("a2"))
        for _ in range(20):
            a1.put(keys.transitions(RUN, "a2"), forged_batch)
            a1.put(keys.weights(RUN, "nnql"), b"FORGED weights")
            a1.put(keys.acks(RUN, "a2"), b"FORGED ack")
            a2.put(keys.transitions(RUN, "a2"), b"a2 private batch")
            time.sleep(0.05)
        time.sleep(2.0)
        with lock:
            private = (f"{p}/transitions/", f"{p}/demos/")
            # a1's own put on transitions/a2 reaches a1's own subscribers inside its session (local
            # delivery, no router): not snooping. Anything else on those keys came from the router.
            return {
                "weight_poisoning": sum(data.startswith(b"FORGED") for _, data in got["weights"]),
                "forged_acks": sum(data.startswith(b"FORGED") for _, data in got["acks"]),
                "snooping": sum(
                    key.startswith(private) and data != forged_batch[:16] for key, data in got["snooped"]
                ),
            }

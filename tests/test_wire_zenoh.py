"""The wire over real Zenoh on 127.0.0.1: a `navlearn router` subprocess, client sessions, every
message kind, a queryable, liveliness of a killed process, late routers, auth, ACL and TLS."""

from __future__ import annotations

import shutil
import signal
import subprocess
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import zenoh
from conftest import free_port
from wire_helpers import N_ACTIONS, REPO, same, small_transitions, start, stop, wait_for_line

from protocols import keys
from protocols.codec import decode, encode
from protocols.limits import Limits
from protocols.messages import DemoBatch, EpisodeMeta, EvalReport, StatusReport, WeightsUpdate
from services.common.transport import Presence, TransportError, ZenohSettings, open_session

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]
RUN = "wiretest"
LIMITS = Limits(n_actions=N_ACTIONS)


def start_router(*flags: str) -> tuple[str, subprocess.Popen, list[str]]:
    listen = next((flags[i + 1] for i, f in enumerate(flags) if f == "--listen"), None)
    endpoint = listen or f"tcp/127.0.0.1:{free_port()}"
    extra = () if listen else ("--listen", endpoint)
    proc, lines = start(["-m", "services.cli", "router", *extra, *flags])
    try:
        wait_for_line(lines, "listening on", 30)
    except BaseException:
        stop(proc)
        raise
    return endpoint, proc, lines


@pytest.fixture
def router():
    endpoint, proc, _ = start_router()
    try:
        yield endpoint
    finally:
        stop(proc)


def client(endpoint: str, **kw) -> zenoh.Session:
    return open_session(ZenohSettings(connect=[endpoint], connect_timeout=10, **kw))


def wait_until(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.02)


def one_of_each(seq: int) -> dict[str, object]:
    demo = DemoBatch(
        source="astar",
        episode_lengths=[3],
        obs=np.full((4, 11), seq),
        actions=[0, 1, 2],
        rewards=[0, 0, 1],
        terminations=[False, False, True],
        truncations=[False, False, False],
        episodes=[EpisodeMeta(map_id="rooms:16", start=(1, 1), goal=(5, 5), seed=seq)],
    )
    messages = {
        keys.transitions(RUN, "a1"): small_transitions(n=64),
        keys.demos(RUN, "astar"): demo,
        keys.weights(RUN, "nnql"): WeightsUpdate(
            model="nnql", version=seq, tensors={"w": np.ones((256, 11))}
        ),
        keys.evaluation(RUN, "ev1"): EvalReport(
            model="nnql", policy_version=seq, metrics={"unseen": {"spl": 0.5}}
        ),
        keys.status(RUN): StatusReport(counters={"rx": seq}),
    }
    for message in messages.values():
        message.sender, message.seq = "tester", seq
    return messages


def test_pubsub_of_every_kind_with_exact_counts(router: str) -> None:
    received: list[tuple[str, object]] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        message = decode(sample.payload.to_bytes(), LIMITS)
        with lock:
            received.append((str(sample.key_expr), message))

    per_kind = 25
    with client(router) as sub_session, client(router) as pub_session:
        sub_session.declare_subscriber(f"{keys.prefix(RUN)}/**", on_sample)
        publishers = {
            key: pub_session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            for key in one_of_each(0)
        }
        wait_until(lambda: all(p.matching_status.matching for p in publishers.values()), 10, "subscription")
        sent = {}
        for seq in range(per_kind):
            for key, message in one_of_each(seq).items():
                publishers[key].put(encode(message))
                sent[key, seq] = message
        wait_until(lambda: len(received) >= len(sent), 20, f"{len(sent)} messages")
        time.sleep(0.3)  # nothing more may arrive
    assert len(received) == len(sent) == 5 * per_kind
    assert Counter(type(m).KIND for _, m in received) == dict.fromkeys(
        ("transitions", "demos", "weights", "eval", "status"), per_kind
    )
    for key, message in received:
        assert same(message, sent[key, message.seq])


def test_a_queryable_answers_a_get(router: str) -> None:
    status = StatusReport(counters={"transitions": 1234}, versions={"nnql": 7}, sender="learner", seq=3)

    def on_query(query) -> None:
        query.reply(query.key_expr, encode(status))

    with client(router) as learner, client(router) as operator:
        learner.declare_queryable(keys.status(RUN), on_query)
        answers = []
        deadline = time.monotonic() + 10
        while not answers and time.monotonic() < deadline:  # until the queryable is known to the router
            answers = [r.ok for r in operator.get(keys.status(RUN), timeout=2) if r.ok is not None]
    assert len(answers) == 1
    assert same(decode(answers[0].payload.to_bytes(), LIMITS), status)


def test_liveliness_token_disappears_when_its_process_is_killed(router: str) -> None:
    changes: list[tuple[str, str, bool]] = []
    with (
        client(router) as session,
        Presence(session, RUN, on_change=lambda *c: changes.append(c)) as presence,
    ):
        proc, lines = start(["tests/wire_peer.py", "alive", router, RUN, "actor7"])
        try:
            wait_for_line(lines, "alive", 30)
            assert presence.wait_for(lambda m: ("actor", "actor7") in m, 10)
            proc.send_signal(signal.SIGKILL)
            proc.wait(10)
            assert presence.wait_for(lambda m: ("actor", "actor7") not in m, 20)
        finally:
            stop(proc)
    assert changes == [("actor", "actor7", True), ("actor", "actor7", False)]


@pytest.mark.slow
def test_a_client_started_before_the_router_recovers_once_it_is_up() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    key = f"{keys.prefix(RUN)}/late"
    proc, lines = start(["tests/wire_peer.py", "listen", endpoint, key])
    router_proc = None
    try:
        wait_for_line(lines, "waiting for a Zenoh router", 30)
        time.sleep(1.0)
        assert proc.poll() is None, lines
        _, router_proc, _ = start_router("--listen", endpoint)
        wait_for_line(lines, "subscribed", 30)
        with client(endpoint) as session:
            deadline = time.monotonic() + 20
            while not any(line.startswith("got") for line in lines) and time.monotonic() < deadline:
                session.put(key, "hello")
                time.sleep(0.1)
        assert proc.wait(10) == 0
        assert "got hello" in lines
    finally:
        stop(proc)
        if router_proc is not None:
            stop(router_proc)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_router_stops_cleanly_on_a_signal(signum: int) -> None:
    endpoint, proc, lines = start_router()
    try:
        with client(endpoint):
            wait_for_line(lines, "joined", 10)
        proc.send_signal(signum)
        assert proc.wait(10) == 0
        wait_for_line(lines, "router stopped", 5)
    finally:
        stop(proc)


def test_auth_and_the_deploy_acl(tmp_path: Path) -> None:
    users = tmp_path / "users.txt"
    users.write_text("learner:lpw\nactor1:apw\n")  # deploy's default ACL: one user per actor id
    creds = {}
    for user, password in (("learner", "lpw"), ("actor1", "apw"), ("intruder", "nope")):
        creds[user] = tmp_path / f"{user}.credentials"
        creds[user].write_text(f"{user}:{password}\n")
    acl = str(REPO / "deploy" / "router-secure.json5")  # its access_control section, run "default"
    endpoint, proc, _ = start_router("--auth-dictionary", str(users), "--acl", acl)
    try:
        with pytest.raises(TransportError):
            open_session(
                ZenohSettings(connect=[endpoint], connect_timeout=1, credentials_file=str(creds["intruder"]))
            )
        with pytest.raises(TransportError):
            open_session(ZenohSettings(connect=[endpoint], connect_timeout=1))
        at_learner: list[tuple[str, bytes]] = []
        at_actor: list[bytes] = []
        transitions, weights = keys.transitions("default", "actor1"), keys.weights("default", "nnql")
        with (
            client(endpoint, credentials_file=str(creds["learner"])) as learner,
            client(endpoint, credentials_file=str(creds["actor1"])) as actor,
        ):
            learner.declare_subscriber(
                "navlearn/default/**", lambda s: at_learner.append((str(s.key_expr), s.payload.to_bytes()))
            )
            actor.declare_subscriber(weights, lambda s: at_actor.append(s.payload.to_bytes()))
            deadline = time.monotonic() + 10
            while (
                not any(k == transitions for k, _ in at_learner) or b"real weights" not in at_actor
            ) and time.monotonic() < deadline:
                actor.put(weights, b"forged weights")
                actor.put(transitions, b"transitions")
                learner.put(weights, b"real weights")
                time.sleep(0.1)
            time.sleep(0.3)
        assert (transitions, b"transitions") in at_learner
        assert (weights, b"forged weights") not in at_learner  # the actor may not publish weights
        assert b"real weights" in at_actor  # but receives the learner's
    finally:
        stop(proc)


def make_certs(folder: Path) -> dict[str, str]:
    """A CA, a router certificate for 127.0.0.1 and a client certificate, made with openssl."""

    def ssl(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True, timeout=30)

    ec_key = ("-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes")
    ssl(
        "req",
        "-x509",
        *ec_key,
        "-keyout",
        "ca.key",
        "-out",
        "ca.pem",
        "-days",
        "2",
        "-subj",
        "/CN=navlearn CA",
    )
    (folder / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    for name in ("router", "client"):
        ssl("req", *ec_key, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}")
        ssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
            "-out", f"{name}.pem", "-days", "2", "-extfile", "san.ext")  # fmt: skip
    return {n: str(folder / n) for n in ("ca.pem", "router.pem", "router.key", "client.pem", "client.key")}


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command")
def test_mutual_tls(tmp_path: Path) -> None:
    certs = make_certs(tmp_path)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    flags = (
        "--tls-root-ca",
        certs["ca.pem"],
        "--tls-cert",
        certs["router.pem"],
        "--tls-key",
        certs["router.key"],
    )
    _, proc, _ = start_router("--listen", endpoint, *flags, "--tls-mtls")
    try:
        with pytest.raises(TransportError):  # no client certificate
            open_session(ZenohSettings(connect=[endpoint], connect_timeout=1, tls_root_ca=certs["ca.pem"]))
        tls = dict(
            tls_root_ca=certs["ca.pem"],
            tls_cert=certs["client.pem"],
            tls_key=certs["client.key"],
            tls_mtls=True,
        )
        with client(endpoint, **tls) as a, client(endpoint, **tls) as b:
            got = threading.Event()
            b.declare_subscriber("navlearn/tls/x", lambda s: got.set())
            deadline = time.monotonic() + 10
            while not got.is_set() and time.monotonic() < deadline:
                a.put("navlearn/tls/x", b"secret")
                time.sleep(0.1)
            assert got.is_set()
    finally:
        stop(proc)

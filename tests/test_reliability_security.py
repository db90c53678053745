"""`navlearn certs` with real TLS: right CA connects (also mutual TLS), a wrong CA is refused;
a remote actor in its own Linux network namespace reaches a learner across a veth pair."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from services.common.transport import TransportError, ZenohSettings, open_session
from services.ops.status import query_status
from tests.conftest import free_port
from tests.reliability_helpers import learner_argv, start_learner, stop_process
from tests.test_wire_zenoh import start_router, stop

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


def certs(out: Path) -> dict[str, str]:
    done = subprocess.run(
        [sys.executable, "-m", "services.cli", "certs", "--out", str(out),
         "--hosts", "127.0.0.1", "localhost", "--clients", "actor1"],
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    assert "wrote" in done.stdout
    return {p.name: str(p) for p in out.iterdir()}


def exchanged(endpoint: str, **tls) -> bool:
    settings = ZenohSettings(connect=[endpoint], connect_timeout=10, **tls)
    with open_session(settings) as a, open_session(settings) as b:
        got = threading.Event()
        b.declare_subscriber("navlearn/tls/x", lambda s: got.set())
        deadline = time.monotonic() + 10
        while not got.is_set() and time.monotonic() < deadline:
            a.put("navlearn/tls/x", b"hello")
            time.sleep(0.1)
        return got.is_set()


def test_certs_tls_and_mtls_connect_and_a_wrong_ca_is_refused(tmp_path: Path) -> None:
    good, other = certs(tmp_path / "good"), certs(tmp_path / "other")
    assert (Path(good["ca.key"]).stat().st_mode & 0o777) == 0o600
    endpoint = f"tls/127.0.0.1:{free_port()}"
    server = (
        "--tls-root-ca",
        good["ca.pem"],
        "--tls-cert",
        good["server.pem"],
        "--tls-key",
        good["server.key"],
    )
    _, proc, _ = start_router("--listen", endpoint, *server)
    try:
        assert exchanged(endpoint, tls_root_ca=good["ca.pem"])
        with pytest.raises(TransportError):
            open_session(ZenohSettings(connect=[endpoint], connect_timeout=2, tls_root_ca=other["ca.pem"]))
    finally:
        stop(proc)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    _, proc, _ = start_router("--listen", endpoint, *server, "--tls-mtls")
    try:
        mine = dict(tls_root_ca=good["ca.pem"], tls_cert=good["actor1.pem"], tls_key=good["actor1.key"])
        assert exchanged(endpoint, tls_mtls=True, **mine)
        stranger = dict(tls_root_ca=good["ca.pem"], tls_cert=other["actor1.pem"], tls_key=other["actor1.key"])
        with pytest.raises(TransportError):  # a client certificate from another CA
            open_session(ZenohSettings(connect=[endpoint], connect_timeout=2, tls_mtls=True, **stranger))
    finally:
        stop(proc)


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)


@pytest.mark.slow
@pytest.mark.timeout(180)
def test_remote_actor_in_a_network_namespace_feeds_the_learner(tmp_path: Path) -> None:
    """A namespace of its own joined by a veth pair: 10.213.7.1/30 (host end), 10.213.7.2/30 (inside)."""
    ns, host_if, ns_if = f"nlt{os.getpid()}", f"nlh{os.getpid()}", f"nln{os.getpid()}"
    if shutil.which("ip") is None:
        pytest.skip("the ip command (iproute2) is not installed")
    made = _ip("netns", "add", ns)
    if made.returncode != 0:
        pytest.skip(f"ip netns not permitted here: {made.stderr.strip()}")
    learner = actor = None
    try:
        for args in (
            ("link", "add", host_if, "type", "veth", "peer", "name", ns_if),
            ("link", "set", ns_if, "netns", ns),
            ("addr", "add", "10.213.7.1/30", "dev", host_if),
            ("link", "set", host_if, "up"),
            ("-n", ns, "addr", "add", "10.213.7.2/30", "dev", ns_if),
            ("-n", ns, "link", "set", ns_if, "up"),
            ("-n", ns, "link", "set", "lo", "up"),
        ):
            done = _ip(*args)
            if done.returncode != 0:
                pytest.skip(f"cannot set up the veth pair (ip {' '.join(args)}): {done.stderr.strip()}")
        port = free_port()
        endpoint, run = f"tcp/10.213.7.1:{port}", f"netns{port}"
        learner = start_learner(learner_argv(endpoint, run, tmp_path / "ckpt"), tmp_path / "learner.log")
        env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
        argv = ["ip", "netns", "exec", ns, sys.executable, "-m", "services.cli", "actor",
                "--connect", endpoint, "--run", run, "--id", "remote1", "--envs", "2",
                "--maps", "rooms:16", "--connect-timeout", "120"]  # fmt: skip
        with open(tmp_path / "actor.log", "wb") as log:
            actor = subprocess.Popen(argv, env=env, stdout=log, stderr=subprocess.STDOUT, cwd=os.getcwd())
        with open_session(ZenohSettings(connect=[endpoint], connect_timeout=120, run=run)) as session:
            deadline, got = time.monotonic() + 120, 0
            while time.monotonic() < deadline and got < 64:
                status = query_status(session, run, timeout=3.0)
                got = status.counters.get("transitions/remote1", 0) if status else 0
                time.sleep(0.5)
        assert got >= 64, (tmp_path / "actor.log").read_text()[-2000:]
    finally:
        for process in (actor, learner):
            if process is not None:
                stop_process(process)
        _ip("link", "del", host_if)
        _ip("netns", "del", ns)
    assert ns not in _ip("netns", "list").stdout

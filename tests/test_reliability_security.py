"""`navlearn certs` with real TLS: right CA connects (also mutual TLS), a wrong CA is refused;
a remote actor in its own Linux network namespace reaches a learner across a veth pair."""

from __future__ import annotations

import subprocess
import threading
import time
from pathlib import Path

import pytest

from services.transport import TransportError, ZenohSettings, open_session
from tests.conftest import free_port
from tests.test_wire_zenoh import start_router, stop

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


def certs(out: Path) -> dict[str, str]:
    done = subprocess.run(
        ["python", "-m", "services.cli", "certs", "--out", str(out), "--hosts", "127.0.0.1", "localhost",
         "--clients", "actor1"],
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

"""Many hosts: actor -> router A ==TLS==> router B <- learner, evaluator on a third host.

Three Linux network namespaces stand for three hosts: host A (a router and an actor), host B
(a router and the learner) and this test's own namespace (the evaluator and the operator's
status query). A veth pair joins A and B (10.213.20.1 - .2/30), another joins the test's
namespace to B (10.213.21.1 - .2/30); A and the test's namespace have no link. Router B
connects to router A over TLS (a certificate from `navlearn certs` for A's address), so every
transition, acknowledgement, weight update and report crosses the router-to-router link.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from services.common.transport import ZenohSettings, open_session
from services.ops.status import query_status
from tests.reliability_helpers import stop_process

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(300)]
A_TO_B = ("10.213.20.1", "10.213.20.2")
HOST_TO_B = ("10.213.21.1", "10.213.21.2")


def ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)


def spawn(log: Path, *argv: str, ns: str | None = None) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    prefix = ["ip", "netns", "exec", ns] if ns else []
    with open(log, "wb") as out:
        return subprocess.Popen(
            [*prefix, sys.executable, "-m", "services.cli", *argv],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )


def test_actor_and_learner_on_two_hosts_joined_router_to_router_over_tls(tmp_path):
    if shutil.which("ip") is None:
        pytest.skip("the ip command (iproute2) is not installed")
    pid = os.getpid()
    ns_a, ns_b = f"nlA{pid}", f"nlB{pid}"
    veth_a, veth_ba, veth_host, veth_bh = f"nla{pid}", f"nlba{pid}", f"nlh{pid}", f"nlbh{pid}"
    made = ip("netns", "add", ns_a)
    if made.returncode != 0:
        pytest.skip(f"ip netns not permitted here: {made.stderr.strip()}")
    processes: list[subprocess.Popen] = []
    try:
        ip("netns", "add", ns_b)
        for args in (
            ("link", "add", veth_a, "type", "veth", "peer", "name", veth_ba),
            ("link", "set", veth_a, "netns", ns_a),
            ("link", "set", veth_ba, "netns", ns_b),
            ("-n", ns_a, "addr", "add", f"{A_TO_B[0]}/30", "dev", veth_a),
            ("-n", ns_b, "addr", "add", f"{A_TO_B[1]}/30", "dev", veth_ba),
            ("link", "add", veth_host, "type", "veth", "peer", "name", veth_bh),
            ("link", "set", veth_bh, "netns", ns_b),
            ("addr", "add", f"{HOST_TO_B[0]}/30", "dev", veth_host),
            ("-n", ns_b, "addr", "add", f"{HOST_TO_B[1]}/30", "dev", veth_bh),
            ("link", "set", veth_host, "up"),
            *(
                ("-n", ns, "link", "set", dev, "up")
                for ns, dev in ((ns_a, veth_a), (ns_b, veth_ba), (ns_b, veth_bh))
            ),
            ("-n", ns_a, "link", "set", "lo", "up"),
            ("-n", ns_b, "link", "set", "lo", "up"),
        ):
            done = ip(*args)
            if done.returncode != 0:
                pytest.skip(f"cannot set up the namespaces (ip {' '.join(args)}): {done.stderr.strip()}")
        assert (
            ip("netns", "exec", ns_a, "ping", "-c1", "-W2", HOST_TO_B[0]).returncode != 0
        )  # A cannot see us

        tls = tmp_path / "tls"
        subprocess.run(
            [sys.executable, "-m", "services.cli", "certs", "--out", str(tls), "--hosts", A_TO_B[0]],
            capture_output=True, timeout=60, check=True,
        )  # fmt: skip
        run, link = "multihost", f"tls/{A_TO_B[0]}:7448"
        processes.append(spawn(
            tmp_path / "router-a.log", "router", "--listen", link, "--listen", "tcp/127.0.0.1:7447",
            "--tls-root-ca", str(tls / "ca.pem"), "--tls-cert", str(tls / "server.pem"),
            "--tls-key", str(tls / "server.key"), ns=ns_a,
        ))  # fmt: skip
        processes.append(spawn(
            tmp_path / "router-b.log", "router", "--listen", "tcp/127.0.0.1:7447",
            "--listen", f"tcp/{HOST_TO_B[1]}:7447", "--connect", link, "--tls-root-ca", str(tls / "ca.pem"),
            ns=ns_b,
        ))  # fmt: skip
        local = ("--connect", "tcp/127.0.0.1:7447", "--run", run, "--connect-timeout", "120")
        processes.append(spawn(
            tmp_path / "learner.log", "learner", *local, "--checkpoint-dir", str(tmp_path / "ckpt"),
            "--hidden-sizes", "16", "--batch-size", "16", "--learning-starts", "64", "--broadcast-every", "5",
            ns=ns_b,
        ))  # fmt: skip
        processes.append(spawn(
            tmp_path / "actor.log", "actor", *local, "--id", "hostA", "--envs", "2", "--maps", "rooms:16",
            ns=ns_a,
        ))  # fmt: skip
        remote = ("--connect", f"tcp/{HOST_TO_B[1]}:7447", "--run", run, "--connect-timeout", "120")
        processes.append(spawn(
            tmp_path / "evaluator.log", "evaluator", *remote, "--families", "unseen", "--episodes", "2",
            "--every-versions", "1", "--max-evals", "1", "--out", str(tmp_path / "eval"),
        ))  # fmt: skip

        settings = ZenohSettings(connect=[f"tcp/{HOST_TO_B[1]}:7447"], run=run, connect_timeout=120)
        with open_session(settings) as session:
            deadline, status = time.monotonic() + 240, None
            while time.monotonic() < deadline:
                status = query_status(session, run, timeout=3.0)
                if status and status.counters.get("transitions/hostA", 0) >= 64 and status.last_eval:
                    break
                time.sleep(1.0)
        logs = "\n".join(f"--- {p.name}\n{p.read_text()[-1500:]}" for p in sorted(tmp_path.glob("*.log")))
        assert status is not None, logs
        assert status.counters.get("transitions/hostA", 0) >= 64, logs  # A's actor reached B's learner
        assert status.versions["nnql"] > 0, logs
        assert status.last_eval, logs  # the evaluator here had the weights from B and reported back
        assert "joined" in (tmp_path / "router-a.log").read_text()  # router B came in over TLS
    finally:
        for process in reversed(processes):
            stop_process(process)
        ip("link", "del", veth_host)
        ip("netns", "del", ns_a)
        ip("netns", "del", ns_b)
    assert ns_a not in ip("netns", "list").stdout

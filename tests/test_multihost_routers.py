"""Many hosts: two Zenoh routers in two network namespaces, linked router-to-router over mutual TLS.

    host A (namespace): actor ──► router A: listens on its loopback,
                        connects to router B at tls/10.213.8.2:7447 (veth 10.213.8.1/30, mutual TLS)
    host B (namespace): learner ──► router B: listens on its loopback, tls/10.213.8.2:7447 and
                        tls/10.213.9.1:7447
    host C (namespace): evaluator ──► tls/10.213.9.1:7447 (veth 10.213.9.2/30, mutual TLS)

The learner host's router listens and each actor host's router connects to it: more actor
hosts are more routers connecting to the same listener. The routers run without Zenoh's shared
memory, which would otherwise carry messages between processes of this one machine past the
TLS link (it is on by default; across real hosts it cannot be used).
Real processes run in the namespaces with ``ip netns exec``. Batches cross both routers and
the TLS link to the learner, acknowledgements and weights cross back to the actor, and the
evaluator (reaching router B only) evaluates the learner's weights and its report arrives. The
addresses exist only inside the namespaces this test creates (every veth end is moved into
one of them), so nothing on the host changes; everything is removed at the end, also on failure.
Skipped with the reason when ``ip`` is missing or namespaces cannot be made (not root).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(420)]

LINK_A, LINK_B = "10.213.8.1", "10.213.8.2"  # the router-to-router link (A side, B side)
EVAL_B, EVAL_C = "10.213.9.1", "10.213.9.2"  # the evaluator host's link to the learner host
PORT = 7447  # every namespace has its own loopback and ports: nothing else listens there
CLI = [sys.executable, "-m", "services.cli"]


def _ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=10)


@contextmanager
def namespaces(names: list[str], links: list[tuple[str, str, str, str]]) -> Iterator[list[tuple[str, str]]]:
    """Make ``names`` and a veth pair per (ns1, addr1/prefix, ns2, addr2/prefix); remove them all after.
    Yields the pairs' interface names (ns1's end, ns2's end)."""
    if shutil.which("ip") is None:
        pytest.skip("the ip command (iproute2) is not installed")
    made: list[str] = []
    ends: list[tuple[str, str]] = []
    try:
        for ns in names:
            done = _ip("netns", "add", ns)
            if done.returncode != 0:
                pytest.skip(f"ip netns add not permitted here (needs root): {done.stderr.strip()}")
            made.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        for i, (ns1, addr1, ns2, addr2) in enumerate(links):
            end1, end2 = f"nlv{os.getpid() % 100000}{i}a", f"nlv{os.getpid() % 100000}{i}b"
            ends.append((end1, end2))
            for args in (
                ("link", "add", end1, "netns", ns1, "type", "veth", "peer", "name", end2, "netns", ns2),
                ("-n", ns1, "addr", "add", addr1, "dev", end1),
                ("-n", ns2, "addr", "add", addr2, "dev", end2),
                ("-n", ns1, "link", "set", end1, "up"),
                ("-n", ns2, "link", "set", end2, "up"),
            ):
                done = _ip(*args)
                if done.returncode != 0:
                    pytest.skip(f"cannot set up the veth pair (ip {' '.join(args)}): {done.stderr.strip()}")
        yield ends
    finally:
        for ns in made:  # deleting a namespace deletes the veth ends inside it, and so their peers
            _ip("netns", "del", ns)


class Hosts:
    """Processes started in namespaces, logged to files, stopped with SIGTERM (then SIGKILL)."""

    def __init__(self, logs: Path) -> None:
        self.logs = logs
        self.processes: dict[str, subprocess.Popen] = {}
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}

    def start(self, name: str, ns: str, *argv: str) -> None:
        with open(self.logs / f"{name}.log", "wb") as log:
            self.processes[name] = subprocess.Popen(
                ["ip", "netns", "exec", ns, *CLI, *argv], env=self.env, stdout=log, stderr=subprocess.STDOUT
            )

    def run(self, ns: str, *argv: str, timeout: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run(
            ["ip", "netns", "exec", ns, *CLI, *argv], env=self.env, capture_output=True, text=True,
            timeout=timeout,
        )  # fmt: skip

    def log(self, name: str) -> str:
        return (self.logs / f"{name}.log").read_text(errors="replace")[-3000:]

    def stop(self) -> dict[str, int]:
        for process in reversed(self.processes.values()):
            if process.poll() is None:
                process.terminate()
        codes = {}
        for name, process in self.processes.items():
            try:
                codes[name] = process.wait(60)
            except subprocess.TimeoutExpired:
                process.kill()
                codes[name] = process.wait()
        return codes


def test_actor_and_learner_behind_two_routers_linked_by_mutual_tls(tmp_path: Path) -> None:
    tag = os.getpid() % 100000
    ns_a, ns_b, ns_c = f"nlA{tag}", f"nlB{tag}", f"nlC{tag}"
    run = f"hosts{tag}"
    tls = tmp_path / "tls"
    made = subprocess.run(
        [*CLI, "certs", "--out", str(tls), "--hosts", LINK_B, EVAL_B, "--clients", "router-a", "evaluator"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    no_shm = tmp_path / "no-shm.json5"
    no_shm.write_text("{ transport: { shared_memory: { enabled: false } } }\n")
    hosts = Hosts(tmp_path)
    codes: dict[str, int] = {}
    with ExitStack() as stack:
        (_, link_b), _ = stack.enter_context(namespaces([ns_a, ns_b, ns_c], [
            (ns_a, f"{LINK_A}/30", ns_b, f"{LINK_B}/30"), (ns_b, f"{EVAL_B}/30", ns_c, f"{EVAL_C}/30"),
        ]))  # fmt: skip
        try:
            local = f"tcp/127.0.0.1:{PORT}"
            ca = ["--zenoh-config", str(no_shm), "--tls-root-ca", str(tls / "ca.pem"), "--tls-mtls"]
            hosts.start(
                "router-b", ns_b, "router", "--listen", f"tls/{LINK_B}:{PORT}",
                "--listen", local, "--listen", f"tls/{EVAL_B}:{PORT}", *ca,
                "--tls-cert", str(tls / "server.pem"), "--tls-key", str(tls / "server.key"),
            )  # fmt: skip
            hosts.start(
                "router-a", ns_a, "router", "--connect", f"tls/{LINK_B}:{PORT}",
                "--listen", local, *ca, "--tls-cert", str(tls / "router-a.pem"),
                "--tls-key", str(tls / "router-a.key"),
            )  # fmt: skip
            zenoh = ["--run", run, "--connect-timeout", "120"]
            hosts.start(
                "learner", ns_b, "learner", "--connect", local, *zenoh, "--checkpoint-dir",
                str(tmp_path / "ckpt"), "--hidden-sizes", "16", "--batch-size", "16", "--learning-starts",
                "64", "--broadcast-every", "5", "--log-every", "2",
            )  # fmt: skip
            hosts.start(
                "actor", ns_a, "actor", "--connect", local, *zenoh, "--id", "far1", "--envs", "2",
                "--maps", "rooms:16", "--log-every", "2",
            )  # fmt: skip
            hosts.start(
                "evaluator", ns_c, "evaluator", "--connect", f"tls/{EVAL_B}:{PORT}", *zenoh, "--families",
                "unseen", "--episodes", "3", "--out", str(tmp_path / "eval"), "--tls-root-ca",
                str(tls / "ca.pem"), "--tls-cert", str(tls / "evaluator.pem"), "--tls-key",
                str(tls / "evaluator.key"), "--tls-mtls",
            )  # fmt: skip
            view: dict = {}
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline:
                done = hosts.run(ns_b, "status", "--json", "--actors", "--run", run, "--connect", local)
                if done.returncode == 0:
                    view = json.loads(done.stdout)
                    actor = view.get("actor_status", {}).get("far1", {}).get("counters", {})
                    if (
                        actor.get("batches_acknowledged", 0) >= 10
                        and actor.get("weights_applied", 0) >= 1
                        and (view["learner"]["last_eval"] or {}).get("policy_version", 0) >= 1
                    ):  # the first report may be of version 0 (weights before any update)
                        break
                time.sleep(2)
            learner = view.get("learner") or {}
            actor = view.get("actor_status", {}).get("far1", {}).get("counters", {})
            context = {n: hosts.log(n) for n in hosts.processes}
            assert learner, context
            assert learner["actors"]["far1"]["transitions"] >= 64, context
            assert actor.get("batches_acknowledged", 0) >= 10, (actor, context)
            assert actor.get("weights_applied", 0) >= 1, (actor, context)
            assert learner["last_eval"] and learner["last_eval"]["policy_version"] >= 1, context
            assert view["alive"].get("evaluator") == ["evaluator"], view["alive"]
            # the transitions' bytes crossed the veth between the routers, where router B listens
            # only on TLS (router A's join may precede the routers' join/leave logging: not checked)
            link = json.loads(_ip("-j", "-s", "-n", ns_b, "link", "show", "dev", link_b).stdout)[0]
            transitions = learner["actors"]["far1"]["transitions"]
            assert link["stats64"]["rx"]["bytes"] > 100 * transitions, (link["stats64"], transitions)
        finally:
            codes = hosts.stop()
    assert not any(ns in _ip("netns", "list").stdout for ns in (ns_a, ns_b, ns_c))
    assert codes == dict.fromkeys(codes, 0), (codes, {n: hosts.log(n) for n in codes})

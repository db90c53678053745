"""`navlearn router` stops on a SIGTERM whichever of its threads the kernel hands the signal to.

A process-directed signal goes to any thread that does not block it; in a router most threads
are Zenoh's. Python runs its handler only when the main thread next runs Python code, so a main
thread in an untimed wait never returned (seen as 1 in 5 routers hanging until SIGKILL when two
linked routers were stopped together). The test directs the SIGTERM at a Zenoh thread itself.
"""

from __future__ import annotations

import ctypes
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import free_port

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

TGKILL = {"x86_64": 234, "aarch64": 131}  # syscall numbers (Linux)


def tgkill(pid: int, tid: int, signum: int) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.syscall(TGKILL[platform.machine()], pid, tid, signum) != 0:
        raise OSError(ctypes.get_errno(), f"tgkill({pid}, {tid}) failed")


def test_router_stops_when_sigterm_lands_on_a_zenoh_thread(tmp_path: Path) -> None:
    if sys.platform != "linux" or platform.machine() not in TGKILL:
        pytest.skip(
            f"needs Linux tgkill on {', '.join(TGKILL)} (this is {sys.platform} {platform.machine()})"
        )
    log_path = tmp_path / "router.log"
    with open(log_path, "wb") as log:
        router = subprocess.Popen(
            [sys.executable, "-m", "services.cli", "router", "--listen", f"tcp/127.0.0.1:{free_port()}"],
            stdout=log, stderr=subprocess.STDOUT,
        )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while "listening" not in log_path.read_text() and time.monotonic() < deadline:
            assert router.poll() is None, log_path.read_text()
            time.sleep(0.2)
        time.sleep(0.5)  # the main thread is in its wait now
        threads = [int(t) for t in os.listdir(f"/proc/{router.pid}/task") if int(t) != router.pid]
        assert threads, "the router runs no thread besides its main thread"
        tgkill(router.pid, threads[-1], signal.SIGTERM)
        assert router.wait(15) == 0, log_path.read_text()
    finally:
        if router.poll() is None:
            router.kill()
            router.wait()
    assert "router stopped" in log_path.read_text()

"""The suite's reader-writer lock between xdist workers (tests/conftest.py's ``machine_share``)."""

from __future__ import annotations

import fcntl
import threading
import time

from conftest import machine_share
from test_wire_zenoh import wait_until


def _held_by_another(path: str) -> bool:
    with open(path, "a") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(f, fcntl.LOCK_UN)
        return False


def test_an_alone_test_waits_for_the_running_test_and_the_next_waits_for_it(tmp_path):
    order: list[str] = []
    release = {name: threading.Event() for name in ("first", "alone")}

    def run(name: str, alone: bool) -> None:
        with machine_share(alone, tmp_path):
            order.append(f"{name} in")
            if name in release:
                release[name].wait(10)
            order.append(f"{name} out")

    first = threading.Thread(target=run, args=("first", False))
    first.start()
    wait_until(lambda: order == ["first in"], 10, "the first test to start")
    alone = threading.Thread(target=run, args=("alone", True))
    alone.start()
    # the alone test waits for the room with the gate held: a new test cannot overtake it
    wait_until(lambda: _held_by_another(str(tmp_path / "machine-share.gate")), 10, "the alone test to queue")
    after = threading.Thread(target=run, args=("after", False))
    after.start()
    time.sleep(0.2)
    assert order == ["first in"]  # neither the alone test nor the next one runs beside the first
    release["first"].set()
    wait_until(lambda: "alone in" in order, 10, "the alone test to start")
    time.sleep(0.2)
    assert order == ["first in", "first out", "alone in"]  # the next test waits for the alone one
    release["alone"].set()
    for t in (first, alone, after):
        t.join(10)
    assert order == ["first in", "first out", "alone in", "alone out", "after in", "after out"]


def test_without_workers_nothing_is_held():
    with machine_share(True, None), machine_share(True, None):
        pass  # two alone holders at once: no lock without xdist

"""``bench.ros2_drive`` stopped mid-run (SIGTERM, as ``kill`` or a supervisor sends) stops the router,
the drive and the sim it started, and keeps the episodes it wrote: real processes, a real router on
127.0.0.1."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def children_of(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_terminated_run_stops_what_it_started_and_keeps_its_episodes(tmp_path):
    out = tmp_path / "run"
    started: list[int] = []
    bench = subprocess.Popen(
        [sys.executable, "-m", "bench.ros2_drive", "--episodes", "3", "--out", str(out)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 240  # the world's episodes, then router, drive and the first sim
        while not (out / "logs" / "sim_0.log").exists() and time.monotonic() < deadline:
            assert bench.poll() is None, "the bench ended before it started its first episode"
            time.sleep(0.5)
        assert (out / "logs" / "sim_0.log").exists(), "no sim started within 240 s"
        started += children_of(bench.pid)
        assert len(started) == 3  # the router, the drive and the episode's sim
        assert (out / "episodes.jsonl").exists()  # written as episodes end (none yet)
        bench.send_signal(signal.SIGTERM)
        bench.wait(timeout=120)
        assert bench.returncode != 0
        assert [pid for pid in started if alive(pid)] == []
    finally:
        if bench.poll() is None:
            bench.kill()
            bench.wait()
        for pid in started:  # what a failed run left behind
            if alive(pid):
                os.kill(pid, signal.SIGKILL)

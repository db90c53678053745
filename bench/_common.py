"""Helpers the benches share: ports, Zenoh settings, child processes, CPU-time rates, random data.

Benches run as modules from the repository root (``python -m bench.learner``), so they import
the project and each other as packages.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from services.common.transport import ZenohSettings
from worlds.config import LEARNING_NAV
from worlds.perception import observation_dim

OBS_DIM, N_ACTIONS = 11, 5
"""The default navigation observation (8 beams + goal features) and action count."""
LEARNER_OBS_DIM = observation_dim(LEARNING_NAV)
"""what ``navlearn learner`` takes: the actors' observation (:data:`worlds.config.LEARNING_NAV`)"""


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def settings(endpoint: str, run: str, mode: str = "client", config_file: str | None = None) -> ZenohSettings:
    """A router listening on ``endpoint``, or a client connecting to it (scouting off; a client
    reads its other Zenoh settings from ``config_file`` when given)."""
    if mode == "router":
        return ZenohSettings(mode="router", listen=[endpoint], run=run)
    return ZenohSettings(
        mode="client", connect=[endpoint], run=run, connect_timeout=120, config_file=config_file
    )


def spawn(*argv: str, log: IO[str] | None = None) -> subprocess.Popen:
    """A child Python process (NAVLEARN_* variables dropped so flags alone rule): a helper whose
    stdout this process reads, or with ``log`` a service whose stdout and stderr go to that file."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    out, err = (subprocess.PIPE, subprocess.DEVNULL) if log is None else (log, subprocess.STDOUT)
    return subprocess.Popen([sys.executable, *argv], env=env, stdout=out, stderr=err, text=True)


def stop(process: subprocess.Popen, timeout: float = 60) -> str:
    """SIGTERM, then SIGKILL after ``timeout``; returns what the process printed."""
    process.send_signal(signal.SIGTERM)
    try:
        out, _ = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out or ""


def wait_ready(process: subprocess.Popen, timeout: float = 120) -> None:
    """Reads the child's stdout until it prints ``ready``; RuntimeError if it exits first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if line.strip() == "ready":
            return
        if not line and process.poll() is not None:
            raise RuntimeError(f"helper process exited with {process.returncode} before it was ready")
    raise RuntimeError(f"helper process was not ready within {timeout} s")


def random_transitions(
    n: int, rng: np.random.Generator, terminal_rate: float = 0.02, obs_dim: int = OBS_DIM
) -> dict[str, np.ndarray]:
    """``n`` transitions in the flat layout ``NNQLLearner.add`` takes."""
    return {
        "obs": rng.random((n, obs_dim), dtype=np.float32),
        "action": rng.integers(0, N_ACTIONS, n),
        "reward": rng.normal(size=n).astype(np.float32),
        "next_obs": rng.random((n, obs_dim), dtype=np.float32),
        "terminated": rng.random(n) < terminal_rate,
        "truncated": np.zeros(n, bool),
    }


@dataclass
class Rate:
    """Work done over a window: per wall-clock second and per CPU second of the process doing it."""

    count: float
    wall: float
    cpu: float

    @property
    def per_s(self) -> float:
        return self.count / self.wall

    @property
    def per_cpu_s(self) -> float:
        return self.count / self.cpu


def timed(step, seconds: float, per_call: int = 1) -> Rate:
    """Calls ``step()`` for ``seconds`` of wall time in this process; ``per_call`` units each."""
    count, wall, cpu = 0, time.perf_counter(), time.process_time()
    while time.perf_counter() - wall < seconds:
        step()
        count += per_call
    return Rate(count, time.perf_counter() - wall, time.process_time() - cpu)


def process_cpu(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (all its threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def median_rate(rates: list[Rate]) -> dict:
    return {
        "per_s": round(float(np.median([r.per_s for r in rates])), 2),
        "per_cpu_s": round(float(np.median([r.per_cpu_s for r in rates])), 2),
        "windows": len(rates),
    }


def overheads(service: dict, baseline: dict) -> dict:
    return {
        "wall": round(1 - service["per_s"] / baseline["per_s"], 4),
        "cpu": round(1 - service["per_cpu_s"] / baseline["per_cpu_s"], 4),
    }


def machine_load() -> list[float]:
    """1, 5 and 15 minute load averages (recorded beside every figure)."""
    return [round(x, 2) for x in os.getloadavg()]


def parse_overrides(parser: argparse.ArgumentParser, items: list[str], config: type, option: str) -> dict:
    """``KEY=VALUE`` strings -> overrides of the dataclass ``config`` (values parsed as JSON, else kept as
    strings); a KEY that is not one of its fields is a usage error naming ``option``."""
    fields = set(config.__dataclass_fields__)
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or key not in fields:
            parser.error(f"{option} {item!r}: expected KEY=VALUE with KEY a {config.__name__} field")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out

"""The actor keeps numpy's BLAS on one thread: set before numpy is first imported, or it is moot.

OpenBLAS splits the policy's small matrix products over every core and spins between calls:
an actor of 64 robots spent 20x its CPU per robot-step that way (bench/RESULTS.md, capacity).
"""

from __future__ import annotations

import os
import subprocess
import sys

PROBE = """
import os, sys
import services.cli as cli
import services.common.process as process
original = process.one_blas_thread
def probe():
    assert "numpy" not in sys.modules, "numpy was imported before the actor limited its BLAS threads"
    original()
    assert os.environ["OPENBLAS_NUM_THREADS"] == sys.argv[1]
    raise SystemExit(0)
process.one_blas_thread = probe
cli.main(["actor", "--envs", "2"])
raise SystemExit("the actor never called one_blas_thread")
"""


def run_probe(expected: str, env_value: str | None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if env_value is not None:
        env["OPENBLAS_NUM_THREADS"] = env_value
    return subprocess.run(
        [sys.executable, "-c", PROBE, expected], capture_output=True, text=True, timeout=120, env=env
    )


def test_actor_sets_one_blas_thread_before_numpy_loads() -> None:
    done = run_probe("1", None)
    assert done.returncode == 0, done.stderr[-2000:]


def test_an_explicit_blas_thread_count_is_kept() -> None:
    done = run_probe("4", "4")
    assert done.returncode == 0, done.stderr[-2000:]

"""Shared test fixtures: the shared data directory, free loopback ports, and the machine's share.

The suite runs on two pytest-xdist workers (the README's ``pytest -n 2``): most tests wait on the
processes they start, so two at a time use the machine's two cores. Before the workers start,
the controller compiles the robot world once (as ``navlearn up`` does; a second on a warm numba
cache), so the workers and the processes their tests start load it instead of each compiling
it at once. The workers take the ``slow`` tests first and one test at a time (xdist's
``--maxschedchunk 1``: a worker is not handed a run of slow tests while the other idles), so the
short ones fill the end. A test marked ``alone`` asserts a rate or a time bound that a second
test beside it would disturb; it runs with the other worker held between its tests (a
reader-writer lock on files both workers open, the writer first: once an ``alone`` test asks,
the other worker starts nothing new until it is done).
"""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from services.common.transport import free_port
from services.common.warmup import compile_world

__all__ = ["free_port"]  # tests import it from here

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
ARENA_MAP = SHARED_DATA / "movingai" / "arena.map"
ARENA_SCEN = SHARED_DATA / "movingai" / "arena.map.scen"


def pytest_sessionstart(session: pytest.Session) -> None:
    if os.environ.get("PYTEST_XDIST_WORKER") or not session.config.getoption("numprocesses", None):
        return  # a worker, or a run without workers: the first test that steps the world compiles it
    if session.config.option.maxschedchunk is None:  # read by xdist's scheduler after this hook
        session.config.option.maxschedchunk = 1
    seconds, compiled = compile_world("mixed:16")
    if compiled:
        reporter = session.config.pluginmanager.get_plugin("terminalreporter")
        reporter.write_line(f"robot world compiled for the workers in {seconds:.0f} s (a cold numba cache)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("PYTEST_XDIST_WORKER"):  # every worker sorts alike: the schedule's order
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture
def arena_paths() -> tuple[Path, Path]:
    if not ARENA_MAP.exists():
        pytest.skip(f"shared data not found at {ARENA_MAP}")
    return ARENA_MAP, ARENA_SCEN


@contextmanager
def machine_share(alone: bool, shared: Path | None) -> Iterator[None]:
    """Hold the machine shared (any test) or alone (``alone`` tests) for the other xdist workers.

    ``shared`` is a directory every worker of the run has (the lock files go there); ``None`` - a
    run without workers - holds nothing. The gate is taken first by both kinds, so a waiting
    ``alone`` test is not overtaken by the other worker's next test.
    """
    if shared is None:
        yield
        return
    with open(shared / "machine-share.gate", "a") as gate, open(shared / "machine-share.room", "a") as room:
        fcntl.flock(gate, fcntl.LOCK_EX)
        try:
            fcntl.flock(room, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        finally:
            fcntl.flock(gate, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(room, fcntl.LOCK_UN)


@pytest.fixture(autouse=True)
def _machine_share(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[None]:
    alone = request.node.get_closest_marker("alone") is not None
    # a worker's base temporary directory is <the run's>/popen-gwN: their parent is the run's own
    shared = tmp_path_factory.getbasetemp().parent if os.environ.get("PYTEST_XDIST_WORKER") else None
    with machine_share(alone, shared):
        yield

"""Shared test fixtures: the shared data directory and free loopback ports."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
ARENA_MAP = SHARED_DATA / "movingai" / "arena.map"
ARENA_SCEN = SHARED_DATA / "movingai" / "arena.map.scen"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def arena_paths() -> tuple[Path, Path]:
    if not ARENA_MAP.exists():
        pytest.skip(f"shared data not found at {ARENA_MAP}")
    return ARENA_MAP, ARENA_SCEN

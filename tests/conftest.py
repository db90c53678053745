"""Shared test fixtures: the shared data directory and free loopback ports."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.common.transport import free_port

__all__ = ["free_port"]  # tests import it from here

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
ARENA_MAP = SHARED_DATA / "movingai" / "arena.map"
ARENA_SCEN = SHARED_DATA / "movingai" / "arena.map.scen"


@pytest.fixture
def arena_paths() -> tuple[Path, Path]:
    if not ARENA_MAP.exists():
        pytest.skip(f"shared data not found at {ARENA_MAP}")
    return ARENA_MAP, ARENA_SCEN

"""Checkpoints of a memory-mapped replay do not stop acknowledgements (issue #18's bound: 1 s).

A real `navlearn learner` with a 10 M-transition memory-mapped replay checkpoints every second
while 4 actors publish through the real Outbox; the longest wait between two
acknowledgements that overlaps a checkpoint must stay under the bound (bench/checkpoint_stall.py
measures the same).
"""

from __future__ import annotations

import argparse

import pytest

from tests.stall_helpers import run_case

# alone: a bound in seconds on the acknowledgements' longest wait, which a test beside it would stretch
pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.alone, pytest.mark.timeout(240)]
BOUND_S = 1.0


def test_checkpoints_while_four_actors_publish_stall_acks_less_than_the_bound(tmp_path):
    args = argparse.Namespace(seconds=6.0, every=1.0, actors=4, batch=128)
    result = run_case("memmap", 10_000_000, args, tmp_path)
    assert result["checkpoints"] >= 3, result
    assert result["acked_transitions_per_s"] > 0
    assert result["longest_stall_over_checkpoint_s"] <= BOUND_S, result
    assert result["checkpoint_max_s"] <= BOUND_S, result

"""bench/nirl.py --nnql-discs: NNQL from scratch trains with the 0..N moving-disc mix it names (issue 15
part 9: every earlier `nnql` row trained on static maps only, unstated), and its line says which."""

from __future__ import annotations

import json
import sys

import bench.nirl as bench_nirl


def run_bench(monkeypatch, tmp_path, *flags: str) -> tuple[dict, list[int]]:
    """One tiny NNQL-from-scratch run through the bench's command line; returns its line and the
    moving-disc mix each train_local call was given."""
    given: list[int] = []
    real = bench_nirl.train_local

    def recording(run, *args, **kwargs):
        given.append(run.moving_discs)
        return real(run, *args, **kwargs)

    monkeypatch.setattr(bench_nirl, "train_local", recording)
    runs = tmp_path / "runs.jsonl"
    argv = ["bench/nirl.py", "--nav", "learning", "--methods", "nnql", "--seeds", "0", "--episodes", "2",
            "--nnql-steps", "256", "--nnql-eval-every", "256", "--val-episodes", "2", "--runs", str(runs),
            *flags]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    assert bench_nirl.main() == 0
    return json.loads(runs.read_text().splitlines()[-1]), given


def test_nnql_discs_reach_the_trainer_and_the_line(monkeypatch, tmp_path):
    row, given = run_bench(monkeypatch, tmp_path, "--nnql-discs", "3")
    assert given == [3] and row["nnql_discs"] == 3 and row["env_steps"] >= 256


def test_default_stays_static_as_the_recorded_rows(monkeypatch, tmp_path):
    row, given = run_bench(monkeypatch, tmp_path)
    assert given == [0] and row["nnql_discs"] == 0

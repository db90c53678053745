"""bench/nirl.py --nnql-discs: NNQL from scratch (and dqfd) trains with the 0..N moving-disc mix it
names (issue 15 part 9: every earlier `nnql` row trained on static maps only, unstated), and its line
says which."""

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


def test_dqfd_trains_with_the_disc_mix_and_head_nnql_is_given(monkeypatch, tmp_path):
    """dqfd is NNQL with demonstrations: the same --nnql-discs and --nnql-dueling (issue 15 part 13;
    the rows before trained it on static maps with the plain head, which the defaults still give)."""
    given: list[tuple[int, bool]] = []
    real = bench_nirl.train_dqfd

    def recording(demos, seed, env_steps, nav, **kwargs):
        given.append((nav.obstacles.count if nav.obstacles.mix else 0, kwargs["dueling"]))
        return real(demos, seed, env_steps, nav, **kwargs)

    monkeypatch.setattr(bench_nirl, "train_dqfd", recording)
    runs = tmp_path / "runs.jsonl"
    common = ["bench/nirl.py", "--nav", "learning", "--methods", "dqfd", "--sets", "5", "--seeds", "0",
              "--episodes", "2", "--iterations", "1", "--steps-per-iteration", "256",
              "--runs", str(runs)]  # fmt: skip
    for flags in (["--nnql-discs", "3", "--nnql-dueling"], []):
        monkeypatch.setattr(sys, "argv", [*common, *flags])
        assert bench_nirl.main() == 0
    rows = [json.loads(line) for line in runs.read_text().splitlines()]
    assert given == [(3, True), (0, False)]
    assert [(r["method"], r["nnql_discs"], r["dueling"]) for r in rows] == [
        ("dqfd", 3, True),
        ("dqfd", 0, False),
    ]
    assert all(r["env_steps"] >= 256 for r in rows)

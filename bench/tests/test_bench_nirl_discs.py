"""bench/nirl.py --nirl-discs: NIRL's own rounds train with the disc mix `navlearn nirl train` uses
unless told otherwise, and each line says which mix it had. (Until 2026-12-07 the bench defaulted
to static maps while the product trained with 0..6 discs: a run that omitted the flag measured
81% with discs where the product's setting gives 89%.)"""

from __future__ import annotations

import json
import sys

import bench.nirl as bench_nirl
from agents.nirl.config import NIRLRun


def run_bench(monkeypatch, tmp_path, *flags: str) -> tuple[dict, list[int]]:
    """One tiny NIRL run through the bench's command line; returns its line and the moving-disc mix
    each train_nirl call was given."""
    given: list[int] = []
    real = bench_nirl.train_nirl

    def recording(demos, config, run, *args, **kwargs):
        given.append(run.moving_discs)
        return real(demos, config, run, *args, **kwargs)

    monkeypatch.setattr(bench_nirl, "train_nirl", recording)
    runs = tmp_path / "runs.jsonl"
    argv = ["bench/nirl.py", "--nav", "learning", "--methods", "nirl", "--sets", "5", "--seeds", "0",
            "--episodes", "2", "--iterations", "1", "--curve-iterations", "1", "--curve-every", "1",
            "--steps-per-iteration", "256", "--val-episodes", "2", "--runs", str(runs), *flags]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    assert bench_nirl.main() == 0
    return json.loads(runs.read_text().splitlines()[-1]), given


def test_default_is_the_products_disc_mix(monkeypatch, tmp_path):
    row, given = run_bench(monkeypatch, tmp_path)
    assert NIRLRun().moving_discs > 0
    assert given == [NIRLRun().moving_discs] and row["nirl_discs"] == NIRLRun().moving_discs


def test_the_flag_reaches_the_rounds_and_the_line(monkeypatch, tmp_path):
    row, given = run_bench(monkeypatch, tmp_path, "--nirl-discs", "0")
    assert given == [0] and row["nirl_discs"] == 0

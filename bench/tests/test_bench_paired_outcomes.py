"""bench/paired_outcomes.py: a run records every set's outcomes episode by episode, and --compare pairs
two runs' episodes (McNemar on the discordant ones)."""

import json

import pytest

from bench.paired_outcomes import GOAL, compare, main


def test_a_run_records_each_set_and_compares_with_itself(tmp_path, capsys):
    out = tmp_path / "run.json"
    argv = ["--sizes", "16", "--cells", "1", "2", "--episodes", "4", "--throughput-seconds", "0.2",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    sets = json.loads(out.read_text())["sets"]
    assert list(sets) == ["mixed:16, cell 1 m", "mixed:16, cell 0.5 m"]
    assert all(len(v) == 4 for v in sets.values())
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert summary["success"] == {k: sum(n == GOAL for n in v) / 4 for k, v in sets.items()}
    assert list(summary["cost"]) == list(sets)
    assert all(c["robot_steps"] >= 16 and c["robot_steps_per_cpu_s"] > 0 for c in summary["cost"].values())
    assert main(["--compare", str(out), str(out)]) == 0
    rows = json.loads(capsys.readouterr().out.splitlines()[-1])["rows"]
    assert [(r["only_before"], r["only_after"], r["p"]) for r in rows] == [(0, 0, 1.0)] * 2


def test_compare_counts_the_discordant_episodes():
    before = {"a": [GOAL, GOAL, "collision", "timeout", GOAL]}
    after = {"a": ["collision", GOAL, GOAL, GOAL, GOAL], "b": [GOAL]}
    (row,) = compare(before, after)
    assert (row["only_before"], row["only_after"]) == (1, 2)
    assert row["failures_before"] == {"collision": 1, "timeout": 1}
    assert row["failures_after"] == {"collision": 1}
    assert row["before"] == pytest.approx(0.6) and row["after"] == pytest.approx(0.8)
    with pytest.raises(ValueError, match="not the same episodes"):
        compare({"a": [GOAL]}, {"a": [GOAL, GOAL]})

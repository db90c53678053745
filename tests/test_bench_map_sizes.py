"""bench/map_sizes.py as its README command runs it: the policy through its reading shield, and the
same network alone beside it on the same episodes (paired); --no-shield runs the network alone."""

from __future__ import annotations

import json

from bench import map_sizes

ARGS = ["--sizes", "16", "--episodes", "6", "--expert-episodes", "2", "--throughput-seconds", "0"]


def _report(capsys, argv: list[str]) -> dict:
    assert map_sizes.main(argv) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_the_policy_runs_shielded_with_the_network_alone_paired(capsys, tmp_path):
    report = _report(capsys, [*ARGS, "--out", str(tmp_path)])
    assert report["shield"] is True
    rows = report["results"]["16"]["static"]
    assert set(rows) == {"policy", "network", "heuristic", "expert"}
    assert rows["network"]["episodes"] == rows["policy"]["episodes"] == 6
    assert rows["network"]["paired"]["episodes"] == 6  # McNemar on the same episodes
    assert json.loads((tmp_path / "map_sizes.json").read_text())["shield"] is True


def test_no_shield_runs_the_network_alone(capsys):
    report = _report(capsys, [*ARGS, "--no-shield"])
    assert report["shield"] is False
    assert "network" not in report["results"]["16"]["static"]

"""`navlearn train --local`: flags, errors, outputs."""

from __future__ import annotations

import json

from services.cli import main
from tests.test_nnql_learning import CORRIDOR


def test_train_requires_local(capsys):
    assert main(["train"]) == 2
    assert "navlearn up" in capsys.readouterr().err


def test_bad_flags_are_one_line_errors(capsys):
    assert main(["train", "--local", "--maps", "nowhere:12"]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert main(["train", "--local", "--hidden-sizes", "0"]) == 2
    assert "hidden_sizes" in capsys.readouterr().err


def test_small_local_run_writes_a_loadable_policy(tmp_path, capsys):
    corridor = tmp_path / "corridor.txt"
    corridor.write_text(CORRIDOR)
    out = tmp_path / "run"
    argv = ["train", "--local", "--steps", "800", "--envs", "4", "--maps", str(corridor), "--out", str(out)]
    argv += [
        "--eval-every",
        "0",
        "--final-eval-episodes",
        "0",
        "--hidden-sizes",
        "16",
        "--no-progress",
        "--sarsa",
    ]
    assert main(argv) == 0
    assert "robot-steps" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env_steps"] == 800 and summary["nnql"]["sarsa"] is True
    from agents.evaluation.policies import load_policy

    policy = load_policy(out)  # the shared loader `navlearn evaluate` uses
    assert policy.kind == "q_network" and policy.model == "nnql"
    assert policy.architecture["hidden_sizes"] == [16]

"""`navlearn up --nirl` end to end on loopback: the learner trains NIRL beside NNQL from an expert
demonstrator's episodes, NIRL's weights go out and the evaluator reports NIRL beside NNQL, every
process in NIRL's observation (``--observation learning_plan``); and a bad --demos dataset stops
`up` before anything starts, with one line naming the file."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest
from test_nirl_demos import _bad_datasets as bad_datasets
from test_nirl_services import SMALL_NIRL

from services.cli import main

SMALL = ["--actors", "1", "--envs", "4", "--eval-episodes", "2", "--hidden-sizes", "16", "--batch-size", "16",
         "--learning-starts", "64", "--maps", "rooms:10"]  # fmt: skip
DEMO_EPISODES = 3


@pytest.mark.integration
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_up_nirl_with_an_expert_demonstrator_trains_broadcasts_and_evaluates_nirl(tmp_path):
    out, run = tmp_path / "run", f"upnirl{os.getpid()}"
    (tmp_path / "nirl.json").write_text(json.dumps(SMALL_NIRL))
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    argv = [sys.executable, "-m", "services.cli", "up", "--run", run, "--out", str(out), *SMALL, "--nirl",
            "--nirl-config", str(tmp_path / "nirl.json"), "--demonstrator", "astar", "--demo-episodes",
            str(DEMO_EPISODES), "--duration", "25", "--observation", "learning_plan"]  # fmt: skip
    result = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=540)
    logs = {p.name: p.read_text()[-1500:] for p in sorted((out / "logs").glob("*.log"))}
    assert result.returncode == 0, (result.stdout, result.stderr, logs)
    assert "demonstrator (astar)" in result.stdout and "observation learning_plan;" in result.stdout

    summary = json.loads((out / "summary.json").read_text())
    # the demonstrator exits 0 only once the learner acknowledged every batch it published
    assert summary["exit_codes"] == {"demonstrator": 0, "actor-1": 0, "learner": 0, "evaluator": 0}, logs
    learner = summary["last_status"]["learner"]
    assert learner["demos"]["astar"]["episodes"] == DEMO_EPISODES
    assert learner["demos"]["astar"]["steps"] == learner["replay_sizes"]["demos"] > 0
    assert learner["versions"]["nirl"] > SMALL_NIRL["warmstart_updates"]  # warm start done, then more
    assert any(name.startswith("nirl/") for name in learner["losses"])
    # the evaluator got NIRL's broadcast weights and reported NIRL beside NNQL on the same sets
    nirl, nnql = summary["last_evaluations"]["nirl"], summary["last_evaluations"]["nnql"]
    assert nirl["policy_version"] >= 1
    assert set(nirl["metrics"]) == set(nnql["metrics"]) == {"unseen", "dynamic"}
    assert summary["last_evaluation"] == nnql
    assert "nirl unseen: success" in result.stdout and "nnql unseen: success" in result.stdout
    # all in learning_plan: nothing refused for its width, both networks observe the plan length
    assert learner["counters"]["transitions_rejected"] == 0
    saved = [out / "policy", *sorted(out.glob("checkpoints/ckpt-*/nirl/q/policy"))]
    assert len(saved) >= 2
    for policy in saved:
        assert json.loads((policy / "config.json").read_text())["observation"]["observation.plan_length"]


def test_up_nirl_stops_on_a_bad_demonstration_dataset_naming_it(tmp_path, capsys):
    for case, (path, message) in bad_datasets(tmp_path).items():
        code = main(["up", "--nirl", "--demos", str(path), "--out", str(tmp_path / "run")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and path.name in err, (case, err)
        assert re.search(message, err), (case, err)
    assert not (tmp_path / "run").exists()  # nothing started


def test_up_demos_without_nirl_is_refused(tmp_path, capsys):
    code = main(["up", "--demos", str(tmp_path), "--out", str(tmp_path / "run")])
    assert code == 2 and "add --nirl" in capsys.readouterr().err

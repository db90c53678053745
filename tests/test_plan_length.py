"""The own map's plan length (ObservationConfig.plan_length) through what users run: `train --local
--plan-length` saves a policy that records it and evaluates in it; a policy saved before the option
existed observes without it and says so in an env with it; the flag without a subgoal is refused
naming the field. Its values are checked in tests/test_worlds_perception.py, its reuse of plans in
tests/test_worlds_reuse.py."""

from __future__ import annotations

import json

import pytest

from agents.evaluation.policies import load_policy
from agents.evaluation.runner import evaluate, make_eval_set
from services.cli import main
from worlds.config import (
    LEARNING_NAV,
    LEARNING_PLAN_NAV,
    check_observation,
    observation_settings,
    saved_observation,
)
from worlds.perception import observation_dim


def test_plan_length_is_recorded_and_checked_in_saved_policies():
    assert observation_dim(LEARNING_PLAN_NAV) == observation_dim(LEARNING_NAV) + 1
    assert observation_settings(LEARNING_PLAN_NAV)["observation.plan_length"] is True
    before = {k: v for k, v in observation_settings(LEARNING_NAV).items() if k != "observation.plan_length"}
    assert saved_observation(before)["observation.plan_length"] is False
    with pytest.raises(ValueError, match=r"observation\.plan_length=False \(the env has True\)"):
        check_observation(saved_observation(before), LEARNING_PLAN_NAV)


def test_train_local_plan_length_trains_saves_and_evaluates(tmp_path, capsys):
    assert main(["train", "--local", "--plan-length", "--subgoal", "none", "--steps", "10"]) == 2
    assert "observation.plan_length=True needs a subgoal" in capsys.readouterr().err
    out = tmp_path / "planned"
    argv = ["train", "--local", "--plan-length", "--steps", "400", "--envs", "4", "--out", str(out),
            "--eval-every", "200", "--eval-episodes", "3", "--eval-dynamic-episodes", "0",
            "--final-eval-episodes", "0", "--hidden-sizes", "16", "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    saved = json.loads((out / "config.json").read_text())["observation"]
    assert saved["observation.plan_length"] is True
    policy = load_policy(out)  # evaluates in the observation it records
    result = evaluate(policy, [make_eval_set("unseen", 3)])
    assert result.metrics["unseen"].episodes == 3
    assert main(["evaluate", "--policy", str(out), "--episodes", "2", "--maps", "unseen"]) == 0


def test_nirl_learns_in_learning_plan_from_demos_recorded_in_it(tmp_path, capsys):
    """README's NIRL path: `demos generate --observation learning_plan`, then `nirl train` in the same
    observation (tiny sizes); a learner of another observation refuses the set naming the field."""
    demos = tmp_path / "planned-v0"
    assert main(["demos", "generate", "--maps", "mixed:16", "--episodes", "3", "--seed", "20011",
                 "--observation", "learning_plan", "--out", str(demos)]) == 0  # fmt: skip
    tiny = ["--iterations", "1", "--warmstart-updates", "4", "--q-updates", "4", "--reward-updates", "1",
            "--steps-per-iteration", "32", "--envs", "4", "--eval-every", "0", "--final-eval-episodes", "0",
            "--hidden-sizes", "16", "--no-progress"]  # fmt: skip
    out = tmp_path / "run"
    argv = [
        "nirl",
        "train",
        "--demos",
        str(demos),
        "--observation",
        "learning_plan",
        "--out",
        str(out),
        *tiny,
    ]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["demo_steps"] > 0
    capsys.readouterr()
    assert main(["nirl", "train", "--demos", str(demos), "--out", str(tmp_path / "other"), *tiny]) == 2
    err = capsys.readouterr().err
    assert str(demos) in err and "observation.plan_length=True" in err
    # ... and which --observation to give either way
    assert "train in their observation (--observation learning_plan)" in err, err
    assert "record them again in the learner's (navlearn demos generate --observation learning)" in err, err
    # up checks its --demos against its own --observation before anything starts
    capsys.readouterr()
    assert main(["up", "--nirl", "--demos", str(demos), "--out", str(tmp_path / "up")]) == 2
    assert "train in their observation (--observation learning_plan)" in capsys.readouterr().err
    assert not (tmp_path / "up").exists()

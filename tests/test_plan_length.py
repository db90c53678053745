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


def test_nirl_with_no_flags_learns_in_learning_plan_and_refuses_other_sets(tmp_path, capsys):
    """NIRL's no-flag path is its best setting: `demos generate` records learning_plan by default and
    `nirl train` learns in it (tiny sizes); a set recorded in `learning` is refused in one line naming
    the flag either side; `up --nirl` (learning) takes the default set with the plan length dropped."""
    from agents.demo_observation import dataset_observation
    from services.ops.up_config import UpConfig, check_nirl

    demos = tmp_path / "planned-v0"
    assert main(["demos", "generate", "--maps", "mixed:16", "--episodes", "3", "--seed", "20011",
                 "--out", str(demos)]) == 0  # fmt: skip
    assert dataset_observation(demos) == (
        observation_settings(LEARNING_PLAN_NAV),
        observation_dim(LEARNING_PLAN_NAV),
    )
    tiny = ["--iterations", "1", "--warmstart-updates", "4", "--q-updates", "4", "--reward-updates", "1",
            "--steps-per-iteration", "32", "--envs", "4", "--eval-every", "0", "--final-eval-episodes", "0",
            "--hidden-sizes", "16", "--no-progress"]  # fmt: skip
    out = tmp_path / "run"
    assert main(["nirl", "train", "--demos", str(demos), "--out", str(out), *tiny]) == 0
    assert json.loads((out / "summary.json").read_text())["demo_steps"] > 0
    saved = json.loads((out / "config.json").read_text())["observation"]
    assert saved == observation_settings(LEARNING_PLAN_NAV)
    check_nirl(UpConfig(nirl=True, demos=str(demos)))  # up's learning observation: the column dropped
    other = tmp_path / "learning-v0"
    assert main(["demos", "generate", "--maps", "mixed:16", "--episodes", "3", "--seed", "20011",
                 "--observation", "learning", "--out", str(other)]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["nirl", "train", "--demos", str(other), "--out", str(tmp_path / "other"), *tiny]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(other) in err and "observation.plan_length=False" in err, err
    assert "train in their observation (--observation learning)" in err, err
    assert "record them again in the learner's (navlearn demos generate --observation learning_plan)" in err
    assert not (tmp_path / "other").exists()

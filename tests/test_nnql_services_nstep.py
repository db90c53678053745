"""`navlearn up` with n-step returns, the dueling head and the disc mix: the learner trains, the actors act
with its (folded) weights, the saved policy records the architecture."""

from __future__ import annotations

import json
import os

import pytest
from test_services_up import up

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(600)]


def test_up_trains_with_n_step_dueling_and_moving_discs(tmp_path):
    out, run = tmp_path / "run", f"ns{os.getpid()}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    flags = ("--n-step", "3", "--dueling", "--moving-discs", "2", "--duration", "8")
    up(out, run, env, *flags)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_codes"] == {"actor-1": 0, "learner": 0, "evaluator": 0}
    assert summary["final_version"] >= 100
    policy = json.loads((out / "policy" / "config.json").read_text())
    assert policy["architecture"]["dueling"] is True and policy["nnql_config"]["n_step"] == 3
    learner = summary["last_status"]["learner"]
    # the actor acts with the learner's new weights: its batches lag the learner by far less than its version
    assert learner["rates"]["policy_lag"] < summary["final_version"] / 2, learner["rates"]
    assert summary["last_evaluation"]["policy_version"] > 0

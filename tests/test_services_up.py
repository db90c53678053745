"""`navlearn up`, the README's main job, end to end with tiny settings: processes, outputs, clean stop."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(400)]


def test_up_trains_evaluates_the_final_policy_and_writes_its_outputs(tmp_path):
    out = tmp_path / "run"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    argv = [
        sys.executable, "-m", "services.cli", "up", "--run", f"up{os.getpid()}", "--out", str(out),
        "--updates", "40", "--duration", "150", "--actors", "1", "--envs", "4", "--eval-episodes", "2",
        "--hidden-sizes", "16", "--batch-size", "16", "--learning-starts", "64",
    ]  # fmt: skip
    result = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=360)
    assert result.returncode == 0, result.stdout + result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_codes"] == {"actor-1": 0, "learner": 0, "evaluator": 0}
    assert summary["final_version"] >= 40
    assert summary["last_evaluation"]["policy_version"] == summary["final_version"]
    assert set(summary["last_evaluation"]["metrics"]) == {"unseen", "dynamic"}
    policy = json.loads((out / "policy" / "config.json").read_text())
    assert policy["version"] == summary["final_version"] and (out / "policy" / "model.safetensors").exists()
    assert (out / "eval" / "learning_curve.png").stat().st_size > 10_000
    assert list((out / "tb").glob("events.out.tfevents.*"))
    assert "final policy version" in result.stdout

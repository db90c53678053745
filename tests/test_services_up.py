"""`navlearn up`, the README's main job, end to end with tiny settings: a first run on a cold numba
cache (visible compile step, the whole budget trained), then a resumed run (processes, outputs,
"resumed from checkpoint", a learning curve with two segments, clean stop)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.integration, pytest.mark.slow, pytest.mark.timeout(900)]
SMALL = ["--actors", "1", "--envs", "4", "--eval-episodes", "2", "--hidden-sizes", "16", "--batch-size", "16",
         "--learning-starts", "64"]  # fmt: skip


def up(out, run: str, env: dict[str, str], *flags: str) -> subprocess.CompletedProcess:
    argv = [sys.executable, "-m", "services.cli", "up", "--run", run, "--out", str(out), *SMALL, *flags]
    result = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=420)
    assert result.returncode == 0, result.stdout + result.stderr
    return result


def test_up_on_a_cold_cache_trains_its_whole_budget_then_resumes(tmp_path):
    out, run = tmp_path / "run", f"up{os.getpid()}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("NAVLEARN_")}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba-cache")  # nothing compiled yet: a first run
    budget = 8.0

    first = up(out, run, env, "--duration", str(budget))
    assert "compiling the robot world (first run only)" in first.stdout
    assert "robot world compiled in" in first.stdout, first.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_codes"] == {"actor-1": 0, "learner": 0, "evaluator": 0}
    assert summary["training_s"] >= budget and summary["resumed_from"] is None
    received = sum(a["transitions"] for a in summary["last_status"]["learner"]["actors"].values())
    assert received > 0 and summary["final_version"] >= 1
    first_version = summary["final_version"]

    second = up(out, run, env, "--updates", str(first_version + 40), "--duration", "150")
    assert "robot world loaded from the compile cache" in second.stdout, second.stdout
    assert f"resumed from checkpoint 1 (version {first_version}, replay " in second.stdout, second.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["exit_codes"] == {"actor-1": 0, "learner": 0, "evaluator": 0}
    assert summary["resumed_from"] == "ckpt-00000001"
    assert summary["final_version"] >= first_version + 40
    assert summary["last_evaluation"]["policy_version"] == summary["final_version"]
    assert set(summary["last_evaluation"]["metrics"]) == {"unseen", "dynamic"}
    points = [json.loads(line) for line in (out / "eval" / "evaluations.jsonl").read_text().splitlines()]
    assert len({p["launch"] for p in points}) == 2  # the learning curve's two segments
    policy = json.loads((out / "policy" / "config.json").read_text())
    assert (out / "policy" / "model.safetensors").exists()
    # keep-best: the best version the evaluator measured (validation seed 1), not necessarily the last
    assert (
        policy["version"]
        == summary["policy_version"]
        == summary["kept"]["version"]
        <= summary["final_version"]
    )
    assert policy["kept"]["eval_seed"] == summary["eval_seed"] == 1
    assert (out / "eval" / "learning_curve.png").stat().st_size > 10_000
    assert list((out / "tb").glob("events.out.tfevents.*"))
    assert "final policy version" in second.stdout

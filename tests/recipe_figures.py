"""The figures of a short, fixed-seed run of the default `navlearn train --local` recipe.

tests/test_recipe_reproducible.py pins them: a refactor of the option system, the configs or the
Q-network variants must leave what the default recipe learns unchanged to the last digit kept.
``python -m tests.recipe_figures`` prints them as JSON (how the pinned values were recorded).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from agents.nnql.policy import NNQLPolicy
from services.cli import main

ARGV = [
    "train", "--local", "--steps", "3000", "--envs", "4", "--seed", "3", "--eval-every", "2000",
    "--eval-episodes", "8", "--final-eval-episodes", "8", "--no-progress",
]  # fmt: skip
"""the run: 3,000 robot-steps of the default recipe (63 updates after the 2,000 learning starts)"""

PROBE_SEED = 11
"""seed of the observations the saved policy's Q-values are read on"""


def recipe_figures(out: Path) -> dict:
    """Run ARGV into ``out``; its updates, curve, final evaluation and Q-values on fixed observations."""
    assert main([*ARGV, "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    curve = [json.loads(line) for line in (out / "curve.jsonl").read_text().splitlines()]
    policy = NNQLPolicy.load(out)
    probe = (
        np.random.default_rng(PROBE_SEED)
        .uniform(0.0, 1.0, (4, policy.architecture["obs_dim"]))
        .astype(np.float32)
    )
    final = summary["final_eval"]
    return {
        "updates": summary["updates"],
        "selected_version": summary["selected_version"],
        "train_success": [round(p["train_success"], 6) for p in curve],
        "episode_return": [round(p["episode_return"], 4) for p in curve],
        "td_loss": [round(p.get("losses/td_loss", 0.0), 6) for p in curve],
        "eval_success": [p["eval_success"] for p in curve if "eval_success" in p],
        "final_success": final["success"]["value"],
        "final_spl": round(final["spl"], 6),
        "q_values": [[round(float(q), 5) for q in row] for row in policy.q_values(probe)],
    }


if __name__ == "__main__":
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        print(json.dumps(recipe_figures(Path(tmp) / "run"), indent=1))
    sys.exit(0)

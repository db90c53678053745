"""NNQL science figure (issue 7): success and path ratio to A* on 100 unseen generated maps,
static and with moving discs, after a fixed training budget on this machine.

Trains with ``navlearn train --local``'s code (``agents.nnql.train_local``), then evaluates the
selected greedy policy and, as the same-run baseline, the hand-written goal-seeking policy
(``worlds.heuristics``) on the shared evaluation sets (seed 0). The learning curve PNG lands in
``--out``. Last line: one JSON object.

    python -m bench.nnql_science --steps 200000 --out runs/bench-nnql
"""

from __future__ import annotations

import argparse
import json
import time

from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.policy import NNQLPolicy
from agents.nnql.train_local import LocalTrainConfig, train_local
from worlds.heuristics import goal_seeking_policy


def figures(result, family: str) -> dict[str, float | None]:
    m = result.metrics[family]
    return {
        "success": m.success.value,
        "success_ci": [m.success.low, m.success.high],
        "spl": m.spl,
        "path_ratio": m.path_ratio if m.path_ratio == m.path_ratio else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--steps", type=int, default=200_000, help="training budget in robot-steps")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per family")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--out", default="runs/bench-nnql", help="outputs: policy, curve.png, summary.json")
    args = parser.parse_args()

    start = time.perf_counter()
    trained = train_local(
        LocalTrainConfig(steps=args.steps, seed=args.seed, out=args.out, final_eval_episodes=0)
    )
    train_wall = time.perf_counter() - start
    policy = NNQLPolicy.load(trained.out)  # the weights train_local kept (best on validation, seed 1)
    sets = [make_eval_set(family, args.episodes, seed=0) for family in ("unseen", "dynamic")]
    ours = evaluate(policy.greedy(), sets)
    baseline = evaluate(goal_seeking_policy(), sets)
    print(f"NNQL after {trained.env_steps} robot-steps, {trained.updates} updates, {train_wall:.0f} s")
    print(ours.table())
    print("goal-seeking baseline (same sets, same run)")
    print(baseline.table())
    out = {
        "train_robot_steps": trained.env_steps,
        "train_updates": trained.updates,
        "train_wall_s": round(train_wall, 1),
        "selected_version": trained.selected_version,
        "curve_png": f"{args.out}/curve.png",
    }
    for family in ("unseen", "dynamic"):
        a, b = figures(ours, family), figures(baseline, family)
        out[f"nnql_{family}"] = a
        out[f"baseline_{family}"] = b
        out[f"success_ratio_vs_baseline_{family}"] = a["success"] / b["success"] if b["success"] else None
    out["aim_static_success_0.90_met"] = out["nnql_unseen"]["success"] >= 0.90
    print(json.dumps(out))


if __name__ == "__main__":
    main()

"""NNQL as good as experience can make it on the default observation (issue 14, "Learner").

Same observation and reward (``worlds.config.LEARNING_NAV``, "D+geo"), same budget of
robot-steps, several seeds, one learner setting per variant:

    default   NNQLConfig's defaults (one-step double DQN, utd 1/16), no moving discs in training
    n3        n-step returns, n = 3 (NNQLConfig.n_step)
    dueling   dueling head (NNQLConfig.dueling)
    discs     training episodes with 0..4 moving discs, uniform (ObstacleConfig.mix)
    utd8      one update per 8 transitions instead of 16
    n3+discs, n3+dueling, n3+dueling+discs, dueling+discs   combinations

Each run keeps its best weights on periodic validations (seed 1, ``--val-episodes``), then is
evaluated on four sets of ``--episodes``: validation (seed 1, unseen static maps, and the same
with 4 moving discs) and test (seed 0, the same two). The winner is chosen on validation only:
the highest mean of the two validation successes, pooled over seeds. Reported per variant:
success [Wilson 95%] per set, pooled and per seed, McNemar's exact test (paired, same episodes)
against the default and against the goal-seeking heuristic per seed, per map family, collisions,
timeouts, SPL, path ratio, robot-steps and wall time to 90% validation success.

Each (variant, seed) run writes ``OUT/<variant>-s<seed>/result.json`` and is skipped when that
file exists, so runs can be split across processes and the report re-made from them:

    python bench/nnql_budget.py --steps 200000 --seeds 0 1                # human lines, JSON last
    python bench/nnql_budget.py --variants default n3 --seeds 0 --steps 20000 --episodes 50
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from perception import heuristic, mcnemar, pooled, scored, to_90

from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.config import NNQLConfig
from agents.nnql.policy import NNQLPolicy
from agents.nnql.train_local import LocalTrainConfig, train_local
from worlds.config import LEARNING_NAV

VARIANTS: dict[str, tuple[dict, int]] = {
    "default": ({}, 0),
    "n3": ({"n_step": 3}, 0),
    "dueling": ({"dueling": True}, 0),
    "discs": ({}, 4),
    "utd8": ({"utd_ratio": 0.125}, 0),
    "n3+discs": ({"n_step": 3}, 4),
    "n3+dueling": ({"n_step": 3, "dueling": True}, 0),
    "n3+dueling+discs": ({"n_step": 3, "dueling": True}, 4),
    "dueling+discs": ({"dueling": True}, 4),
}
"""variant -> (NNQLConfig fields, moving discs per training episode at most)"""
SETS = (
    ("validation", "unseen", 1),
    ("validation_dynamic", "dynamic", 1),
    ("test", "unseen", 0),
    ("test_dynamic", "dynamic", 0),
)
CHOICE = ("validation", "validation_dynamic")
"""the sets whose mean pooled success picks the winner"""


def run_one(variant: str, seed: int, args, sets: dict) -> dict:
    out = Path(args.out) / f"{variant}-s{seed}"
    cached = out / "result.json"
    if cached.is_file():
        return json.loads(cached.read_text())
    fields, discs = VARIANTS[variant]
    run = LocalTrainConfig(
        steps=args.steps, envs=16, seed=seed, out=str(out), eval_every=args.steps // 4,
        eval_episodes=args.val_episodes, final_eval_episodes=0, progress=False, moving_discs=discs,
        maps="mixed:16", eval_sizes=(16,),  # 16x16 maps and validation, as the recorded runs
    )  # fmt: skip
    start = time.perf_counter()
    plain = {"dueling": False, "network": "mlp"}  # the recorded runs' MLP, plain unless named
    trained = train_local(run, NNQLConfig(seed=seed, **{**plain, **fields}))
    wall = time.perf_counter() - start
    policy = NNQLPolicy.load(out).greedy()
    results = {name: evaluate(policy, es, config=LEARNING_NAV) for name, es in sets.items()}
    record = {
        "variant": variant,
        "seed": seed,
        "nnql": fields,
        "moving_discs": discs,
        "train_robot_steps": trained.env_steps,
        "train_wall_s": round(wall, 1),
        "selected_version": trained.selected_version,
        "to_90_validation": to_90(trained.curve),
        **scored(results, sets),
    }
    cached.write_text(json.dumps(record) + "\n")
    return record


def compare_runs(runs: dict[str, list[dict]], base: dict, names: list[str]) -> None:
    """McNemar per seed and set against the heuristic and against the default variant (in place)."""
    for v, records in runs.items():
        for r in records:
            for name in names:
                mine = np.array(r["episodes"][name])
                r["sets"][name]["mcnemar_vs_heuristic"] = mcnemar(mine, np.array(base["episodes"][name]))
                ref = next((x for x in runs.get("default", []) if x["seed"] == r["seed"]), None)
                if ref is not None and v != "default":
                    r["sets"][name]["mcnemar_vs_default"] = mcnemar(mine, np.array(ref["episodes"][name]))


def report_of(runs: dict[str, list[dict]], base: dict, args) -> dict:
    compare_runs(runs, base, args.sets)
    report: dict = {"steps": args.steps, "seeds": args.seeds, "episodes": args.episodes, "sets": args.sets}
    report["variants"] = {}
    report["heuristic"] = base["sets"]
    for v, records in runs.items():
        entry = {name: pooled(records, name) for name in args.sets}
        entry["choice_score"] = float(np.mean([entry[name]["success"] for name in CHOICE]))
        entry["seeds"] = [r["seed"] for r in records]
        entry["train_wall_s"] = [r["train_wall_s"] for r in records]
        entry["to_90_validation"] = [r["to_90_validation"] for r in records]
        entry["runs"] = [
            {k: r[k] for k in ("seed", "train_wall_s", "to_90_validation", "sets")} for r in records
        ]
        report["variants"][v] = entry
    report["best_by_validation"] = max(
        report["variants"], key=lambda v: report["variants"][v]["choice_score"]
    )
    return report


def print_report(report: dict) -> None:
    print(f"NNQL on LEARNING_NAV, {report['steps']} robot-steps per run, seeds {report['seeds']}, "
          f"{report['episodes']} episodes per set; success [Wilson 95%] pooled over seeds")  # fmt: skip
    print(f"{'variant':<20} {'choice':>6}  " + " ".join(f"{n:<23}" for n in report["sets"]))
    rows = [*report["variants"].items(), ("heuristic", None)]
    for v, e in rows:
        cells = []
        for name in report["sets"]:
            p = e[name] if e else report["heuristic"][name]
            cells.append(f"{p['success']:6.1%} [{p['ci'][0]:.1%},{p['ci'][1]:.1%}]")
        score = f"{e['choice_score']:6.1%}" if e else ""
        label = v if e is None else f"{v} ({len(e['seeds'])})"
        print(f"{label:<20} {score:>6}  " + " ".join(f"{c:<23}" for c in cells))
    for v, e in report["variants"].items():
        for r in e["runs"]:
            parts = []
            for name in report["sets"]:
                s = r["sets"][name]
                vs = s.get("mcnemar_vs_default", {}).get("p")
                parts.append(
                    f"{name} {s['success']:.1%} (p heur {s['mcnemar_vs_heuristic']['p']:.2g}"
                    + (f", p default {vs:.2g})" if vs is not None else ")")
                )
            print(f"  {v} s{r['seed']}: " + ", ".join(parts)
                  + f"; train {r['train_wall_s']:.0f} s, to 90% val {r['to_90_validation']}")  # fmt: skip
    print(f"best by validation (mean of {' and '.join(CHOICE)}): {report['best_by_validation']}")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--steps", type=int, default=200_000, help="training budget per run (robot-steps)")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per evaluation set")
    parser.add_argument("--val-episodes", type=int, default=100, help="episodes of the periodic validations")
    parser.add_argument(
        "--sets", nargs="+", default=[n for n, _, _ in SETS], choices=[n for n, _, _ in SETS],
        help="evaluation sets (the choice needs both validation sets)",
    )  # fmt: skip
    parser.add_argument("--out", default="runs/nnql_budget", help="run directories and result files")
    parser.add_argument(
        "--cached-only", action="store_true", help="report the runs already in --out, train nothing"
    )
    args = parser.parse_args()

    start = time.perf_counter()
    sets = {
        name: make_eval_set(family, args.episodes, seed=seed)
        for name, family, seed in SETS
        if name in args.sets
    }
    out = Path(args.out)
    base = heuristic(sets, out)
    if args.cached_only:
        have = {
            v: [s for s in args.seeds if (out / f"{v}-s{s}" / "result.json").is_file()] for v in args.variants
        }
        runs = {v: [run_one(v, s, args, sets) for s in seeds] for v, seeds in have.items() if seeds}
    else:
        runs = {v: [run_one(v, s, args, sets) for s in args.seeds] for v in args.variants}
    report = report_of(runs, base, args)
    report["wall_s"] = round(time.perf_counter() - start, 1)
    print_report(report)
    print(json.dumps(report))


if __name__ == "__main__":
    main()

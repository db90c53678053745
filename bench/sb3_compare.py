"""NNQL against Stable-Baselines3's PPO and DQN on the learning observation (issue 14).

All three learn ``worlds.config.LEARNING_NAV`` (24 sector minima, goal, subgoal from the robot's
own map, geodesic progress reward) on the training maps ("mixed:16") with the same training
episodes (``--train-discs``: 0..N moving discs per episode, default ``navlearn train --local``'s
0..6 (0..4 in the recorded runs); 0 for static maps only) for the same number of robot-steps:

    nnql  ``navlearn train --local``'s code (``train_local``, 16 robots, default ``NNQLConfig``,
          keep-best on 4 validation evaluations of 100 episodes, seed 1 - inside its wall time)
    ppo   ``stable_baselines3.PPO("MlpPolicy", env)``, default hyper-parameters, one env
    dqn   ``stable_baselines3.DQN("MlpPolicy", env)``, default hyper-parameters, one env

(the env is ``worlds.env.NavigationEnv``; torch on one thread for all three). Each trained
policy is evaluated greedily on the same test episodes (seed 0: ``--episodes`` unseen static maps
and the same with 4 moving discs, ``agents.evaluation``); reported: success [Wilson 95%], per
map family, SPL, training wall and CPU time, McNemar's exact test NNQL vs each SB3 algorithm
(paired, same seed, same episodes). The issue's target: NNQL ahead of SB3's best with p < 0.01 in
less wall time.

Each (algorithm, seed) run writes ``OUT/<algo>-s<seed>/result.json`` and is skipped when that file
exists, so runs can be split across processes and the report re-made (``--cached-only``):

    python bench/sb3_compare.py --steps 200000 --seeds 0 1     # human lines, JSON last
    python bench/sb3_compare.py --steps 5000 --episodes 30     # a smoke run

SB3 is a benchmark-only dependency: ``pip install -e ".[bench]"``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.runner import evaluate, make_eval_set
from agents.nnql.policy import NNQLPolicy
from agents.nnql.train_local import LocalTrainConfig, train_local
from bench.perception import pooled, scored
from worlds.config import LEARNING_NAV, TRAINING_DISCS, observation_settings, with_moving_discs
from worlds.env import NavigationEnv

ALGOS = ("nnql", "ppo", "dqn")
SETS = (("test", "unseen", 0), ("test_dynamic", "dynamic", 0))
TRAIN_MAPS = "mixed:16"


class SB3Greedy:
    """An SB3 model as an ``agents.evaluation`` policy: observations (N, d) -> greedy actions (N,)."""

    def __init__(self, model) -> None:
        self.model = model
        self.observation = observation_settings(LEARNING_NAV)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        actions, _ = self.model.predict(np.asarray(obs, dtype=np.float32), deterministic=True)
        return np.asarray(actions, dtype=np.int64).reshape(len(obs))


def train_nnql(steps: int, seed: int, discs: int, out: Path):
    run = LocalTrainConfig(
        steps=steps, envs=16, seed=seed, maps=TRAIN_MAPS, moving_discs=discs, out=str(out),
        eval_every=steps // 4, eval_episodes=100, final_eval_episodes=0, progress=False, eval_sizes=(16,),
    )  # fmt: skip
    trained = train_local(run)
    info = {
        "robot_steps": trained.env_steps,
        "updates": trained.updates,
        "dueling": trained.learner.config.dueling,
    }
    return NNQLPolicy.load(out).greedy(), info


def train_sb3(algo: str, steps: int, seed: int, discs: int, out: Path):
    from stable_baselines3 import DQN, PPO

    env = NavigationEnv(with_moving_discs(LEARNING_NAV, discs), maps=TRAIN_MAPS)
    model = {"ppo": PPO, "dqn": DQN}[algo]("MlpPolicy", env, seed=seed, device="cpu", verbose=0)
    model.learn(total_timesteps=steps)
    model.save(out / "model.zip")
    return SB3Greedy(model), {"robot_steps": int(model.num_timesteps)}


def run_one(algo: str, seed: int, args, sets: dict) -> dict:
    out = Path(args.out) / f"{algo}-s{seed}"
    cached = out / "result.json"
    if cached.is_file():
        record = json.loads(cached.read_text())
        if record.get("train_discs", 0) != args.train_discs:  # runs before the option trained static
            sys.exit(f"{cached}: trained with {record.get('train_discs', 0)} discs, not --train-discs "
                     f"{args.train_discs}; give another --out")  # fmt: skip
        return record
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(1)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    if algo == "nnql":
        policy, info = train_nnql(args.steps, seed, args.train_discs, out)
    else:
        policy, info = train_sb3(algo, args.steps, seed, args.train_discs, out)
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    results = {name: evaluate(policy, es, config=LEARNING_NAV) for name, es in sets.items()}
    record = {"algo": algo, "seed": seed, "train_discs": args.train_discs, "train_wall_s": round(wall, 1),
              "train_cpu_s": round(cpu, 1), **info, **scored(results, sets)}  # fmt: skip
    cached.write_text(json.dumps(record) + "\n")
    return record


def paired(a: dict, b: dict, name: str) -> dict:
    x, y = np.array(a["episodes"][name]), np.array(b["episodes"][name])
    only_a, only_b = int((x & ~y).sum()), int((~x & y).sum())
    return {"only_nnql": only_a, "only_other": only_b, "p": mcnemar_exact(only_a, only_b)}


def pooled_pairs(tests: list[dict]) -> dict:
    """McNemar's exact test over every seed's episodes, each NNQL seed paired with the same seed of the
    other learner (as bench/nirl.py pools its seeds)."""
    only_a = sum(t["only_nnql"] for t in tests)
    only_b = sum(t["only_other"] for t in tests)
    return {"only_nnql": only_a, "only_other": only_b, "p": mcnemar_exact(only_a, only_b)}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--algos", nargs="+", default=list(ALGOS), choices=ALGOS)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--steps", type=int, default=200_000, help="robot-steps of training per run")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per test set")
    parser.add_argument(
        "--train-discs", type=int, default=TRAINING_DISCS,
        help="training episodes have 0..N moving discs, for every learner (default %(default)s; 0: static)",
    )  # fmt: skip
    parser.add_argument("--out", default="runs/sb3")
    parser.add_argument("--cached-only", action="store_true", help="report the runs in --out, train nothing")
    args = parser.parse_args()

    start = time.perf_counter()
    sets = {name: make_eval_set(family, args.episodes, seed=seed) for name, family, seed in SETS}
    runs: dict[str, list[dict]] = {}
    for seed in args.seeds:
        for algo in args.algos:
            if args.cached_only and not (Path(args.out) / f"{algo}-s{seed}" / "result.json").is_file():
                continue
            runs.setdefault(algo, []).append(run_one(algo, seed, args, sets))
    report: dict = {"steps": args.steps, "seeds": args.seeds, "episodes": args.episodes,
                    "train_discs": args.train_discs, "algos": {}}  # fmt: skip
    for algo, records in runs.items():
        entry = {name: pooled(records, name) for name, _, _ in SETS}
        entry["seeds"] = [r["seed"] for r in records]
        entry["train_wall_s"] = [r["train_wall_s"] for r in records]
        entry["train_cpu_s"] = [r["train_cpu_s"] for r in records]
        entry["robot_steps"] = [r["robot_steps"] for r in records]
        nnql = {r["seed"]: r for r in runs.get("nnql", [])}
        if algo != "nnql":
            entry["mcnemar_nnql_vs"] = {
                name: [{"seed": r["seed"], **paired(nnql[r["seed"]], r, name)} for r in records
                       if r["seed"] in nnql]
                for name, _, _ in SETS
            }  # fmt: skip
            entry["mcnemar_nnql_vs_pooled"] = {
                name: pooled_pairs(tests) for name, tests in entry["mcnemar_nnql_vs"].items()
            }
        report["algos"][algo] = entry
    others = [a for a in report["algos"] if a != "nnql"]
    if "nnql" in report["algos"] and others:
        best = max(others, key=lambda a: report["algos"][a]["test"]["success"])
        n, b = report["algos"]["nnql"], report["algos"][best]
        tests = b["mcnemar_nnql_vs"]["test"]
        report["sb3_best"] = best
        report["target_met"] = bool(
            tests
            and all(t["p"] < 0.01 and t["only_nnql"] > t["only_other"] for t in tests)
            and np.mean(n["train_wall_s"]) < np.mean(b["train_wall_s"])
        )
    report["wall_s"] = round(time.perf_counter() - start, 1)

    print(f"LEARNING_NAV, {args.steps} robot-steps per run, seeds {args.seeds}, "
          f"{args.episodes} episodes per set")  # fmt: skip
    for algo, e in report["algos"].items():
        cells = [f"{name} {e[name]['success']:.1%} [{e[name]['ci'][0]:.1%},{e[name]['ci'][1]:.1%}]"
                 for name, _, _ in SETS]  # fmt: skip
        print(f"{algo:<5} " + "  ".join(cells) + f"  wall {e['train_wall_s']} s, CPU {e['train_cpu_s']} s")
        for name, tests in e.get("mcnemar_nnql_vs", {}).items():
            for t in tests:
                print(f"   nnql vs {algo}, {name}, seed {t['seed']}: only nnql {t['only_nnql']}, "
                      f"only {algo} {t['only_other']}, p = {t['p']:.3g}")  # fmt: skip
        for name, t in e.get("mcnemar_nnql_vs_pooled", {}).items():
            print(f"   nnql vs {algo}, {name}, seeds pooled: only nnql {t['only_nnql']}, "
                  f"only {algo} {t['only_other']}, p = {t['p']:.3g}")  # fmt: skip
    if "target_met" in report:
        print(f"target (NNQL ahead of SB3's best, {report['sb3_best']}, p < 0.01, less wall time): "
              f"{'met' if report['target_met'] else 'not met'}")  # fmt: skip
    print(json.dumps(report))


if __name__ == "__main__":
    main()

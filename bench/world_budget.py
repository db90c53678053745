"""The world against what consumes it: robot-steps per CPU-second per observation, and a training run's.

Issue 14 asks the world to "stay >= 200k robot-steps per CPU-second [at the new default
observation], far above what the learner consumes". This bench measures both sides in one run:

1. The world alone (``NavigationVectorEnv``, 1 thread, 256 robots, maps "mixed:16"), per CPU second
   of this process, for the observations of the ablation (bench/perception.py's variants): A (8
   beams), B (24 sector minima of 96 rays), B+geo (and the geodesic progress reward), D (B + the
   subgoal planned on the robot's own map) and D+geo = ``worlds.config.LEARNING_NAV``, the
   default; and the default as the trainers run it, with 0..``TRAINING_DISCS`` moving discs per
   episode. Random and goal-seeking actions, interleaved ``--rounds`` times (A, B, ..., A, B, ...),
   medians: the ratios between observations come from the same rounds and load.
2. The consumer: ``navlearn train --local``'s code with its defaults (16 robots, NNQLConfig(),
   the disc mix) for ``--train-steps`` robot-steps without evaluations, robot-steps per CPU second
   of the whole run (world, policy, replay, updates) - what the world must stay far above.

    python -m bench.world_budget                       # human lines, one JSON object last
    python -m bench.world_budget --rounds 1 --seconds 0.5 --train-steps 5000   # a smoke run
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

from agents.nnql.train_local import LocalTrainConfig, train_local
from bench.env_throughput import TARGET_LEARNING_STEPS_PER_CPU_S, make_policy, measure
from bench.perception import VARIANTS
from worlds.config import LEARNING_NAV, TRAINING_DISCS, NavConfig, with_moving_discs
from worlds.vector_env import NavigationVectorEnv

OBSERVATIONS: dict[str, NavConfig] = {
    **{name: VARIANTS[name] for name in ("A", "B", "B+geo", "D", "D+geo")},
    f"D+geo, 0..{TRAINING_DISCS} discs": with_moving_discs(LEARNING_NAV, TRAINING_DISCS),
}
"""what is measured; "D+geo" is LEARNING_NAV (checked in main)"""


def world_rates(robots: int, seconds: float, rounds: int, policies: list[str], seed: int) -> dict:
    """{policy: {observation: [robot-steps per CPU s of each round]}}, observations interleaved."""
    envs = {name: NavigationVectorEnv(robots, nav, threads=1) for name, nav in OBSERVATIONS.items()}
    rates: dict[str, dict[str, list[float]]] = {p: {name: [] for name in envs} for p in policies}
    for name, env in envs.items():  # warm-up: compiled code loaded
        measure(env, robots, 0.2, 10**9, seed, make_policy(OBSERVATIONS[name], "random"))
    for policy in policies:
        for _ in range(rounds):
            for name, env in envs.items():
                row = measure(env, robots, seconds, 10**9, seed, make_policy(OBSERVATIONS[name], policy))
                rates[policy][name].append(row["robot_steps_per_cpu_s"])
    for env in envs.values():
        env.close()
    return rates


def training_rate(steps: int, seed: int) -> dict:
    """Robot-steps per CPU and wall second of ``train_local`` with its defaults, no evaluations."""
    with tempfile.TemporaryDirectory() as out:
        run = LocalTrainConfig(
            steps=steps, seed=seed, out=out, eval_every=0, final_eval_episodes=0, progress=False
        )
        wall0, cpu0 = time.perf_counter(), time.process_time()
        result = train_local(run)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    steps = result.env_steps
    return {"robot_steps": steps, "updates": result.updates, "cpu_s": cpu, "wall_s": wall,
            "robot_steps_per_cpu_s": steps / cpu, "robot_steps_per_s": steps / wall}  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=int, default=256)
    parser.add_argument("--seconds", type=float, default=3.0, help="time per world measurement")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds per observation")
    parser.add_argument("--policies", nargs="+", choices=["random", "goal"], default=["random", "goal"])
    parser.add_argument("--train-steps", type=int, default=50_000, help="robot-steps of the training run")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if VARIANTS["D+geo"] != LEARNING_NAV:
        sys.exit("bench.perception's D+geo is no longer LEARNING_NAV: name the default here")
    load_before = os.getloadavg()
    rates = world_rates(args.robots, args.seconds, args.rounds, args.policies, args.seed)
    medians = {p: {name: float(np.median(v)) for name, v in by.items()} for p, by in rates.items()}
    for policy, by in medians.items():
        for name, rate in by.items():
            print(f"{policy:6s} actions, {name:18s}: {rate:>9,.0f} robot-steps per CPU s "
                  f"(x{rate / by['D+geo']:.2f} of the default)")  # fmt: skip
    train = training_rate(args.train_steps, args.seed)
    print(f"train --local defaults: {train['robot_steps_per_cpu_s']:,.0f} robot-steps per CPU s, "
          f"{train['robot_steps_per_s']:,.0f} per wall s ({train['updates']} updates)")  # fmt: skip
    default = {p: by["D+geo"] for p, by in medians.items()}
    trained_world = {p: by[f"D+geo, 0..{TRAINING_DISCS} discs"] for p, by in medians.items()}
    consumed = train["robot_steps_per_cpu_s"]
    print(json.dumps({
        "bench": "world_budget", "robots": args.robots, "seconds": args.seconds, "rounds": args.rounds,
        "load_average_before": load_before, "load_average_after": os.getloadavg(),
        "world_cpu_rates": rates, "world_cpu_medians": medians, "training": train,
        "target_steps_per_cpu_s": TARGET_LEARNING_STEPS_PER_CPU_S,
        "default_meets_target": {p: r >= TARGET_LEARNING_STEPS_PER_CPU_S for p, r in default.items()},
        "world_over_training": {p: r / consumed for p, r in trained_world.items()},
        "world_share_of_training_cpu": {p: consumed / r for p, r in trained_world.items()},
    }))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())

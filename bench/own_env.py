"""navlearn on a Gymnasium env nobody here wrote, through the real services, beside SB3's DQN (issue 40).

For each seed, two runs on the same machine with the same robot-step budget (``--steps``):

    navlearn  ``navlearn up --env ENV --seed S --eval-episodes 100`` (router, learner, actors, evaluator;
              default NNQLConfig and `up` settings, keep-best included: nothing is set per env). The
              bench reads the evaluator's ``eval/evaluations.jsonl`` (validation episodes, seed 1) and
              stops the run (SIGINT: `up`'s own clean stop) at the first version whose 100 greedy
              episodes reach the target, or once the actors have stepped ``--steps`` robot-steps, or
              after ``--max-s`` seconds; then the run's saved policy (keep-best's choice) plays 100
              test episodes (seed 0): ``saved_policy.held`` says whether it holds the target.
    sb3-dqn   ``stable_baselines3.DQN`` with the RL Baselines3 Zoo hyper-parameters for the env
              (``hyperparams/dqn.yml``, commit 019107eb of DLR-RM/rl-baselines3-zoo; SB3's defaults
              where the zoo has none), one env, torch on one thread; every ``--eval-every`` steps
              its greedy policy plays the same kind of 100 seeded episodes
              (``agents.evaluation.env_returns``); evaluation time is not counted in its wall time.
              Its final model plays the same 100 test episodes (``final_model.held``).
              ``--sb3-budget navlearn``: the same robot-step budget as navlearn's run of the same seed
              had, per seed: SB3 may step as many robot-steps as that run stepped to its target (all it
              stepped where it missed), read from ``OUT/<env>/navlearn-s<seed>/result.json``, and
              ``--max-s`` does not stop it (its wall time is whatever those steps take), so "SB3 had not
              reached the target" means "in the robot-steps navlearn needed", not "in the wall cap". Its
              process CPU seconds are recorded beside the wall seconds (``cpu_s``).

The target is the env's registered ``reward_threshold`` for the mean return of 100 greedy episodes, or
``--success`` (a success rate from ``info["is_success"]``) where given. Reported per run: reached or not,
wall seconds to the target (navlearn: from `up`'s start, its start-up included; SB3: training time
only), robot-steps to it, best mean return / success seen; one JSON line on stdout last:

    python bench/own_env.py --env CartPole-v1 --seeds 0 1 2 --steps 400000
    python bench/own_env.py --env LunarLander-v3 --seeds 0 --steps 1000000 --max-s 1200

Each run writes ``OUT/<env>/<system>-s<seed>/result.json`` and is skipped when that file exists.
SB3 and the Box2D / MiniGrid envs are benchmark-only dependencies: ``pip install -e ".[bench]"``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from agents.evaluation.env_returns import evaluate_env
from agents.evaluation.policies import load_policy
from agents.evaluation.selection import TEST_SEED
from worlds.own_env import EnvConfig, make_env, reward_threshold

REPO = Path(__file__).resolve().parents[1]
SB3_EVAL_SEED = 10_000
"""SB3's periodic evaluations play the episodes of this seed (+ the run's seed), apart from the test ones"""
ZOO_DQN = {  # hyperparams/dqn.yml of DLR-RM/rl-baselines3-zoo at 019107eb (LunarLander-v2's for v3)
    "CartPole-v1": dict(
        learning_rate=2.5e-4,
        batch_size=512,
        buffer_size=100_000,
        learning_starts=0,
        gamma=0.99,
        target_update_interval=5000,
        train_freq=16,
        gradient_steps=4,
        exploration_fraction=0.06,
        exploration_final_eps=0.11,
    ),
    "LunarLander-v3": dict(
        learning_rate=8.8e-4,
        batch_size=32,
        buffer_size=1_000_000,
        learning_starts=0,
        gamma=0.99,
        target_update_interval=10000,
        train_freq=16,
        gradient_steps=-1,
        exploration_fraction=0.2,
        exploration_final_eps=0.1,
        policy_kwargs={"net_arch": [256, 256]},
    ),
}
"""the zoo's n_timesteps are replaced by the bench's --steps (the same for both systems)"""


def reached(metrics: dict, threshold: float | None, success: float | None) -> bool:
    m = next(iter(metrics.values()))
    if success is not None:
        return "success" in m and m["success"]["value"] >= success
    return threshold is not None and m["return"]["mean"] >= threshold


def headline(metrics: dict) -> float:
    m = next(iter(metrics.values()))
    return m["success"]["value"] if "success" in m else m["return"]["mean"]


def run_navlearn(env: EnvConfig, seed: int, args, out: Path, threshold, success) -> dict:
    """`navlearn up --env` until the target, the step budget or --max-s; the first version at target."""
    run_dir = out / "run"
    argv = [
        sys.executable,
        "-m",
        "services.cli",
        "up",
        *env.flags(),
        "--run",
        out.name,
        "--out",
        str(run_dir),
        "--seed",
        str(seed),
        "--eval-episodes",
        str(args.episodes),
        "--duration",
        str(args.max_s),
    ]
    start = time.time()
    log = open(out / "up.log", "w")  # noqa: SIM115 - closed below, after the process
    proc = subprocess.Popen(argv, cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
    lines = run_dir / "eval" / "evaluations.jsonl"
    hit, best, seen = None, None, 0
    steps = 0
    while proc.poll() is None:
        time.sleep(1.0)
        points = [json.loads(x) for x in lines.read_text().splitlines()[seen:]] if lines.exists() else []
        seen += len(points)
        steps = actor_steps(run_dir)
        for point in points:
            value = headline(point["metrics"])
            best = value if best is None else max(best, value)
            if hit is None and reached(point["metrics"], threshold, success):
                hit = {
                    "wall_s": point["time"] - start,
                    "version": point["policy_version"],
                    "steps": steps,
                    "metrics": point["metrics"],
                }
        if hit is not None or steps >= args.steps:
            proc.send_signal(signal.SIGINT)
            break
    proc.wait()
    log.close()
    wall = time.time() - start
    shutil.rmtree(run_dir / "checkpoints", ignore_errors=True)  # replay and networks: tens of MB, kept out
    return {
        "reached": hit is not None,
        "to_target": hit,
        "best": best,
        "robot_steps": steps,
        "wall_s": wall,
        "saved_policy": saved_policy(run_dir / "policy", env, args, threshold, success),
        "command": " ".join(argv[1:]),
    }


def saved_policy(path: Path, env: EnvConfig, args, threshold, success) -> dict | None:
    """The run's saved policy (`up`'s keep-best choice) on --episodes fresh test episodes (seed 0): does
    the policy a user gets hold the target, not just one evaluation during training?"""
    if not (path / "config.json").exists():
        return None
    config = json.loads((path / "config.json").read_text())
    metrics = evaluate_env(load_policy(path), env, args.episodes, seed=TEST_SEED)
    return {"version": config["version"], "kept": config.get("kept") is not None, "test_seed": TEST_SEED,
            "held": reached(metrics, threshold, success), "metrics": metrics}  # fmt: skip


def actor_steps(run_dir: Path) -> int:
    """Robot-steps so far: the newest "(N in all)" of each actor's progress lines (`up`'s logs/actor-*.log,
    every 10 s), or its final "done: N robot-steps" line."""
    total = 0
    for path in (run_dir / "logs").glob("actor-*.log"):
        found = re.findall(r"\((\d+) in all\)|done: (\d+) robot-steps", path.read_text(errors="replace"))
        if found:
            total += int(found[-1][0] or found[-1][1])
    return total


class SB3Greedy:
    def __init__(self, model) -> None:
        self.model = model

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.asarray(self.model.predict(obs, deterministic=True)[0], dtype=np.int64)


def navlearn_budget(out: Path, seed: int) -> int:
    """The robot-steps navlearn's run of ``seed`` stepped to its target (all of its steps where it missed):
    SB3's budget under ``--sb3-budget navlearn``."""
    path = out / f"navlearn-s{seed}" / "result.json"
    if not path.exists():
        raise SystemExit(
            f"--sb3-budget navlearn: {path} is missing; run --systems navlearn for seed {seed} first"
        )
    row = json.loads(path.read_text())
    return int(row["to_target"]["steps"] if row["to_target"] else row["robot_steps"])


def run_sb3(env: EnvConfig, seed: int, args, threshold, success, budget: int, max_s: float) -> dict:
    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.callbacks import BaseCallback

    torch.set_num_threads(1)
    params = ZOO_DQN.get(env.env, {})
    start, cpu_start = time.perf_counter(), time.process_time()
    evaluating = [0.0]
    state = {"hit": None, "best": None}

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps % args.eval_every:
                return True
            t0 = time.perf_counter()
            metrics = evaluate_env(SB3Greedy(self.model), env, args.episodes, seed=SB3_EVAL_SEED + seed)
            evaluating[0] += time.perf_counter() - t0
            value = headline(metrics)
            state["best"] = value if state["best"] is None else max(state["best"], value)
            if reached(metrics, threshold, success):
                wall = time.perf_counter() - start - evaluating[0]
                state["hit"] = {"wall_s": wall, "steps": self.num_timesteps, "metrics": metrics}
                return False
            return time.perf_counter() - start - evaluating[0] < max_s

    model = DQN("MlpPolicy", make_env(env), seed=seed, verbose=0, **params)
    model.learn(total_timesteps=budget, callback=Evaluate())
    wall = time.perf_counter() - start - evaluating[0]
    cpu = time.process_time() - cpu_start  # evaluations included: an upper bound of its training's CPU
    tested = evaluate_env(SB3Greedy(model), env, args.episodes, seed=TEST_SEED)  # its final model
    return {
        "final_model": {
            "test_seed": TEST_SEED,
            "held": reached(tested, threshold, success),
            "metrics": tested,
        },
        "reached": state["hit"] is not None,
        "to_target": state["hit"],
        "best": state["best"],
        "robot_steps": int(model.num_timesteps),
        "budget_steps": budget,
        "wall_cap_s": None if max_s == float("inf") else max_s,
        "wall_s": wall,
        "cpu_s": cpu,
        "hyper_parameters": dict(params) or "SB3 defaults (no zoo entry)",
    }


def main() -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--env", required=True, help="Gymnasium id, module:Id or module:callable")
    parser.add_argument("--env-kwargs", default="", help="JSON object of the env's keyword arguments")
    parser.add_argument("--env-module", default="", help="module imported first (it registers --env)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=400_000, help="robot-step budget of each run")
    parser.add_argument("--max-s", type=float, default=900.0, help="wall seconds at most per run")
    parser.add_argument("--episodes", type=int, default=100, help="greedy episodes per evaluation")
    parser.add_argument("--eval-every", type=int, default=10_000, help="SB3: steps between evaluations")
    parser.add_argument("--success", type=float, help="target: this success rate (is_success) instead")
    parser.add_argument("--systems", nargs="+", default=["navlearn", "sb3-dqn"])
    parser.add_argument(
        "--sb3-budget",
        choices=("steps", "navlearn"),
        default="steps",
        help="SB3's robot-step budget: --steps and the --max-s wall cap (steps), or the robot-steps "
        "navlearn's run of the same seed stepped to its target, with no wall cap (navlearn)",
    )
    parser.add_argument("--out", default="results/own-env")
    args = parser.parse_args()
    env = EnvConfig(env=args.env, env_kwargs=args.env_kwargs, env_module=args.env_module)
    threshold = reward_threshold(env)
    rows = []
    for seed in args.seeds:
        for system in args.systems:
            same_steps = system != "navlearn" and args.sb3_budget == "navlearn"
            label = f"{system}-navlearn-steps" if same_steps else system
            out = Path(args.out) / env.env.replace(":", "_").replace("/", "_") / f"{label}-s{seed}"
            path = out / "result.json"
            if path.exists():
                rows.append(json.loads(path.read_text()))
                continue
            out.mkdir(parents=True, exist_ok=True)
            load = os.getloadavg()[0]
            if system == "navlearn":
                result = run_navlearn(env, seed, args, out, threshold, args.success)
            else:
                same = args.sb3_budget == "navlearn"
                budget = navlearn_budget(out.parent, seed) if same else args.steps
                max_s = float("inf") if same else args.max_s
                result = run_sb3(env, seed, args, threshold, args.success, budget, max_s)
            row = {
                "budget_steps": args.steps,
                "env": env.signature(),
                "system": system,
                "seed": seed,
                "threshold": threshold,
                "success_target": args.success,
                "load_1min_at_start": load,
                "date": datetime.now(UTC).isoformat(timespec="seconds"),
                "commit": commit(),
                **result,
            }
            path.write_text(json.dumps(row, indent=1) + "\n")
            rows.append(row)
            hit = row["to_target"]
            said = f"target in {hit['wall_s']:.0f} s, {hit['steps']} steps" if hit else "not reached"
            print(
                f"{system} seed {seed}: {said} (best {row['best']}, {row['wall_s']:.0f} s)", file=sys.stderr
            )
    summary = {
        "env": env.signature(),
        "threshold": threshold,
        "success_target": args.success,
        "budget_steps": args.steps,
        "runs": [
            {k: r[k] for k in ("system", "seed", "reached", "best", "robot_steps", "wall_s")}
            | {"to_target_s": r["to_target"]["wall_s"] if r["to_target"] else None}
            | {"test_held": (r.get("saved_policy") or r.get("final_model") or {}).get("held")}
            for r in rows
        ],
    }
    print(json.dumps(summary))


def commit() -> str:
    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    return done.stdout.strip()


if __name__ == "__main__":
    main()

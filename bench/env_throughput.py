"""Robot-world throughput: NavigationVectorEnv against gymnasium's SyncVectorEnv of the single env.

Both step the same robots (default NavConfig: 8 beams with exact grid ray casting, motion and
range noise, maps "mixed:16") with uniformly random actions, so episodes are short and resets
frequent (about one robot-step in ten). Robot-steps/s at 1, 64 and 1024 robots; the baseline is
gymnasium.vector.SyncVectorEnv of gym.make("navlearn/Navigation-v0") envs (the usual way to batch
a gymnasium env; its SAME_STEP autoreset), timed for a bounded number of steps. Our env is
measured twice: with one thread (``threads=1``: the serial kernel, no parallel code; the
one-core figure) and with ``--threads`` threads (Python threads stepping ranges of robots in
the GIL-free kernel; 64 robots and more). SyncVectorEnv steps its envs one after the other in
one thread. The machine is shared, so each figure is reported per wall-clock second and per
CPU second of this process (all its threads), with the load average; the threaded ratio is a
wall-clock ratio (what threads buy is wall-clock time).

    python -m bench.env_throughput     # human lines, then one JSON object on the last line
    python -m bench.env_throughput --nav learning --robots 256   # the observation policies learn with

``--policy goal`` steps with :func:`worlds.heuristics.goal_seeking_policy` instead (episodes of about
40 steps rather than 11); ``--reuse-ablation ROUNDS`` measures only our env, with the perception's
reuse (kept plans, paused geodesic Dijkstra) off and on, interleaved.

``--compare-tree PATH --rounds R`` measures only our env (1 thread), in this tree and in another
checkout (e.g. main before a speed change), each in its own subprocess, interleaved (other, this,
other, this, ...) R times at every robot count and ``--policies``, and reports per CPU second
both medians and their ratio: the before/after of a change, in the same run and load.

``--nav learning`` measures :data:`worlds.config.LEARNING_NAV` (sector minima, own-map subgoal
..., issue 14) instead of ``NavConfig()``; its target is 200k robot-steps per CPU-second, far
above what a learner consumes (a few thousand per second).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import worlds  # noqa: F401  (registers navlearn/Navigation-v0)
from worlds.config import LEARNING_NAV, NavConfig
from worlds.heuristics import goal_seeking_policy
from worlds.perception import REUSE_PARAM
from worlds.vector_env import NavigationVectorEnv

TARGET_STEPS_PER_S = 1_000_000
TARGET_RATIO = 200.0
TARGET_LEARNING_STEPS_PER_CPU_S = 200_000
NAVS = {"default": NavConfig(), "learning": LEARNING_NAV}


def measure(env, n: int, seconds: float, max_steps: int, seed: int, policy=None) -> dict:
    """Step ``env`` (``n`` robots) with random actions (or ``policy(obs)``'s) for about ``seconds``
    (at most ``max_steps`` env steps) after a warm-up; robot-steps per wall and per CPU second."""
    obs, _ = env.reset(seed=seed)
    actions = np.random.default_rng(seed).integers(NavConfig().robot.n_actions, size=(256, n))
    act = (lambda t, obs: actions[t % 256]) if policy is None else (lambda t, obs: policy(obs))
    for t in range(3):  # warm-up (compiled code loaded, caches filled)
        obs, *_ = env.step(act(t, obs))
    steps, ended = 0, 0
    wall0, cpu0 = time.perf_counter(), time.process_time()
    while steps < max_steps and time.perf_counter() - wall0 < seconds:
        obs, _, terminated, truncated, _ = env.step(act(steps, obs))
        ended += int(np.count_nonzero(terminated | truncated))
        steps += 1
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    return {
        "robots": n,
        "env_steps": steps,
        "robot_steps_per_s": n * steps / wall,
        "robot_steps_per_cpu_s": n * steps / cpu,
        "mean_episode_length": n * steps / max(ended, 1),
    }


def make_policy(config: NavConfig, kind: str):
    """None (random actions) or the goal-seeking heuristic on the readings and goal of ``config``."""
    if kind == "random":
        return None
    heuristic, width = goal_seeking_policy(config), config.sensors.n_beams + 3
    return lambda obs: heuristic(np.asarray(obs)[:, :width])


def reuse_ablation(config: NavConfig, args) -> int:
    """Robot-steps per CPU second of our env (1 thread) with the perception's reuse (kept plans,
    paused geodesic Dijkstra) off and on, interleaved (off, on, off, on, ...) at each robot count;
    the two give the same observations (tests/test_worlds_reuse.py)."""
    load_before = os.getloadavg()[0]
    policy = make_policy(config, args.policy)
    results = []
    for n in args.robots:
        runs: dict[str, list[float]] = {"off": [], "on": []}
        for _ in range(args.reuse_ablation):
            for name in runs:
                env = NavigationVectorEnv(n, config, threads=1)
                env.batch.perception.params[REUSE_PARAM] = float(name == "on")
                row = measure(env, n, args.seconds, 10**9, args.seed, policy)
                runs[name].append(row["robot_steps_per_cpu_s"])
        off, on = float(np.median(runs["off"])), float(np.median(runs["on"]))
        results.append({"robots": n, "reuse_off_cpu": runs["off"], "reuse_on_cpu": runs["on"],
                        "median_off": off, "median_on": on, "speedup": on / off})  # fmt: skip
        print(f"{n:5d} robots, {args.policy} actions: reuse off {off:>10,.0f}, on {on:>10,.0f} robot-steps "
              f"per CPU s (median of {args.reuse_ablation}), x{on / off:.2f}")  # fmt: skip
    print(json.dumps({
        "bench": "env_throughput_reuse", "nav": args.nav, "policy": args.policy, "seconds": args.seconds,
        "load_average_before": load_before, "load_average_after": os.getloadavg()[0], "results": results,
        "learning_target_steps_per_cpu_s": TARGET_LEARNING_STEPS_PER_CPU_S,
        "learning_target_met_cpu": results[-1]["median_on"] >= TARGET_LEARNING_STEPS_PER_CPU_S,
    }))  # fmt: skip
    return 0


CHILD = """
import json, sys
from bench.env_throughput import NAVS, make_policy, measure
from worlds.vector_env import NavigationVectorEnv
nav, n, policy, seconds, seed = sys.argv[1:]
config, n = NAVS[nav], int(n)
env = NavigationVectorEnv(n, config, threads=1)
print(json.dumps(measure(env, n, float(seconds), 10**9, int(seed), make_policy(config, policy))))
"""
"""one measurement of our env in the tree it runs in (cwd), as a JSON line"""


def measure_in(tree: Path, nav: str, n: int, policy: str, seconds: float, seed: int) -> dict:
    """:func:`measure` of ``tree``'s own code, in a subprocess started there."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cmd = [sys.executable, "-c", CHILD, nav, str(n), policy, str(seconds), str(seed)]
    done = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare_trees(args) -> int:
    """Robot-steps per CPU second of our env (1 thread) in ``args.compare_tree`` ("before") and in this
    tree ("after"), interleaved ``args.rounds`` times per robot count and policy."""
    here, other = Path(__file__).resolve().parent.parent, Path(args.compare_tree).resolve()
    for tree in (other, here):  # compile (numba caches) outside the timed runs
        measure_in(tree, args.nav, 1, "random", 0.2, args.seed)
    load_before, results = os.getloadavg(), []
    for policy in args.policies:
        for n in args.robots:
            runs: dict[str, list[float]] = {"before": [], "after": []}
            for _ in range(args.rounds):
                for name, tree in (("before", other), ("after", here)):
                    row = measure_in(tree, args.nav, n, policy, args.seconds, args.seed)
                    runs[name].append(row["robot_steps_per_cpu_s"])
            before, after = float(np.median(runs["before"])), float(np.median(runs["after"]))
            met = after >= TARGET_LEARNING_STEPS_PER_CPU_S
            results.append({"policy": policy, "robots": n, "before_cpu": runs["before"],
                            "after_cpu": runs["after"], "median_before": before, "median_after": after,
                            "speedup": after / before, "target_met": met})  # fmt: skip
            print(f"{policy:6s} actions, {n:4d} robots: before {before:>9,.0f}, after {after:>9,.0f} "
                  f"robot-steps per CPU s (median of {args.rounds}), x{after / before:.2f}")  # fmt: skip
    print(json.dumps({
        "bench": "env_throughput_compare", "nav": args.nav, "before_tree": str(other),
        "after_tree": str(here),
        "seconds": args.seconds, "rounds": args.rounds, "load_average_before": load_before,
        "load_average_after": os.getloadavg(), "results": results,
        "learning_target_steps_per_cpu_s": TARGET_LEARNING_STEPS_PER_CPU_S,
        "learning_target_met_cpu": all(r["target_met"] for r in results),
    }))  # fmt: skip
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 64, 1024], help="robot counts")
    parser.add_argument("--seconds", type=float, default=4.0, help="time per measurement of our env")
    parser.add_argument(
        "--baseline-seconds", type=float, default=4.0, help="time per SyncVectorEnv measurement"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--threads",
        type=int,
        default=os.cpu_count() or 1,
        help="threads of the threaded measurement (default: the core count)",
    )
    parser.add_argument("--nav", choices=list(NAVS), default="default", help="NavConfig() or LEARNING_NAV")
    parser.add_argument(
        "--policy", choices=["random", "goal"], default="random",
        help="random actions, or worlds.heuristics.goal_seeking_policy (longer episodes)",
    )  # fmt: skip
    parser.add_argument(
        "--reuse-ablation", type=int, default=0, metavar="ROUNDS",
        help="instead: our env (1 thread) with the perception's reuse off and on, interleaved ROUNDS times",
    )  # fmt: skip
    parser.add_argument(
        "--compare-tree", metavar="PATH",
        help="instead: our env (1 thread) in the checkout PATH and in this tree, interleaved --rounds times",
    )  # fmt: skip
    parser.add_argument("--rounds", type=int, default=3, help="rounds of --compare-tree")
    parser.add_argument("--policies", nargs="+", choices=["random", "goal"], default=["random", "goal"],
                        help="action policies of --compare-tree")  # fmt: skip
    args = parser.parse_args()
    config = NAVS[args.nav]
    if args.compare_tree:
        return compare_trees(args)
    if args.reuse_ablation:
        return reuse_ablation(config, args)
    load_before = os.getloadavg()[0]
    results = []
    for n in args.robots:
        policy = make_policy(config, args.policy)
        ours = measure(NavigationVectorEnv(n, config, threads=1), n, args.seconds, 10**9, args.seed, policy)
        threaded = None
        if n >= 64 and args.threads > 1:
            env = NavigationVectorEnv(n, config, threads=args.threads)
            threaded = measure(env, n, args.seconds, 10**9, args.seed, policy)
            threaded["threads"] = env.batch.threads
            env.close()
        sync = SyncVectorEnv(
            [lambda: gym.make("navlearn/Navigation-v0", config=config) for _ in range(n)],
            autoreset_mode=AutoresetMode.SAME_STEP,
        )
        base = measure(sync, n, args.baseline_seconds, 10**9, args.seed, policy)
        sync.close()
        row = {
            "robots": n,
            "ours": ours,
            "ours_threaded": threaded,
            "sync_vector_env": base,
            "ratio_wall": ours["robot_steps_per_s"] / base["robot_steps_per_s"],
            "ratio_cpu": ours["robot_steps_per_cpu_s"] / base["robot_steps_per_cpu_s"],
            "ratio_threaded_wall": None
            if threaded is None
            else threaded["robot_steps_per_s"] / base["robot_steps_per_s"],
        }
        results.append(row)
        print(
            f"{n:5d} robots: ours 1 thread {ours['robot_steps_per_s']:>12,.0f} robot-steps/s "
            f"({ours['robot_steps_per_cpu_s']:>12,.0f} per CPU s), SyncVectorEnv "
            f"{base['robot_steps_per_s']:>9,.0f} ({base['robot_steps_per_cpu_s']:>9,.0f}), "
            f"ratio {row['ratio_wall']:.0f}x wall / {row['ratio_cpu']:.0f}x CPU "
            f"(mean episode {ours['mean_episode_length']:.1f} steps)"
        )
        if threaded is not None:
            print(
                f"{'':13s}ours {threaded['threads']} threads {threaded['robot_steps_per_s']:>11,.0f} "
                f"robot-steps/s wall, ratio {row['ratio_threaded_wall']:.0f}x wall"
            )
    largest = results[-1]
    threaded_ratio = largest["ratio_threaded_wall"]
    summary = {
        "bench": "env_throughput",
        "config": f"{'NavConfig() defaults' if args.nav == 'default' else 'LEARNING_NAV'}, maps mixed:16, "
        f"{args.policy} actions; ours with threads=1 and threads={args.threads} ({os.cpu_count()} cores)",
        "nav": args.nav,
        "observation_dim": NavigationVectorEnv(1, config).batch.obs_dim,
        "load_average_before": load_before,
        "load_average_after": os.getloadavg()[0],
        "results": results,
        "target_steps_per_s": TARGET_STEPS_PER_S,
        "target_ratio": TARGET_RATIO,
        "steps_per_s_met_wall": largest["ours"]["robot_steps_per_s"] >= TARGET_STEPS_PER_S,
        "steps_per_s_met_cpu": largest["ours"]["robot_steps_per_cpu_s"] >= TARGET_STEPS_PER_S,
        "ratio_met_wall": largest["ratio_wall"] >= TARGET_RATIO,
        "ratio_met_cpu": largest["ratio_cpu"] >= TARGET_RATIO,
        "ratio_met_threaded_wall": threaded_ratio is not None and threaded_ratio >= TARGET_RATIO,
    }
    if args.nav == "learning":
        cpu = largest["ours"]["robot_steps_per_cpu_s"]
        summary["learning_target_steps_per_cpu_s"] = TARGET_LEARNING_STEPS_PER_CPU_S
        summary["learning_target_met_cpu"] = cpu >= TARGET_LEARNING_STEPS_PER_CPU_S
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())

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
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import worlds  # noqa: F401  (registers navlearn/Navigation-v0)
from worlds.config import NavConfig
from worlds.vector_env import NavigationVectorEnv

TARGET_STEPS_PER_S = 1_000_000
TARGET_RATIO = 200.0


def measure(env, n: int, seconds: float, max_steps: int, seed: int) -> dict:
    """Step ``env`` (``n`` robots) with random actions for about ``seconds`` (at most
    ``max_steps`` env steps) after a warm-up; robot-steps per wall and per CPU second."""
    env.reset(seed=seed)
    actions = np.random.default_rng(seed).integers(NavConfig().robot.n_actions, size=(256, n))
    for t in range(3):  # warm-up (compiled code loaded, caches filled)
        env.step(actions[t])
    steps, ended = 0, 0
    wall0, cpu0 = time.perf_counter(), time.process_time()
    while steps < max_steps and time.perf_counter() - wall0 < seconds:
        _, _, terminated, truncated, _ = env.step(actions[steps % 256])
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
    args = parser.parse_args()
    config = NavConfig()
    load_before = os.getloadavg()[0]
    results = []
    for n in args.robots:
        ours = measure(NavigationVectorEnv(n, config, threads=1), n, args.seconds, 10**9, args.seed)
        threaded = None
        if n >= 64 and args.threads > 1:
            env = NavigationVectorEnv(n, config, threads=args.threads)
            threaded = measure(env, n, args.seconds, 10**9, args.seed) | {"threads": env.batch.threads}
            env.close()
        sync = SyncVectorEnv(
            [lambda: gym.make("navlearn/Navigation-v0", config=config) for _ in range(n)],
            autoreset_mode=AutoresetMode.SAME_STEP,
        )
        base = measure(sync, n, args.baseline_seconds, 10**9, args.seed)
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
        "config": "NavConfig() defaults, maps mixed:16, random actions; ours with threads=1 and "
        f"threads={args.threads} ({os.cpu_count()} cores)",
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
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())

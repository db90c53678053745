"""Evaluation speed and a paired comparison: the shipped NNQL policy against the goal-seeking heuristic.

Measures ``agents.evaluation.evaluate`` in episodes per wall-clock second and per CPU second of
this process on the headline sets (``--episodes`` per set, default 500, of ``unseen`` and
``dynamic``, seed 0), for the shipped NNQL policy (``pretrained/nnql``, a 11-128-128-5 MLP) and
for the heuristic of ``worlds.heuristics`` (numpy only, no matrix product). It also times the
policy call alone on a ``(--batch, 11)`` observation batch with BLAS at its library default
threads and held to one thread: on a busy machine the difference is what made evaluation slow.
Then it compares the two policies on the same episodes (``agents.evaluation.compare``: exact
McNemar, per map family, path ratio on jointly solved episodes) and prints the table. The policy
acts through its reading shield and the shield's disc tracker, as ``navlearn evaluate`` runs it
(:mod:`agents.shield`, :mod:`agents.disc_tracker`); the same
network without the shield (``network``) is run and compared on the same episodes too.

    python bench/evaluation.py       # human lines, then one JSON object on the last line
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from threadpoolctl import threadpool_info, threadpool_limits

from agents.evaluation import compare, evaluate, make_eval_set
from agents.evaluation.policies import load_policy
from worlds.heuristics import goal_seeking_policy

PRETRAINED = Path(__file__).resolve().parents[1] / "pretrained" / "nnql"


def timed(fn, *args):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn(*args)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def call_ms(policy, obs: np.ndarray, calls: int) -> float:
    for _ in range(3):
        policy(obs)
    t = time.perf_counter()
    for _ in range(calls):
        policy(obs)
    return 1e3 * (time.perf_counter() - t) / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500, help="episodes per set")
    parser.add_argument("--batch", type=int, default=128, help="observation batch of the policy-call timing")
    parser.add_argument("--calls", type=int, default=100, help="policy calls per timing")
    args = parser.parse_args()

    network = load_policy(PRETRAINED)
    nnql = load_policy(PRETRAINED).use_shield(network.nav_config())
    heuristic = goal_seeking_policy()
    sets, set_wall, _ = timed(
        lambda: [make_eval_set(f, args.episodes, seed=0) for f in ("unseen", "dynamic")]
    )
    evaluate(nnql, make_eval_set("unseen", 4, seed=9))  # compiled code loaded
    n_episodes = sum(len(s) for s in sets)

    obs = np.random.default_rng(0).uniform(0, 1, (args.batch, nnql.obs_dim)).astype(np.float32)
    blas = [(i["internal_api"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]
    default_ms = call_ms(nnql, obs, args.calls)
    with threadpool_limits(limits=1, user_api="blas"):
        one_ms = call_ms(nnql, obs, args.calls)
    print(
        f"policy call, batch {args.batch}: {default_ms:.3f} ms with BLAS {blas}, "
        f"{one_ms:.3f} ms on one thread"
    )

    report: dict = {
        "episodes_per_set": args.episodes,
        "make_sets_s": round(set_wall, 2),
        "policy_call_ms": {"blas_default": round(default_ms, 4), "blas_1": round(one_ms, 4), "blas": blas},
        "load_avg_1m": round(os.getloadavg()[0], 2),
    }
    results = {}
    for name, policy in (("nnql", nnql), ("network", network), ("heuristic", heuristic)):
        result, wall, cpu = timed(evaluate, policy, sets)
        results[name] = result
        report[name] = {
            "episodes_per_s": round(n_episodes / wall, 1),
            "episodes_per_cpu_s": round(n_episodes / cpu, 1),
            "success": {k: m.success.to_dict() for k, m in result.metrics.items()},
        }
        print(
            f"{name}: {n_episodes} episodes in {wall:.2f} s "
            f"({n_episodes / wall:.0f}/s, {n_episodes / cpu:.0f}/CPU-s)"
        )
    comparison = compare(results["nnql"], results["heuristic"], names=("nnql (pretrained)", "heuristic"))
    print(comparison.table())
    report["compare"] = comparison.to_dict()
    shield = compare(results["nnql"], results["network"], names=("nnql (shielded)", "network alone"))
    print(shield.table())
    report["compare_shield"] = shield.to_dict()
    report["load_avg_1m_end"] = round(os.getloadavg()[0], 2)
    print(json.dumps(report))


if __name__ == "__main__":
    main()

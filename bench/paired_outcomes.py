"""Per-episode outcomes of a saved policy on fixed validation sets, so that two versions of the code
(two trees, or a change to the world) can be compared episode by episode: exact McNemar
(:func:`agents.evaluation.compare.mcnemar_exact`) and Wilson intervals
(:func:`agents.evaluation.metrics.wilson_interval`).

The sets: generated ``mixed`` maps of each ``--sizes`` side at every ``--cells`` factor (each cell
split k x k, the walls in metres unchanged: :func:`bench.map_size_parts.finer`; a 2,000-step limit,
as ``map_size_parts``'s ``long`` variant, so that only the policy's driving decides), and each
``--maps`` file with the world's step rule (``bench.map_sizes --map``'s episodes). Run it once per
tree, then compare::

    PYTHONPATH=<tree> python -m bench.paired_outcomes --out before.json
    python -m bench.paired_outcomes --compare before.json after.json

The last line printed is one JSON object (each set's success rate, or the comparison's rows).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from agents.evaluation import evaluate, make_eval_set, make_map_eval_set
from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.metrics import wilson_interval
from agents.evaluation.policies import load_policy
from agents.evaluation.runner import fixed_sampler
from agents.planning.astar import astar
from bench.map_size_parts import finer
from bench.map_sizes import throughput
from worlds.outcomes import OUTCOME_NAMES, Outcome
from worlds.tasks import MIXED_FAMILIES

GOAL = OUTCOME_NAMES[int(Outcome.GOAL)]
LONG_LIMIT = 2000
"""the step limit of the generated sets (``bench.map_size_parts``'s ``long`` variant)"""


def outcomes(args: argparse.Namespace, cost: dict[str, dict] | None = None) -> dict[str, list[str]]:
    """Each set's outcome names, episode by episode, in a fixed order; ``cost`` gets the world's
    robot-steps per CPU-second on each generated set's maps (:func:`bench.map_sizes.throughput`: the
    heuristic driving 16 robots, ``--throughput-seconds`` each; 0: not measured)."""
    cost = {} if cost is None else cost

    def run_set(name: str, eval_set, config) -> None:
        out[name] = _names(evaluate(policy, eval_set, config), eval_set)
        line = f"{len(out)}. {name}: {_rate(out)}"
        if args.throughput_seconds > 0 and name.startswith("mixed"):
            maps = fixed_sampler(eval_set.tasks, name)
            cost[name] = throughput(nav, 0, args.throughput_seconds, args.seed, maps=maps)
            line += f"; world {cost[name]['robot_steps_per_cpu_s']:,.0f} robot-steps per CPU-second"
        print(line, flush=True)

    policy = load_policy(args.policy)
    nav = policy.nav_config()
    long_nav = replace(nav, max_steps=LONG_LIMIT)
    out: dict[str, list[str]] = {}
    for size in args.sizes:
        es = make_eval_set("unseen", args.episodes, seed=args.seed, size=size, families=MIXED_FAMILIES)
        for k in args.cells:
            run = es
            if k > 1:
                tasks = tuple(finer(t, k) for t in es.tasks)
                shortest = np.array([astar(t.grid, t.start, t.goal).length for t in tasks])
                run = replace(es, tasks=tasks, shortest=shortest)
            run_set(f"mixed:{size}, cell {1.0 / k:g} m", run, long_nav)
    for path in args.maps:
        es = make_map_eval_set(str(path), args.map_episodes, seed=args.seed)
        run_set(Path(path).name, es, nav)
    return out


def _names(result, eval_set) -> list[str]:
    return [OUTCOME_NAMES[e.outcome] for e in result.episodes[eval_set.family]]


def _failures(names: list[str]) -> dict[str, int]:
    kinds, counts = np.unique([n for n in names if n != GOAL], return_counts=True)
    return {str(k): int(c) for k, c in zip(kinds, counts, strict=True)}


def _rate(out: dict[str, list[str]]) -> str:
    last = list(out.values())[-1]
    return f"{100 * np.mean(np.array(last) == GOAL):.1f}% of {len(last)}"


def compare(before: dict[str, list[str]], after: dict[str, list[str]]) -> list[dict]:
    """One row per set both runs have: success before and after, discordant pairs, McNemar p."""
    rows = []
    for name, old in before.items():
        if name not in after:
            continue
        a, b = np.array(old) == GOAL, np.array(after[name]) == GOAL
        n = len(a)
        if len(b) != n:
            raise ValueError(f"set {name!r}: {n} episodes before, {len(b)} after; not the same episodes")
        only_old, only_new = int((a & ~b).sum()), int((b & ~a).sum())
        r = {
            "set": name, "episodes": n, "before": float(a.mean()), "after": float(b.mean()),
            "before_ci": list(wilson_interval(int(a.sum()), n)),
            "after_ci": list(wilson_interval(int(b.sum()), n)),
            "only_before": only_old, "only_after": only_new, "p": mcnemar_exact(only_old, only_new),
            "failures_before": _failures(old), "failures_after": _failures(after[name]),
        }  # fmt: skip
        rows.append(r)
        lo_a, hi_a, lo_b, hi_b = (100 * v for v in (*r["before_ci"], *r["after_ci"]))
        print(f"{name:<26} n {n}: {100 * r['before']:5.1f} [{lo_a:4.1f}, {hi_a:5.1f}] -> "
              f"{100 * r['after']:5.1f} [{lo_b:4.1f}, {hi_b:5.1f}]; only before {only_old}, "
              f"only after {only_new}, McNemar p {r['p']:.2g}; "
              f"failures {r['failures_before']} -> {r['failures_after']}")  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--policy", default="pretrained/nnql", help="saved policy directory")
    parser.add_argument("--seed", type=int, default=1, help="evaluation seed (1: validation; 0 is the test)")
    parser.add_argument("--sizes", type=int, nargs="*", default=[32, 48], help="generated map sides (cells)")
    parser.add_argument("--cells", type=int, nargs="+", default=[1, 10], help="cell split factors (1: 1 m)")
    parser.add_argument("--episodes", type=int, default=200, help="episodes per generated set")
    parser.add_argument("--maps", nargs="*", default=[], help="map files, each a set of its own")
    parser.add_argument("--map-episodes", type=int, default=100, help="episodes per map file")
    parser.add_argument(
        "--throughput-seconds", type=float, default=5.0, help="world timing per generated set (0: none)"
    )
    parser.add_argument("--out", help="JSON file for this tree's outcomes")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), help="two --out files")
    args = parser.parse_args(argv)
    if args.compare:
        before, after = (json.loads(Path(p).read_text())["sets"] for p in args.compare)
        rows = compare(before, after)
        print(json.dumps({"bench": "paired_outcomes", "compare": args.compare, "rows": rows}))
        return 0
    if not args.out:
        parser.error("give --out FILE (a run) or --compare BEFORE AFTER")
    record = {"bench": "paired_outcomes", "policy": args.policy, "seed": args.seed,
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "load_average_before": os.getloadavg()[0]}  # fmt: skip
    cost: dict[str, dict] = {}
    sets = outcomes(args, cost)
    record["load_average_after"] = os.getloadavg()[0]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({**record, "cost": cost, "sets": sets}) + "\n")
    success = {k: float(np.mean(np.array(v) == GOAL)) for k, v in sets.items()}
    print(json.dumps({**record, "success": success, "cost": cost}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

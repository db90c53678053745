"""Why does a policy drop on bigger maps? One part changed at a time (issue 39, validation seed).

For each map side and family (``rooms`` and ``mixed``), on the same episodes of the validation seed,
the policy (default the shipped ``pretrained/nnql``) runs in these variants of its world:

* ``base``: as a user gets it (the world's default step limit);
* ``long``: a step limit of ``--long-limit`` steps (2,000: no episode ends for time): what is left
  once the limit is out of the way;
* ``long+clamp``: ``long`` with the observed goal distance clamped to what 16x16 training maps show
  (at most 20 m): is the input scaling of the goal distance the part?
* ``long+known``: ``long`` with the subgoal planned on the true map instead of the robot's own map:
  what exploring with the own-map subgoal costs (an oracle, not a policy a user without a map has);
* ``long+heuristic``: the goal-seeking heuristic in ``long`` (the baseline).

Printed per row: success, static collisions, timeouts, SPL, the mean A* length, and the collisions per
metre of A* path (``-ln(1 - collisions) / mean A*``): if that hazard stays flat with size, bigger maps
only fail more because paths are longer; if it grows, something in bigger maps is new to the policy.

``--cells`` adds the same geometry at finer cells (each cell split in k x k, the world in metres
unchanged, A* re-measured): does the policy depend on the cell size? ``--cell-variants`` names the
variants run there (default ``long``; ``long+known`` at fine cells tells the own map's part from the
policy's).

    python -m bench.map_size_parts --episodes 200 --out results/navigation/parts.jsonl

Human lines, then one JSON object on the last line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.policies import load_policy
from agents.planning.astar import astar
from worlds.heuristics import goal_seeking_policy
from worlds.maps import GridMap, Task

VARIANTS = ("base", "long", "long+clamp", "long+known", "long+heuristic")
CLAMP_M = 20.0
"""the longest goal distance 16x16 training maps show, about (their diagonal is 21 m)"""


def clamped(policy, n_beams: int, max_range: float):
    """``policy`` reading the goal distance clamped to :data:`CLAMP_M` (squashed ``d / (d + max_range)``)."""
    cap = CLAMP_M / (CLAMP_M + max_range)

    def act(obs: np.ndarray) -> np.ndarray:
        obs = obs.copy()
        obs[:, n_beams] = np.minimum(obs[:, n_beams], cap)
        return policy(obs)

    return act


def finer(task: Task, k: int) -> Task:
    """``task`` with every cell split in ``k`` x ``k``: the same walls in metres, cells ``1/k`` as big."""
    grid = task.grid
    blocked = grid.blocked.repeat(k, 0).repeat(k, 1)
    fine = GridMap(blocked, cell_size=grid.cell_size / k, name=f"{grid.name}/{k}")
    start = (task.start[0] * k + k // 2, task.start[1] * k + k // 2)
    goal = (task.goal[0] * k + k // 2, task.goal[1] * k + k // 2)
    return Task(fine, start, goal, fine.name)


def row(result, **keys) -> dict:
    m = result.metrics[next(iter(result.metrics))]
    eps = next(iter(result.episodes.values()))
    shortest = float(np.mean([e.shortest for e in eps]))
    collisions = m.collision_static.value
    return {
        **keys,
        "episodes": m.episodes,
        "success": m.success.value,
        "success_ci": [m.success.low, m.success.high],
        "collision": collisions,
        "timeout": m.timeout.value,
        "spl": m.spl,
        "astar_mean_m": shortest,
        "collisions_per_m": max(-math.log(max(1.0 - collisions, 1e-9)), 0.0) / shortest,
        "steps_max": int(max(e.steps for e in eps)),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--policy", default="pretrained/nnql", help="saved policy directory")
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 48, 64], help="map sides (cells)")
    parser.add_argument(
        "--families", nargs="+", default=["rooms", "mixed"], help="rooms, rects, discs, mixed"
    )
    parser.add_argument("--episodes", type=int, default=200, help="episodes per size and family")
    parser.add_argument("--seed", type=int, default=1, help="evaluation seed (1: validation)")
    parser.add_argument("--long-limit", type=int, default=2000, help="the step limit of the long variants")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--cells", type=int, nargs="*", default=[2, 4], help="finer-cell factors (mixed)")
    parser.add_argument(
        "--cell-variants",
        nargs="+",
        default=["long"],
        choices=VARIANTS,
        help="the variants run at finer cells",
    )
    parser.add_argument("--out", help="JSON lines file for the rows")
    args = parser.parse_args(argv)

    policy = load_policy(args.policy)
    nav = policy.nav_config()
    n_beams, max_range = nav.sensors.n_beams, nav.sensors.max_range
    long_nav = replace(nav, max_steps=args.long_limit)
    worlds = {
        "base": (nav, policy),
        "long": (long_nav, policy),
        "long+clamp": (long_nav, clamped(policy, n_beams, max_range)),
        "long+known": (
            replace(long_nav, observation=replace(long_nav.observation, subgoal="known_map")),
            lambda obs: policy(obs),  # a plain callable: the env observes otherwise than the policy records
        ),
        "long+heuristic": (long_nav, goal_seeking_policy(long_nav)),
    }
    report = {"bench": "map_size_parts", "policy": args.policy, "seed": args.seed, "episodes": args.episodes,
              "max_steps": nav.max_steps, "long_limit": args.long_limit,
              "load_average_before": os.getloadavg()[0],
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "rows": []}  # fmt: skip
    print(f"{args.policy} (v{policy.version}), seed {args.seed}, {args.episodes} episodes per row, load "
          f"{report['load_average_before']:.1f}")  # fmt: skip
    print(f"{'size':>4} {'family':<7} {'variant':<22} {'success %':>9} {'coll. %':>7} {'timeout %':>9} "
          f"{'SPL':>5} {'A* m':>6} {'coll./km':>8}")  # fmt: skip

    def show(r: dict) -> None:
        print(f"{r['size']:>4} {r['family']:<7} {r['variant']:<22} {100 * r['success']:9.1f} "
              f"{100 * r['collision']:7.1f} {100 * r['timeout']:9.1f} {r['spl']:5.2f} "
              f"{r['astar_mean_m']:6.1f} "
              f"{1000 * r['collisions_per_m']:8.2f}")  # fmt: skip
        report["rows"].append(r)

    for size in args.sizes:
        for family in args.families:
            families = ("rects", "discs", "rooms") if family == "mixed" else (family,)
            es = make_eval_set("unseen", args.episodes, seed=args.seed, size=size, families=families)
            for variant in args.variants:
                config, act = worlds[variant]
                show(row(evaluate(act, es, config), size=size, family=family, variant=variant, cell=1.0))
            if family != "mixed" or not args.cells:
                continue
            for k in args.cells:
                tasks = tuple(finer(t, k) for t in es.tasks)
                shortest = np.array([astar(t.grid, t.start, t.goal).length for t in tasks])
                fine = replace(es, tasks=tasks, shortest=shortest)
                for variant in args.cell_variants:
                    config, act = worlds[variant]
                    r = row(
                        evaluate(act, fine, config),
                        size=size,
                        family=family,
                        variant=f"{variant}, cell 1/{k}",
                    )
                    show({**r, "cell": 1.0 / k})
    report["load_average_after"] = os.getloadavg()[0]
    if args.out:
        path = Path(args.out)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w") as fh:
            for r in report["rows"]:
                fh.write(json.dumps(r) + "\n")
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The expert and the evaluation's A* on big map files: seconds per episode.

For each map (default: the 512x512 MovingAI validation maps ``maze512-8-0`` and ``64room_000``)
it draws ``--episodes`` start/goal pairs by A* distance (``worlds.pairs``, ``--min-distance`` to
``--max-distance`` metres) and times, per episode:

* ``astar_s``: the evaluation's grid A* length of the task (``agents.planning.astar.astar``, what
  ``make_eval_set`` computes for SPL);
* ``expert_s``: the modified-A* expert driving the whole episode in ``NavigationEnv`` (its distance
  field, every lattice plan and replan, the env steps), with the step limit of the episode's path;
* ``plan_s``: one lattice plan from the start (``agents.planning.lattice.plan_lattice``);

and reports the median and the largest over the episodes, wall and CPU (user + system) seconds, and
the expert's outcomes. The first episode of each map is run once untimed (numba compiles).

    python -m bench.map_planning                  # human lines, then one JSON object on the last line
    python -m bench.map_planning --episodes 3 --maps path/to/map.yaml
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np

from agents.planning.astar import astar, distance_field
from agents.planning.expert import Expert
from agents.planning.lattice import plan_lattice
from worlds.config import NavConfig
from worlds.env import NavigationEnv
from worlds.outcomes import Outcome
from worlds.tasks import parse_map_spec, with_options

VALIDATION = Path("/work/shared/data/movingai/validation")
DEFAULT_MAPS = [str(VALIDATION / "maze512-8-0.map"), str(VALIDATION / "64room_000.map")]


def _clock() -> tuple[float, float]:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return time.perf_counter(), usage.ru_utime + usage.ru_stime


def _since(start: tuple[float, float]) -> tuple[float, float]:
    wall, cpu = _clock()
    return wall - start[0], cpu - start[1]


def run_expert(env: NavigationEnv, expert: Expert, task, seed: int) -> tuple[int, int]:
    """Drive ``task`` with the expert; returns (outcome, steps)."""
    obs, info = env.reset(seed=seed, options={"task": task})
    expert.reset(task, info["pose"])
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(expert.act(info["pose"], obs))
        done = terminated or truncated
    return int(info["outcome"]), int(info["steps"])


def measure(spec: str, episodes: int, seed: int) -> dict:
    sampler = parse_map_spec(spec)
    grid = sampler.maps[0].grid
    tasks = sampler.draw_pool(episodes, seed)
    nav = NavConfig()
    env = NavigationEnv(nav, maps=sampler)
    expert = Expert(nav)
    run_expert(env, expert, tasks[0], seed)  # compile
    rows = []
    for i, task in enumerate(tasks):
        t = _clock()
        length = astar(task.grid, task.start, task.goal).length
        astar_s = _since(t)
        t = _clock()
        x, y = grid.cell_center(task.start)
        r = nav.robot
        plan_lattice(
            grid, (x, y, 0.0), task.goal, r.turns, r.step, r.radius, nav.goal_tolerance, None, None,
            distance_field(grid, task.goal),
        )  # fmt: skip
        plan_s = _since(t)
        t = _clock()
        outcome, steps = run_expert(env, expert, task, seed + i)
        expert_s = _since(t)
        rows.append((length, astar_s, plan_s, expert_s, outcome, steps))
        print(
            f"  {grid.name} episode {i}: A* {length:6.1f} m in {astar_s[0]:.3f} s; "
            f"one plan {plan_s[0]:.3f} s; "
            f"expert {Outcome(outcome).name.lower()} in {steps} steps, {expert_s[0]:.2f} s wall "
            f"({expert_s[1]:.2f} s CPU)"
        )

    def stats(k: int) -> dict:
        wall = np.array([row[k][0] for row in rows])
        cpu = np.array([row[k][1] for row in rows])
        return {"median_wall": float(np.median(wall)), "max_wall": float(wall.max()),
                "median_cpu": float(np.median(cpu)), "max_cpu": float(cpu.max())}  # fmt: skip

    outcomes = [Outcome(row[4]).name.lower() for row in rows]
    return {
        "map": grid.name,
        "cells": f"{grid.width}x{grid.height}",
        "episodes": len(rows),
        "path_m_median": float(np.median([row[0] for row in rows])),
        "astar_s": stats(1),
        "plan_s": stats(2),
        "expert_s": stats(3),
        "expert_outcomes": {name: outcomes.count(name) for name in sorted(set(outcomes))},
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--maps", nargs="+", default=DEFAULT_MAPS, help="map files (default: two 512x512 maps)"
    )
    parser.add_argument("--episodes", type=int, default=10, help="episodes per map (default 10)")
    parser.add_argument("--min-distance", type=float, default=20.0, help="least A* distance, m (default 20)")
    parser.add_argument(
        "--max-distance", type=float, default=80.0, help="largest A* distance, m (default 80)"
    )
    parser.add_argument("--seed", type=int, default=0, help="pair seed (default 0)")
    args = parser.parse_args()
    results = []
    for path in args.maps:
        spec = with_options(path, min_distance=args.min_distance, max_distance=args.max_distance)
        results.append(measure(spec, args.episodes, args.seed))
    print(json.dumps({"bench": "map_planning", "seed": args.seed, "maps": results}))


if __name__ == "__main__":
    main()

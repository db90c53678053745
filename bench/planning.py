"""Planning and imitation benchmark (issue 5, thesis ch. 3).

(a) our grid A* (numba) against networkx's ``astar_path`` (octile heuristic, the same
    8-connected no-corner-cutting graph, built once and not timed) on the 130 MovingAI
    arena scenarios and on 512x512 generated maps: every length must agree; the figure
    is the time ratio (target: ours >= 5x faster);
(b) the modified-A* expert in the env on the evaluation sets (its success rate);
(c) the imitation policy: expert demonstrations on training maps (``mixed:16``, noise
    0.3), behaviour cloning, then 100 unseen generated maps, static and with 4 moving
    discs, plus the MovingAI arena: success rate with its 95% interval, SPL and path
    length ratio to A*, against a uniform random policy in the same run.

    python -m bench.planning            # human lines, then one JSON object on the last line
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace

import numpy as np

from agents.evaluation import evaluate, make_eval_set
from agents.evaluation.runner import MOVINGAI_DIR, EvalSet, fixed_sampler
from agents.planning import astar
from agents.planning.expert import Expert
from worlds.config import NavConfig
from worlds.env import NavigationEnv
from worlds.generators import generate
from worlds.maps import GridMap, load_movingai, load_scenarios, sample_task
from worlds.outcomes import Outcome


def grid_graph(grid: GridMap):
    """The networkx graph of the MovingAI move rules (octile costs, no corner cutting)."""
    import networkx as nx

    graph = nx.Graph()
    blocked = grid.blocked
    h, w = blocked.shape
    for r, c in np.argwhere(~blocked):
        graph.add_node((int(r), int(c)))
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            nr, nc = r + dr, c + dc
            if not (0 <= nr < h and 0 <= nc < w) or blocked[nr, nc]:
                continue
            if dr and dc and (blocked[r, nc] or blocked[nr, c]):
                continue
            graph.add_edge((int(r), int(c)), (int(nr), int(nc)), weight=math.hypot(dr, dc))
    return graph


def octile(a, b) -> float:
    dr, dc = abs(a[0] - b[0]), abs(a[1] - b[1])
    return max(dr, dc) + (math.sqrt(2) - 1) * min(dr, dc)


def compare_astar(grid: GridMap, pairs: list[tuple], label: str) -> dict:
    import networkx as nx

    graph = grid_graph(grid)
    astar(grid, pairs[0][0], pairs[0][1])  # load the compiled code before timing
    ours_s = nx_s = 0.0
    worst = 0.0
    for start, goal in pairs:
        t = time.perf_counter()
        ours = astar(grid, start, goal)
        ours_s += time.perf_counter() - t
        t = time.perf_counter()
        path = nx.astar_path(graph, start, goal, heuristic=octile, weight="weight")
        length = nx.path_weight(graph, path, weight="weight")
        nx_s += time.perf_counter() - t
        worst = max(worst, abs(ours.length - length))
    ratio = nx_s / ours_s
    print(
        f"A* {label}: {len(pairs)} searches, ours {1e3 * ours_s / len(pairs):.3f} ms, networkx "
        f"{1e3 * nx_s / len(pairs):.2f} ms per search, {ratio:.1f}x, max length difference {worst:.2e}"
    )
    n = len(pairs)
    return {"searches": n, "ours_ms": 1e3 * ours_s / n, "networkx_ms": 1e3 * nx_s / n, "speedup": ratio,
            "max_length_diff": worst}  # fmt: skip


def expert_outcomes(eval_set: EvalSet, config: NavConfig) -> list[int]:
    """The expert's outcome (worlds.outcomes.Outcome) on each episode of ``eval_set`` (same tasks,
    seeds, discs), in the world ``config`` (its observation is what the expert reads its beams from)."""
    config = replace(config, obstacles=eval_set.obstacles)
    env = NavigationEnv(config, maps=fixed_sampler(eval_set.tasks, f"bench:{eval_set.family}"))
    expert = Expert(config)
    outcomes = []
    for task, seed in zip(eval_set.tasks, eval_set.seeds, strict=True):
        obs, info = env.reset(seed=seed, options={"task": task})
        expert.reset(task, info["pose"])
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert.act(info["pose"], obs))
            done = terminated or truncated
        outcomes.append(int(info["outcome"]))
    return outcomes


def expert_success(eval_set: EvalSet, config: NavConfig) -> float:
    """The expert's success on exactly the episodes of ``eval_set`` (same tasks, seeds, discs)."""
    return float(np.mean([o == Outcome.GOAL for o in expert_outcomes(eval_set, config)]))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--big-maps", type=int, default=3, help="512x512 generated maps (rects, rooms, maze)")
    parser.add_argument("--pairs", type=int, default=4, help="start/goal pairs per 512x512 map")
    parser.add_argument("--demo-episodes", type=int, default=1500, help="expert episodes for imitation")
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per map type")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    out: dict = {"date": "2026-11-23"}

    # (a) grid A* against networkx
    arena = load_movingai(MOVINGAI_DIR / "arena.map")
    scenarios = load_scenarios(MOVINGAI_DIR / "arena.map.scen", arena)
    optimal_err = max(abs(astar(arena, s.start, s.goal).length - s.optimal_length) for s in scenarios)
    print(f"arena: all {len(scenarios)} scenario lengths within {optimal_err:.1e} of the listed optimum")
    out["astar_arena"] = compare_astar(arena, [(s.start, s.goal) for s in scenarios], "arena 49x49")
    out["astar_arena"]["max_optimal_diff"] = optimal_err
    big = {"searches": 0, "ours_s": 0.0, "networkx_s": 0.0, "max_length_diff": 0.0}
    rng = np.random.default_rng(args.seed)
    for k, family in enumerate(("rects", "rooms", "maze")[: args.big_maps]):
        grid = generate(family, 512, 512, seed=args.seed + k)
        pairs = []
        for _ in range(args.pairs):
            task = sample_task(grid, rng, min_distance=250.0)
            pairs.append((task.start, task.goal))
        r = compare_astar(grid, pairs, f"{family} 512x512")
        big["searches"] += r["searches"]
        big["ours_s"] += r["ours_ms"] * r["searches"] / 1e3
        big["networkx_s"] += r["networkx_ms"] * r["searches"] / 1e3
        big["max_length_diff"] = max(big["max_length_diff"], r["max_length_diff"])
    big["speedup"] = big["networkx_s"] / big["ours_s"]
    print(f"A* 512x512 overall: {big['speedup']:.1f}x faster than networkx")
    out["astar_512"] = big

    # (b, c) expert, imitation, random on the same evaluation sets
    from agents.imitation.config import ImitationConfig
    from agents.imitation.train import train_policy
    from agents.planning.demonstrate import generate_demos

    config = NavConfig()
    t = time.perf_counter()
    demos, stats = generate_demos("mixed:16", args.demo_episodes, seed=args.seed, noise=0.3, config=config)
    print(f"demos: {stats.kept}/{stats.episodes} expert episodes kept, {stats.steps} steps, "
          f"{time.perf_counter() - t:.0f} s")  # fmt: skip
    t = time.perf_counter()
    result = train_policy(demos, ImitationConfig(seed=args.seed), n_actions=config.robot.n_actions)
    best = result.best
    print(f"imitation: {len(result.history)} epochs, best {result.best_epoch}, val accuracy "
          f"{best['val_accuracy']:.3f}, {time.perf_counter() - t:.0f} s")  # fmt: skip
    out["demos"] = {"episodes": stats.episodes, "kept": stats.kept, "steps": stats.steps}
    out["training"] = {"epochs": len(result.history), "best_epoch": result.best_epoch,
                       "val_accuracy": best["val_accuracy"], "val_loss": best["val_loss"]}  # fmt: skip
    sets = [make_eval_set(f, args.episodes, seed=args.seed) for f in ("unseen", "dynamic", "movingai")]
    learned = evaluate(result.policy(), sets, config)
    print("imitation policy:\n" + learned.table())
    rand_rng = np.random.default_rng(args.seed)
    random = evaluate(lambda obs: rand_rng.integers(0, config.robot.n_actions, len(obs)), sets, config)
    print("random policy:\n" + random.table())
    out["imitation"] = {}
    for es in sets:
        m, r = learned.metrics[es.family], random.metrics[es.family]
        expert = expert_success(es, config)
        print(
            f"{es.family}: expert {expert:.1%}, imitation {m.success.value:.1%}, random {r.success.value:.1%}"
        )
        out["imitation"][es.family] = {
            "success": m.success.value, "success_ci": [m.success.low, m.success.high],
            "collision_static": m.collision_static.value, "collision_dynamic": m.collision_dynamic.value,
            "timeout": m.timeout.value, "spl": m.spl,
            "path_ratio": None if math.isnan(m.path_ratio) else m.path_ratio,
            "random_success": r.success.value, "expert_success": expert,
        }  # fmt: skip
    print(json.dumps(out))


if __name__ == "__main__":
    main()

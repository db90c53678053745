"""Per-episode outcomes of the shipped policy on this record's validation sets (seed 1), so that two
versions of the code can be compared episode by episode (exact McNemar,
:func:`agents.evaluation.compare.mcnemar_exact`; Wilson intervals, :mod:`agents.evaluation.metrics`).

The sets are those of ``bench.map_sizes --map`` (the two map_server files, the world's step rule) and
of ``bench.map_size_parts --sizes 32 --families mixed --variants long --cells 4`` (mixed:32 at 1 m and
with every cell split 4x4, a 2,000-step limit), 100 episodes each. Run it once per tree, then compare::

    PYTHONPATH=<tree> python results/maps/inflation/paired.py --out before.json
    python results/maps/inflation/paired.py --compare before.json after.json

``--digest`` prints a SHA-256 of the observations and rewards of a seeded rollout on 1 m maps
(mixed:32, the shipped policy's world, 16 robots, 400 steps, half of them at random): equal digests
on two trees mean the 1 m world is bit-for-bit the same.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from agents.evaluation import evaluate, make_eval_set, make_map_eval_set
from agents.evaluation.compare import mcnemar_exact
from agents.evaluation.metrics import wilson_interval
from agents.evaluation.policies import load_policy
from agents.planning.astar import astar
from bench.map_size_parts import finer
from worlds.heuristics import goal_seeking_policy
from worlds.outcomes import OUTCOME_NAMES, Outcome
from worlds.vector_env import NavigationVectorEnv

HERE = Path(__file__).resolve()
POLICY = HERE.parents[3] / "pretrained" / "nnql"
MAPS = Path("/work/shared/data/map_server")
SEED, EPISODES = 1, 100


def outcomes() -> dict[str, list[str]]:
    """Each set's outcome names, episode by episode."""
    policy = load_policy(str(POLICY))
    nav = policy.nav_config()
    long_nav = replace(nav, max_steps=2000)
    out = {}
    for name in ("smoothers_world", "tb3_sandbox"):
        es = make_map_eval_set(str(MAPS / f"{name}.yaml"), EPISODES, seed=SEED)
        out[name] = evaluate(policy, es, nav).episodes[es.family]
    es = make_eval_set("unseen", EPISODES, seed=SEED, size=32, families=("rects", "discs", "rooms"))
    out["mixed:32 long"] = evaluate(policy, es, long_nav).episodes[es.family]
    tasks = tuple(finer(t, 4) for t in es.tasks)
    fine = replace(es, tasks=tasks, shortest=np.array([astar(t.grid, t.start, t.goal).length for t in tasks]))
    out["mixed:32 long, cell 1/4"] = evaluate(policy, fine, long_nav).episodes[fine.family]
    return {name: [OUTCOME_NAMES[e.outcome] for e in eps] for name, eps in out.items()}


def digest(n: int = 16, steps: int = 400) -> str:
    """SHA-256 of a seeded rollout's observations and rewards on mixed:32 (1 m cells)."""
    nav = load_policy(str(POLICY)).nav_config()
    env = NavigationVectorEnv(n, nav, maps="mixed:32", threads=1)
    obs, _ = env.reset(seed=SEED)
    rng, seek = np.random.default_rng(SEED), goal_seeking_policy(nav)
    width = nav.sensors.n_beams + 3
    sha = hashlib.sha256(obs.tobytes())
    for _ in range(steps):
        actions = seek(obs[:, :width])
        actions[::2] = rng.integers(nav.robot.n_actions, size=len(actions[::2]))
        obs, reward, *_ = env.step(actions)
        sha.update(obs.tobytes())
        sha.update(reward.tobytes())
    env.close()
    return sha.hexdigest()


def compare(before: dict, after: dict) -> None:
    goal = OUTCOME_NAMES[int(Outcome.GOAL)]
    for name, old in before.items():
        new = after[name]
        a, b = np.array(old) == goal, np.array(new) == goal
        n = len(a)
        lo_a, hi_a = wilson_interval(int(a.sum()), n)
        lo_b, hi_b = wilson_interval(int(b.sum()), n)
        only_old, only_new = int((a & ~b).sum()), int((b & ~a).sum())
        print(f"{name:<24} n {n}: {100 * a.mean():5.1f} [{100 * lo_a:4.1f}, {100 * hi_a:5.1f}] -> "
              f"{100 * b.mean():5.1f} [{100 * lo_b:4.1f}, {100 * hi_b:5.1f}]; only before {only_old}, "
              f"only after {only_new}, McNemar p {mcnemar_exact(only_old, only_new):.2g}; "
              f"identical outcomes: {old == new}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", help="JSON file for this tree's outcomes")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), help="two --out files")
    parser.add_argument("--digest", action="store_true", help="the 1 m rollout's SHA-256")
    args = parser.parse_args()
    if args.digest:
        print(digest())
    elif args.compare:
        compare(*(json.loads(Path(p).read_text()) for p in args.compare))
    elif args.out:
        Path(args.out).write_text(json.dumps(outcomes(), indent=1) + "\n")
    else:
        parser.error("give --out, --compare or --digest")


if __name__ == "__main__":
    main()
